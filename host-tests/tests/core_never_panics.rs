//! Nothing in the core panics on any input (issue 2), checked with property tests in the dev
//! profile, where integer overflow panics too:
//!
//! - arbitrary configurations — every `f32` parameter an arbitrary bit pattern (NaN,
//!   infinities, subnormals, huge values) or a plausible value, names drawn from a small pool
//!   (so duplicates, unknown names and empty names are common) or arbitrary strings — into
//!   `detector_build::build`;
//! - for those that build, arbitrary samples (any 16.16 bits, the extremes included),
//!   arbitrary fault masks, phase switches by arbitrary index and a free-running tick that
//!   wraps, into `Detector::tick`; the outputs must be consistent: every confidence in
//!   [0, 1], `evaluated` the active phase's events, confidences zero outside it,
//!   `unjudgeable` and `degraded` disjoint subsets of it with unjudgeable events at zero,
//!   levels up only for judged evaluated events, decisions only for those, at most one per
//!   event and level per tick, each with this tick, its event's confidence and an onset no
//!   later than now;
//! - every query of the detector and its state with arbitrary indices and names, and
//!   `Detector::sample_from_si` with arbitrary values;
//! - `Cdf::new` and `Cdf::eval` on arbitrary parameters and inputs;
//! - `Config::from_toml` on arbitrary text and on mutated valid text.
//!
//! Case counts: [`CASES`] configurations of up to [`TICKS`] ticks, [`CDF_CASES`] CDFs,
//! [`TOML_CASES`] texts (override with `PROPTEST_CASES`).

#[path = "reference_support.rs"]
mod support;

use detector_build::{
    ChannelSpec, Config, ContextTerm, EarlySpec, EventSpec, FeatureSpec, LevelSpec, PhaseSpec,
    SensorTerm,
};
use detector_core::{
    Cdf, CdfSpec, Crossing, Detector, EventId, LongerWarmUp, Shut, Signal, StageSpec, Window,
};
use proptest::prelude::*;
use support::*;

/// Configurations per property.
const CASES: u32 = 256;
/// Most ticks per configuration.
const TICKS: usize = 48;
/// CDFs per property.
const CDF_CASES: u32 = 1024;
/// TOML texts per property.
const TOML_CASES: u32 = 256;

/// Any `f32`: arbitrary bits, or a plausible value.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        2 => any::<u32>().prop_map(f32::from_bits),
        1 => Just(f32::NAN),
        1 => prop_oneof![Just(f32::INFINITY), Just(f32::NEG_INFINITY), Just(f32::MAX), Just(-0.0f32), Just(f32::MIN_POSITIVE)],
        6 => -4.0f32..4.0,
        2 => 0.0f32..=1.0,
        1 => -40000.0f32..40000.0,
    ]
}

/// A name: mostly from a small pool shared by all kinds, sometimes empty or arbitrary.
fn any_name() -> impl Strategy<Value = String> {
    prop_oneof![
        8 => prop::sample::select(vec!["c0", "c1", "c2", "c3", "f0", "f1", "f2", "f3", "e0", "e1", "e2", "p0", "p1"])
            .prop_map(name),
        1 => Just(name("")),
        1 => "\\PC{0,30}",
    ]
}

/// A plausible CDF: ordered parameters of moderate size, now and then anything.
fn plausible_cdf() -> impl Strategy<Value = CdfSpec> {
    prop_oneof![
        30 => (prop::array::uniform4(-8.0f32..8.0), 0u8..5).prop_map(|(mut v, shape)| {
            v.sort_by(f32::total_cmp);
            let [a, b, c, d] = v;
            match shape {
                0 => CdfSpec::Sigmoid { low: a, high: d, falling: false },
                1 => CdfSpec::Sigmoid { low: a, high: d, falling: true },
                2 => CdfSpec::Bell { center: b, half_width: d - a },
                3 => CdfSpec::FlatBell { low: a, plateau_low: b, plateau_high: c, high: d },
                _ => CdfSpec::Binary { threshold: b, above: c > 0.0 },
            }
        }),
        1 => any_cdf(),
    ]
}

/// A reference to an earlier item: mostly by index (resolved to an existing name), now and
/// then any name at all.
#[derive(Clone, Debug)]
enum Ref {
    Index(u8),
    Named(String),
}

fn any_ref() -> impl Strategy<Value = Ref> {
    prop_oneof![
        80 => any::<u8>().prop_map(Ref::Index),
        1 => any_name().prop_map(Ref::Named),
    ]
}

/// Resolves a reference among `names` (by index modulo their count; `fallback` if none).
fn resolve(r: &Ref, names: &[String], fallback: &str) -> String {
    match r {
        Ref::Index(i) if !names.is_empty() => names[usize::from(*i) % names.len()].clone(),
        Ref::Index(_) => name(fallback),
        Ref::Named(n) => n.clone(),
    }
}

fn any_stage() -> impl Strategy<Value = StageSpec<Ref>> {
    let n = any_ref;
    prop_oneof![
        n().prop_map(|input| StageSpec::Raw { input }),
        n().prop_map(|input| StageSpec::Abs { input }),
        n().prop_map(|input| StageSpec::Positive { input }),
        (
            n(),
            prop_oneof![1 => any_f32(), 12 => 0.1f32..4.9, 2 => 0.1f32..3000.0],
            prop::option::of(prop_oneof![1 => any_f32(), 6 => 0.1f32..200.0]),
            prop::option::of((n(), any_f32())),
            prop::option::of((
                n(),
                any_f32(),
                prop_oneof![1 => any_f32(), 6 => 0.1f32..400.0]
            )),
        )
            .prop_map(
                |(input, cutoff_hz, warm_up_ms, until, longer)| StageSpec::LowPass {
                    input,
                    cutoff_hz,
                    warm_up_ms,
                    warm_up_until: until.map(|(feature, above)| Crossing { feature, above }),
                    warm_up_longer: longer.map(|(feature, above, warm_up_ms)| LongerWarmUp {
                        feature,
                        above,
                        warm_up_ms,
                    }),
                },
            ),
        (n(), prop_oneof![1 => any_f32(), 6 => 0.1f32..4.9])
            .prop_map(|(input, cutoff_hz)| StageSpec::HighPass { input, cutoff_hz }),
        (n(), prop_oneof![1 => any_f32(), 6 => 0.1f32..4.9])
            .prop_map(|(input, cutoff_hz)| StageSpec::Envelope { input, cutoff_hz }),
        (
            n(),
            n(),
            prop::option::of(any_f32()),
            prop::option::of(any_f32()),
            prop_oneof![4 => Just(0.0f32), 2 => 0.0f32..1.0, 1 => any_f32()]
        )
            .prop_map(|(input, feature, above, below, leak)| StageSpec::Gate {
                input,
                unless: Shut {
                    feature,
                    above,
                    below
                },
                leak,
            }),
        (
            n(),
            n(),
            prop_oneof![1 => any_f32(), 6 => -40_000.0f32..40_000.0],
            prop_oneof![1 => any_f32(), 6 => 0.1f32..4.9]
        )
            .prop_map(|(input, motion, gain, cutoff_hz)| StageSpec::Cancel {
                input,
                motion,
                gain,
                cutoff_hz
            }),
        n().prop_map(|input| StageSpec::Rate { input }),
        (
            n(),
            n(),
            prop_oneof![1 => any_f32(), 2 => Just(1.0f32), 6 => -40_000.0f32..40_000.0]
        )
            .prop_map(|(a, b, gain)| StageSpec::Difference { a, b, gain }),
        (
            n(),
            prop_oneof![1 => any::<u16>(), 1 => 0u16..=140, 20 => 1u16..=128]
        )
            .prop_map(|(input, window)| StageSpec::Mean { input, window }),
        (n(), n(), n(), n()).prop_map(|(a, b, c, d)| StageSpec::Dot {
            a: [a, b],
            b: [c, d]
        }),
        (n(), n()).prop_map(|(a, b)| StageSpec::Magnitude { of: [a, b] }),
        (
            n(),
            prop_oneof![1 => any::<u16>(), 1 => 0u16..=140, 20 => 1u16..=128],
            any::<bool>()
        )
            .prop_map(|(input, window, tri)| StageSpec::Ste {
                input,
                window,
                shape: if tri {
                    Window::Triangular
                } else {
                    Window::Rectangular
                }
            }),
    ]
}

fn any_cdf() -> impl Strategy<Value = CdfSpec> {
    let f = any_f32;
    prop_oneof![
        (f(), f(), any::<bool>()).prop_map(|(low, high, falling)| CdfSpec::Sigmoid {
            low,
            high,
            falling
        }),
        (f(), f()).prop_map(|(center, half_width)| CdfSpec::Bell { center, half_width }),
        (f(), f(), f(), f()).prop_map(|(a, b, c, d)| CdfSpec::FlatBell {
            low: a,
            plateau_low: b,
            plateau_high: c,
            high: d
        }),
        (f(), any::<bool>()).prop_map(|(threshold, above)| CdfSpec::Binary { threshold, above }),
    ]
}

/// Alert and confirm levels: mostly in order, now and then anything.
fn any_levels() -> impl Strategy<Value = (LevelSpec, LevelSpec)> {
    let any_level = || {
        (any_f32(), any_f32(), any_f32(), any_f32()).prop_map(|(on, off, dwell_ms, hold_ms)| {
            LevelSpec {
                on,
                off,
                dwell_ms,
                hold_ms,
                early: None,
            }
        })
    };
    prop_oneof![
        1 => (any_level(), any_level()),
        20 => (0.05f32..=0.5, 0.0f32..=0.05, 0.5f32..=1.0, 0.0f32..=0.5, proptest::array::uniform4(0.0f32..5.0))
            .prop_map(|(a_on, a_off, c_on, c_off, [a_dwell, c_dwell, a_hold, c_hold])| {
                (
                    LevelSpec { on: a_on, off: a_off, dwell_ms: a_dwell, hold_ms: a_hold, early: None },
                    LevelSpec { on: c_on, off: c_off, dwell_ms: c_dwell, hold_ms: c_hold, early: None },
                )
            }),
    ]
}

/// An event whose terms name their features by [`Ref`] (resolved later).
#[derive(Clone, Debug)]
struct EventPlan {
    context: Vec<(Ref, CdfSpec)>,
    sensor: Vec<(Ref, f32, CdfSpec)>,
    alert: LevelSpec,
    confirm: LevelSpec,
    onset_level: f32,
    /// The confirm level's early dwell: its feature (`None`: the first sensor term's), its
    /// level and its dwell.
    early: Option<(Option<Ref>, f32, f32)>,
}

fn any_event() -> impl Strategy<Value = EventPlan> {
    (
        prop::collection::vec((any_ref(), plausible_cdf()), 0..=2),
        prop_oneof![
            1 => prop::collection::vec((any_ref(), any_f32(), plausible_cdf()), 0..=9),
            12 => prop::collection::vec((any_ref(), 0.0f32..0.25, plausible_cdf()), 1..=4),
        ],
        any_levels(),
        prop_oneof![1 => any_f32(), 20 => Just(0.0f32), 5 => 0.0f32..0.05],
        prop::option::weighted(
            0.3,
            (
                prop::option::weighted(0.3, any_ref()),
                prop_oneof![1 => any_f32(), 4 => -2.0f32..2.0],
                prop_oneof![1 => any_f32(), 4 => 0.0f32..5.0],
            ),
        ),
    )
        .prop_map(
            |(context, sensor, (alert, confirm), onset_level, early)| EventPlan {
                context,
                sensor,
                alert,
                confirm,
                onset_level,
                early,
            },
        )
}

/// A list's `i`-th name: `prefix{i}`, now and then any name (duplicates, empties, unknowns).
fn nth_name(prefix: &str, i: usize, replace: &Option<String>) -> String {
    replace
        .clone()
        .unwrap_or_else(|| name(&format!("{prefix}{i}")))
}

fn any_config() -> impl Strategy<Value = Config> {
    let renamed = || prop::option::weighted(0.02, any_name());
    (
        prop_oneof![1 => any_f32(), 20 => 10.0f32..50_000.0],
        prop_oneof![1 => 0usize..=17, 8 => 1usize..=5].prop_flat_map(move |n| {
            prop::collection::vec(
                (
                    renamed(),
                    prop_oneof![1 => any_f32(), 20 => Just(1.0f32), 4 => 0.001f32..1000.0],
                ),
                n,
            )
        }),
        prop_oneof![
            1 => prop::collection::vec((renamed(), any_stage()), 0..=17),
            8 => prop::collection::vec((renamed(), any_stage()), 1..=6),
        ],
        prop_oneof![
            1 => prop::collection::vec((renamed(), any_event()), 0..=9),
            8 => prop::collection::vec((renamed(), any_event()), 1..=3),
        ],
        prop_oneof![
            1 => prop::collection::vec((renamed(), prop::collection::vec(any_ref(), 0..=9)), 0..=9),
            8 => prop::collection::vec((renamed(), prop::collection::vec(any_ref(), 0..=3)), 1..=3),
        ],
    )
        .prop_map(|(rate_hz, channels, features, events, phases)| {
            let mut c = Config {
                rate_hz,
                channels: Default::default(),
                features: Default::default(),
                events: Default::default(),
                phases: Default::default(),
            };
            for (i, (n, scale)) in channels.iter().enumerate() {
                c.channels.push(ChannelSpec {
                    name: nth_name("c", i, n),
                    unit: Default::default(),
                    scale: *scale,
                });
            }
            let mut slots: Vec<String> = c.channels.iter().map(|ch| ch.name.clone()).collect();
            for (i, (n, stage)) in features.into_iter().enumerate() {
                let stage = stage
                    .map_inputs(|r| Ok::<_, ()>(resolve(r, &slots, "c0")))
                    .unwrap_or(StageSpec::Raw { input: name("c0") });
                let fname = nth_name("f", i, &n);
                slots.push(fname.clone());
                c.features.push(FeatureSpec { name: fname, stage });
            }
            let features: Vec<String> = c.features.iter().map(|f| f.name.clone()).collect();
            for (i, (n, e)) in events.into_iter().enumerate() {
                let mut spec = EventSpec {
                    name: nth_name("e", i, &n),
                    context: Default::default(),
                    sensor: Default::default(),
                    alert: e.alert,
                    confirm: e.confirm,
                    onset_level: e.onset_level,
                    // Every other event excludes the first, so that exclusions run too.
                    excludes: c
                        .events
                        .first()
                        .filter(|_| i % 2 == 1)
                        .map(|first| vec![first.name.clone()])
                        .unwrap_or_default(),
                };
                for (r, cdf) in e.context {
                    let feature = resolve(&r, &features, "f0");
                    spec.context.push(ContextTerm { feature, cdf });
                }
                for (r, weight, cdf) in e.sensor {
                    let feature = resolve(&r, &features, "f0");
                    spec.sensor.push(SensorTerm {
                        feature,
                        weight,
                        cdf,
                    });
                }
                if let Some((r, above, dwell_ms)) = e.early {
                    let feature = match r {
                        Some(r) => resolve(&r, &features, "f0"),
                        None => spec
                            .sensor
                            .first()
                            .map_or(name("f0"), |t| t.feature.clone()),
                    };
                    spec.confirm.early = Some(EarlySpec {
                        feature,
                        above,
                        dwell_ms,
                    });
                }
                c.events.push(spec);
            }
            let events: Vec<String> = c.events.iter().map(|e| e.name.clone()).collect();
            for (i, (n, refs)) in phases.into_iter().enumerate() {
                let mut p = PhaseSpec {
                    name: nth_name("p", i, &n),
                    events: Default::default(),
                };
                for (k, r) in refs.iter().enumerate() {
                    let e = resolve(r, &events, "e0");
                    // Mostly distinct; a repeat now and then.
                    if !p.events.contains(&e) || k == 7 {
                        p.events.push(e);
                    }
                }
                c.phases.push(p);
            }
            c
        })
}

/// One tick's arbitrary inputs: samples, faults, a phase index to switch to.
fn any_tick() -> impl Strategy<Value = ([i32; 16], u32, Option<u8>)> {
    let sample = prop_oneof![
        4 => any::<i32>(),
        1 => prop::sample::select(vec![i32::MIN, i32::MAX, 0, -1, 1, i32::MIN + 1]),
        4 => -(1i32 << 20)..(1i32 << 20),
        12 => -(8i32 << 16)..(8i32 << 16),
    ];
    (
        prop::array::uniform16(sample),
        prop_oneof![3 => Just(0u32), 1 => any::<u32>()],
        prop_oneof![6 => Just(None), 1 => any::<u8>().prop_map(Some)],
    )
}

/// Runs a built detector over arbitrary ticks and checks every output's consistency.
fn exercise(
    det: &Detector,
    ticks: &[([i32; 16], u32, Option<u8>)],
    start: u32,
) -> Result<(), TestCaseError> {
    let mut st = det.new_state();
    for (k, (samples, faults, switch)) in ticks.iter().enumerate() {
        if let Some(p) = switch.and_then(|i| det.phase_at(i)) {
            det.set_phase(&mut st, p);
        }
        let now = start.wrapping_add(k as u32);
        let out = det.tick(&mut st, now, &inputs(samples, *faults));
        let phase_events = det.phase_events(st.phase());
        prop_assert_eq!(out.evaluated, phase_events);
        prop_assert_eq!(out.unjudgeable & !out.evaluated, 0);
        prop_assert_eq!(out.degraded & !out.evaluated, 0);
        prop_assert_eq!(out.degraded & out.unjudgeable, 0);
        let judged = out.evaluated & !out.unjudgeable;
        prop_assert_eq!(out.alerting & !judged, 0);
        prop_assert_eq!(out.confirmed & !judged, 0);
        for (i, c) in out.confidences.iter().enumerate() {
            prop_assert!(c.to_bits() <= 32768);
            if judged & (1 << i) == 0 {
                prop_assert_eq!(
                    c.to_bits(),
                    0,
                    "event {} not judged but has a confidence",
                    i
                );
            }
        }
        let mut seen = Vec::new();
        for d in &out.decisions {
            let e = usize::from(d.event.0);
            prop_assert!(e < det.events().len());
            prop_assert!(judged & (1 << e) != 0, "decision for an event not judged");
            prop_assert!(!seen.contains(&(e, d.level)), "two decisions for one level");
            seen.push((e, d.level));
            prop_assert_eq!(d.tick, now);
            prop_assert_eq!(d.confidence, out.confidences[e]);
            prop_assert!(
                now.wrapping_sub(d.onset) <= k as u32,
                "onset {} after now {}",
                d.onset,
                now
            );
            let up = match d.level {
                detector_core::Level::Alert => out.alerting,
                detector_core::Level::Confirm => out.confirmed,
            };
            prop_assert!(up & (1 << e) != 0, "raised level not up");
        }
        // Queries with arbitrary indices.
        for e in [0u8, 7, 8, 255] {
            let _ = det.event_channels(EventId(e));
            let _ = st.terms(det, EventId(e));
        }
        for f in [0usize, 15, 16, usize::MAX] {
            let _ = st.feature(f);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(proptest_config(CASES, "proptest-regressions/core_never_panics.txt"))]

    /// Arbitrary configurations never panic `build`; those that build never panic `tick`
    /// and give consistent outputs.
    #[test]
    fn build_and_tick_never_panic(
        config in any_config(),
        ticks in prop::collection::vec(any_tick(), 1..=TICKS),
        start in prop_oneof![Just(u32::MAX - 5), any::<u32>()],
    ) {
        let built = detector_build::build(&config);
        if let Err(e) = &built {
            // The error's text renders too.
            prop_assert!(!e.to_string().is_empty());
        }
        if let Ok(det) = built {
            for n in ["", "c0", "e0", "p0", "nope"] {
                let _ = (det.channel(n), det.event(n), det.phase(n));
            }
            for p in [0u8, 1, 7, 8, 255] {
                let _ = det.phase_at(p);
            }
            for (i, v) in [(0usize, f64::NAN), (1, f64::INFINITY), (2, -1e300), (15, 0.5), (16, 1.0), (usize::MAX, -0.0)] {
                let _ = det.sample_from_si(i, v);
            }
            exercise(&det, &ticks, start)?;
        }
    }

    /// Plausible configurations (built from valid parts) with arbitrary samples: these
    /// build far more often, so `tick` sees many shapes of detector.
    #[test]
    fn plausible_configs_tick_without_panicking(
        kinds in prop::collection::vec((0u8..14, any::<[u8; 4]>(), 1u16..=128, 0.5f32..400.0), 1..=6),
        cdfs in prop::collection::vec((plausible_cdf(), any::<u8>(), 0.0f32..=0.25), 1..=8),
        masks in prop::collection::vec(any::<u8>(), 1..=3),
        ticks in prop::collection::vec(any_tick(), 1..=TICKS),
    ) {
        let channels = ["c0", "c1", "c2", "c3"];
        let mut slots: Vec<String> = channels.iter().map(|s| s.to_string()).collect();
        let mut features = Vec::new();
        for (k, (kind, picks, window, cutoff)) in kinds.iter().enumerate() {
            let p = |i: usize| name(&slots[usize::from(picks[i]) % slots.len()]);
            let stage = match kind {
                0 => StageSpec::Raw { input: p(0) },
                1 => StageSpec::Abs { input: p(0) },
                2 => StageSpec::LowPass {
                    input: p(0),
                    cutoff_hz: *cutoff,
                    warm_up_ms: k.is_multiple_of(2).then_some(5.0),
                    warm_up_until: k.is_multiple_of(3).then(|| Crossing {
                        feature: p(1),
                        above: *cutoff - 200.0,
                    }),
                    warm_up_longer: k.is_multiple_of(4).then(|| LongerWarmUp {
                        feature: p(2),
                        above: 200.0 - *cutoff,
                        warm_up_ms: 10.0,
                    }),
                },
                3 => StageSpec::Rate { input: p(0) },
                4 => StageSpec::Difference { a: p(0), b: p(1), gain: *cutoff - 200.0 },
                5 => StageSpec::Dot { a: [p(0), p(1)], b: [p(2), p(3)] },
                6 => StageSpec::Magnitude { of: [p(0), p(1)] },
                7 => StageSpec::HighPass { input: p(0), cutoff_hz: *cutoff },
                8 => StageSpec::Cancel { input: p(0), motion: p(1), gain: *cutoff - 200.0, cutoff_hz: *cutoff },
                9 => StageSpec::Mean { input: p(0), window: (*window).min(40) },
                10 => StageSpec::Envelope { input: p(0), cutoff_hz: *cutoff },
                11 => {
                    let level = *cutoff - 200.0;
                    let unless = if picks[1].is_multiple_of(2) { Shut::above(p(1), level) } else { Shut::below(p(1), level) };
                    StageSpec::Gate { input: p(0), unless, leak: f32::from(picks[1] % 3) / 2.0 }
                }
                12 => StageSpec::Positive { input: p(0) },
                _ => StageSpec::Ste { input: p(0), window: (*window).min(40), shape: if picks[1] % 2 == 0 { Window::Rectangular } else { Window::Triangular } },
            };
            let n = format!("f{k}");
            features.push((n.clone(), stage));
            slots.push(n);
        }
        let fnames: Vec<String> = features.iter().map(|(n, _)| n.clone()).collect();
        let events: Vec<EventSpec> = (0..3)
            .map(|e| {
                let pick = |i: usize| fnames[usize::from(cdfs[i % cdfs.len()].1) % fnames.len()].clone();
                let ctx = if e == 0 { vec![] } else { vec![context(&pick(e), cdfs[e % cdfs.len()].0)] };
                let sen = (0..3)
                    .map(|j| sensor(&pick(e + j + 1), cdfs[(e + j) % cdfs.len()].2, cdfs[(e + j + 1) % cdfs.len()].0))
                    .collect();
                let mut ev = event(&format!("e{e}"), ctx, sen);
                ev.alert = level(0.125, 0.0625, 0.0);
                ev.confirm = level(0.25, 0.125, 2.0);
                ev
            })
            .collect();
        let phases = masks
            .iter()
            .enumerate()
            .map(|(i, m)| {
                let names: Vec<String> = (0..3).filter(|e| m & (1 << e) != 0).map(|e| format!("e{e}")).collect();
                let refs: Vec<&str> = names.iter().map(String::as_str).collect();
                phase(&format!("p{i}"), &refs)
            })
            .collect();
        let feats = features.iter().map(|(n, s)| (n.as_str(), s.clone())).collect();
        let c = config(1000.0, &channels, feats, events, phases);
        if let Ok(det) = detector_build::build(&c) {
            exercise(&det, &ticks, 0)?;
        }
    }
}

proptest! {
    #![proptest_config(proptest_config(CDF_CASES, "proptest-regressions/core_never_panics.txt"))]

    /// Any CDF specification either is rejected or evaluates every input within [0, 1].
    #[test]
    fn cdfs_never_panic(spec in any_cdf(), xs in prop::collection::vec(any::<i32>(), 1..16)) {
        if let Ok(c) = Cdf::new(&spec) {
            for x in xs.into_iter().chain([i32::MIN, i32::MAX, 0]) {
                prop_assert!(c.eval(Signal::from_bits(x)).to_bits() <= 32768);
            }
        }
    }
}

proptest! {
    #![proptest_config(proptest_config(TOML_CASES, "proptest-regressions/core_never_panics.txt"))]

    /// Arbitrary text, and valid text with a random cut and insertion, never panic the TOML
    /// loader.
    #[test]
    fn toml_loading_never_panics(
        text in "\\PC{0,200}",
        cut in any::<prop::sample::Index>(),
        insert in "[\\[\\]={}\",.a-z0-9 \n-]{0,12}",
    ) {
        let _ = Config::from_toml(&text);
        let approach = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/approach.toml"
        ))
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let mut at = cut.index(approach.len() + 1);
        while !approach.is_char_boundary(at) {
            at -= 1;
        }
        let mutated = format!("{}{}{}", &approach[..at], insert, &approach[at..]);
        let _ = Config::from_toml(&mutated);
    }
}
