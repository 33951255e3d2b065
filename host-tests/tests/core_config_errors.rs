//! Configuration validation as issue 2 asks: each bad input is rejected with an error naming
//! the item and the value (in the error and in its `Display` text), and a rejected
//! configuration changes nothing. Also the TOML layer: syntax errors with their line,
//! unknown fields, and invalid-but-well-formed files.

#[path = "reference_support.rs"]
mod support;

use detector_core::config::LoadError;
use detector_core::{
    CdfError, CdfSpec, Config, ConfigError, Detector, Item, Problem, StageError, StageSpec, Window,
};
use support::*;

/// A valid configuration: channels `a b`, features `fa` (raw a), `fb` (raw b), event `e` with
/// a context term on `fb` and sensor terms on `fa` and `fb`, phase `p`.
fn good() -> Config {
    config(
        1000.0,
        &["a", "b"],
        vec![("fa", raw("a")), ("fb", raw("b"))],
        vec![event(
            "e",
            vec![context("fb", sigmoid(0.0, 1.0))],
            vec![
                sensor("fa", 0.5, sigmoid(0.0, 1.0)),
                sensor("fb", 0.5, sigmoid(0.0, 1.0)),
            ],
        )],
        vec![phase("p", &["e"])],
    )
}

/// Builds `bad` (made from [`good`] by `change`), expects an error, and checks that the
/// configuration is untouched and that `Display` names each of `words`.
fn reject(change: impl FnOnce(&mut Config), words: &[&str]) -> ConfigError {
    let mut bad = good();
    change(&mut bad);
    let before = bad.clone();
    let err = Detector::build(&bad).expect_err("must be rejected");
    assert_eq!(
        format!("{bad:?}"),
        format!("{before:?}"),
        "build changed its input"
    );
    let text = err.to_string();
    for w in words {
        assert!(text.contains(w), "{text:?} does not name {w:?}");
    }
    err
}

fn item_sensor(e: &str, f: &str) -> Item {
    Item::SensorTerm(name(e), name(f))
}

#[test]
fn the_good_config_builds() {
    assert!(Detector::build(&good()).is_ok());
}

#[test]
fn weights_summing_above_one() {
    let err = reject(
        |c| c.events[0].sensor[1].weight = 0.6,
        &["event 'e'", "1.1", "above 1"],
    );
    assert_eq!(err.item, Item::Event(name("e")));
    assert!(matches!(err.problem, Problem::WeightSum(s) if (s - 1.1).abs() < 1e-6));
}

#[test]
fn a_weight_outside_zero_one() {
    for w in [-0.25f32, 1.5] {
        let err = reject(
            |c| c.events[0].sensor[0].weight = w,
            &["event 'e', sensor term 'fa'", &w.to_string()],
        );
        assert_eq!(
            err,
            ConfigError {
                item: item_sensor("e", "fa"),
                problem: Problem::Weight(w)
            }
        );
    }
}

#[test]
fn cdf_parameters_out_of_order() {
    let err = reject(
        |c| c.events[0].sensor[0].cdf = sigmoid(2.0, 1.0),
        &["sensor term 'fa'", "low = 2", "high = 1"],
    );
    assert_eq!(
        err,
        ConfigError {
            item: item_sensor("e", "fa"),
            problem: Problem::Cdf(CdfError::OutOfOrder {
                first: "low",
                first_value: 2.0,
                second: "high",
                second_value: 1.0
            })
        }
    );
    let err = reject(
        |c| {
            c.events[0].context[0].cdf = CdfSpec::FlatBell {
                low: 0.0,
                plateau_low: 3.0,
                plateau_high: 2.0,
                high: 4.0,
            }
        },
        &["context term 'fb'", "plateau_low = 3", "plateau_high = 2"],
    );
    assert_eq!(err.item, Item::ContextTerm(name("e"), name("fb")));
    // Equal ends of a sigmoid, and a bell without width.
    reject(
        |c| c.events[0].sensor[0].cdf = sigmoid(1.0, 1.0),
        &["low = 1", "high = 1"],
    );
    let err = reject(
        |c| {
            c.events[0].sensor[0].cdf = CdfSpec::Bell {
                center: 0.0,
                half_width: 0.0,
            }
        },
        &["half_width = 0"],
    );
    assert!(matches!(
        err.problem,
        Problem::Cdf(CdfError::TooNarrow { .. })
    ));
}

#[test]
fn nan_anywhere() {
    let nan = f32::NAN;
    let e = reject(|c| c.rate_hz = nan, &["configuration", "NaN"]);
    assert!(matches!(e.problem, Problem::Rate(r) if r.is_nan()));
    let e = reject(
        |c| c.events[0].sensor[0].cdf = sigmoid(nan, 1.0),
        &["sensor term 'fa'", "low = NaN"],
    );
    assert!(matches!(
        e.problem,
        Problem::Cdf(CdfError::NotRepresentable { param: "low", value }) if value.is_nan()
    ));
    let e = reject(
        |c| c.events[0].sensor[0].weight = nan,
        &["sensor term 'fa'", "weight = NaN"],
    );
    assert!(matches!(e.problem, Problem::Weight(w) if w.is_nan()));
    let e = reject(
        |c| c.events[0].alert.on = nan,
        &["event 'e', alert level", "on = NaN"],
    );
    assert_eq!(e.item, Item::Level(name("e"), "alert"));
    let e = reject(
        |c| c.events[0].confirm.dwell_ms = nan,
        &["confirm level", "dwell_ms = NaN"],
    );
    assert!(matches!(e.problem, Problem::Dwell(d) if d.is_nan()));
    let e = reject(
        |c| {
            c.features[0].stage = StageSpec::LowPass {
                input: name("a"),
                cutoff_hz: nan,
            }
        },
        &["feature 'fa'", "cutoff_hz = NaN"],
    );
    assert_eq!(e.item, Item::Feature(name("fa")));
    let e = reject(|c| c.events[0].onset_level = nan, &["onset_level = NaN"]);
    assert_eq!(e.item, Item::Event(name("e")));
}

#[test]
fn infinity_anywhere() {
    let inf = f32::INFINITY;
    reject(|c| c.rate_hz = inf, &["configuration", "inf"]);
    let e = reject(
        |c| {
            c.events[0].context[0].cdf = CdfSpec::Binary {
                threshold: -inf,
                above: true,
            }
        },
        &["context term 'fb'", "threshold = -inf"],
    );
    assert_eq!(e.item, Item::ContextTerm(name("e"), name("fb")));
    reject(
        |c| c.events[0].sensor[1].weight = inf,
        &["sensor term 'fb'", "weight = inf"],
    );
    reject(
        |c| c.events[0].alert.dwell_ms = inf,
        &["alert level", "dwell_ms = inf"],
    );
    reject(
        |c| {
            c.features[1].stage = StageSpec::LowPass {
                input: name("b"),
                cutoff_hz: inf,
            }
        },
        &["feature 'fb'", "cutoff_hz = inf"],
    );
    // Finite but beyond the 16.16 range.
    reject(
        |c| c.events[0].sensor[0].cdf = sigmoid(0.0, 40000.0),
        &["high = 40000"],
    );
}

#[test]
fn an_unknown_channel() {
    let e = reject(
        |c| c.features[0].stage = raw("nope"),
        &["feature 'fa'", "'nope'"],
    );
    assert_eq!(
        e,
        ConfigError {
            item: Item::Feature(name("fa")),
            problem: Problem::UnknownInput(name("nope"))
        }
    );
    // A feature may only read earlier features.
    let e = reject(
        |c| c.features[0].stage = raw("fb"),
        &["feature 'fa'", "'fb'"],
    );
    assert_eq!(e.problem, Problem::UnknownInput(name("fb")));
}

#[test]
fn an_unknown_feature() {
    let e = reject(
        |c| c.events[0].sensor[0].feature = name("nope"),
        &["event 'e', sensor term 'nope'", "feature 'nope'"],
    );
    assert_eq!(e.problem, Problem::UnknownFeature(name("nope")));
    // A channel is not a feature.
    let e = reject(
        |c| c.events[0].context[0].feature = name("a"),
        &["context term 'a'", "feature 'a'"],
    );
    assert_eq!(e.item, Item::ContextTerm(name("e"), name("a")));
}

#[test]
fn a_phase_naming_an_undefined_event() {
    let e = reject(
        |c| c.phases[0] = phase("p", &["e", "ghost"]),
        &["phase 'p'", "'ghost'"],
    );
    assert_eq!(
        e,
        ConfigError {
            item: Item::Phase(name("p")),
            problem: Problem::UnknownEvent(name("ghost"))
        }
    );
    let e = reject(
        |c| c.phases[0] = phase("p", &["e", "e"]),
        &["phase 'p'", "'e' twice"],
    );
    assert_eq!(e.problem, Problem::RepeatedEvent(name("e")));
}

#[test]
fn a_window_longer_than_supported() {
    let ste = |window| StageSpec::Ste {
        input: name("a"),
        window,
        shape: Window::Triangular,
    };
    for w in [0u16, 129, u16::MAX] {
        let e = reject(
            |c| c.features[0].stage = ste(w),
            &["feature 'fa'", &format!("window = {w}")],
        );
        assert_eq!(
            e.problem,
            Problem::Stage(StageError::WindowLength { window: w })
        );
    }
    assert!(
        Detector::build(&{
            let mut c = good();
            c.features[0].stage = ste(128);
            c
        })
        .is_ok()
    );
    // Three full windows need 384 samples of history; the detector holds 256.
    let e = reject(
        |c| {
            c.features[0].stage = ste(128);
            c.features[1].stage = ste(128);
            c.features
                .push(detector_core::FeatureSpec {
                    name: name("fc"),
                    stage: ste(128),
                })
                .expect("fits");
        },
        &["feature 'fc'", "384"],
    );
    assert_eq!(
        e.problem,
        Problem::Stage(StageError::WindowPool { needed: 384 })
    );
}

#[test]
fn a_duplicate_name() {
    let e = reject(
        |c| c.channels[1].name = name("a"),
        &["channel 'a'", "twice"],
    );
    assert_eq!(e.item, Item::Channel(name("a")));
    let e = reject(
        |c| c.features[1].name = name("fa"),
        &["feature 'fa'", "twice"],
    );
    assert_eq!(e.item, Item::Feature(name("fa")));
    let e = reject(
        |c| c.features[1].name = name("a"),
        &["feature 'a'", "twice"],
    );
    assert_eq!(e.problem, Problem::Duplicate);
    let e = reject(
        |c| {
            let again = c.events[0].clone();
            c.events.push(again).expect("fits");
        },
        &["event 'e'", "twice"],
    );
    assert_eq!(e.item, Item::Event(name("e")));
    let e = reject(
        |c| c.phases.push(phase("p", &[])).expect("fits"),
        &["phase 'p'", "twice"],
    );
    assert_eq!(e.item, Item::Phase(name("p")));
}

#[test]
fn a_bad_channel_scale() {
    for k in [0.0f32, -1.0, f32::NAN, f32::INFINITY] {
        let e = reject(
            |c| c.channels[1].scale = k,
            &["channel 'b'", &format!("scale = {k}")],
        );
        assert_eq!(e.item, Item::Channel(name("b")));
        assert!(matches!(e.problem, Problem::Scale(v) if v.to_bits() == k.to_bits()));
    }
}

#[test]
fn other_rules() {
    reject(|c| c.rate_hz = 5.0, &["rate_hz = 5"]);
    reject(|c| c.rate_hz = 50_001.0, &["rate_hz = 50001"]);
    reject(|c| c.channels.clear(), &["channel"]);
    reject(
        |c| c.events[0].sensor.clear(),
        &["event 'e'", "sensor term"],
    );
    reject(|c| c.channels[0].name = name(""), &["empty"]);
    reject(|c| c.events[0].alert.on = 0.0, &["alert level", "on = 0"]);
    reject(|c| c.events[0].alert.on = 1.5, &["alert level", "on = 1.5"]);
    reject(
        |c| c.events[0].alert.off = 0.75,
        &["alert level", "off = 0.75"],
    );
    reject(
        |c| c.events[0].confirm = level(0.25, 0.1, 0.0),
        &["confirm level", "on = 0.25", "alert"],
    );
    reject(|c| c.events[0].onset_level = 0.5, &["onset_level = 0.5"]);
    reject(|c| c.events[0].alert.dwell_ms = -1.0, &["dwell_ms = -1"]);
    // 70 s at 1 kHz is more than 65535 ticks.
    reject(
        |c| c.events[0].confirm.dwell_ms = 70_000.0,
        &["dwell_ms = 70000"],
    );
    reject(
        |c| {
            c.features[0].stage = StageSpec::LowPass {
                input: name("a"),
                cutoff_hz: 500.0,
            }
        },
        &["cutoff_hz = 500", "500 Hz"],
    );
}

/// A rejected configuration leaves a running detector as it was: a detector built before,
/// run over the same inputs with failed builds in between, gives identical outputs.
#[test]
fn a_rejected_config_changes_nothing() {
    let det = Detector::build(&good()).expect("valid");
    let mut bad = good();
    bad.events[0].sensor[0].weight = 2.0;
    let run = |interleave: bool| {
        let mut st = det.new_state();
        (0..20)
            .map(|t| {
                if interleave {
                    assert!(Detector::build(&bad).is_err());
                }
                det.tick(&mut st, t, &inputs_f64(&[f64::from(t) / 10.0, 0.7], 0))
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(run(false), run(true));
}

/// TOML: a syntax error names its line; an unknown field is an error naming it; a
/// well-formed but invalid file gives the validation error; the approach file loads and
/// round-trips.
#[test]
fn toml_errors() {
    let broken = "rate_hz = 1000.0\n\n[[channel]\nname = \"a\"\n";
    match Config::from_toml(broken) {
        Err(LoadError::Syntax(e)) => {
            let text = LoadError::Syntax(e).to_string();
            assert!(text.contains("line 3"), "{text}");
        }
        other => panic!("expected a syntax error, got {other:?}"),
    }
    let mut text = good().to_toml();
    assert!(Config::from_toml(&text).is_ok(), "{text}");
    text = text.replacen("[[channel]]\n", "[[channel]]\ncolour = \"red\"\n", 1);
    match Config::from_toml(&text) {
        Err(e @ LoadError::Syntax(_)) => {
            let msg = e.to_string();
            assert!(msg.contains("colour"), "{msg}");
            assert!(msg.contains("line"), "{msg}");
        }
        other => panic!("expected an unknown-field error, got {other:?}"),
    }
    let mut bad = good();
    bad.events[0].sensor[0].weight = 0.9;
    match Config::from_toml(&bad.to_toml()) {
        Err(LoadError::Invalid(e)) => {
            assert_eq!(e.item, Item::Event(name("e")));
            assert!(e.to_string().contains("1.4"), "{e}");
        }
        other => panic!("expected a validation error, got {other:?}"),
    }
    let approach = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/approach.toml"
    ))
    .expect("readable");
    let c = Config::from_toml(&approach).expect("approach.toml is valid");
    assert_eq!(Config::from_toml(&c.to_toml()).expect("round trip"), c);
}

/// A configuration of eight events with eight context and eight sensor terms each, on
/// feature `fa`; term `k` of event `i` uses `cdf(i, k)`.
fn full_events(cdf: impl Fn(usize, usize) -> CdfSpec) -> Config {
    let events = (0..8)
        .map(|i| {
            let ctx = (0..8).map(|k| context("fa", cdf(i, k))).collect();
            let sen = (8..16).map(|k| sensor("fa", 0.125, cdf(i, k))).collect();
            event(&format!("e{i}"), ctx, sen)
        })
        .collect();
    config(
        1000.0,
        &["a"],
        vec![("fa", raw("a"))],
        events,
        vec![phase("p", &["e0"])],
    )
}

#[test]
fn terms_alike_count_once_against_the_distinct_term_limit() {
    // 128 terms, one distinct pair: builds.
    assert!(Detector::build(&full_events(|_, _| sigmoid(0.0, 1.0))).is_ok());
    // 64 distinct pairs: each event's context term k and sensor term k + 8 are alike.
    let per_event = |i: usize, k: usize| sigmoid(0.0, 1.0 + (i * 8 + k % 8) as f32);
    assert!(Detector::build(&full_events(per_event)).is_ok());
    // 128 distinct pairs: the 65th, event e4's first context term, is rejected by name.
    let err = Detector::build(&full_events(|i, k| sigmoid(0.0, 1.0 + (i * 16 + k) as f32)))
        .expect_err("more distinct terms than the detector holds");
    assert_eq!(err.item, Item::ContextTerm(name("e4"), name("fa")));
    assert_eq!(err.problem, Problem::DistinctTerms(64));
    assert!(err.to_string().contains("more than 64 distinct"), "{err}");
}
