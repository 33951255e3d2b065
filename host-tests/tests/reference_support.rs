//! Helpers shared by the `reference_*` and `core_*` tests (included with `#[path]`): building
//! configurations in code, running the fixed-point engine and the `f64` model side by side.
#![allow(dead_code)]

use detector_build::{
    ChannelSpec, Config, ContextTerm, EventSpec, FeatureSpec, LevelSpec, PhaseSpec, SensorTerm,
};
use detector_core::{CdfSpec, EventId, Inputs, Output, Signal, StageSpec};
use host_tests::reference::{Model, ModelOutput};

/// A name.
pub fn name(s: &str) -> String {
    s.to_owned()
}

/// A level without hold.
pub fn level(on: f32, off: f32, dwell_ms: f32) -> LevelSpec {
    LevelSpec {
        on,
        off,
        dwell_ms,
        hold_ms: 0.0,
        early: None,
    }
}

/// A sensor term.
pub fn sensor(feature: &str, weight: f32, cdf: CdfSpec) -> SensorTerm {
    SensorTerm {
        feature: name(feature),
        weight,
        cdf,
    }
}

/// A context term.
pub fn context(feature: &str, cdf: CdfSpec) -> ContextTerm {
    ContextTerm {
        feature: name(feature),
        cdf,
    }
}

/// An event with default levels (alert 0.5/0.25, confirm 0.75/0.5, no dwell).
pub fn event(event_name: &str, ctx: Vec<ContextTerm>, sen: Vec<SensorTerm>) -> EventSpec {
    let mut e = EventSpec {
        name: name(event_name),
        context: Default::default(),
        sensor: Default::default(),
        alert: level(0.5, 0.25, 0.0),
        confirm: level(0.75, 0.5, 0.0),
        onset_level: 0.0,
        excludes: Vec::new(),
    };
    for c in ctx {
        e.context.push(c);
    }
    for s in sen {
        e.sensor.push(s);
    }
    e
}

/// A phase.
pub fn phase(phase_name: &str, events: &[&str]) -> PhaseSpec {
    let mut p = PhaseSpec {
        name: name(phase_name),
        events: Default::default(),
    };
    for e in events {
        p.events.push(name(e));
    }
    p
}

/// A configuration from its parts.
pub fn config(
    rate_hz: f32,
    channels: &[&str],
    features: Vec<(&str, StageSpec<String>)>,
    events: Vec<EventSpec>,
    phases: Vec<PhaseSpec>,
) -> Config {
    let mut c = Config {
        rate_hz,
        channels: Default::default(),
        features: Default::default(),
        events: Default::default(),
        phases: Default::default(),
    };
    for ch in channels {
        c.channels.push(ChannelSpec {
            name: name(ch),
            unit: "1".into(),
            scale: 1.0,
        });
    }
    for (n, stage) in features {
        c.features.push(FeatureSpec {
            name: name(n),
            stage,
        });
    }
    for e in events {
        c.events.push(e);
    }
    for p in phases {
        c.phases.push(p);
    }
    c
}

/// A raw feature of `input`.
pub fn raw(input: &str) -> StageSpec<String> {
    StageSpec::Raw { input: name(input) }
}

/// A rising sigmoid.
pub fn sigmoid(low: f32, high: f32) -> CdfSpec {
    CdfSpec::Sigmoid {
        low,
        high,
        falling: false,
    }
}

/// Inputs from raw 16.16 samples and a fault mask.
pub fn inputs(samples: &[i32], faults: u32) -> Inputs {
    let mut i = Inputs {
        faults,
        ..Inputs::default()
    };
    for (slot, &s) in i.samples.iter_mut().zip(samples) {
        *slot = Signal::from_bits(s);
    }
    i
}

/// Inputs from `f64` samples (converted to 16.16, rounding) and a fault mask.
pub fn inputs_f64(samples: &[f64], faults: u32) -> Inputs {
    let bits: Vec<i32> = samples
        .iter()
        .map(|&v| Signal::from_f64(v).to_bits())
        .collect();
    inputs(&bits, faults)
}

/// One step of a scripted run: the samples (raw 16.16), the faulty channels, and a phase to
/// switch to before the tick.
#[derive(Clone, Debug, Default)]
pub struct Step {
    /// Raw 16.16 samples, by channel.
    pub samples: Vec<i32>,
    /// Faulty channels.
    pub faults: u32,
    /// Phase index to switch to before this tick.
    pub switch_to: Option<u8>,
}

/// One tick of a side-by-side run.
#[derive(Clone, Debug)]
pub struct Both {
    /// The engine's output.
    pub out: Output,
    /// The engine's term confidences per event (context, sensor), as `f64`.
    pub terms: Vec<(Vec<f64>, Vec<f64>)>,
    /// The engine's feature values, as `f64`.
    pub features: Vec<f64>,
    /// The model's output.
    pub model: ModelOutput,
}

/// Runs the engine and the model side by side over `steps`, tick `i` at `now = i`.
pub fn run_both(config: &Config, steps: &[Step]) -> Vec<Both> {
    let det = detector_build::build(config).expect("config builds");
    let model = Model::new(config).expect("model resolves");
    let mut st = det.new_state();
    let mut ms = model.new_state();
    let mut out = Vec::with_capacity(steps.len());
    for (i, step) in steps.iter().enumerate() {
        if let Some((p, id)) = step.switch_to.and_then(|p| Some((p, det.phase_at(p)?))) {
            det.set_phase(&mut st, id);
            model.set_phase(&mut ms, usize::from(p));
        }
        let inp = inputs(&step.samples, step.faults);
        let samples: Vec<f64> = step
            .samples
            .iter()
            .map(|&b| Signal::from_bits(b).to_f64())
            .collect();
        let now = i as u32;
        let o = det.tick(&mut st, now, &inp);
        let m = model.tick(&mut ms, now, &samples, step.faults);
        let terms = (0..config.events.len())
            .map(|e| {
                let (c, s) = st.terms(&det, EventId(e as u8)).expect("event exists");
                (
                    c.iter().map(|x| x.to_f64()).collect(),
                    s.iter().map(|x| x.to_f64()).collect(),
                )
            })
            .collect();
        let features = (0..config.features.len())
            .map(|f| st.feature(f).expect("feature exists").to_f64())
            .collect();
        out.push(Both {
            out: o,
            terms,
            features,
            model: m,
        });
    }
    out
}

/// The proptest case count: `default`, or the `PROPTEST_CASES` environment variable when
/// set (for longer runs: `PROPTEST_CASES=2000 cargo test ...`).
pub fn cases(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// A proptest configuration: [`cases`]`(default_cases)` cases, failures persisted to
/// `proptest-regressions/<file>.txt` under `host-tests/` (the working directory of tests).
pub fn proptest_config(default_cases: u32, file: &'static str) -> proptest::test_runner::Config {
    proptest::test_runner::Config {
        cases: cases(default_cases),
        failure_persistence: Some(Box::new(
            proptest::test_runner::FileFailurePersistence::Direct(file),
        )),
        ..proptest::test_runner::Config::default()
    }
}

// ---- Error analysis: how far the engine may be from the model -------------------------

/// One 16.16 step.
pub const LSB: f64 = 1.0 / 65536.0;
/// The CDF evaluation error bound for exact inputs and parameters (checked in
/// `core_cdf_shapes.rs`): 2.5 steps of Q15.
pub const CDF_ERROR: f64 = 2.5 / 32768.0;

/// Per-slot statistics of a run of the model (channels then features).
#[derive(Clone, Copy, Debug, Default)]
pub struct Stats {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Largest magnitude.
    pub abs: f64,
    /// Largest change from one tick to the next.
    pub step: f64,
}

/// Statistics per slot of a series of rows (one row per tick, one column per slot).
pub fn stats(series: &[Vec<f64>]) -> Vec<Stats> {
    let slots = series.first().map_or(0, Vec::len);
    (0..slots)
        .map(|s| {
            let mut st = Stats {
                min: f64::INFINITY,
                max: f64::NEG_INFINITY,
                ..Stats::default()
            };
            let mut prev: Option<f64> = None;
            for row in series {
                let v = row[s];
                st.min = st.min.min(v);
                st.max = st.max.max(v);
                st.abs = st.abs.max(v.abs());
                if let Some(p) = prev {
                    st.step = st.step.max((v - p).abs());
                }
                prev = Some(v);
            }
            st
        })
        .collect()
}

/// Runs the model's features over `samples` (rows of channel values); returns each tick's
/// row of channel values then feature values.
pub fn model_series(config: &Config, samples: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let model = Model::new(config).expect("model resolves");
    let mut ms = model.new_state();
    samples
        .iter()
        .map(|row| {
            let f = model.update_features(&mut ms, row);
            row.iter().copied().chain(f).collect()
        })
        .collect()
}

/// Each slot's error bound (channels: 0, the inputs being exact), from the slots'
/// statistics over the run. Per stage, with `LSB = 2⁻¹⁶` (the bounds `reference_features.rs`
/// checks, carried through chains):
///
/// - raw, abs: the input's error; difference: `δ_a + |g| δ_b`, and at a gain other than
///   1 `+ LSB + 2⁻¹⁷ max|b|` (the scaled subtrahend floored, the gain rounded to 2⁻¹⁶);
/// - rate: 0 at an integer rate, else `2⁻⁸ max|Δx| + LSB` (its input assumed exact);
/// - low-pass: the input's + `LSB + (2⁻²⁰ + W 2⁻³¹) max|x|`, W = min(⌈1/α⌉, 65535) the
///   samples it warms up over (each warm-up gain 1/n rounded down to 2⁻³¹, an error the
///   running mean carries n/2 times);
/// - high-pass: twice the input's + the low-pass's own;
/// - envelope: the input's + `LSB + 2⁻²⁰ max|x|` (up exactly, down as a warm low-pass);
/// - gate: the input's, and `max|x|` more when the watched slot is not exact (the model and
///   the engine may then see it on either side of the level);
/// - mean: the input's + `LSB + N 2⁻²⁴ max|x|` (2²⁴/n rounded);
/// - cancel: the input's + `2 LSB + |g| (δ_m + the low-pass's own) + 2⁻¹⁷ max|m|` (the
///   motion's low-pass times the gain, the gain rounded to 2⁻¹⁶);
/// - dot: `LSB + Σ |a| δ_b + |b| δ_a + δ_a δ_b`;
/// - magnitude: `LSB + 2⁻¹⁵ max|m| + δ_x + δ_y`;
/// - STE: `2 LSB + N 2⁻²³ max x² + N 2⁻²⁵ max ζ + 2 max|x| δ_x + δ_x²`.
pub fn slot_errors(config: &Config, stats: &[Stats]) -> Vec<f64> {
    let mut names: Vec<&str> = config.channels.iter().map(|c| c.name.as_str()).collect();
    names.extend(config.features.iter().map(|f| f.name.as_str()));
    let channels = config.channels.len();
    let mut delta = vec![0.0f64; names.len()];
    for (k, f) in config.features.iter().enumerate() {
        let slot = |n: &str| names.iter().position(|s| *s == n).expect("resolved");
        let d = |n: &str| delta[slot(n)];
        let m = |n: &str| stats[slot(n)].abs;
        let here = &stats[channels + k];
        // A low-pass's own error at `cutoff_hz` on an input of at most `x`.
        let low_pass = |cutoff_hz: f32, x: f64| {
            let alpha = host_tests::reference::low_pass_alpha(
                f64::from(config.rate_hz),
                f64::from(cutoff_hz),
            );
            let warm = (1.0 / alpha).ceil().min(65535.0);
            LSB + x * (1.0 / 1_048_576.0 + warm / 2_147_483_648.0)
        };
        let e = match &f.stage {
            StageSpec::Raw { input } | StageSpec::Abs { input } | StageSpec::Positive { input } => {
                d(input)
            }
            StageSpec::LowPass {
                input, cutoff_hz, ..
            } => d(input) + low_pass(*cutoff_hz, m(input)),
            StageSpec::HighPass { input, cutoff_hz } => {
                2.0 * d(input) + low_pass(*cutoff_hz, m(input))
            }
            StageSpec::Envelope { input, .. } => d(input) + LSB + m(input) / 1_048_576.0,
            StageSpec::Gate {
                input,
                unless,
                leak,
            } => {
                let undecided = if d(&unless.feature) > 0.0 {
                    m(input)
                } else {
                    0.0
                };
                // A leak's product: its rounding down, and the leak's own to 2^-16.
                let leaked = if *leak == 0.0 {
                    0.0
                } else {
                    LSB + m(input) / 131_072.0
                };
                d(input) + undecided + leaked
            }
            StageSpec::Cancel {
                input,
                motion,
                gain,
                cutoff_hz,
            } => {
                let g = f64::from(*gain).abs();
                d(input)
                    + 2.0 * LSB
                    + g * (d(motion) + low_pass(*cutoff_hz, m(motion)))
                    + m(motion) / 131_072.0
            }
            StageSpec::Rate { input } => {
                if config.rate_hz.fract() == 0.0 {
                    0.0
                } else {
                    stats[slot(input)].step / 256.0 + LSB
                }
            }
            StageSpec::Difference { a, b, gain } => {
                let g = f64::from(*gain);
                let scaled = if g == 1.0 {
                    0.0
                } else {
                    LSB + m(b) / 131_072.0
                };
                d(a) + g.abs() * d(b) + scaled
            }
            StageSpec::Mean { input, window } => {
                d(input) + LSB + f64::from(*window) * m(input) / 16_777_216.0
            }
            StageSpec::Dot { a, b } => {
                LSB + m(&a[0]) * d(&b[0])
                    + m(&b[0]) * d(&a[0])
                    + m(&a[1]) * d(&b[1])
                    + m(&b[1]) * d(&a[1])
                    + d(&a[0]) * d(&b[0])
                    + d(&a[1]) * d(&b[1])
            }
            StageSpec::Magnitude { of } => LSB + here.abs / 32768.0 + d(&of[0]) + d(&of[1]),
            StageSpec::Ste { input, window, .. } => {
                let n = f64::from(*window);
                let x = m(input);
                let dx = d(input);
                2.0 * LSB
                    + n * x * x / 8_388_608.0
                    + n * here.abs / 33_554_432.0
                    + 2.0 * x * dx
                    + dx * dx
            }
        };
        delta[channels + k] = e;
    }
    delta
}

/// How far a parameter moves when the engine rounds it to 16.16.
pub fn param_rounding(p: f32) -> f64 {
    (f64::from(p) - Signal::from_f32(p).to_f64()).abs()
}

/// A term's confidence error bound for a feature error `delta`: the CDF's own error plus
/// its steepest slope (2 / narrowest shoulder) times `delta` plus the rounding of its
/// parameters to 16.16. For a binary CDF, 0: such terms are only compared away from the
/// threshold (see [`binary_margin`]).
pub fn term_bound(cdf: &CdfSpec, delta: f64) -> f64 {
    let r = param_rounding;
    let (span, shift) = match *cdf {
        CdfSpec::Sigmoid { low, high, .. } => (f64::from(high) - f64::from(low), r(low) + r(high)),
        CdfSpec::Bell { center, half_width } => (f64::from(half_width), r(center) + r(half_width)),
        CdfSpec::FlatBell {
            low,
            plateau_low,
            plateau_high,
            high,
        } => (
            (f64::from(plateau_low) - f64::from(low))
                .min(f64::from(high) - f64::from(plateau_high)),
            r(low).max(r(high)) + r(plateau_low).max(r(plateau_high)),
        ),
        CdfSpec::Binary { .. } => return 0.0,
    };
    (CDF_ERROR + 2.0 * (delta + shift) / span).min(1.0)
}

/// Within how far of a binary CDF's threshold a feature with error `delta` may be judged
/// differently by the engine and the model (the feature error plus the threshold's rounding).
pub fn binary_margin(cdf: &CdfSpec, delta: f64) -> Option<(f64, f64)> {
    match *cdf {
        CdfSpec::Binary { threshold, .. } => {
            Some((f64::from(threshold), delta + param_rounding(threshold)))
        }
        _ => None,
    }
}

/// An event confidence's error bound from its terms' bounds (eq. 14): each context factor
/// (at most 1) moves the product by at most its own error, the weighted sensor sum by at
/// most the largest sensor error; plus the rounding of each weight to Q15 (½ step each) and
/// of each product (½ step each).
pub fn event_bound(context: &[f64], sensor: &[f64]) -> f64 {
    let q = 1.0 / 65536.0;
    let sensors = sensor.iter().copied().fold(0.0, f64::max);
    context.iter().sum::<f64>() + sensors + sensor.len() as f64 * q + (context.len() + 1) as f64 * q
}

/// The index of a feature by name.
pub fn feature_index(config: &Config, feature: &str) -> usize {
    config
        .features
        .iter()
        .position(|g| g.name == *feature)
        .expect("feature exists")
}
