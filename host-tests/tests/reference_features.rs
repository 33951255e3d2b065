//! Each feature stage of the fixed-point engine against its `f64` definition (the
//! `StageSpec` documentation, eq. 17 for the STE), over random inputs given as raw 16.16 bits
//! (so input quantization is not counted). The bounds, with `LSB = 2⁻¹⁶`:
//!
//! | stage | inputs | bound |
//! |---|---|---|
//! | raw, abs, difference | any | exact (saturating at the `Signal` range) |
//! | gate | any | exact (the input or 0) |
//! | difference, gain g ≠ 1 | any, |g| < 4 | `1 LSB + 2⁻¹⁷ |b|` (saturating) |
//! | rate | any, integer rate | exact (saturating) |
//! | rate | any, any rate | `2⁻⁸ |Δx| + 1 LSB` (the rate is held to 1/256 Hz) |
//! | dot | any | 1 LSB (saturating) |
//! | magnitude | any | `1 LSB + 2⁻¹⁵ |m|` (16 significant bits above 1 unit) |
//! | low-pass | `|x| < 16384`, `f_s/10⁵ ≤ f_c ≤ 0.45 f_s` | `1 LSB + (2⁻²⁰ + W 2⁻³¹) max|x|`, W = min(⌈1/α⌉, 65535) |
//! | high-pass | as the low-pass | as the low-pass, and bit for bit `x − low_pass(x)` |
//! | envelope | as the low-pass | `1 LSB + 2⁻²⁰ max|x|` |
//! | mean | any, N in 1..=128 | `1 LSB + N 2⁻²⁴ max|x|` |
//! | STE, eq. 17 | `|x| < 256`, N in 1..=128 | `2 LSB + N 2⁻²³ max x² + N 2⁻²⁵ ζ` |
//!
//! The low-pass's W term is its warm-up: while 1/n weighs more than α, its n-th sample
//! weighs 1/n rounded down to 2⁻³¹, an error the running mean it then is carries about n/2
//! times.
//!
//! The STE bound's middle term is the Q24 rounding of the window taps (a triangular window's
//! end taps are only about 2⁻¹² of the window, so their relative rounding is 2⁻¹²), the last
//! the rounding of 1/N.
//!
//! Two edge cases once got wrong are pinned by their own tests: an STE of samples above 256
//! (whose squares exceed 65 536) and a low-pass whose input is more than 32768 away from its
//! state.
//!
//! Case counts: [`CASES`] per property (override with `PROPTEST_CASES`).

#[path = "reference_support.rs"]
mod support;

use detector_build::Config;
use detector_core::{Crossing, LongerWarmUp, Shut, Signal, StageSpec, Window};
use proptest::prelude::*;
use support::*;

/// Cases per property.
const CASES: u32 = 128;
/// One 16.16 step.
const LSB: f64 = 1.0 / 65536.0;

/// A configuration with channels `x y z w` and the given features (one event on the first).
fn features_config(rate_hz: f32, features: Vec<(&str, StageSpec<String>)>) -> Config {
    let first = features[0].0.to_string();
    config(
        rate_hz,
        &["x", "y", "z", "w"],
        features,
        vec![event(
            "e",
            vec![],
            vec![sensor(&first, 1.0, sigmoid(0.0, 1.0))],
        )],
        vec![phase("p", &["e"])],
    )
}

/// Runs the engine and the model; per tick, the (engine, model) feature values.
fn run(config: &Config, samples: &[[i32; 4]]) -> Vec<(Vec<f64>, Vec<f64>)> {
    let steps: Vec<Step> = samples
        .iter()
        .map(|s| Step {
            samples: s.to_vec(),
            ..Step::default()
        })
        .collect();
    run_both(config, &steps)
        .into_iter()
        .map(|b| (b.features, b.model.features))
        .collect()
}

/// The fixed-point core's first feature on `samples` is `want`, tick by tick, within two
/// LSB.
fn first_feature_follows(config: &Config, samples: &[[i32; 4]], want: &[f64]) {
    let got = run(config, samples);
    for (t, ((got, _), want)) in got.iter().zip(want).enumerate() {
        assert!((got[0] - want).abs() <= 2.0 * LSB, "tick {t}: {}", got[0]);
    }
}

/// Raw samples within ±2^k for a random k in `kmin..=kmax` (k = 31: any bits).
fn samples(kmin: u32, kmax: u32, len: usize) -> impl Strategy<Value = Vec<[i32; 4]>> {
    (kmin..=kmax).prop_flat_map(move |k| {
        prop::collection::vec(any::<[i32; 4]>(), 1..=len).prop_map(move |v| {
            v.into_iter()
                .map(|s| s.map(|w| if k >= 31 { w } else { w >> (31 - k) }))
                .collect()
        })
    })
}

fn stage(kind: &str) -> StageSpec<String> {
    match kind {
        "abs" => StageSpec::Abs { input: name("x") },
        "positive" => StageSpec::Positive { input: name("x") },
        "difference" => StageSpec::Difference {
            a: name("x"),
            b: name("y"),
            gain: 1.0,
        },
        "rate" => StageSpec::Rate { input: name("x") },
        "dot" => StageSpec::Dot {
            a: [name("x"), name("y")],
            b: [name("z"), name("w")],
        },
        "magnitude" => StageSpec::Magnitude {
            of: [name("x"), name("y")],
        },
        "gate" => StageSpec::Gate {
            input: name("x"),
            unless: Shut::above(name("y"), 0.0),
            leak: 0.0,
        },
        "gate_below" => StageSpec::Gate {
            input: name("x"),
            unless: Shut::below(name("y"), 0.0),
            leak: 0.0,
        },
        _ => raw("x"),
    }
}

proptest! {
    #![proptest_config(proptest_config(CASES, "proptest-regressions/reference_features.txt"))]

    /// Raw, abs, positive, difference, gates (shut above or below a level), and rate at an
    /// integer detector rate are exact, saturating at the `Signal` range, including the
    /// extremes of the input range.
    #[test]
    fn exact_stages_are_exact(
        rate in 10u32..=50_000,
        s in prop_oneof![samples(4, 31, 80), Just(vec![[i32::MIN, i32::MAX, 0, -1], [i32::MAX, i32::MIN, 1, 0], [i32::MIN; 4]])],
    ) {
        let kinds = ["raw", "abs", "positive", "difference", "rate", "gate", "gate_below"];
        let c = features_config(rate as f32, kinds.iter().map(|k| (*k, stage(k))).collect());
        for (t, (got, want)) in run(&c, &s).iter().enumerate() {
            for (i, kind) in kinds.iter().enumerate() {
                prop_assert_eq!(got[i], want[i], "{} at tick {}", kind, t);
            }
        }
    }

    /// A leaking gate, shut, passes its leak's fraction of the input within the leak's
    /// rounding to 2⁻¹⁶ (|x| 2⁻¹⁷) and the product's, floored (1 LSB); open, the input
    /// exactly.
    #[test]
    fn leaking_gate_within_bound(
        leak in prop_oneof![Just(0.0f32), 0.0001f32..=1.0],
        s in samples(4, 31, 60),
    ) {
        let c = gate_config(0.0, leak);
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            let x = Signal::from_bits(row[0]).to_f64();
            let bound = if row[1] > 0 { x.abs() / 131_072.0 + LSB } else { 0.0 };
            prop_assert!((got[0] - want[0]).abs() <= bound,
                "tick {}: engine {} model {} (leak {})", t, got[0], want[0], leak);
        }
    }

    /// The rate at any detector rate: within 2⁻⁸ |Δx| + 1 LSB; zero on the first tick.
    #[test]
    fn rate_within_bound(rate in 10.0f32..=50_000.0, s in samples(4, 31, 60)) {
        let c = features_config(rate, vec![("rate", stage("rate"))]);
        let mut prev: Option<f64> = None;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            let x = Signal::from_bits(row[0]).to_f64();
            let dx = prev.map_or(0.0, |p| (x - p).abs());
            prev = Some(x);
            if t == 0 {
                prop_assert_eq!(got[0], 0.0);
            }
            prop_assert!((got[0] - want[0]).abs() <= dx / 256.0 + LSB,
                "tick {}: engine {} model {} (rate {})", t, got[0], want[0], rate);
        }
    }

    /// The dot product: within 1 LSB, saturating.
    #[test]
    fn dot_within_one_lsb(s in samples(4, 31, 60)) {
        let c = features_config(5000.0, vec![("dot", stage("dot"))]);
        for (t, (got, want)) in run(&c, &s).iter().enumerate() {
            prop_assert!((got[0] - want[0]).abs() <= LSB, "tick {}: engine {} model {}", t, got[0], want[0]);
        }
    }

    /// The magnitude: within 1 LSB + 2⁻¹⁵ of its value, saturating.
    #[test]
    fn magnitude_within_relative_bound(s in samples(4, 31, 60)) {
        let c = features_config(5000.0, vec![("magnitude", stage("magnitude"))]);
        for (t, (got, want)) in run(&c, &s).iter().enumerate() {
            prop_assert!((got[0] - want[0]).abs() <= LSB + want[0] / 32768.0,
                "tick {}: engine {} model {}", t, got[0], want[0]);
        }
    }

    /// The low-pass (backward Euler, α = Δt/(τ + Δt), warming up as the mean of what it has
    /// seen): within its bound for inputs below 16384 and cut-offs from f_s/10⁵ to 0.45 f_s.
    #[test]
    fn low_pass_within_bound(
        rate in 10.0f32..=50_000.0,
        fraction in prop_oneof![0.001f32..=0.45, 0.00001f32..=0.001],
        s in samples(4, 29, 300),
    ) {
        let lp = |cutoff_hz| StageSpec::LowPass {
            input: name("x"),
            cutoff_hz,
            warm_up_ms: None,
            warm_up_until: None,
        warm_up_longer: None,
    };
        let cutoffs = [rate * fraction, rate * 0.45];
        let c = features_config(rate, vec![("lp", lp(cutoffs[0])), ("lp2", lp(cutoffs[1]))]);
        let mut max_x: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            max_x = max_x.max(Signal::from_bits(row[0]).to_f64().abs());
            for i in 0..2 {
                let bound = low_pass_bound(rate, cutoffs[i], max_x);
                prop_assert!((got[i] - want[i]).abs() <= bound,
                    "feature {} tick {}: engine {} model {} bound {:e}", i, t, got[i], want[i], bound);
            }
        }
    }

    /// A warm-up carried on to a longer one while a channel reads above a level as the
    /// shorter ends (and ended early by another): within the low-pass's bound, the two
    /// models taking the same turns on the same exact channels.
    #[test]
    fn low_pass_with_a_longer_warm_up_within_bound(
        fraction in prop_oneof![0.0001f32..=0.01, 0.01f32..=0.45],
        warm_ms in 1u8..=30,
        more_ms in 1u8..=30,
        above in -3.0f32..3.0,
        ends in prop::option::of(-3.0f32..3.0),
        s in samples(4, 18, 120),
    ) {
        let rate = 1000.0;
        let cutoff_hz = rate * fraction;
        let c = features_config(rate, vec![(
            "lp",
            StageSpec::LowPass {
                input: name("x"),
                cutoff_hz,
                warm_up_ms: Some(f32::from(warm_ms)),
                warm_up_until: ends.map(|above| Crossing { feature: name("z"), above }),
                warm_up_longer: Some(LongerWarmUp {
                    feature: name("y"),
                    above,
                    warm_up_ms: f32::from(warm_ms) + f32::from(more_ms),
                }),
            },
        )]);
        let mut max_x: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            max_x = max_x.max(Signal::from_bits(row[0]).to_f64().abs());
            let bound = low_pass_bound(rate, cutoff_hz, max_x);
            prop_assert!((got[0] - want[0]).abs() <= bound,
                "tick {}: engine {} model {} bound {:e}", t, got[0], want[0], bound);
        }
    }

    /// The envelope: up with the input at once (exactly), down as the low-pass: within
    /// 1 LSB + 2⁻²⁰ max|x| of the model, never below the input.
    #[test]
    fn envelope_within_bound(
        rate in 10.0f32..=50_000.0,
        fraction in 0.001f32..=0.45,
        s in samples(4, 29, 300),
    ) {
        let c = features_config(rate, vec![
            ("env", StageSpec::Envelope { input: name("x"), cutoff_hz: rate * fraction }),
        ]);
        let mut max_x: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            let x = Signal::from_bits(row[0]).to_f64();
            max_x = max_x.max(x.abs());
            prop_assert!(got[0] >= x, "tick {}: {} below the input {}", t, got[0], x);
            prop_assert!((got[0] - want[0]).abs() <= LSB + max_x / 1_048_576.0,
                "tick {}: engine {} model {}", t, got[0], want[0]);
        }
    }

    /// A difference with a gain: within 1 LSB + 2⁻¹⁷ |b| of a − g b (the scaled subtrahend
    /// floored, the gain rounded to 2⁻¹⁶), saturating; a gain of 1 is bit for bit the plain
    /// difference.
    #[test]
    fn difference_with_a_gain_within_bound(
        gain in -4.0f32..4.0,
        s in samples(4, 31, 80),
    ) {
        let diff = |gain| StageSpec::Difference { a: name("x"), b: name("y"), gain };
        let c = features_config(5000.0, vec![
            ("scaled", diff(gain)),
            ("unit", diff(1.0)),
            ("plain", StageSpec::Difference { a: name("x"), b: name("y"), gain: 1.0 }),
        ]);
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            let b = Signal::from_bits(row[1]).to_f64().abs();
            prop_assert!((got[0] - want[0]).abs() <= LSB + b / 131_072.0,
                "tick {}: engine {} model {}", t, got[0], want[0]);
            let x = Signal::from_bits(row[0]).to_f64();
            let y = Signal::from_bits(row[1]).to_f64();
            prop_assert_eq!(got[1], Signal::from_f64(x - y).to_f64(), "tick {}", t);
        }
    }

    /// The mean of the last N inputs (of those that have arrived, before N have): within
    /// 1 LSB + N 2⁻²⁴ max|x| of the model, for any input and N in 1..=128.
    #[test]
    fn mean_within_bound(
        n in 1u16..=128,
        s in samples(4, 31, 300),
    ) {
        let c = features_config(5000.0, vec![
            ("mean", StageSpec::Mean { input: name("x"), window: n }),
        ]);
        let mut max_x: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            max_x = max_x.max(Signal::from_bits(row[0]).to_f64().abs());
            let bound = LSB + f64::from(n) * max_x / 16_777_216.0;
            prop_assert!((got[0] - want[0]).abs() <= bound,
                "tick {}: engine {} model {} bound {:e}", t, got[0], want[0], bound);
        }
    }

    /// The high-pass is, bit for bit, the input less its low-pass at the same cut-off (the
    /// two-feature form it replaces), and within its bound of the model.
    #[test]
    fn high_pass_is_the_input_less_its_low_pass(
        rate in 10.0f32..=50_000.0,
        fraction in 0.001f32..=0.45,
        s in samples(4, 29, 300),
    ) {
        let cutoff_hz = rate * fraction;
        let c = features_config(rate, vec![
            ("hp", StageSpec::HighPass { input: name("x"), cutoff_hz }),
            (
                "lp",
                StageSpec::LowPass {
                    input: name("x"),
                    cutoff_hz,
                    warm_up_ms: None,
                    warm_up_until: None,
                warm_up_longer: None,
            },
            ),
            ("diff", StageSpec::Difference { a: name("x"), b: name("lp"), gain: 1.0 }),
        ]);
        let mut max_x: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            max_x = max_x.max(Signal::from_bits(row[0]).to_f64().abs());
            prop_assert_eq!(got[0].to_bits(), got[2].to_bits(), "tick {}", t);
            let bound = low_pass_bound(rate, cutoff_hz, max_x);
            prop_assert!((got[0] - want[0]).abs() <= bound,
                "tick {}: engine {} model {}", t, got[0], want[0]);
        }
    }

    /// Self-motion cancellation is the input less `gain` times the motion's low-pass: within
    /// its bound of the model (the low-pass's, times |gain|, plus the gain's rounding to
    /// 2⁻¹⁶); an input that is exactly `gain` times the same low-pass cancels to within
    /// that bound; a gain of 0 passes the input bit for bit.
    #[test]
    fn cancel_removes_the_predicted_part(
        gain in -60.0f32..60.0,
        fraction in 0.001f32..=0.45,
        s in samples(4, 20, 300),
    ) {
        let rate = 5000.0;
        let cutoff_hz = rate * fraction;
        let cancel = |input: &str, gain| StageSpec::Cancel {
            input: name(input),
            motion: name("y"),
            gain,
            cutoff_hz,
        };
        let c = features_config(rate, vec![
            ("c", cancel("x", gain)),
            (
                // The cancellation's own low-pass, which warms up over the filter's natural
                // length (a shorter warm-up would differ below 5.3 Hz, where that length
                // is above 30 ms).
                "lp",
                StageSpec::LowPass {
                    input: name("y"),
                    cutoff_hz,
                    warm_up_ms: None,
                    warm_up_until: None,
                    warm_up_longer: None,
                },
            ),
            ("zero", cancel("x", 0.0)),
        ]);
        let g = f64::from(gain).abs();
        let mut max_y: f64 = 0.0;
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            max_y = max_y.max(Signal::from_bits(row[1]).to_f64().abs());
            let bound = 2.0 * LSB + g * low_pass_bound(rate, cutoff_hz, max_y) + max_y / 131_072.0;
            prop_assert!((got[0] - want[0]).abs() <= bound,
                "tick {}: engine {} model {} bound {:e}", t, got[0], want[0], bound);
            let x = Signal::from_bits(row[0]).to_f64();
            prop_assert_eq!(got[2], x, "tick {}", t);
            // The engine's own low-pass of y, times the gain, is what it took away.
            let predicted = f64::from(gain) * got[1];
            prop_assert!((got[0] - (x - predicted)).abs() <= 2.0 * LSB + max_y / 131_072.0,
                "tick {}: {} vs {} - {}", t, got[0], x, predicted);
        }
    }

    /// The short-time energy against eq. 17 with the normalized window, both shapes, windows
    /// 1..=128, inputs below 256 in magnitude, from the first tick (before N samples, the
    /// rectangular window's mean square of those that have arrived, the triangular window's
    /// missing samples zero).
    #[test]
    fn ste_matches_eq_17(
        n1 in 1u16..=128,
        n2 in 1u16..=128,
        s in samples(4, 23, 300),
    ) {
        let ste = |input: &str, window, shape| StageSpec::Ste { input: name(input), window, shape };
        let c = features_config(5000.0, vec![
            ("rect", ste("x", n1, Window::Rectangular)),
            ("tri", ste("y", n2, Window::Triangular)),
        ]);
        let mut max_sq = [0.0f64; 2];
        for (t, ((got, want), row)) in run(&c, &s).iter().zip(&s).enumerate() {
            for (i, n) in [n1, n2].into_iter().enumerate() {
                let x = Signal::from_bits(row[i]).to_f64();
                max_sq[i] = max_sq[i].max(x * x);
                let n = f64::from(n);
                let bound = 2.0 * LSB + n * max_sq[i] / 8_388_608.0 + n * want[i] / 33_554_432.0;
                prop_assert!((got[i] - want[i]).abs() <= bound,
                    "window {} tick {}: engine {} model {} bound {:e}", i, t, got[i], want[i], bound);
            }
        }
    }
}

/// Eq. 17 by hand for a constant input: after N samples ζ = x² whatever the window; before,
/// the rectangular window is the mean square of what has arrived, x², and the triangular one
/// counts the missing samples as zero.
#[test]
fn ste_of_a_constant_by_hand() {
    let ste = |window, shape| StageSpec::Ste {
        input: name("x"),
        window,
        shape,
    };
    let c = features_config(
        5000.0,
        vec![
            ("rect", ste(4, Window::Rectangular)),
            ("tri", ste(5, Window::Triangular)),
        ],
    );
    // x = 3: x² = 9. Rectangular N = 4: 9 from the first sample.
    // Triangular N = 5: taps ∝ 1 − |2m − 4|/6 = 1/3, 2/3, 1, 2/3, 1/3 (sum 3), so
    // h = 1/9, 2/9, 3/9, 2/9, 1/9 and the partial sums of 9 h are 1, 3, 6, 8, 9.
    let x = 3 << 16;
    let got: Vec<(f64, f64)> = run(&c, &[[x, 0, 0, 0]; 6])
        .into_iter()
        .map(|(g, _)| (g[0], g[1]))
        .collect();
    let rect = [9.0; 6];
    let tri = [1.0, 3.0, 6.0, 8.0, 9.0, 9.0];
    for (t, (r, tr)) in got.into_iter().enumerate() {
        assert!((r - rect[t]).abs() <= 2.0 * LSB, "rect tick {t}: {r}");
        assert!((tr - tri[t]).abs() <= 4.0 * LSB, "tri tick {t}: {tr}");
    }
}

/// The low-pass by hand: at f_c = f_s / (2π), τ = Δt so α = ½; seeded with the first sample
/// (the warm-up's 1/n never weighs more than ½ after it).
#[test]
fn low_pass_by_hand() {
    let rate = 1000.0f32;
    let c = features_config(
        rate,
        vec![(
            "lp",
            StageSpec::LowPass {
                input: name("x"),
                cutoff_hz: rate / (2.0 * std::f32::consts::PI),
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            },
        )],
    );
    // x: 2, 4, 4, 0 → y: 2 (seed), 3, 3.5, 1.75.
    let s = [2, 4, 4, 0].map(|v| [v << 16, 0, 0, 0]);
    let want = [2.0, 3.0, 3.5, 1.75];
    first_feature_follows(&c, &s, &want);
}

/// The envelope by hand at α = ½: inputs 10, 0, 0, 20, 0 give 10, 5, 2.5, 20, 10 (up at
/// once, down halfway each tick).
#[test]
fn envelope_by_hand() {
    let rate = 1000.0f32;
    let c = features_config(
        rate,
        vec![(
            "env",
            StageSpec::Envelope {
                input: name("x"),
                cutoff_hz: rate / (2.0 * std::f32::consts::PI),
            },
        )],
    );
    let s = [10, 0, 0, 20, 0].map(|v| [v << 16, 0, 0, 0]);
    let want = [10.0, 5.0, 2.5, 20.0, 10.0];
    first_feature_follows(&c, &s, &want);
}

/// A gate of x, shut while y is above `above`, leaking `leak`.
fn gate_config(above: f32, leak: f32) -> Config {
    gate_on_side(Some(above), None, leak)
}

/// A gate of x, shut while y is above `above` or below `below`, leaking `leak`.
fn gate_on_side(above: Option<f32>, below: Option<f32>, leak: f32) -> Config {
    features_config(
        1000.0,
        vec![(
            "gate",
            StageSpec::Gate {
                input: name("x"),
                unless: Shut {
                    feature: name("y"),
                    above,
                    below,
                },
                leak,
            },
        )],
    )
}

/// The gate by hand, x 3, 4, 5, 6, 7 with y 0, 0.5, 0.75, -2, 1: shut above 0.5, x passes
/// while y is at or below it and reads 0 above (3, 4, 0, 6, 0); shut below 0.5, x passes
/// while y is at or above it and reads 0 below (0, 4, 5, 0, 7), or, leaking a half, half
/// of x (1.5, 4, 5, 3, 7).
#[test]
fn gate_by_hand() {
    let s = [
        (3, 0),
        (4, 1 << 15),
        (5, 3 << 14),
        (6, -2 << 16),
        (7, 1 << 16),
    ]
    .map(|(x, y)| [x << 16, y, 0, 0]);
    for (above, below, leak, want) in [
        (Some(0.5), None, 0.0, [3.0, 4.0, 0.0, 6.0, 0.0]),
        (None, Some(0.5), 0.0, [0.0, 4.0, 5.0, 0.0, 7.0]),
        (None, Some(0.5), 0.5, [1.5, 4.0, 5.0, 3.0, 7.0]),
    ] {
        let c = gate_on_side(above, below, leak);
        let got: Vec<f64> = run(&c, &s).into_iter().map(|(g, _)| g[0]).collect();
        assert_eq!(got, want, "above {above:?}, below {below:?}, leak {leak}");
    }
}

/// A leaking gate passes its fraction of the input while shut: with a leak of 0.1, x 3,
/// -5, 40 with y 0, 1, 1 give 3, -0.5 and 4, each rounded down to 2^-16 (the leak is
/// 6554 / 65536, and the product is floored).
#[test]
fn leaking_gate_by_hand() {
    let c = gate_config(0.5, 0.1);
    let s = [(3, 0), (-5, 1 << 16), (40, 1 << 16)].map(|(x, y)| [x << 16, y, 0, 0]);
    let got: Vec<f64> = run(&c, &s).into_iter().map(|(g, _)| g[0]).collect();
    let leak = 6554.0 / 65536.0;
    let floored = |v: f64| (v * leak * 65536.0).floor() / 65536.0;
    assert_eq!(got, [3.0, floored(-5.0), floored(40.0)]);
    assert!((got[1] + 0.5).abs() < 1e-4 && (got[2] - 4.0).abs() < 1e-3);
}

/// The low-pass warms up as the mean of what it has seen: at f_c = 1 Hz and f_s = 1 kHz
/// (α ≈ 1/160), inputs 1, 2, 3, 4, 100 give 1, 1.5, 2, 2.5, 22; a mean's window of 3 gives
/// 1, 1.5, 2, 3, 35.667.
#[test]
fn low_pass_and_mean_warm_up_as_the_mean_so_far() {
    let c = features_config(
        1000.0,
        vec![
            (
                "lp",
                StageSpec::LowPass {
                    input: name("x"),
                    cutoff_hz: 1.0,
                    warm_up_ms: None,
                    warm_up_until: None,
                    warm_up_longer: None,
                },
            ),
            (
                "mean",
                StageSpec::Mean {
                    input: name("x"),
                    window: 3,
                },
            ),
        ],
    );
    let s = [1, 2, 3, 4, 100].map(|v| [v << 16, 0, 0, 0]);
    let lp = [1.0, 1.5, 2.0, 2.5, 22.0];
    let mean = [1.0, 1.5, 2.0, 3.0, 107.0 / 3.0];
    for (t, (got, model)) in run(&c, &s).into_iter().enumerate() {
        assert!(
            (got[0] - lp[t]).abs() <= 4.0 * LSB,
            "low-pass tick {t}: {}",
            got[0]
        );
        assert!(
            (model[0] - lp[t]).abs() <= 1e-9,
            "model tick {t}: {}",
            model[0]
        );
        assert!(
            (got[1] - mean[t]).abs() <= 2.0 * LSB,
            "mean tick {t}: {}",
            got[1]
        );
    }
}

/// Documented: the STE is a mean square saturating at the `Signal` range. One sample of 300
/// in a full rectangular window of 4 is 300²/4 = 22500, well inside the range; alone, before
/// the window has filled, it is 300² and saturates.
#[test]
fn ste_of_a_large_sample_saturates_only_at_the_signal_range() {
    let c = features_config(
        5000.0,
        vec![(
            "ste",
            StageSpec::Ste {
                input: name("x"),
                window: 4,
                shape: Window::Rectangular,
            },
        )],
    );
    let got = run(&c, &[[0; 4], [0; 4], [0; 4], [300 << 16, 0, 0, 0]]);
    assert!((got[3].0[0] - 22500.0).abs() <= 2.0 * LSB, "{:?}", got[3]);
    let alone = run(&c, &[[300 << 16, 0, 0, 0]]);
    assert_eq!(alone[0].0[0], Signal::MAX.to_f64(), "{:?}", alone[0]);
}

/// Documented: y += α (x − y), x − y saturated to the feature range. From y = 30000,
/// x = −30000 at α = ½: the step of −60000 is cut to −32768, giving 13616; then −43616 is
/// cut again, giving −2768; then −27232 is whole, giving −16384.
#[test]
fn low_pass_follows_a_step_across_the_range() {
    let rate = 1000.0f32;
    let c = features_config(
        rate,
        vec![(
            "lp",
            StageSpec::LowPass {
                input: name("x"),
                cutoff_hz: rate / (2.0 * std::f32::consts::PI),
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            },
        )],
    );
    let s = [30000, -30000, -30000, -30000].map(|v| [v << 16, 0, 0, 0]);
    let want = [30000.0, 13616.0, -2768.0, -16384.0];
    for (t, (got, model)) in run(&c, &s).into_iter().enumerate() {
        // α is ½ to within f32 rounding of the cut-off: a few 10⁻³ at this scale.
        assert!(
            (model[0] - want[t]).abs() <= 0.01,
            "model tick {t}: {}",
            model[0]
        );
        assert!((got[0] - want[t]).abs() <= 0.01, "tick {t}: {}", got[0]);
    }
}

/// The low-pass's bound at `cutoff_hz` on inputs of at most `max_x` (the module doc).
fn low_pass_bound(rate_hz: f32, cutoff_hz: f32, max_x: f64) -> f64 {
    let alpha = host_tests::reference::low_pass_alpha(f64::from(rate_hz), f64::from(cutoff_hz));
    let warm = (1.0 / alpha).ceil().min(65535.0);
    LSB + max_x * (1.0 / 1_048_576.0 + warm / 2_147_483_648.0)
}
