//! A plain `f64` model of the detection scheme, written from its documented definitions
//! (the paper's eq. 14 and 17 and the doc comments of `detector_core`'s configuration
//! types), independently of the fixed-point engine. The tests hold the engine to it.
//!
//! It takes the same [`Config`] as [`detector_build::build`] and channel samples as
//! `f64` in each channel's working unit (SI × the channel's `scale`, as the engine's
//! `Inputs` carry them; [`Model::working_unit`] converts), and produces per tick the feature
//! values, the term confidences, the event confidences and the decisions, all in `f64` with
//! no quantization, except:
//!
//! - every channel sample and every feature value saturates at the `Signal` range
//!   [−32768, 32768 − 2⁻¹⁶] (documented on `detector_core::feature`: "saturating at the
//!   Signal range");
//! - configuration parameters are the `f32` values of the [`Config`], widened exactly.
//!
//! The model trusts its configuration: validating it is [`detector_build::build`]'s
//! job. [`Model::new`] only resolves names and fails on names it cannot resolve.
//!
//! # The definitions it implements
//!
//! - **S-function** ([`s_curve`]): S(t) = 2t² for t ≤ ½, 1 − 2(1 − t)² for t ≥ ½, clamped to
//!   0 below t = 0 and 1 above t = 1.
//! - **CDFs** ([`cdf`]): sigmoid S((x − low)/(high − low)) (1 minus that when falling);
//!   bell 1 − S(|x − center| / half_width) (1 at the centre, ½ at half the half-width, 0
//!   beyond it); flat bell S((x − low)/(plateau_low − low)) on the rising shoulder, 1 on the
//!   plateau, 1 − S((x − plateau_high)/(high − plateau_high)) on the falling one, 0
//!   outside [low, high]; binary 1 when x ≥ threshold (`above`) or x ≤ threshold.
//! - **Features** ([`Model::tick`]): raw, |x|, low-pass y ← y + α(x − y) with
//!   α = Δt/(τ + Δt), τ = 1/(2π f_c), x − y saturated to the feature range (±32768, as
//!   every difference of the engine's; it cuts only a step from one end of the range to the
//!   other), seeded with the first sample (the documentation does
//!   not say where y starts; the engine seeds it, and a filter starting at 0 would only add
//!   a start-up transient); high-pass x − y; cancel x − g y with y the low-pass of the
//!   motion input; rate (x_n − x_{n−1}) f_s, 0 on the first tick; a − b;
//!   a_x b_x + a_y b_y; √(x² + y²); STE (eq. 17)
//!   ζ_n = Σ_{m=0}^{N−1} x²(n − m) h(m) with h normalized to sum 1 ([`window`]) and samples
//!   before the first counted as zero.
//! - **Events** (eq. 14, [`combine`]): Ψ = Π context ψ × min(1, Σ w ψ). A term whose feature
//!   reads a faulty channel (directly or through earlier features) is lost: a lost sensor
//!   term counts 0 and marks the event degraded; a lost context term, or every sensor term
//!   lost, makes the event unjudgeable: confidence 0, every level lowered, no decision.
//! - **Decisions** ([`Model::decide`]): per event and level, the level is raised at the
//!   tick on which the confidence has been at or above `on` for `dwell` consecutive ticks,
//!   `dwell = max(1, round(dwell_ms · rate_hz / 1000))` (so a dwell of 0 raises it on the
//!   first tick at or above `on`; the documentation leaves the conversion to ticks open, this
//!   is the engine's), and lowered at the tick on which the confidence has been below `off`
//!   for `hold` consecutive ticks (converted the same way from `hold_ms`). A level with an
//!   early dwell is raised after that dwell instead (converted the same way) once its
//!   feature has been strictly above its level at a tick of the current run, the event not
//!   degraded at that tick; the level is the core's, rounded to 16.16. A raised
//!   level reports the confidence, the tick and the onset: the first tick of the current
//!   run of confidence strictly above `onset_level`. Switching to another phase lowers every
//!   level and forgets onsets; only the active phase's events are evaluated. While an event
//!   that excludes another has its confirm level up (as it stands when the other is decided,
//!   in event order), the other's levels are held down.

use detector_build::Config;
use detector_core::{CdfSpec, Level, Signal, StageSpec, Window};

/// The largest value of the core's 16.16 `Signal`, 32768 − 2⁻¹⁶.
pub const SIGNAL_MAX: f64 = 32768.0 - 1.0 / 65536.0;
/// The smallest value of the core's 16.16 `Signal`, −32768.
pub const SIGNAL_MIN: f64 = -32768.0;

/// Saturates a value at the `Signal` range; NaN becomes 0 (as `Signal::from_f64` does).
pub fn saturate(v: f64) -> f64 {
    if v.is_nan() {
        0.0
    } else {
        v.clamp(SIGNAL_MIN, SIGNAL_MAX)
    }
}

/// The fuzzy-logic S-function of a position `t`: 0 for t ≤ 0, 2t² up to ½, 1 − 2(1 − t)²
/// from ½, 1 for t ≥ 1.
pub fn s_curve(t: f64) -> f64 {
    if t <= 0.0 {
        0.0
    } else if t >= 1.0 {
        1.0
    } else if t <= 0.5 {
        2.0 * t * t
    } else {
        let u = 1.0 - t;
        1.0 - 2.0 * u * u
    }
}

/// The confidence a confidence distribution function gives the feature value `x`, in [0, 1].
/// Parameters are the `f32` values of the specification, used exactly.
pub fn cdf(spec: &CdfSpec, x: f64) -> f64 {
    match *spec {
        CdfSpec::Sigmoid { low, high, falling } => {
            let (low, high) = (f64::from(low), f64::from(high));
            let rise = s_curve((x - low) / (high - low));
            if falling { 1.0 - rise } else { rise }
        }
        CdfSpec::Bell { center, half_width } => {
            1.0 - s_curve((x - f64::from(center)).abs() / f64::from(half_width))
        }
        CdfSpec::FlatBell {
            low,
            plateau_low,
            plateau_high,
            high,
        } => {
            let (low, pl, ph, high) = (
                f64::from(low),
                f64::from(plateau_low),
                f64::from(plateau_high),
                f64::from(high),
            );
            if x <= low || x >= high {
                0.0
            } else if x < pl {
                s_curve((x - low) / (pl - low))
            } else if x <= ph {
                1.0
            } else {
                1.0 - s_curve((x - ph) / (high - ph))
            }
        }
        CdfSpec::Binary { threshold, above } => {
            let t = f64::from(threshold);
            let on = if above { x >= t } else { x <= t };
            if on { 1.0 } else { 0.0 }
        }
    }
}

/// Eq. 14: the product of the context confidences times the weighted sum of the sensor
/// confidences (`(weight, confidence)` pairs), the sum capped at 1.
pub fn combine(context: &[f64], sensor: &[(f64, f64)]) -> f64 {
    let gate: f64 = context.iter().product();
    let sum: f64 = sensor.iter().map(|(w, c)| w * c).sum();
    gate * sum.min(1.0)
}

/// The STE window h(0..N) of eq. 17, normalized to sum 1: rectangular h(m) = 1/N, or the
/// triangle h(m) ∝ 1 − |2m − (N − 1)| / (N + 1).
pub fn window(shape: Window, n: usize) -> Vec<f64> {
    let raw: Vec<f64> = (0..n)
        .map(|m| match shape {
            Window::Rectangular => 1.0,
            Window::Triangular => {
                let d = (2.0 * m as f64 - (n as f64 - 1.0)).abs();
                1.0 - d / (n as f64 + 1.0)
            }
        })
        .collect();
    let total: f64 = raw.iter().sum();
    raw.into_iter().map(|h| h / total).collect()
}

/// The low-pass coefficient α = Δt / (τ + Δt) with Δt = 1/f_s and τ = 1/(2π f_c).
pub fn low_pass_alpha(rate_hz: f64, cutoff_hz: f64) -> f64 {
    let dt = 1.0 / rate_hz;
    let tau = 1.0 / (2.0 * std::f64::consts::PI * cutoff_hz);
    dt / (tau + dt)
}

/// A level's dwell or hold as consecutive ticks: `max(1, round(ms · rate_hz / 1000))`.
pub fn level_ticks(ms: f32, rate_hz: f32) -> u32 {
    let ticks = (f64::from(ms) * f64::from(rate_hz) / 1000.0).round();
    if ticks.is_finite() && ticks >= 1.0 {
        ticks.min(f64::from(u32::MAX)) as u32
    } else {
        1
    }
}

/// A name in the configuration the model could not resolve.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ModelError(pub String);

impl std::fmt::Display for ModelError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "unknown name '{}'", self.0)
    }
}

impl std::error::Error for ModelError {}

/// A feature stage with its inputs resolved to slots (channels first, then features).
#[derive(Clone, Debug)]
enum Stage {
    Raw(usize),
    Abs(usize),
    Positive(usize),
    LowPass {
        input: usize,
        alpha: f64,
        /// The most samples the warm-up's mean counts.
        warm: u32,
        /// The warm-up ends once this slot is above the level.
        until: Option<(usize, f64)>,
        /// The warm-up goes on to this many samples if this slot is above the level once
        /// `warm` samples are in.
        longer: Option<(usize, f64, u32)>,
    },
    HighPass {
        input: usize,
        alpha: f64,
    },
    Envelope {
        input: usize,
        alpha: f64,
    },
    Cancel {
        input: usize,
        motion: usize,
        alpha: f64,
        gain: f64,
    },
    /// The input, or its fraction `leak` while the watched slot is above the level (below
    /// it, if `below`).
    Gate {
        input: usize,
        unless: (usize, f64),
        below: bool,
        leak: f64,
    },
    Rate {
        input: usize,
        rate: f64,
    },
    Difference {
        a: usize,
        b: usize,
        gain: f64,
    },
    Dot([usize; 2], [usize; 2]),
    Magnitude([usize; 2]),
    Mean {
        input: usize,
        window: usize,
    },
    Ste {
        input: usize,
        h: Vec<f64>,
        /// Whether the window is rectangular: then, until it has filled, the mean square
        /// of the samples that have arrived.
        rectangular: bool,
    },
}

/// A term: the feature slot it judges, its CDF and its weight (0 for context terms).
#[derive(Clone, Debug)]
struct Term {
    feature: usize,
    cdf: CdfSpec,
    weight: f64,
}

/// A decision level's parameters.
#[derive(Clone, Copy, Debug)]
struct LevelParams {
    on: f64,
    off: f64,
    dwell: u32,
    hold: u32,
    /// The early dwell: the feature watched, its level, the shorter dwell.
    early: Option<(usize, f64, u32)>,
}

#[derive(Clone, Debug)]
struct Event {
    context: Vec<Term>,
    sensor: Vec<Term>,
    levels: [LevelParams; 2],
    onset_level: f64,
    /// The events whose confirm level, while up, holds this one's levels down.
    excluded_by: u8,
}

/// The reference model of one configuration (immutable); its running state is a
/// [`ModelState`].
#[derive(Clone, Debug)]
pub struct Model {
    channels: usize,
    /// Each channel's scale from SI to its working unit.
    scales: Vec<f64>,
    stages: Vec<Stage>,
    /// Per feature, the channels it reads directly or through earlier features.
    feature_channels: Vec<u32>,
    events: Vec<Event>,
    phases: Vec<u8>,
}

/// Per-feature running state.
#[derive(Clone, Debug, Default)]
struct StageState {
    /// Low-pass output.
    y: f64,
    /// Previous input (rate), if any.
    previous: Option<f64>,
    /// Inputs, most recent last (STE, mean), at most the window length.
    history: Vec<f64>,
    /// Samples the low-pass has seen.
    seen: u32,
    /// The low-pass's warm-up goes on to its longer limit.
    longer: bool,
}

/// The most samples a low-pass warms up over.
const WARM_LIMIT: u32 = 65535;

impl StageState {
    /// One tick of the low-pass y += g (x − y) with g = max(α, 1/n) for the n-th sample
    /// while n ≤ `warm` (at most [`WARM_LIMIT`]), α after: the mean of the samples so far
    /// until α weighs more or the warm-up's limit has passed.
    fn low_pass(&mut self, x: f64, alpha: f64, warm: u32) -> f64 {
        self.seen = self.seen.saturating_add(1);
        let mean_gain = if self.seen <= warm {
            1.0 / f64::from(self.seen)
        } else {
            0.0
        };
        self.y += alpha.max(mean_gain) * saturate(x - self.y);
        self.y
    }

    /// Adds `x` to the window history of `n` samples and returns it.
    fn window(&mut self, x: f64, n: usize) -> &[f64] {
        self.history.push(x);
        if self.history.len() > n {
            self.history.remove(0);
        }
        &self.history
    }
}

/// One decision level's running state.
#[derive(Clone, Copy, Debug, Default)]
struct LevelState {
    up: bool,
    /// Consecutive ticks at or above `on`.
    run: u32,
    /// Consecutive ticks below `off`.
    below: u32,
    /// The early dwell's feature has been above its level during the current run.
    shown: bool,
}

/// One event's decision state.
#[derive(Clone, Copy, Debug, Default)]
struct EventState {
    /// The first tick of the current run above the onset level, if in one.
    onset: Option<u32>,
    levels: [LevelState; 2],
}

/// Everything the model changes as it runs.
#[derive(Clone, Debug)]
pub struct ModelState {
    stages: Vec<StageState>,
    events: Vec<EventState>,
    phase: usize,
}

impl ModelState {
    /// The active phase's index.
    pub fn phase(&self) -> usize {
        self.phase
    }
}

/// What the model judged at one tick, before decisions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Judgement {
    /// Each event's confidence (eq. 14), by event index; 0 for events not evaluated or
    /// unjudgeable.
    pub confidences: Vec<f64>,
    /// Per event, its context terms' confidences (0 for lost terms); empty for events not
    /// evaluated.
    pub context: Vec<Vec<f64>>,
    /// Per event, its sensor terms' confidences (0 for lost terms); empty for events not
    /// evaluated.
    pub sensor: Vec<Vec<f64>>,
    /// The events of the active phase, bit `i` for event `i`.
    pub evaluated: u8,
    /// Events that cannot be judged (a context term, or every sensor term, lost).
    pub unjudgeable: u8,
    /// Judged events that lost some sensor terms.
    pub degraded: u8,
}

/// A level raised by the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelDecision {
    /// The event's index.
    pub event: usize,
    /// Which level.
    pub level: Level,
    /// The event's confidence at that tick.
    pub confidence: f64,
    /// The back-dated onset tick.
    pub onset: u32,
    /// The tick at which the level was raised.
    pub tick: u32,
}

/// The decision stage's results at one tick.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Decided {
    /// Events whose alert level is up after this tick.
    pub alerting: u8,
    /// Events whose confirm level is up after this tick.
    pub confirmed: u8,
    /// Levels raised at this tick, events in index order, alert before confirm.
    pub decisions: Vec<ModelDecision>,
}

/// Everything the model computes at one tick.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelOutput {
    /// Feature values, in configuration order.
    pub features: Vec<f64>,
    /// Term and event confidences.
    pub judgement: Judgement,
    /// Decisions.
    pub decided: Decided,
}

impl Model {
    /// Resolves the configuration's names. Does not validate parameters: pass only
    /// configurations that `detector_build::build` accepts.
    pub fn new(config: &Config) -> Result<Model, ModelError> {
        let channel_names: Vec<&str> = config.channels.iter().map(|c| c.name.as_str()).collect();
        let rate = f64::from(config.rate_hz);
        let mut feature_names: Vec<&str> = Vec::new();
        let mut stages = Vec::new();
        let mut feature_channels: Vec<u32> = Vec::new();
        for f in &config.features {
            let mut deps = 0u32;
            let resolved = f.stage.map_inputs(|name| {
                if let Some(i) = channel_names.iter().position(|c| *c == name.as_str()) {
                    deps |= 1 << i;
                    Ok(i)
                } else if let Some(j) = feature_names.iter().position(|g| *g == name.as_str()) {
                    deps |= feature_channels[j];
                    Ok(channel_names.len() + j)
                } else {
                    Err(ModelError(name.to_string()))
                }
            })?;
            stages.push(match resolved {
                StageSpec::Raw { input } => Stage::Raw(input),
                StageSpec::Abs { input } => Stage::Abs(input),
                StageSpec::Positive { input } => Stage::Positive(input),
                StageSpec::LowPass {
                    input,
                    cutoff_hz,
                    warm_up_ms,
                    warm_up_until,
                    warm_up_longer,
                } => {
                    // Rounded as the configuration's f32 values are (the sample count is
                    // part of the stage's definition).
                    let samples = |ms: f32| {
                        ((ms * config.rate_hz / 1000.0 + 0.5) as u32).clamp(1, WARM_LIMIT - 1)
                    };
                    Stage::LowPass {
                        input,
                        alpha: low_pass_alpha(rate, f64::from(cutoff_hz)),
                        warm: warm_up_ms.map_or(WARM_LIMIT, samples),
                        // The levels as the core holds them (16.16).
                        until: warm_up_until
                            .map(|l| (l.feature, Signal::from_f32(l.above).to_f64())),
                        longer: warm_up_longer.map(|l| {
                            let above = Signal::from_f32(l.above).to_f64();
                            (l.feature, above, samples(l.warm_up_ms))
                        }),
                    }
                }
                StageSpec::HighPass { input, cutoff_hz } => Stage::HighPass {
                    input,
                    alpha: low_pass_alpha(rate, f64::from(cutoff_hz)),
                },
                StageSpec::Envelope { input, cutoff_hz } => Stage::Envelope {
                    input,
                    alpha: low_pass_alpha(rate, f64::from(cutoff_hz)),
                },
                StageSpec::Cancel {
                    input,
                    motion,
                    gain,
                    cutoff_hz,
                } => Stage::Cancel {
                    input,
                    motion,
                    alpha: low_pass_alpha(rate, f64::from(cutoff_hz)),
                    gain: f64::from(gain),
                },
                StageSpec::Gate {
                    input,
                    unless,
                    leak,
                } => Stage::Gate {
                    input,
                    // The level as the core holds it (16.16).
                    unless: (
                        unless.feature,
                        Signal::from_f32(unless.above.or(unless.below).unwrap_or(0.0)).to_f64(),
                    ),
                    below: unless.below.is_some(),
                    leak: f64::from(leak),
                },
                StageSpec::Rate { input } => Stage::Rate { input, rate },
                StageSpec::Difference { a, b, gain } => Stage::Difference {
                    a,
                    b,
                    gain: f64::from(gain),
                },
                StageSpec::Dot { a, b } => Stage::Dot(a, b),
                StageSpec::Magnitude { of } => Stage::Magnitude(of),
                StageSpec::Mean { input, window } => Stage::Mean {
                    input,
                    window: usize::from(window),
                },
                StageSpec::Ste {
                    input,
                    window: n,
                    shape,
                } => Stage::Ste {
                    input,
                    h: window(shape, usize::from(n)),
                    rectangular: shape == Window::Rectangular,
                },
            });
            feature_channels.push(deps);
            feature_names.push(f.name.as_str());
        }
        let feature = |name: &str| {
            feature_names
                .iter()
                .position(|g| *g == name)
                .ok_or_else(|| ModelError(name.to_string()))
        };
        let level = |l: &detector_build::LevelSpec| -> Result<LevelParams, ModelError> {
            Ok(LevelParams {
                on: f64::from(l.on),
                off: f64::from(l.off),
                dwell: level_ticks(l.dwell_ms, config.rate_hz),
                hold: level_ticks(l.hold_ms, config.rate_hz),
                early: match &l.early {
                    // The level as the core holds it (16.16).
                    Some(e) => Some((
                        feature(&e.feature)?,
                        Signal::from_f32(e.above).to_f64(),
                        level_ticks(e.dwell_ms, config.rate_hz),
                    )),
                    None => None,
                },
            })
        };
        let mut events = Vec::new();
        for e in &config.events {
            let mut context = Vec::new();
            for t in &e.context {
                context.push(Term {
                    feature: feature(&t.feature)?,
                    cdf: t.cdf,
                    weight: 0.0,
                });
            }
            let mut sensor = Vec::new();
            for t in &e.sensor {
                sensor.push(Term {
                    feature: feature(&t.feature)?,
                    cdf: t.cdf,
                    weight: f64::from(t.weight),
                });
            }
            events.push(Event {
                context,
                sensor,
                levels: [level(&e.alert)?, level(&e.confirm)?],
                onset_level: f64::from(e.onset_level),
                excluded_by: 0,
            });
        }
        for (i, e) in config.events.iter().enumerate() {
            for name in &e.excludes {
                let j = config
                    .events
                    .iter()
                    .position(|o| o.name == *name)
                    .ok_or_else(|| ModelError(name.clone()))?;
                events[j].excluded_by |= 1 << i;
            }
        }
        let mut phases = Vec::new();
        for p in &config.phases {
            let mut mask = 0u8;
            for name in &p.events {
                let i = config
                    .events
                    .iter()
                    .position(|e| e.name == *name)
                    .ok_or_else(|| ModelError(name.to_string()))?;
                mask |= 1 << i;
            }
            phases.push(mask);
        }
        Ok(Model {
            channels: channel_names.len(),
            scales: config.channels.iter().map(|c| f64::from(c.scale)).collect(),
            stages,
            feature_channels,
            events,
            phases,
        })
    }

    /// A fresh state: features empty, first phase active, no level up.
    pub fn new_state(&self) -> ModelState {
        ModelState {
            stages: vec![StageState::default(); self.stages.len()],
            events: vec![EventState::default(); self.events.len()],
            phase: 0,
        }
    }

    /// The sample of channel `index` in its working unit from its SI value: `si × scale`
    /// (unscaled for an unknown channel), not rounded.
    pub fn working_unit(&self, index: usize, si: f64) -> f64 {
        si * self.scales.get(index).copied().unwrap_or(1.0)
    }

    /// The number of events.
    pub fn event_count(&self) -> usize {
        self.events.len()
    }

    /// The events of phase `phase`, bit `i` for event `i` (0 for an unknown phase).
    pub fn phase_events(&self, phase: usize) -> u8 {
        self.phases.get(phase).copied().unwrap_or(0)
    }

    /// The channels feature `feature` reads, directly or through earlier features.
    pub fn feature_channels(&self, feature: usize) -> u32 {
        self.feature_channels.get(feature).copied().unwrap_or(0)
    }

    /// Switches to phase `phase` (ignored if there is no such phase). Switching to another
    /// phase lowers every level and forgets every onset; switching to the active phase
    /// changes nothing. Features keep their state.
    pub fn set_phase(&self, state: &mut ModelState, phase: usize) {
        if phase < self.phases.len() && phase != state.phase {
            state.phase = phase;
            for e in &mut state.events {
                *e = EventState::default();
            }
        }
    }

    /// Stage 1: updates every feature from the channel samples (missing samples count as
    /// 0), in order, and returns their values.
    pub fn update_features(&self, state: &mut ModelState, samples: &[f64]) -> Vec<f64> {
        let mut slots: Vec<f64> = (0..self.channels)
            .map(|i| saturate(samples.get(i).copied().unwrap_or(0.0)))
            .collect();
        for (stage, st) in self.stages.iter().zip(state.stages.iter_mut()) {
            let v = |i: usize| slots[i];
            let value = match stage {
                Stage::Raw(i) => v(*i),
                Stage::Abs(i) => v(*i).abs(),
                Stage::Positive(i) => v(*i).max(0.0),
                Stage::LowPass {
                    input,
                    alpha,
                    warm,
                    until,
                    longer,
                } => {
                    if let Some((u, above)) = until
                        && st.seen > 0
                        && v(*u) > *above
                    {
                        st.seen = u32::MAX;
                    }
                    if let Some((w, above, _)) = longer
                        && st.seen == *warm
                    {
                        st.longer = v(*w) > *above;
                    }
                    let limit = match longer {
                        Some((_, _, n)) if st.longer => *n,
                        _ => *warm,
                    };
                    st.low_pass(v(*input), *alpha, limit)
                }
                Stage::HighPass { input, alpha } => {
                    let x = v(*input);
                    x - st.low_pass(x, *alpha, WARM_LIMIT)
                }
                Stage::Envelope { input, alpha } => {
                    let x = v(*input);
                    st.seen = st.seen.saturating_add(1);
                    st.y = if st.seen == 1 || x >= st.y {
                        x
                    } else {
                        st.y + alpha * saturate(x - st.y)
                    };
                    st.y
                }
                Stage::Cancel {
                    input,
                    motion,
                    alpha,
                    gain,
                } => v(*input) - gain * st.low_pass(v(*motion), *alpha, WARM_LIMIT),
                Stage::Gate {
                    input,
                    unless: (watch, level),
                    below,
                    leak,
                } => {
                    let shut = if *below {
                        v(*watch) < *level
                    } else {
                        v(*watch) > *level
                    };
                    if shut { leak * v(*input) } else { v(*input) }
                }
                Stage::Rate { input, rate } => {
                    let x = v(*input);
                    let r = st.previous.map_or(0.0, |p| (x - p) * rate);
                    st.previous = Some(x);
                    r
                }
                Stage::Difference { a, b, gain } => v(*a) - gain * v(*b),
                Stage::Dot(a, b) => v(a[0]) * v(b[0]) + v(a[1]) * v(b[1]),
                Stage::Magnitude(of) => v(of[0]).hypot(v(of[1])),
                Stage::Mean { input, window } => {
                    let history = st.window(v(*input), *window);
                    history.iter().sum::<f64>() / history.len() as f64
                }
                Stage::Ste {
                    input,
                    h,
                    rectangular,
                } => {
                    let history = st.window(v(*input), h.len());
                    if *rectangular {
                        history.iter().map(|x| x * x).sum::<f64>() / history.len() as f64
                    } else {
                        // h(m) weighs the sample m ticks ago: the newest is at the
                        // history's end; missing samples count as zero.
                        history.iter().rev().zip(h).map(|(x, w)| x * x * w).sum()
                    }
                }
            };
            slots.push(saturate(value));
        }
        slots.split_off(self.channels)
    }

    /// Stage 2 and 3: the term confidences and eq. 14 for the active phase's events, given
    /// the feature values and the faulty channels.
    pub fn judge(&self, state: &ModelState, features: &[f64], faults: u32) -> Judgement {
        let n = self.events.len();
        let mut j = Judgement {
            confidences: vec![0.0; n],
            context: vec![Vec::new(); n],
            sensor: vec![Vec::new(); n],
            evaluated: self.phase_events(state.phase),
            ..Judgement::default()
        };
        for (i, e) in self.events.iter().enumerate() {
            let bit = 1u8 << i;
            if j.evaluated & bit == 0 {
                continue;
            }
            let lost = |t: &Term| self.feature_channels(t.feature) & faults != 0;
            let psi = |t: &Term| {
                if lost(t) {
                    0.0
                } else {
                    cdf(&t.cdf, features.get(t.feature).copied().unwrap_or(0.0))
                }
            };
            j.context[i] = e.context.iter().map(psi).collect();
            j.sensor[i] = e.sensor.iter().map(psi).collect();
            let lost_sensors = e.sensor.iter().filter(|t| lost(t)).count();
            if e.context.iter().any(lost) || lost_sensors == e.sensor.len() {
                j.unjudgeable |= bit;
                continue;
            }
            if lost_sensors > 0 {
                j.degraded |= bit;
            }
            let sensor: Vec<(f64, f64)> = e
                .sensor
                .iter()
                .map(|t| t.weight)
                .zip(j.sensor[i].iter().copied())
                .collect();
            j.confidences[i] = combine(&j.context[i], &sensor);
        }
        j
    }

    /// Stage 4: decision levels and onsets for the events `judgement.evaluated` from their
    /// confidences (`judgement.confidences[i]` for event `i`); events in
    /// `judgement.unjudgeable` have their levels lowered and count as confidence 0; early
    /// dwells read `features` (in configuration order) and show nothing for events in
    /// `judgement.degraded`. Usable on
    /// any confidences and features, e.g. the fixed-point engine's, to check its decisions
    /// alone.
    pub fn decide(
        &self,
        state: &mut ModelState,
        now: u32,
        judgement: &Judgement,
        features: &[f64],
    ) -> Decided {
        let (confidences, evaluated, unjudgeable) = (
            &judgement.confidences,
            judgement.evaluated,
            judgement.unjudgeable,
        );
        let mut d = Decided::default();
        for (i, e) in self.events.iter().enumerate() {
            let bit = 1u8 << i;
            if evaluated & bit == 0 {
                continue;
            }
            let excluded = state
                .events
                .iter()
                .enumerate()
                .any(|(j, other)| e.excluded_by & (1 << j) != 0 && other.levels[1].up);
            let st = &mut state.events[i];
            let judged = unjudgeable & bit == 0;
            let c = if judged {
                confidences.get(i).copied().unwrap_or(0.0)
            } else {
                0.0
            };
            if c > e.onset_level {
                st.onset.get_or_insert(now);
            } else {
                st.onset = None;
            }
            for (k, (p, l)) in e.levels.iter().zip(st.levels.iter_mut()).enumerate() {
                if !judged || excluded {
                    *l = LevelState::default();
                    continue;
                }
                l.run = if c >= p.on {
                    l.run.saturating_add(1)
                } else {
                    0
                };
                // The early dwell's feature, above its level at a tick of the run while
                // the event has all its terms.
                let shows = p.early.is_some_and(|(f, above, _)| {
                    judgement.degraded & bit == 0 && features.get(f).is_some_and(|&x| x > above)
                });
                l.shown = l.run > 0 && (l.shown || shows);
                let dwell = match p.early {
                    Some((_, _, early)) if l.shown => early,
                    _ => p.dwell,
                };
                l.below = if c < p.off {
                    l.below.saturating_add(1)
                } else {
                    0
                };
                if l.up && l.below >= p.hold {
                    l.up = false;
                }
                if !l.up && l.run >= dwell {
                    l.up = true;
                    d.decisions.push(ModelDecision {
                        event: i,
                        level: if k == 0 { Level::Alert } else { Level::Confirm },
                        confidence: c,
                        onset: st.onset.unwrap_or(now),
                        tick: now,
                    });
                }
            }
            if st.levels[0].up {
                d.alerting |= bit;
            }
            if st.levels[1].up {
                d.confirmed |= bit;
            }
        }
        d
    }

    /// One whole tick: features, term and event confidences, decisions.
    pub fn tick(
        &self,
        state: &mut ModelState,
        now: u32,
        samples: &[f64],
        faults: u32,
    ) -> ModelOutput {
        let features = self.update_features(state, samples);
        let judgement = self.judge(state, &features, faults);
        let decided = self.decide(state, now, &judgement, &features);
        ModelOutput {
            features,
            judgement,
            decided,
        }
    }
}
