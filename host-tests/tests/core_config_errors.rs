//! Configuration validation: each bad input is rejected with an error naming the item and
//! the value (in the error and in its `Display` text), and a rejected configuration changes
//! nothing. Also the TOML layer: syntax errors with their line,
//! unknown fields, and invalid-but-well-formed files.

#[path = "reference_support.rs"]
mod support;

use detector_build::LoadError;
use detector_build::{
    ChannelSpec, Config, ConfigError, EarlySpec, FeatureSpec, Item, Problem, Warning,
};
use detector_core::{
    CdfError, CdfSpec, Crossing, LongerWarmUp, Shut, StageError, StageSpec, Window,
};
use proptest::prelude::*;
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
    let err = detector_build::build(&bad).expect_err("must be rejected");
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
    assert!(detector_build::build(&good()).is_ok());
}

/// Weights may sum to 3 (three terms each sufficient), not beyond.
#[test]
fn weights_summing_above_three() {
    let each_sufficient = |c: &mut Config| {
        for t in &mut c.events[0].sensor {
            t.weight = 1.0;
        }
        c.events[0]
            .sensor
            .push(sensor("fa", 1.0, sigmoid(0.0, 2.0)));
    };
    let mut three = good();
    each_sufficient(&mut three);
    assert!(detector_build::build(&three).is_ok());
    let err = reject(
        |c| {
            each_sufficient(c);
            c.events[0]
                .sensor
                .push(sensor("fb", 0.25, sigmoid(0.0, 2.0)));
        },
        &["event 'e'", "3.25", "above 3"],
    );
    assert_eq!(err.item, Item::Event(name("e")));
    assert!(matches!(err.problem, Problem::WeightSum(s) if (s - 3.25).abs() < 1e-6));
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
    assert!(matches!(e.problem, Problem::Time { param: "dwell_ms", value } if value.is_nan()));
    let e = reject(
        |c| {
            c.features[0].stage = StageSpec::LowPass {
                input: name("a"),
                cutoff_hz: nan,
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            }
        },
        &["feature 'fa'", "cutoff_hz = NaN"],
    );
    assert_eq!(e.item, Item::Feature(name("fa")));
    let e = reject(
        |c| {
            c.features[0].stage = StageSpec::LowPass {
                input: name("a"),
                cutoff_hz: 1.0,
                warm_up_ms: Some(nan),
                warm_up_until: None,
                warm_up_longer: None,
            }
        },
        &["feature 'fa'", "warm_up_ms = NaN"],
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
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
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
    // So may the feature a low-pass's warm-up or a gate watches, and its level must be
    // finite and within the 16.16 range; a channel's crossing is accepted.
    let until = |feature: &str, above: f32| StageSpec::LowPass {
        input: name("a"),
        cutoff_hz: 1.0,
        warm_up_ms: None,
        warm_up_until: Some(Crossing {
            feature: name(feature),
            above,
        }),
        warm_up_longer: None,
    };
    let longer = |feature: &str, above: f32| StageSpec::LowPass {
        input: name("a"),
        cutoff_hz: 1.0,
        warm_up_ms: Some(20.0),
        warm_up_until: None,
        warm_up_longer: Some(LongerWarmUp {
            feature: name(feature),
            above,
            warm_up_ms: 40.0,
        }),
    };
    let gate = |feature: &str, above: f32| StageSpec::Gate {
        input: name("a"),
        unless: Shut::above(name(feature), above),
        leak: 0.0,
    };
    let gate_below = |feature: &str, below: f32| StageSpec::Gate {
        input: name("a"),
        unless: Shut::below(name(feature), below),
        leak: 0.0,
    };
    let watchers: [fn(&str, f32) -> StageSpec<String>; 4] = [until, longer, gate, gate_below];
    for watcher in watchers {
        let e = reject(
            |c| c.features[0].stage = watcher("fb", 1.0),
            &["feature 'fa'", "'fb'"],
        );
        assert_eq!(e.problem, Problem::UnknownInput(name("fb")));
        for above in [f32::NAN, f32::INFINITY, 40000.0, -40000.0] {
            let e = reject(
                |c| c.features[0].stage = watcher("b", above),
                &["feature 'fa'", "the level "],
            );
            assert_eq!(e.item, Item::Feature(name("fa")));
            assert!(
                matches!(e.problem, Problem::Stage(StageError::Level { .. })),
                "{e:?}"
            );
        }
        let mut config = good();
        config.features[0].stage = watcher("b", -1.0);
        assert!(detector_build::build(&config).is_ok());
    }
}

/// A gate shuts on one side of its level: above it or below it, never both or neither.
#[test]
fn a_gate_shuts_on_one_side() {
    for (above, below) in [(Some(1.0), Some(2.0)), (None, None)] {
        let e = reject(
            |c| {
                c.features[0].stage = StageSpec::Gate {
                    input: name("a"),
                    unless: Shut {
                        feature: name("b"),
                        above,
                        below,
                    },
                    leak: 0.0,
                }
            },
            &["feature 'fa'", "exactly one of above and below"],
        );
        assert_eq!(e.problem, Problem::Stage(StageError::GateSide));
    }
}

/// A longer warm-up carries a warm-up on: it needs one, longer than that one in samples
/// (at the configuration's 1 kHz, 2.4 ms is the same 2 samples as 2 ms), and a warm-up of
/// its own the counter holds.
#[test]
fn a_longer_warm_up_must_carry_a_shorter_one_on() {
    let stage = |warm_up_ms: Option<f32>, longer_ms: f32| StageSpec::LowPass {
        input: name("a"),
        cutoff_hz: 1.0,
        warm_up_ms,
        warm_up_until: None,
        warm_up_longer: Some(LongerWarmUp {
            feature: name("b"),
            above: 1.0,
            warm_up_ms: longer_ms,
        }),
    };
    for (shorter, longer, words) in [
        (None, 40.0, &["warm_up_ms = 40", "(NaN)"][..]),
        (Some(20.0), 20.0, &["warm_up_ms = 20", "(20)"][..]),
        (Some(20.0), 10.0, &["warm_up_ms = 10", "(20)"][..]),
        (Some(2.0), 2.4, &["warm_up_ms = 2.4", "(2)"][..]),
    ] {
        let e = reject(|c| c.features[0].stage = stage(shorter, longer), words);
        assert_eq!(e.item, Item::Feature(name("fa")));
        assert!(
            matches!(e.problem, Problem::Stage(StageError::WarmUpLonger { .. })),
            "{e:?}"
        );
    }
    for longer in [f32::NAN, -1.0, 1e9] {
        let e = reject(
            |c| c.features[0].stage = stage(Some(20.0), longer),
            &["feature 'fa'", "warm_up_ms = "],
        );
        assert!(
            matches!(e.problem, Problem::Stage(StageError::WarmUp { .. })),
            "{e:?}"
        );
    }
    let mut config = good();
    config.features[0].stage = stage(Some(20.0), 40.0);
    assert!(detector_build::build(&config).is_ok());
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

/// An exclusion names an event that exists, not the event itself, each once.
#[test]
fn an_exclusion_naming_a_bad_event() {
    for (excludes, words, problem) in [
        (
            vec!["ghost"],
            vec!["event 'e'", "'ghost'"],
            Problem::UnknownEvent(name("ghost")),
        ),
        (
            vec!["e"],
            vec!["event 'e'", "excludes itself"],
            Problem::ExcludesItself,
        ),
    ] {
        let e = reject(
            |c| c.events[0].excludes = excludes.iter().map(|n| name(n)).collect(),
            &words,
        );
        assert_eq!(e.item, Item::Event(name("e")));
        assert_eq!(e.problem, problem);
    }
    let mut two = good();
    let mut other = two.events[0].clone();
    other.name = name("f");
    two.events.push(other);
    two.phases[0] = phase("p", &["e", "f"]);
    two.events[0].excludes = vec![name("f"), name("f")];
    let e = detector_build::build(&two).expect_err("repeated");
    assert_eq!(e.problem, Problem::RepeatedEvent(name("f")));
    two.events[0].excludes = vec![name("f")];
    assert!(detector_build::build(&two).is_ok());
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
        detector_build::build(&{
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
            c.features.push(detector_build::FeatureSpec {
                name: name("fc"),
                stage: ste(128),
            });
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
            c.events.push(again);
        },
        &["event 'e'", "twice"],
    );
    assert_eq!(e.item, Item::Event(name("e")));
    let e = reject(|c| c.phases.push(phase("p", &[])), &["phase 'p'", "twice"]);
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
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            }
        },
        &["cutoff_hz = 500", "500 Hz"],
    );
    reject(|c| c.events[0].confirm.hold_ms = -1.0, &["hold_ms = -1"]);
    reject(
        |c| c.events[0].alert.hold_ms = f32::NAN,
        &["alert level", "hold_ms = NaN"],
    );
    let cancel = |gain: f32, motion: &str| StageSpec::Cancel {
        input: name("a"),
        motion: name(motion),
        gain,
        cutoff_hz: 50.0,
    };
    for (gain, shown) in [
        (f32::NAN, "gain = NaN"),
        (f32::INFINITY, "gain = inf"),
        (40_000.0, "gain = 40000"),
        (-32_768.0, "gain = -32768"),
        (1e-7, "gain = 0.0000001"),
    ] {
        reject(
            |c| c.features[0].stage = cancel(gain, "a"),
            &["feature", shown],
        );
    }
    reject(
        |c| c.features[0].stage = cancel(1.0, "nowhere"),
        &["feature", "nowhere"],
    );
    // Zero and the largest gains are legal.
    for gain in [0.0, 32_767.99, -32_767.99] {
        let mut c = good();
        c.features[0].stage = cancel(gain, "a");
        detector_build::build(&c).unwrap_or_else(|e| panic!("gain {gain}: {e}"));
    }
}

/// A rejected configuration leaves a running detector as it was: a detector built before,
/// run over the same inputs with failed builds in between, gives identical outputs.
#[test]
fn a_rejected_config_changes_nothing() {
    let det = detector_build::build(&good()).expect("valid");
    let mut bad = good();
    bad.events[0].sensor[0].weight = 2.0;
    let run = |interleave: bool| {
        let mut st = det.new_state();
        (0..20)
            .map(|t| {
                if interleave {
                    assert!(detector_build::build(&bad).is_err());
                }
                det.tick(&mut st, t, &inputs_f64(&[f64::from(t) / 10.0, 0.7], 0))
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(run(false), run(true));
}

/// TOML: a syntax error names its line; an unknown field is an error naming it; a
/// well-formed but invalid file gives the validation error; every shipped configuration
/// loads, round-trips and compiles without warnings.
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
    bad.events[0].sensor[0].weight = 1.5;
    match Config::from_toml(&bad.to_toml()) {
        Err(LoadError::Invalid(e)) => {
            assert_eq!(e.item, item_sensor("e", "fa"));
            assert!(e.to_string().contains("1.5"), "{e}");
        }
        other => panic!("expected a validation error, got {other:?}"),
    }
    for shipped in ["approach.toml", "paper.toml", "ur3_cobotops.toml"] {
        let path = format!("{}/../configs/{shipped}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).expect("readable");
        let c = Config::from_toml(&text).unwrap_or_else(|e| panic!("{shipped}: {e}"));
        assert_eq!(Config::from_toml(&c.to_toml()).expect("round trip"), c);
        let compiled = detector_build::compile(&c).unwrap_or_else(|e| panic!("{shipped}: {e}"));
        assert!(
            compiled.warnings.is_empty(),
            "{shipped}: {:?}",
            compiled.warnings
        );
    }
}

/// The paper's reference detector has its seven features exactly (section 3.1 and 3.2),
/// each one stage of the kind the paper describes, and monitors its three events.
#[test]
fn paper_configuration_has_the_papers_seven_features() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../configs/paper.toml"
    ))
    .expect("readable");
    let c = Config::from_toml(&text).expect("valid");
    let kinds: Vec<(&str, &str)> = c
        .features
        .iter()
        .map(|f| {
            let kind = match &f.stage {
                StageSpec::Magnitude { .. } => "magnitude",
                StageSpec::Dot { .. } => "dot",
                StageSpec::LowPass { .. } => "low_pass",
                StageSpec::Ste { window: 32, .. } => "ste32",
                StageSpec::Abs { .. } => "abs",
                _ => "other",
            };
            (f.name.as_str(), kind)
        })
        .collect();
    assert_eq!(
        kinds,
        [
            ("acc_des", "magnitude"),
            ("force_dot_vel", "dot"),
            ("vel_des", "magnitude"),
            ("pos_err", "magnitude"),
            ("force", "low_pass"),
            ("ste_skin", "ste32"),
            ("stress", "abs"),
        ]
    );
    let events: Vec<&str> = c.events.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(events, ["contact", "link_collision", "disturbance"]);
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
    assert!(detector_build::build(&full_events(|_, _| sigmoid(0.0, 1.0))).is_ok());
    // 64 distinct pairs: each event's context term k and sensor term k + 8 are alike.
    let per_event = |i: usize, k: usize| sigmoid(0.0, 1.0 + (i * 8 + k % 8) as f32);
    assert!(detector_build::build(&full_events(per_event)).is_ok());
    // 128 distinct pairs: the 65th, event e4's first context term, is rejected by name.
    let err = detector_build::build(&full_events(|i, k| sigmoid(0.0, 1.0 + (i * 16 + k) as f32)))
        .expect_err("more distinct terms than the detector holds");
    assert_eq!(err.item, Item::ContextTerm(name("e4"), name("fa")));
    assert_eq!(err.problem, Problem::DistinctTerms(64));
    assert!(err.to_string().contains("more than 64 distinct"), "{err}");
}

/// Sets the name of the first item of one kind (0 channel, 1 feature, 2 event, 3 phase),
/// keeping every reference to it, and gives the item the error must name.
fn rename(c: &mut Config, kind: usize, to: &str) -> Item {
    let to = to.to_owned();
    match kind {
        0 => {
            c.channels[0].name = to.clone();
            c.features[0].stage = raw(&to);
            Item::Channel(to)
        }
        1 => {
            c.features[0].name = to.clone();
            c.events[0].sensor[0].feature = to.clone();
            Item::Feature(to)
        }
        2 => {
            c.events[0].name = to.clone();
            c.phases[0].events[0] = to.clone();
            Item::Event(to)
        }
        _ => {
            c.phases[0].name = to.clone();
            Item::Phase(to)
        }
    }
}

/// Names are letters, digits, '_' and '-', 1 to 24 bytes, and not a trace column: every
/// other name, of every kind of item, is refused naming the item (a name with a comma or a
/// newline would break the CSV files the tools write).
#[test]
fn names_outside_the_allowed_set() {
    let too_long = "n".repeat(25);
    let table: [(&str, Problem); 9] = [
        ("a,b", Problem::NameCharacter(',')),
        ("a\nb", Problem::NameCharacter('\n')),
        ("a b", Problem::NameCharacter(' ')),
        ("caf\u{e9}", Problem::NameCharacter('\u{e9}')),
        ("bell\u{7}", Problem::NameCharacter('\u{7}')),
        (&too_long, Problem::NameLength(25)),
        ("t", Problem::ReservedName),
        ("phase", Problem::ReservedName),
        ("truth", Problem::ReservedName),
    ];
    for kind in 0..4 {
        for (bad, problem) in &table {
            let mut c = good();
            let item = rename(&mut c, kind, bad);
            let before = c.clone();
            let err = detector_build::build(&c).expect_err(bad);
            assert_eq!(c, before);
            assert_eq!(err.item, item, "{bad:?}");
            assert_eq!(&err.problem, problem, "{bad:?}");
        }
        let mut c = good();
        rename(&mut c, kind, "Tip-force_2");
        assert!(detector_build::build(&c).is_ok(), "a good name refused");
    }
    let err = reject(
        |c| c.channels[0].unit = "metres per second".into(),
        &["channel 'a'", "unit"],
    );
    assert_eq!(err.problem, Problem::Unit);
}

proptest! {
    /// Any name holding a character outside the set is refused, naming the character.
    #[test]
    fn any_name_with_a_foreign_character_is_refused(
        head in "[a-z]{0,5}",
        bad in any::<char>().prop_filter("outside the set", |c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-')),
        kind in 0usize..4,
    ) {
        let mut c = good();
        rename(&mut c, kind, &format!("{head}{bad}"));
        let err = detector_build::build(&c).expect_err("refused");
        prop_assert_eq!(err.problem, Problem::NameCharacter(bad));
    }
}

/// A list longer than a detector holds is refused with the limit, not a parser's
/// "invalid length".
#[test]
fn too_many_items_name_the_limit() {
    let channels: Vec<String> = (0..17).map(|k| format!("c{k}")).collect();
    let names: Vec<&str> = channels.iter().map(String::as_str).collect();
    let mut c = good();
    let extra = config(1000.0, &names, Vec::new(), Vec::new(), Vec::new());
    c.channels = extra.channels;
    let err = detector_build::build(&c).expect_err("17 channels");
    assert_eq!(err.problem, Problem::TooMany("channel", 17, 16));
    assert!(
        err.to_string().contains("17 channels, more than the 16"),
        "{err}"
    );
    let err = reject(
        |c| {
            let term = c.events[0].context[0].clone();
            c.events[0].context = vec![term; 9];
        },
        &["event 'e'", "9 context terms, more than the 8"],
    );
    assert_eq!(err.problem, Problem::TooMany("context term", 9, 8));
    let toml: String = std::iter::once(good().to_toml())
        .chain((0..15).map(|k| format!("\n[[channel]]\nname = \"c{k}\"\nunit = \"N\"\n")))
        .collect();
    match Config::from_toml(&toml) {
        Err(LoadError::Invalid(e)) => assert_eq!(e.problem, Problem::TooMany("channel", 17, 16)),
        other => panic!("expected the channel limit, got {other:?}"),
    }
}

/// A 2-vector takes exactly two inputs: a third is refused, not dropped.
#[test]
fn fixed_arity_lists_are_checked() {
    let text = good().to_toml();
    let base = "[feature.stage.raw]\ninput = \"b\"";
    assert!(text.contains(base), "{text}");
    for (of, ok) in [
        ("[\"a\", \"b\"]", true),
        ("[\"a\", \"b\", \"a\"]", false),
        ("[\"a\"]", false),
    ] {
        let changed = text.replacen(base, &format!("[feature.stage.magnitude]\nof = {of}"), 1);
        match Config::from_toml(&changed) {
            Ok(_) => assert!(ok, "{of} accepted"),
            Err(e) => {
                assert!(!ok, "{of}: {e}");
                assert!(e.to_string().contains("exactly two"), "{e}");
            }
        }
    }
    let dot = "[feature.stage.dot]\na = [\"a\", \"b\", \"a\"]\nb = [\"a\", \"b\"]";
    let err = Config::from_toml(&text.replacen(base, dot, 1)).expect_err("three inputs");
    assert!(err.to_string().contains("exactly two"), "{err}");
}

/// What is legal but probably a mistake is compiled, with a warning naming it.
#[test]
fn an_event_in_no_phase_and_a_phase_without_events_are_warned_of() {
    let mut c = good();
    c.phases.push(phase("idle", &[]));
    let mut second = c.events[0].clone();
    second.name = name("unused");
    c.events.push(second);
    let compiled = detector_build::compile(&c).expect("legal");
    assert_eq!(
        compiled.warnings,
        vec![
            Warning::EventInNoPhase(name("unused")),
            Warning::PhaseWithoutEvents(name("idle"))
        ]
    );
    assert_eq!(
        compiled.warnings[0].to_string(),
        "event 'unused' is in no phase, so it is never evaluated"
    );
    assert!(
        detector_build::compile(&good())
            .expect("good")
            .warnings
            .is_empty()
    );
}

/// An early dwell names a feature that exists and reads only channels the event's terms
/// read, at a level a feature can hold, no longer than its level's dwell once both are
/// rounded to ticks; on either level.
#[test]
fn an_early_dwell_is_checked() {
    let early = |feature: &str, above: f32, dwell_ms: f32| EarlySpec {
        feature: name(feature),
        above,
        dwell_ms,
    };
    let with = |e: EarlySpec| {
        move |c: &mut Config| {
            c.events[0].confirm.dwell_ms = 5.0;
            c.events[0].confirm.early = Some(e);
        }
    };
    let mut fine = good();
    with(early("fa", 0.5, 2.0))(&mut fine);
    assert!(detector_build::build(&fine).is_ok());
    // As long as the dwell is allowed; a dwell of 0 rounds to one tick, as the level's.
    with(early("fa", 0.5, 5.0))(&mut fine);
    assert!(detector_build::build(&fine).is_ok());

    let e = reject(
        with(early("nope", 0.5, 2.0)),
        &["event 'e', confirm level", "feature 'nope'"],
    );
    assert_eq!(e.problem, Problem::UnknownFeature(name("nope")));
    assert_eq!(e.item, Item::Level(name("e"), "confirm"));
    let e = reject(
        with(early("fa", 0.5, 6.0)),
        &["confirm level", "early.dwell_ms = 6", "dwell_ms = 5"],
    );
    assert_eq!(e.problem, Problem::EarlyDwell(6.0, 5.0));
    for above in [f32::NAN, f32::INFINITY, -40_000.0, 32_768.0] {
        let e = reject(with(early("fa", above, 2.0)), &["early.above"]);
        assert!(matches!(e.problem, Problem::EarlyLevel(v) if v.to_bits() == above.to_bits()));
    }
    let e = reject(with(early("fa", 0.5, -1.0)), &["early.dwell_ms = -1"]);
    assert_eq!(
        e.problem,
        Problem::Time {
            param: "early.dwell_ms",
            value: -1.0
        }
    );
    // Channel `c` is read by no term of the event: a fault on it would not degrade it.
    let e = reject(
        |c| {
            c.channels.push(ChannelSpec {
                name: name("c"),
                unit: name("N"),
                scale: 1.0,
            });
            c.features.push(FeatureSpec {
                name: name("fc"),
                stage: raw("c"),
            });
            with(early("fc", 0.5, 2.0))(c);
        },
        &["early.feature 'fc'", "channel 'c'"],
    );
    assert_eq!(e.problem, Problem::EarlyChannel(name("fc"), name("c")));
    // The alert level is checked the same way.
    let e = reject(
        |c| {
            c.events[0].alert.early = Some(early("fa", 0.5, 3.0));
        },
        &[
            "event 'e', alert level",
            "early.dwell_ms = 3",
            "dwell_ms = 0",
        ],
    );
    assert_eq!(e.problem, Problem::EarlyDwell(3.0, 0.0));
}

/// In TOML, an early dwell is a table of `feature`, `above` and `dwell_ms`, nothing else.
#[test]
fn an_early_dwell_in_toml() {
    let text = |early: &str| {
        format!(
            "rate_hz = 1000.0\n\
             [[channel]]\nname = \"a\"\nunit = \"N\"\n\
             [[feature]]\nname = \"fa\"\nstage = {{ raw = {{ input = \"a\" }} }}\n\
             [[event]]\nname = \"e\"\n\
             sensor = [{{ feature = \"fa\", weight = 1.0, cdf = {{ sigmoid = {{ low = 0.0, high = 1.0 }} }} }}]\n\
             alert = {{ on = 0.5, off = 0.25 }}\n\
             confirm = {{ on = 0.75, off = 0.5, dwell_ms = 5.0, early = {early} }}\n\
             [[phase]]\nname = \"p\"\nevents = [\"e\"]\n"
        )
    };
    let config = Config::from_toml(&text("{ feature = \"fa\", above = 0.5, dwell_ms = 2.0 }"))
        .expect("valid");
    let detector = detector_build::build(&config).expect("builds");
    let [_, confirm] = detector
        .event_levels(detector.event("e").expect("event"))
        .expect("levels");
    let e = confirm.early().expect("an early dwell");
    assert_eq!((e.dwell(), e.above()), (2, 1 << 15));
    let err = Config::from_toml(&text(
        "{ feature = \"fa\", above = 0.5, dwell_ms = 2.0, below = 1.0 }",
    ))
    .expect_err("an unknown field");
    assert!(err.to_string().contains("below"), "{err}");
}
