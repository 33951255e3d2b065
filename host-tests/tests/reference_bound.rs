//! The fixed-point engine against the `f64` reference model over random configurations and
//! random inputs: every event confidence at every tick within 2⁻¹⁰ of the model's, every term
//! confidence within 2⁻¹², the evaluated / unjudgeable / degraded sets identical, and the
//! decisions identical to the model's decision stage fed the engine's own confidences.
//!
//! # The bound and why it holds
//!
//! Per term, the engine's confidence differs from the model's by at most
//! `ε_t = e_cdf + (2 / span) · δ_f`, where
//!
//! - `e_cdf < 2.5 · 2⁻¹⁵` is the CDF evaluation error for an exact input and exact parameters
//!   (`core_cdf_shapes.rs` checks it), 0 for binary CDFs;
//! - `2 / span` is the steepest slope of the S-function shoulders (span: the sigmoid's
//!   `high − low`, the bell's half-width, each flat-bell shoulder);
//! - `δ_f` is the feature's proven error bound (`reference_features.rs` checks each stage),
//!   carried through chains of features: raw/abs pass the input's error on, a difference adds
//!   its inputs' (the subtrahend's times |gain|, plus `2⁻¹⁶ + 2⁻¹⁷ max|b|` at a gain other
//!   than 1), low-pass adds `2⁻¹⁶ + (2⁻²⁰ + W 2⁻³¹) max|x|` (W the samples it warms up
//!   over), the envelope `2⁻¹⁶ + 2⁻²⁰ max|x|`, the mean `2⁻¹⁶ + N 2⁻²⁴ max|x|`, the dot product `2⁻¹⁶ + |a|δ_b + |b|δ_a`,
//!   the magnitude `2⁻¹⁶ + 2⁻¹⁵ max|m| + δ_x + δ_y`, the STE
//!   `2⁻¹⁵ + N 2⁻²³ max x² + N 2⁻²⁵ max ζ + 2 max|x| δ_x + δ_x²`, the rate
//!   `2⁻⁸ max|Δx| + 2⁻¹⁶` (its input must be exact), the gate its input's (it watches
//!   an exact slot, so both models shut it on the same ticks), and where it leaks a
//!   fraction of its input `2⁻¹⁶ + 2⁻¹⁷ max|x|` more (the product rounded down, the leak
//!   to 2⁻¹⁶).
//!
//! The generator makes every ramp at least `2¹⁴ δ_f` wide, so `(2/span) δ_f ≤ 2⁻¹³` and
//! `ε_t < 6.5 · 2⁻¹⁵ < 2⁻¹²`. Eq. 14 then moves by at most `ε_t` per context term (each
//! factor is at most 1) plus `Σ w ε_t ≤ ε_t` for the sensor sum; with at most 3 context and 4
//! sensor terms, weights rounded to Q15 (≤ 2⁻¹⁶ each) and one rounding per product
//! (≤ 2⁻¹⁶ each), the total is below `4 · 6.5 · 2⁻¹⁵ + 4 · 2⁻¹⁶ + 4 · 2⁻¹⁶ = 30 · 2⁻¹⁵`, under
//! `2⁻¹⁰ = 32 · 2⁻¹⁵`.
//!
//! The test checks each term against its own `ε_t` (`reference_support::term_bound`), each
//! event against its own bound (`reference_support::event_bound`), and that bound against
//! 2⁻¹⁰. Over 3000 random configurations the largest event difference seen was 2⁻¹²·⁷ and
//! the largest term difference 1.7 · 10⁻⁴ (5.5 steps of Q15).
//!
//! # Constraints on the random configurations (what makes the bound provable)
//!
//! - Inputs are raw 16.16 bits (exactly representable, so input quantization is not
//!   counted), each channel within ±2^k for k in 4..=22 (at most ±64), as i.i.d. noise, a
//!   random walk, or a step signal.
//! - CDF parameters are 16.16 values exact in `f32`; every shoulder is at least `2¹⁴ δ_f`
//!   wide (for an exact feature — raw, abs, difference of channels, rate at an integer rate —
//!   any width from 2⁻¹⁶ up); where that would exceed the representable range the term is
//!   binary instead. A binary term is only compared at ticks where the model's feature is
//!   more than `δ_f` from the threshold (exact features: every tick).
//! - A rate reads only an exact slot (a rate amplifies its input's error by `2 f_s`).
//! - An STE reads only a slot bounded below 256 in magnitude by construction (see
//!   `reference_features.rs`: the engine saturates each square at 65 536).
//! - Low-pass cut-offs are between `f_s / 1000` and `0.45 f_s` (α ≥ 0.006), and a low-pass
//!   reads only a slot bounded below 16384 in magnitude by construction (see
//!   `reference_features.rs`: the engine goes wrong when the input moves more than 32768 away
//!   from the filter's state).
//! - At most 3 context and 4 sensor terms per event; up to 5 events, 3 phases; random phase
//!   switches and fault masks.
//! - Decision levels are multiples of 2⁻¹⁵ (the confidence resolution) so that comparing a
//!   confidence with them is exact in both.
//!
//! Case counts: [`CASES`] random configurations of [`TICKS`] ticks each, per property
//! (override with `PROPTEST_CASES`).
//!
//! The largest difference seen over a run is printed (`cargo test -- --nocapture`).

#[path = "reference_support.rs"]
mod support;

use std::sync::atomic::{AtomicU64, Ordering};

use detector_build::{Config, EarlySpec, EventSpec};
use detector_core::{CdfSpec, Crossing, LongerWarmUp, Shut, Signal, StageSpec, Window};
use host_tests::reference::{Judgement, Model, cdf};
use proptest::prelude::*;
use support::*;

/// Random configurations per property.
const CASES: u32 = 128;
/// Ticks per run.
const TICKS: usize = 220;
/// The bound on every event confidence.
const EVENT_BOUND: f64 = 1.0 / 1024.0;
/// The bound on every term confidence.
const TERM_BOUND: f64 = 1.0 / 4096.0;
/// Ramps at least this many times the feature's error bound wide.
const RAMP_PER_ERROR: f64 = 16384.0;

/// Largest event-confidence difference seen, as f64 bits.
static WORST_EVENT: AtomicU64 = AtomicU64::new(0);
/// Largest term-confidence difference seen, as f64 bits.
static WORST_TERM: AtomicU64 = AtomicU64::new(0);

fn record(cell: &AtomicU64, v: f64) {
    cell.fetch_max(v.to_bits(), Ordering::Relaxed);
}

/// How one channel's samples are generated.
#[derive(Clone, Debug)]
struct ChannelPlan {
    /// Magnitude bound 2^k (raw bits).
    k: u32,
    /// 0: i.i.d., 1: random walk, 2: steps.
    mode: u8,
    /// Random words, one per tick.
    words: Vec<i32>,
}

impl ChannelPlan {
    fn samples(&self) -> Vec<i32> {
        let lim = 1i64 << self.k;
        let mut x = 0i64;
        self.words
            .iter()
            .map(|&w| {
                let w = i64::from(w);
                x = match self.mode {
                    0 => w >> (31 - self.k),
                    1 => (x + (w >> (35 - self.k))).clamp(-lim, lim),
                    _ => {
                        if w & 15 == 0 {
                            w >> (31 - self.k)
                        } else {
                            x
                        }
                    }
                };
                x as i32
            })
            .collect()
    }
}

/// A feature: its kind (0 raw, 1 abs, 2 low-pass, 3 rate, 4 difference, 5 dot,
/// 6 magnitude, 7 rectangular STE, 8 triangular STE, 9 mean, 10 envelope, 11 gate, 12 positive),
/// input picks and a parameter.
#[derive(Clone, Debug)]
struct FeaturePlan {
    kind: u8,
    picks: [u8; 4],
    param: u16,
}

/// A term: its feature pick, CDF shape (0 rising sigmoid, 1 falling sigmoid, 2 bell,
/// 3 flat bell, 4 binary above, 5 binary below) and four fractions placing its parameters.
#[derive(Clone, Debug)]
struct TermPlan {
    feature: u8,
    shape: u8,
    fractions: [u16; 4],
}

#[derive(Clone, Debug)]
struct EventPlan {
    context: Vec<TermPlan>,
    sensor: Vec<(u16, TermPlan)>,
    weight_total: u16,
    /// alert on, alert off, confirm on, confirm off, onset (fractions of 2^15), dwells.
    levels: [u16; 5],
    dwells: [u8; 2],
    /// The confirm level's early dwell, on its first sensor term's feature: its level as a
    /// fraction of 2^16 of the feature's range over the run.
    early: Option<u16>,
}

#[derive(Clone, Debug)]
struct Plan {
    rate_hz: f32,
    channels: Vec<ChannelPlan>,
    features: Vec<FeaturePlan>,
    events: Vec<EventPlan>,
    phases: Vec<u8>,
    switches: Vec<(u8, u8)>,
    faults: Vec<(u8, u8, u16)>,
}

fn term_plan() -> impl Strategy<Value = TermPlan> {
    (any::<u8>(), 0u8..6, any::<[u16; 4]>()).prop_map(|(feature, shape, fractions)| TermPlan {
        feature,
        shape,
        fractions,
    })
}

fn event_plan() -> impl Strategy<Value = EventPlan> {
    (
        prop::collection::vec(term_plan(), 0..=3),
        prop::collection::vec((1u16..1000, term_plan()), 1..=4),
        6000u16..=32768,
        any::<[u16; 5]>(),
        any::<[u8; 2]>(),
        prop::option::of(any::<u16>()),
    )
        .prop_map(
            |(context, sensor, weight_total, levels, dwells, early)| EventPlan {
                context,
                sensor,
                weight_total,
                levels,
                dwells,
                early,
            },
        )
}

fn plan() -> impl Strategy<Value = Plan> {
    let rate = prop_oneof![
        (10u32..=50_000).prop_map(|r| r as f32),
        (10.0f32..50_000.0),
        Just(5000.0f32),
    ];
    let channel = (
        4u32..=22,
        0u8..3,
        prop::collection::vec(any::<i32>(), TICKS),
    )
        .prop_map(|(k, mode, words)| ChannelPlan { k, mode, words });
    let feature = (0u8..13, any::<[u8; 4]>(), any::<u16>())
        .prop_map(|(kind, picks, param)| FeaturePlan { kind, picks, param });
    (
        rate,
        prop::collection::vec(channel, 3..=6),
        prop::collection::vec(feature, 2..=12),
        prop::collection::vec(event_plan(), 1..=5),
        prop::collection::vec(any::<u8>(), 1..=3),
        prop::collection::vec((any::<u8>(), any::<u8>()), 0..4),
        prop::collection::vec((any::<u8>(), any::<u8>(), any::<u16>()), 0..4),
    )
        .prop_map(
            |(rate_hz, channels, features, events, phases, switches, faults)| Plan {
                rate_hz,
                channels,
                features,
                events,
                phases,
                switches,
                faults,
            },
        )
}

/// What the generator knows about a slot while building features.
#[derive(Clone, Copy, Debug)]
struct SlotInfo {
    /// Bound on |value| by construction.
    bound: f64,
    /// Exact in the engine (no error at all)?
    exact: bool,
}

/// A feature's stage from its plan, with inputs constrained as the module doc says.
fn stage_for(
    p: &FeaturePlan,
    names: &[String],
    info: &[SlotInfo],
    rate_hz: f32,
    integer_rate: bool,
    pool: &mut usize,
) -> (StageSpec<String>, SlotInfo) {
    let pick = |i: usize| usize::from(p.picks[i]) % names.len();
    let n = |s: usize| name(&names[s]);
    let bound_cap = |b: f64| b.min(32768.0);
    let a = pick(0);
    let ia = info[a];
    match p.kind {
        0 => (StageSpec::Raw { input: n(a) }, ia),
        1 => (StageSpec::Abs { input: n(a) }, ia),
        12 => (StageSpec::Positive { input: n(a) }, ia),
        2 => {
            // Only inputs bounded below 16384 (see the module doc); channel 0 otherwise.
            let s = if ia.bound < 16384.0 { a } else { 0 };
            let f = 0.001 + 0.449 * f32::from(p.param) / 65535.0;
            let cutoff_hz = rate_hz * f;
            let warm_up_ms = p
                .param
                .is_multiple_of(3)
                .then(|| 1.0 + f32::from(p.param % 97));
            (
                StageSpec::LowPass {
                    input: n(s),
                    cutoff_hz,
                    // A third with a warm-up of 1-97 ms.
                    warm_up_ms,
                    // Half end their warm-up early when an exact slot (the same value in
                    // both models) rises above a level within its usual range.
                    warm_up_until: (p.param.is_multiple_of(2) && info[pick(1)].exact).then(|| {
                        Crossing {
                            feature: n(pick(1)),
                            above: f32::from(p.picks[2]) - 128.0,
                        }
                    }),
                    // Of those with a warm-up, most carry it on by 1-50 ms (and by at
                    // least one sample more, as the stage needs) when another exact slot
                    // is above a level within its usual range.
                    warm_up_longer: warm_up_ms
                        .filter(|_| !p.param.is_multiple_of(5) && info[pick(3)].exact)
                        .map(|ms| LongerWarmUp {
                            feature: n(pick(3)),
                            above: f32::from(p.picks[1]) - 128.0,
                            warm_up_ms: (ms + 1.0 + f32::from(p.param % 50))
                                .max(ms + 1500.0 / rate_hz),
                        }),
                },
                SlotInfo {
                    bound: info[s].bound,
                    exact: false,
                },
            )
        }
        3 => {
            // Only exact inputs; channel 0 otherwise.
            let s = if ia.exact { a } else { 0 };
            (
                StageSpec::Rate { input: n(s) },
                SlotInfo {
                    bound: 32768.0,
                    exact: integer_rate,
                },
            )
        }
        4 => {
            let b = pick(1);
            // An even parameter: a plain difference; an odd one: a gain within ±2.
            let gain = if p.param.is_multiple_of(2) {
                1.0
            } else {
                snap(f64::from(p.param / 2) / 8192.0 - 2.0)
            };
            (
                StageSpec::Difference {
                    a: n(a),
                    b: n(b),
                    gain,
                },
                SlotInfo {
                    bound: bound_cap(ia.bound + f64::from(gain).abs() * info[b].bound),
                    exact: gain == 1.0 && ia.exact && info[b].exact,
                },
            )
        }
        11 => {
            // The watched slot exact (the same value in both models, so both shut the gate
            // on the same ticks), channel 0 otherwise; a level within its usual range.
            let w = if info[pick(1)].exact { pick(1) } else { 0 };
            // Shut: nothing, or a quarter, half or three quarters, or all of it; a
            // fraction's product is rounded down.
            let leak = f32::from(p.picks[3] % 5) / 4.0;
            (
                StageSpec::Gate {
                    input: n(a),
                    unless: {
                        let level = f32::from(p.picks[2]) - 128.0;
                        if p.picks[2].is_multiple_of(2) {
                            Shut::above(n(w), level)
                        } else {
                            Shut::below(n(w), level)
                        }
                    },
                    leak,
                },
                SlotInfo {
                    exact: ia.exact && (leak == 0.0 || leak == 1.0),
                    ..ia
                },
            )
        }
        10 => {
            // Only inputs bounded below 16384, as the low-pass.
            let s = if ia.bound < 16384.0 { a } else { 0 };
            let f = 0.001 + 0.449 * f32::from(p.param) / 65535.0;
            (
                StageSpec::Envelope {
                    input: n(s),
                    cutoff_hz: rate_hz * f,
                },
                SlotInfo {
                    bound: info[s].bound,
                    exact: false,
                },
            )
        }
        9 => {
            // A mean within the pool.
            let left = detector_core::feature::WINDOW_POOL - *pool;
            let window = (usize::from(p.param) % 128 + 1).min(left);
            if window == 0 {
                return (StageSpec::Raw { input: n(a) }, ia);
            }
            *pool += window;
            (
                StageSpec::Mean {
                    input: n(a),
                    window: window as u16,
                },
                SlotInfo {
                    bound: ia.bound,
                    exact: false,
                },
            )
        }
        5 => {
            let [b, c, d] = [pick(1), pick(2), pick(3)];
            (
                StageSpec::Dot {
                    a: [n(a), n(b)],
                    b: [n(c), n(d)],
                },
                SlotInfo {
                    bound: bound_cap(ia.bound * info[c].bound + info[b].bound * info[d].bound),
                    exact: false,
                },
            )
        }
        6 => {
            let b = pick(1);
            (
                StageSpec::Magnitude { of: [n(a), n(b)] },
                SlotInfo {
                    bound: bound_cap(ia.bound.hypot(info[b].bound)),
                    exact: false,
                },
            )
        }
        _ => {
            // STE of a slot bounded below 256, channel 0 otherwise; within the pool.
            let s = if ia.bound < 256.0 { a } else { 0 };
            let left = detector_core::feature::WINDOW_POOL - *pool;
            let window = (usize::from(p.param) % 128 + 1).min(left);
            if window == 0 {
                return (StageSpec::Raw { input: n(s) }, info[s]);
            }
            *pool += window;
            let shape = if p.kind == 7 {
                Window::Rectangular
            } else {
                Window::Triangular
            };
            (
                StageSpec::Ste {
                    input: n(s),
                    window: window as u16,
                    shape,
                },
                SlotInfo {
                    bound: bound_cap(info[s].bound * info[s].bound),
                    exact: false,
                },
            )
        }
    }
}

/// Snaps a value to a 16.16 step that `f32` holds exactly, within ±32000.
fn snap(v: f64) -> f32 {
    Signal::from_f64(v.clamp(-32000.0, 32000.0)).to_f32()
}

/// `low + span`, snapped as [`snap`] does, and strictly above `low`: from 256 in magnitude
/// up, an `f32` step is coarser than a 16.16 one, and a narrow span would snap back onto
/// `low`. Widening it only makes the curve gentler.
fn snap_above(low: f32, span: f64) -> f32 {
    let f32_step = f64::from(low.abs()) * f64::from(f32::EPSILON);
    snap(f64::from(low) + span.max(2.0 * f32_step))
}

/// A CDF for a feature with statistics `st` and error bound `delta`, placed by the term's
/// fractions, every shoulder at least `RAMP_PER_ERROR · delta` wide.
fn cdf_for(t: &TermPlan, st: &Stats, delta: f64) -> CdfSpec {
    let frac = |i: usize| f64::from(t.fractions[i]) / 65535.0;
    let width = (st.max - st.min).max(LSB);
    let min_span = (RAMP_PER_ERROR * delta).max(LSB);
    let span = |i: usize| min_span + frac(i) * 2.0 * width.max(min_span);
    let binary = |above: bool| CdfSpec::Binary {
        threshold: snap(st.min + frac(0) * width),
        above,
    };
    let fits = |v: &[f64]| v.iter().all(|x| x.abs() <= 32000.0);
    match t.shape {
        0 | 1 => {
            let s = span(1);
            let low = st.min - s + frac(0) * (width + s);
            if !fits(&[low, low + s]) {
                return binary(t.shape == 0);
            }
            let low = snap(low);
            CdfSpec::Sigmoid {
                low,
                high: snap_above(low, s),
                falling: t.shape == 1,
            }
        }
        2 => {
            let (center, half_width) = (st.min + frac(0) * width, span(1));
            if !fits(&[center, half_width]) {
                return binary(true);
            }
            CdfSpec::Bell {
                center: snap(center),
                half_width: snap(half_width),
            }
        }
        3 => {
            let (s1, s2) = (span(1), span(2));
            let low = st.min - s1 + frac(0) * (width + s1);
            let plateau = frac(3) * width;
            if !fits(&[low, low + s1 + plateau + s2]) {
                return binary(false);
            }
            let low = snap(low);
            let plateau_low = snap_above(low, s1);
            let plateau_high = snap(f64::from(plateau_low) + plateau);
            let high = snap_above(plateau_high, s2);
            CdfSpec::FlatBell {
                low,
                plateau_low,
                plateau_high,
                high,
            }
        }
        s => binary(s == 4),
    }
}

/// A level value on the Q15 grid from a fraction, within `lo..=hi` (raw Q15 bits).
fn q15(frac: u16, lo: u32, hi: u32) -> f32 {
    let bits = lo + (u32::from(frac) * (hi - lo + 1)) / 65536;
    bits.min(hi) as f32 / 32768.0
}

/// The configuration and the run's steps from a plan; also each feature's error bound.
fn realize(plan: &Plan) -> (Config, Vec<Step>, Vec<f64>) {
    let rate_hz = plan.rate_hz;
    let integer_rate = rate_hz.fract() == 0.0;
    let channel_names: Vec<String> = (0..plan.channels.len()).map(|i| format!("c{i}")).collect();
    let mut slot_names = channel_names.clone();
    let mut info: Vec<SlotInfo> = plan
        .channels
        .iter()
        .map(|c| SlotInfo {
            bound: (1u64 << c.k) as f64 / 65536.0,
            exact: true,
        })
        .collect();
    let mut pool = 0;
    let mut features = Vec::new();
    for (k, fp) in plan.features.iter().enumerate() {
        let (stage, si) = stage_for(fp, &slot_names, &info, rate_hz, integer_rate, &mut pool);
        let fname = format!("f{k}");
        features.push((fname.clone(), stage));
        slot_names.push(fname);
        info.push(si);
    }
    let feature_count = features.len();
    let event_names: Vec<String> = (0..plan.events.len()).map(|i| format!("e{i}")).collect();
    // Events with placeholder CDFs first: features do not depend on them.
    let mut events: Vec<EventSpec> = Vec::new();
    for (i, ep) in plan.events.iter().enumerate() {
        let fname = |t: &TermPlan| format!("f{}", usize::from(t.feature) % feature_count);
        let ctx = ep
            .context
            .iter()
            .map(|t| context(&fname(t), sigmoid(0.0, 1.0)))
            .collect();
        let raw_total: u32 = ep.sensor.iter().map(|(w, _)| u32::from(*w)).sum();
        let total = f64::from(ep.weight_total) / 32768.0;
        let sen = ep
            .sensor
            .iter()
            .map(|(w, t)| {
                let weight = (total * f64::from(*w) / f64::from(raw_total)) as f32;
                sensor(&fname(t), weight, sigmoid(0.0, 1.0))
            })
            .collect();
        let mut e = event(&event_names[i], ctx, sen);
        let [a_on, a_off, c_on, c_off, onset] = ep.levels;
        let alert_on = q15(a_on, 1, 32768);
        let alert_on_bits = (alert_on * 32768.0) as u32;
        let confirm_on = q15(c_on, alert_on_bits, 32768);
        let confirm_on_bits = (confirm_on * 32768.0) as u32;
        let dwell = |d: u8| f32::from(d % 6) * 1000.0 / rate_hz;
        e.alert = level(alert_on, q15(a_off, 0, alert_on_bits), dwell(ep.dwells[0]));
        e.confirm = level(
            confirm_on,
            q15(c_off, 0, confirm_on_bits),
            dwell(ep.dwells[1]),
        );
        e.onset_level = q15(onset, 0, alert_on_bits - 1);
        // Half the events exclude some others (bits of the second dwell's byte).
        if ep.dwells[0] >= 128 {
            e.excludes = (0..plan.events.len())
                .filter(|&j| j != i && (ep.dwells[1] >> (j % 8)) & 1 == 1)
                .map(|j| event_names[j].clone())
                .collect();
        }
        events.push(e);
    }
    let phases: Vec<_> = plan
        .phases
        .iter()
        .enumerate()
        .map(|(i, mask)| {
            let names: Vec<&str> = event_names
                .iter()
                .enumerate()
                .filter(|(j, _)| mask & (1 << j) != 0)
                .map(|(_, n)| n.as_str())
                .collect();
            phase(&format!("p{i}"), &names)
        })
        .collect();
    let ch: Vec<&str> = channel_names.iter().map(String::as_str).collect();
    let feats: Vec<(&str, StageSpec<String>)> = features
        .iter()
        .map(|(n, s)| (n.as_str(), s.clone()))
        .collect();
    let mut config = config(rate_hz, &ch, feats, events, phases);

    // The inputs, and the model's feature values over them.
    let samples: Vec<Vec<i32>> = plan.channels.iter().map(ChannelPlan::samples).collect();
    let rows: Vec<Vec<f64>> = (0..TICKS)
        .map(|t| {
            samples
                .iter()
                .map(|c| Signal::from_bits(c[t]).to_f64())
                .collect()
        })
        .collect();
    let st = stats(&model_series(&config, &rows));
    let delta = slot_errors(&config, &st);
    let channels = config.channels.len();
    for (e, ep) in config.events.iter_mut().zip(&plan.events) {
        let slot = |t: &TermPlan| channels + usize::from(t.feature) % feature_count;
        for (term, t) in e.context.iter_mut().zip(&ep.context) {
            term.cdf = cdf_for(t, &st[slot(t)], delta[slot(t)]);
        }
        for (term, (_, t)) in e.sensor.iter_mut().zip(&ep.sensor) {
            term.cdf = cdf_for(t, &st[slot(t)], delta[slot(t)]);
        }
        // An early dwell a third of the confirm dwell (never half a tick, where the model's
        // rounding of a time to ticks and the compiler's may differ), at a level within
        // the feature's range.
        if let (Some(fraction), Some((_, t))) = (ep.early, ep.sensor.first()) {
            let s = &st[slot(t)];
            let above = s.min + (s.max - s.min) * f64::from(fraction) / 65536.0;
            e.confirm.early = Some(EarlySpec {
                feature: format!("f{}", usize::from(t.feature) % feature_count),
                above: above as f32,
                dwell_ms: e.confirm.dwell_ms / 3.0,
            });
        }
    }

    let steps = (0..TICKS)
        .map(|t| Step {
            samples: samples.iter().map(|c| c[t]).collect(),
            faults: plan
                .faults
                .iter()
                .filter(|(start, len, _)| {
                    let start = usize::from(*start);
                    t >= start && t < start + usize::from(*len) % 40
                })
                .fold(0, |m, (_, _, mask)| m | u32::from(*mask)),
            switch_to: plan
                .switches
                .iter()
                .find(|(at, _)| usize::from(*at) == t)
                .map(|(_, p)| p % plan.phases.len() as u8),
        })
        .collect();
    (config, steps, delta[channels..].to_vec())
}

proptest! {
    #![proptest_config(proptest_config(CASES, "proptest-regressions/reference_bound.txt"))]

    /// Event confidences within 2⁻¹⁰, term confidences within 2⁻¹², identical
    /// evaluated / unjudgeable / degraded sets.
    #[test]
    fn engine_stays_within_bound_of_model(plan in plan()) {
        let (config, steps, delta) = realize(&plan);
        let det = detector_build::build(&config);
        prop_assert!(det.is_ok(), "generated config rejected: {:?}", det.err());
        for (t, b) in run_both(&config, &steps).iter().enumerate() {
            let (out, m) = (&b.out, &b.model);
            let j = &m.judgement;
            prop_assert_eq!(out.evaluated, j.evaluated, "evaluated at tick {}", t);
            prop_assert_eq!(out.unjudgeable, j.unjudgeable, "unjudgeable at tick {}", t);
            prop_assert_eq!(out.degraded, j.degraded, "degraded at tick {}", t);
            for (i, e) in config.events.iter().enumerate() {
                if j.evaluated & (1 << i) == 0 {
                    prop_assert_eq!(out.confidences[i].to_bits(), 0);
                    continue;
                }
                // A binary term whose feature is within its error of the threshold may
                // legitimately flip: skip that term, and the event, at this tick.
                let near = |f: &str, c: &CdfSpec| match c {
                    CdfSpec::Binary { threshold, .. } => {
                        let k = feature_index(&config, f);
                        delta[k] > 0.0
                            && (m.features[k] - f64::from(*threshold)).abs() <= delta[k] * 1.000_001
                    }
                    _ => false,
                };
                let (ctx, sen) = &b.terms[i];
                let terms = e
                    .context
                    .iter()
                    .map(|c| (&c.feature, &c.cdf))
                    .zip(ctx.iter().zip(&j.context[i]))
                    .chain(
                        e.sensor
                            .iter()
                            .map(|s| (&s.feature, &s.cdf))
                            .zip(sen.iter().zip(&j.sensor[i])),
                    );
                let mut skip = false;
                let mut bounds = (Vec::new(), Vec::new());
                for (n, ((f, c), (got, want))) in terms.enumerate() {
                    if near(f, c) {
                        skip = true;
                        continue;
                    }
                    let bound = term_bound(c, delta[feature_index(&config, f)]);
                    if n < e.context.len() { bounds.0.push(bound) } else { bounds.1.push(bound) }
                    record(&WORST_TERM, (got - want).abs());
                    prop_assert!(bound <= TERM_BOUND, "generated term {:?} too steep: bound {:e}", c, bound);
                    prop_assert!(
                        (got - want).abs() <= bound,
                        "event {} term {} ({:?}) tick {}: engine {} model {} (bound {:e}); \
                         feature engine {} model {} error bound {:e}; stages {:?}",
                        i, f.as_str(), c, t, got, want, bound,
                        b.features[feature_index(&config, f)],
                        m.features[feature_index(&config, f)],
                        delta[feature_index(&config, f)],
                        config.features.iter().map(|f| (f.name.as_str(), &f.stage)).collect::<Vec<_>>()
                    );
                }
                if skip {
                    continue;
                }
                let bound = event_bound(&bounds.0, &bounds.1);
                prop_assert!(bound <= EVENT_BOUND, "analytic bound {:e} above 2^-10", bound);
                let got = out.confidences[i].to_f64();
                let want = j.confidences[i];
                record(&WORST_EVENT, (got - want).abs());
                prop_assert!(
                    (got - want).abs() <= bound,
                    "event {} tick {}: engine {} model {} (diff {:.3e}, bound {:.3e})",
                    i, t, got, want, (got - want).abs(), bound
                );
            }
        }
        println!(
            "worst event difference so far: {:.3e} (2^{:.2}), worst term {:.3e}",
            f64::from_bits(WORST_EVENT.load(Ordering::Relaxed)),
            f64::from_bits(WORST_EVENT.load(Ordering::Relaxed)).log2(),
            f64::from_bits(WORST_TERM.load(Ordering::Relaxed)),
        );
    }
}

proptest! {
    #![proptest_config(proptest_config(CASES, "proptest-regressions/reference_bound.txt"))]

    /// The engine's decisions (levels raised, ticks, onsets, confidences, and the
    /// alerting / confirmed sets) equal the model's decision stage fed the engine's own
    /// confidences, tick for tick, through phase switches and faults.
    #[test]
    fn engine_decisions_equal_model_decisions_on_engine_confidences(plan in plan()) {
        let (config, steps, _) = realize(&plan);
        let det = detector_build::build(&config).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let model = Model::new(&config).expect("model resolves");
        let mut st = det.new_state();
        let mut ms = model.new_state();
        for (t, step) in steps.iter().enumerate() {
            if let Some(p) = step.switch_to {
                det.set_phase(&mut st, det.phase_at(p).expect("phase exists"));
                model.set_phase(&mut ms, usize::from(p));
            }
            let now = t as u32;
            let out = det.tick(&mut st, now, &inputs(&step.samples, step.faults));
            let judgement = Judgement {
                confidences: out.confidences.iter().map(|c| c.to_f64()).collect(),
                evaluated: out.evaluated,
                unjudgeable: out.unjudgeable,
                degraded: out.degraded,
                ..Judgement::default()
            };
            let features: Vec<f64> = (0..config.features.len())
                .map(|k| st.feature(k).map_or(0.0, Signal::to_f64))
                .collect();
            let d = model.decide(&mut ms, now, &judgement, &features);
            let engine: Vec<(usize, &str, u16, u32, u32)> = out
                .decisions
                .iter()
                .map(|x| {
                    (usize::from(x.event.0), x.level.name(), x.confidence.to_bits(), x.onset, x.tick)
                })
                .collect();
            let expected: Vec<(usize, &str, u16, u32, u32)> = d
                .decisions
                .iter()
                .map(|x| {
                    (x.event, x.level.name(), (x.confidence * 32768.0) as u16, x.onset, x.tick)
                })
                .collect();
            prop_assert_eq!(engine, expected, "decisions at tick {}", t);
            prop_assert_eq!(out.alerting, d.alerting, "alerting at tick {}", t);
            prop_assert_eq!(out.confirmed, d.confirmed, "confirmed at tick {}", t);
        }
    }
}

#[test]
fn cdf_for_respects_minimum_span() {
    let st = Stats {
        min: -1.0,
        max: 3.0,
        abs: 3.0,
        step: 0.5,
    };
    let t = TermPlan {
        feature: 0,
        shape: 0,
        fractions: [0, 0, 0, 0],
    };
    match cdf_for(&t, &st, 1e-4) {
        CdfSpec::Sigmoid { low, high, .. } => {
            assert!(f64::from(high - low) >= 1.6384 - 2.0 * LSB);
            assert_eq!(
                cdf(
                    &CdfSpec::Sigmoid {
                        low,
                        high,
                        falling: false
                    },
                    -10.0
                ),
                0.0
            );
        }
        other => panic!("expected a sigmoid, got {other:?}"),
    }
}
