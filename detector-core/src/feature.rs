//! Features: small stateful stages, each fed once per tick, turning channel samples (or
//! other features) into the numbers the confidence functions judge.
//!
//! A feature reads *slots*: the input channels come first, then the features in their
//! declaration order, so a feature can build on any channel or any earlier feature
//! (a low-pass of a derivative, the STE of a difference, ...). All arithmetic is integer,
//! saturating at the [`Signal`](crate::Signal) range, with no division.

use crate::MAX_WINDOW;
use crate::image::{ImageError, Reader, Sink};

/// Whether an optional factor is left at its default, 0 (serde leaves it out).
#[cfg(feature = "serde")]
fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

/// A window shape for the short-time energy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Window {
    /// Every sample of the window weighs the same: h(m) = 1/N.
    Rectangular,
    /// Symmetric triangle (Bartlett without zero end points):
    /// h(m) ∝ 1 − |2m − (N − 1)| / (N + 1), normalized to sum 1.
    Triangular,
}

/// How a feature is computed, as a user describes it. Inputs name a channel or an earlier
/// feature.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(
    feature = "serde",
    serde(rename_all = "snake_case", deny_unknown_fields)
)]
pub enum StageSpec<N> {
    /// The input as it is.
    Raw {
        /// Source channel or feature.
        input: N,
    },
    /// |input|.
    Abs {
        /// Source channel or feature.
        input: N,
    },
    /// max(input, 0): the input where it is positive, else 0, e.g. a jerk towards the pad
    /// only, the one sign that can make a film read a load.
    Positive {
        /// Source channel or feature.
        input: N,
    },
    /// First-order low-pass, backward-Euler discretization:
    /// y += α (x − y) with α = Δt / (τ + Δt), τ = 1 / (2π f_c). It warms up as the mean of
    /// what it has seen: the n-th sample weighs max(α, 1/n), so the output starts at the
    /// first sample (a channel's offset does not look like a step) and is the plain mean of
    /// the samples so far until that mean would forget more slowly than the filter (at most
    /// the first 65,535 samples), or until `warm_up_ms` has passed. The state keeps 31
    /// bits below the output's last; x − y saturates to the feature range, which cuts only
    /// a step from one end of the range to the other.
    LowPass {
        /// Source channel or feature.
        input: N,
        /// Cut-off frequency f_c in Hz, above 0 and below half the detector rate.
        cutoff_hz: f32,
        /// The longest the warm-up's plain mean lasts (ms): after it the filter forgets at
        /// its cut-off, so that what comes later is not averaged in at the mean's weight
        /// (a usual level learnt over the first tens of ms, not over the first second).
        /// Above 0 and at most 65,534 samples; absent, the warm-up lasts as long as the
        /// mean would weigh a sample more than the filter.
        #[cfg_attr(
            feature = "serde",
            serde(default, skip_serializing_if = "Option::is_none")
        )]
        warm_up_ms: Option<f32>,
        /// Ends the warm-up's plain mean early, once another feature rises above a level:
        /// what follows an event (a structure ringing after a collision) is not the quiet
        /// the mean assumes, and would weigh 1/n in it. Absent, only `warm_up_ms` and the
        /// mean's own weight end it.
        #[cfg_attr(
            feature = "serde",
            serde(default, skip_serializing_if = "Option::is_none")
        )]
        warm_up_until: Option<Crossing<N>>,
        /// Carries the warm-up's plain mean on to a longer limit when, as `warm_up_ms`
        /// ends, another feature is above a level: a usual level learnt over one period of
        /// the mains hum while the finger moved steadily, over two when a change of its
        /// commanded motion has just set the skin ringing, whose reading a mean of one
        /// period keeps. Needs `warm_up_ms`, which its own must exceed.
        #[cfg_attr(
            feature = "serde",
            serde(default, skip_serializing_if = "Option::is_none")
        )]
        warm_up_longer: Option<LongerWarmUp<N>>,
    },
    /// The input's envelope: up with the input at once, down as the
    /// [`StageSpec::LowPass`] at `cutoff_hz` (y = x when x ≥ y, else y += α (x − y)):
    /// what the input reached lately, forgotten with the time constant 1 / (2π f_c), e.g.
    /// a commanded acceleration remembered while the structure it shook still rings.
    /// Starts at the first sample.
    Envelope {
        /// Source channel or feature.
        input: N,
        /// Cut-off frequency f_c of its decay in Hz, above 0 and below half the detector
        /// rate.
        cutoff_hz: f32,
    },
    /// First-order high-pass: x − y with y the [`StageSpec::LowPass`] of x at the same
    /// cut-off, i.e. what the input does above f_c, its offset and slow drift removed. Zero
    /// on the first tick. Bit for bit the `difference` of the input and its `low_pass`, in
    /// one feature.
    HighPass {
        /// Source channel or feature.
        input: N,
        /// Cut-off frequency f_c in Hz, above 0 and below half the detector rate.
        cutoff_hz: f32,
    },
    /// Self-motion cancellation: `input − gain · y`, y the [`StageSpec::LowPass`] of `motion`
    /// at `cutoff_hz`. What a sensor reads that the finger's own commanded motion does not
    /// explain: a small linear filter driven by the commanded motion (e.g. the commanded
    /// acceleration, whose inertial load on the force sensor is −m a), its gain and cut-off
    /// identified from event-free motion. The output saturates at the
    /// [`Signal`](crate::Signal) range.
    Cancel {
        /// The sensor channel or feature.
        input: N,
        /// The commanded motion that drives the prediction.
        motion: N,
        /// The prediction's gain, in the input's unit per motion unit; |gain| below 32768,
        /// in steps of 2⁻¹⁶.
        gain: f32,
        /// Cut-off of the motion's low-pass, above 0 and below half the detector rate.
        cutoff_hz: f32,
    },
    /// The input while another feature stays at or below a level (or at or above one),
    /// else 0 (or the fraction `leak` of the input): evidence that means something only in
    /// a given state, e.g. a vibration judged against the usual one only while the
    /// commanded motion, which sets the usual one, holds steady; or evidence that weighs
    /// less in a state, e.g. a jolt while the arm's own loops may jolt it. The output is
    /// the input exactly (or its fraction), in the input's unit; the watched feature's unit
    /// is its own, never traded against the input's.
    Gate {
        /// Source channel or feature.
        input: N,
        /// The gate shuts while this feature is above its level, or below it.
        unless: Shut<N>,
        /// The fraction of the input a shut gate passes, within [0, 1], in steps of 2⁻¹⁶;
        /// 0 (nothing) when absent.
        #[cfg_attr(feature = "serde", serde(default, skip_serializing_if = "is_zero"))]
        leak: f32,
    },
    /// Rate of change: (x_n − x_{n−1}) · f_s, in the input's unit per second. Zero on the
    /// first tick.
    Rate {
        /// Source channel or feature.
        input: N,
    },
    /// a − gain · b: a difference of two quantities in the same unit, the subtrahend
    /// scaled by a pure number (a − 0.7 b: how far a exceeds 70 % of b). Saturates at the
    /// [`Signal`](crate::Signal) range.
    Difference {
        /// Minuend.
        a: N,
        /// Subtrahend.
        b: N,
        /// The subtrahend's factor, |gain| below 32768 in steps of 2⁻¹⁶; 1 by default.
        #[cfg_attr(feature = "serde", serde(default = "unit_gain"))]
        gain: f32,
    },
    /// Dot product of two 2-vectors: a_x b_x + a_y b_y (e.g. force · desired velocity, in W).
    Dot {
        /// The first vector's x and y.
        #[cfg_attr(feature = "serde", serde(deserialize_with = "exact_pair"))]
        a: [N; 2],
        /// The second vector's x and y.
        #[cfg_attr(feature = "serde", serde(deserialize_with = "exact_pair"))]
        b: [N; 2],
    },
    /// Euclidean magnitude of a 2-vector, √(x² + y²).
    Magnitude {
        /// The vector's x and y.
        #[cfg_attr(feature = "serde", serde(deserialize_with = "exact_pair"))]
        of: [N; 2],
    },
    /// The mean of the last N inputs (a moving average): what the input does over the
    /// window, its fluctuations faster than the window averaged out (a window of 20 ms
    /// nulls 50 Hz mains hum and all its harmonics). Until N samples have arrived it is the
    /// mean of those that have.
    Mean {
        /// Source channel or feature.
        input: N,
        /// Window length N, 1..=[`MAX_WINDOW`] samples.
        window: u16,
    },
    /// Short-time energy (the paper's eq. 17): ζ_n = Σ_{m=0}^{N−1} x²(n−m) h(m), with the
    /// window h normalized to sum 1, so ζ is a mean square in the input's unit squared
    /// whatever N. Until N samples have arrived, a rectangular window is the mean square of
    /// those that have, and a tapered one counts the missing ones as zero. Inputs saturate
    /// at ±2048 before squaring (so a window's sums fit 64 bits); the result saturates at
    /// the [`Signal`](crate::Signal) range.
    Ste {
        /// Source channel or feature.
        input: N,
        /// Window length N, 1..=[`MAX_WINDOW`] samples.
        window: u16,
        /// Window shape.
        #[cfg_attr(feature = "serde", serde(default = "default_window"))]
        shape: Window,
    },
}

/// A feature rising above a level (see [`StageSpec::LowPass`]'s `warm_up_until`).
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct Crossing<N> {
    /// The channel or earlier feature watched.
    pub feature: N,
    /// The level, in the watched feature's unit; below 32768 in magnitude.
    pub above: f32,
}

/// Where a gate shuts (see [`StageSpec::Gate`]'s `unless`): while a feature is above one
/// level, or below one. Exactly one of `above` and `below` is given.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct Shut<N> {
    /// The channel or earlier feature watched.
    pub feature: N,
    /// Shut while the feature is above this level, in its unit; below 32768 in magnitude.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "Option::is_none")
    )]
    pub above: Option<f32>,
    /// Shut while the feature is below this level, in its unit; below 32768 in magnitude.
    #[cfg_attr(
        feature = "serde",
        serde(default, skip_serializing_if = "Option::is_none")
    )]
    pub below: Option<f32>,
}

impl<N> Shut<N> {
    /// Shut while `feature` is above `level`.
    pub fn above(feature: N, level: f32) -> Shut<N> {
        Shut {
            feature,
            above: Some(level),
            below: None,
        }
    }

    /// Shut while `feature` is below `level`.
    pub fn below(feature: N, level: f32) -> Shut<N> {
        Shut {
            feature,
            above: None,
            below: Some(level),
        }
    }
}

/// A low-pass's longer warm-up (see [`StageSpec::LowPass`]'s `warm_up_longer`): taken when
/// a feature is above a level as the shorter one ends.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct LongerWarmUp<N> {
    /// The channel or earlier feature watched.
    pub feature: N,
    /// The level, in the watched feature's unit; below 32768 in magnitude.
    pub above: f32,
    /// The longer warm-up (ms), above the stage's `warm_up_ms`.
    pub warm_up_ms: f32,
}

#[cfg(feature = "serde")]
fn default_window() -> Window {
    Window::Rectangular
}

#[cfg(feature = "serde")]
fn unit_gain() -> f32 {
    1.0
}

/// A 2-vector's inputs: a list of exactly two, so that a third is refused, not dropped.
#[cfg(feature = "serde")]
fn exact_pair<'de, D, N>(d: D) -> Result<[N; 2], D::Error>
where
    D: serde::Deserializer<'de>,
    N: serde::Deserialize<'de>,
{
    use serde::de::{Error, IgnoredAny, SeqAccess, Visitor};

    struct Pair<N>(core::marker::PhantomData<N>);

    impl<'de, N: serde::Deserialize<'de>> Visitor<'de> for Pair<N> {
        type Value = [N; 2];

        fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            f.write_str("a list of exactly two inputs (x, y)")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[N; 2], A::Error> {
            let x = seq
                .next_element()?
                .ok_or_else(|| A::Error::invalid_length(0, &self))?;
            let y = seq
                .next_element()?
                .ok_or_else(|| A::Error::invalid_length(1, &self))?;
            let mut n = 2;
            while seq.next_element::<IgnoredAny>()?.is_some() {
                n += 1;
            }
            if n > 2 {
                return Err(A::Error::invalid_length(n, &self));
            }
            Ok([x, y])
        }
    }

    d.deserialize_seq(Pair(core::marker::PhantomData))
}

impl<N> StageSpec<N> {
    /// The same stage with every input name mapped through `f` (used to resolve names to
    /// slots), stopping at the first error.
    pub fn map_inputs<M, E>(
        &self,
        mut f: impl FnMut(&N) -> Result<M, E>,
    ) -> Result<StageSpec<M>, E> {
        Ok(match self {
            StageSpec::Raw { input } => StageSpec::Raw { input: f(input)? },
            StageSpec::Abs { input } => StageSpec::Abs { input: f(input)? },
            StageSpec::Positive { input } => StageSpec::Positive { input: f(input)? },
            StageSpec::LowPass {
                input,
                cutoff_hz,
                warm_up_ms,
                warm_up_until,
                warm_up_longer,
            } => StageSpec::LowPass {
                input: f(input)?,
                cutoff_hz: *cutoff_hz,
                warm_up_ms: *warm_up_ms,
                warm_up_until: match warm_up_until {
                    Some(l) => Some(Crossing {
                        feature: f(&l.feature)?,
                        above: l.above,
                    }),
                    None => None,
                },
                warm_up_longer: match warm_up_longer {
                    Some(l) => Some(LongerWarmUp {
                        feature: f(&l.feature)?,
                        above: l.above,
                        warm_up_ms: l.warm_up_ms,
                    }),
                    None => None,
                },
            },
            StageSpec::Envelope { input, cutoff_hz } => StageSpec::Envelope {
                input: f(input)?,
                cutoff_hz: *cutoff_hz,
            },
            StageSpec::HighPass { input, cutoff_hz } => StageSpec::HighPass {
                input: f(input)?,
                cutoff_hz: *cutoff_hz,
            },
            StageSpec::Cancel {
                input,
                motion,
                gain,
                cutoff_hz,
            } => StageSpec::Cancel {
                input: f(input)?,
                motion: f(motion)?,
                gain: *gain,
                cutoff_hz: *cutoff_hz,
            },
            StageSpec::Gate {
                input,
                unless,
                leak,
            } => StageSpec::Gate {
                input: f(input)?,
                unless: Shut {
                    feature: f(&unless.feature)?,
                    above: unless.above,
                    below: unless.below,
                },
                leak: *leak,
            },
            StageSpec::Rate { input } => StageSpec::Rate { input: f(input)? },
            StageSpec::Difference { a, b, gain } => StageSpec::Difference {
                a: f(a)?,
                b: f(b)?,
                gain: *gain,
            },
            StageSpec::Dot { a, b } => StageSpec::Dot {
                a: [f(&a[0])?, f(&a[1])?],
                b: [f(&b[0])?, f(&b[1])?],
            },
            StageSpec::Magnitude { of } => StageSpec::Magnitude {
                of: [f(&of[0])?, f(&of[1])?],
            },
            StageSpec::Mean { input, window } => StageSpec::Mean {
                input: f(input)?,
                window: *window,
            },
            StageSpec::Ste {
                input,
                window,
                shape,
            } => StageSpec::Ste {
                input: f(input)?,
                window: *window,
                shape: *shape,
            },
        })
    }

    /// The stage's kind as written in a configuration file.
    pub fn kind(&self) -> &'static str {
        match self {
            StageSpec::Raw { .. } => "raw",
            StageSpec::Abs { .. } => "abs",
            StageSpec::Positive { .. } => "positive",
            StageSpec::LowPass { .. } => "low_pass",
            StageSpec::Envelope { .. } => "envelope",
            StageSpec::HighPass { .. } => "high_pass",
            StageSpec::Cancel { .. } => "cancel",
            StageSpec::Gate { .. } => "gate",
            StageSpec::Rate { .. } => "rate",
            StageSpec::Difference { .. } => "difference",
            StageSpec::Dot { .. } => "dot",
            StageSpec::Magnitude { .. } => "magnitude",
            StageSpec::Mean { .. } => "mean",
            StageSpec::Ste { .. } => "ste",
        }
    }
}

/// Why a feature's parameters were rejected.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum StageError {
    /// The low- or high-pass cut-off is not finite, not positive, or not below half the detector rate.
    Cutoff {
        /// The cut-off in Hz.
        cutoff_hz: f32,
        /// Half the detector rate, in Hz.
        nyquist_hz: f32,
    },
    /// A cancellation's or a difference's gain is not finite, not below 32768 in
    /// magnitude, or not zero but below its resolution of 2⁻¹⁶.
    Gain {
        /// The gain.
        gain: f32,
    },
    /// A gate's leak is not within [0, 1], or not zero but below its resolution of 2⁻¹⁶.
    Leak {
        /// The leak.
        leak: f32,
    },
    /// A low-pass's warm-up is not finite, not positive, or longer than its sample counter
    /// holds at the detector rate.
    WarmUp {
        /// The requested warm-up in ms.
        warm_up_ms: f32,
        /// The longest the detector rate allows, in ms.
        max_ms: f32,
    },
    /// A low-pass's longer warm-up is not longer than its warm-up, or it has no warm-up to
    /// carry on.
    WarmUpLonger {
        /// The warm-up in ms (NaN when absent).
        warm_up_ms: f32,
        /// The longer warm-up in ms.
        longer_ms: f32,
    },
    /// A level a low-pass's warm-up or a gate watches is not finite or not below 32768 in
    /// magnitude.
    Level {
        /// The requested level.
        level: f32,
    },
    /// A gate's `unless` gives both `above` and `below`, or neither.
    GateSide,
    /// An STE or mean window is empty or longer than [`MAX_WINDOW`].
    WindowLength {
        /// The requested length.
        window: u16,
    },
    /// The STE and mean windows of all features together need more history than the
    /// detector holds.
    WindowPool {
        /// Samples needed so far, this feature included.
        needed: usize,
    },
}

impl core::fmt::Display for StageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            StageError::Cutoff {
                cutoff_hz,
                nyquist_hz,
            } => write!(
                f,
                "cutoff_hz = {cutoff_hz} must be above 0 and below half the detector rate ({nyquist_hz} Hz)"
            ),
            StageError::WarmUp { warm_up_ms, max_ms } => write!(
                f,
                "warm_up_ms = {warm_up_ms} must be above 0 and at most {max_ms} ms (65,534 samples at the detector rate)"
            ),
            StageError::WarmUpLonger {
                warm_up_ms,
                longer_ms,
            } => write!(
                f,
                "warm_up_longer's warm_up_ms = {longer_ms} must exceed the stage's own warm_up_ms ({warm_up_ms}), which it needs"
            ),
            StageError::Level { level } => write!(
                f,
                "the level {level} must be finite and below 32768 in magnitude"
            ),
            StageError::GateSide => {
                write!(f, "a gate's unless needs exactly one of above and below")
            }
            StageError::Gain { gain } => write!(
                f,
                "gain = {gain} must be finite, below 32768 in magnitude, and 0 or at least 2^-16 (0.0000153) in magnitude"
            ),
            StageError::Leak { leak } => write!(
                f,
                "leak = {leak} must be within [0, 1], and 0 or at least 2^-16 (0.0000153)"
            ),
            StageError::WindowLength { window } => write!(
                f,
                "window = {window} must be between 1 and {MAX_WINDOW} samples"
            ),
            StageError::WindowPool { needed } => write!(
                f,
                "the STE and mean windows together need {needed} samples of history, more than the {WINDOW_POOL} the detector holds"
            ),
        }
    }
}

/// Slots a stage can read: the channels, then the features.
pub const MAX_SLOTS: usize = (crate::MAX_CHANNELS + crate::MAX_FEATURES).next_power_of_two();

/// Samples of history the detector holds for all its STE and mean features together.
pub const WINDOW_POOL: usize = 2 * MAX_WINDOW;

// Slot and history reads mask the index with MAX_SLOTS - 1 or WINDOW_POOL - 1: one
// instruction, no bounds check.
const _: () = assert!(MAX_SLOTS.is_power_of_two() && WINDOW_POOL.is_power_of_two());

/// A compiled feature stage: input slots and precomputed coefficients, made by
/// [`Stage::compile`] or read from an image, so always within the ranges the tick relies
/// on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stage(StageKind);

/// A compiled stage's kind and values, for generated code (`detector_core::__private`),
/// which builds a [`Stage`] from them through a `const fn` that checks them.
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StageKind {
    Raw(u8),
    Abs(u8),
    Positive(u8),
    /// `alpha` is α in Q31; `warm` the last sample the warm-up's mean counts: the
    /// configured limit or, sooner, where 1/n falls to α ([`mean_gain_samples`]); the
    /// warm-up also ends once slot `until` is above `until_above` (Q16.16; `i32::MAX`:
    /// never, `until` then the input). It goes on to `longer` (likewise limited) if slot
    /// `watch` is above `watch_above` as the `warm`-th sample's tick has passed; `longer`
    /// equals `warm` without a longer warm-up.
    LowPass {
        input: u8,
        alpha: u32,
        warm: u16,
        until: u8,
        until_above: i32,
        longer: u16,
        watch: u8,
        watch_above: i32,
    },
    /// Up at once, down as a low-pass, `alpha` as for [`StageKind::LowPass`]. It starts
    /// at its first sample, which lifts a fresh state ([`Stage::fresh_state`]) at once:
    /// no flag to keep.
    Envelope {
        input: u8,
        alpha: u32,
    },
    /// The input minus its low-pass, `alpha` and `warm` as for [`StageKind::LowPass`]
    /// (`warm` derived from `alpha`, not carried in an image).
    HighPass {
        input: u8,
        alpha: u32,
        warm: u16,
    },
    /// `input − gain · low-pass(motion)`, `alpha` and `warm` as for
    /// [`StageKind::HighPass`], `gain` in Q16.16 (never `i32::MIN`).
    Cancel {
        input: u8,
        motion: u8,
        alpha: u32,
        gain: i32,
        warm: u16,
    },
    /// `input`, or `input · leak` (`leak` in Q16.16, within [0, 1]) while slot `watch` is
    /// above `level` (Q16.16), or below it if `below`.
    Gate {
        input: u8,
        watch: u8,
        level: i32,
        below: bool,
        leak: i32,
    },
    /// `rate` is the detector rate in Hz, Q8.
    Rate {
        input: u8,
        rate: u32,
    },
    /// `a − gain · b`, `gain` in Q16.16 (never `i32::MIN`; 1 is exactly `a − b`).
    Difference {
        a: u8,
        b: u8,
        gain: i32,
    },
    Dot([u8; 4]),
    Magnitude(u8, u8),
    /// History of inputs `ring[offset..offset + len]` (Q16 as `i64` bits), a running sum
    /// scaled by `recip` = 2²⁴/N once the window is full.
    Mean {
        input: u8,
        offset: u16,
        len: u16,
        recip: u32,
    },
    /// History of squares `ring[offset..offset + len]` (Q16, at most 2³⁸); rectangular windows keep a running sum and
    /// scale by `recip` = 2²⁴/N, tapered ones use `weights[offset..offset + len]` (Q24).
    Ste {
        input: u8,
        offset: u16,
        len: u16,
        recip: u32,
        tapered: bool,
    },
}

/// Per-feature running state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct StageState {
    /// A filter's output times 2³² plus twice the fraction below its last bit that a Q31
    /// accumulator would hold (so its lower word is even and its upper word is the output,
    /// without a shift), or a window's running sum (of squares for STE, below 2⁴⁶; of
    /// inputs for a mean, below 2³⁸ in magnitude; Q16).
    acc: i64,
    /// The previous input (rate).
    prev: i32,
    /// A window's next history position to overwrite, relative to the feature's offset; a
    /// filter's samples seen while it warms up (0: none yet; the first one primes it).
    pos: u16,
    /// Whether a rate has seen a sample; a window's: whether it has filled.
    primed: bool,
}

impl Stage {
    /// The stage's state before its first sample: all zero, except an envelope's, which
    /// holds the least value a state can, so that its first sample, whatever it is, lifts
    /// it at once.
    pub(crate) fn fresh_state(&self) -> StageState {
        match self.0 {
            StageKind::Envelope { .. } => StageState {
                acc: i64::MIN,
                ..StageState::default()
            },
            _ => StageState::default(),
        }
    }
}

impl StageState {
    /// Bytes of a saved stage state: `acc` (`i64`), `prev` (`i32`), `pos` (`u16`),
    /// `primed` (0 or 1), little-endian.
    pub(crate) const BYTES: usize = 15;

    /// Writes the saved form.
    pub(crate) fn save(&self) -> [u8; StageState::BYTES] {
        let mut b = [0u8; StageState::BYTES];
        let (acc, rest) = b.split_at_mut(8);
        acc.copy_from_slice(&self.acc.to_le_bytes());
        let (prev, rest) = rest.split_at_mut(4);
        prev.copy_from_slice(&self.prev.to_le_bytes());
        let (pos, primed) = rest.split_at_mut(2);
        pos.copy_from_slice(&self.pos.to_le_bytes());
        primed[0] = u8::from(self.primed);
        b
    }

    /// Reads the saved form; `None` when the flag byte is neither 0 nor 1.
    pub(crate) fn restore(b: [u8; StageState::BYTES]) -> Option<StageState> {
        let [
            a0,
            a1,
            a2,
            a3,
            a4,
            a5,
            a6,
            a7,
            p0,
            p1,
            p2,
            p3,
            s0,
            s1,
            primed,
        ] = b;
        Some(StageState {
            acc: i64::from_le_bytes([a0, a1, a2, a3, a4, a5, a6, a7]),
            prev: i32::from_le_bytes([p0, p1, p2, p3]),
            pos: u16::from_le_bytes([s0, s1]),
            primed: match primed {
                0 => false,
                1 => true,
                _ => return None,
            },
        })
    }
}

impl Stage {
    /// Whether `st`, with the stage's share of the window history `ring`, is a state
    /// this stage can have reached: a filter's output within `i32`, a window's position
    /// inside it, its entries within what its inputs make and its running sum exactly
    /// theirs (of those that have arrived, until it has filled). A state read from
    /// outside (a recording) is held to this before a tick runs on it, so that no
    /// arithmetic of the tick can overflow.
    pub(crate) fn admits(&self, st: &StageState, ring: &[u64; WINDOW_POOL]) -> bool {
        // The entries the running sum holds, with the window's: `None` for a position
        // outside the window.
        let window = |offset: u16, len: u16| {
            let start = usize::from(offset);
            let held = if st.primed { len } else { st.pos };
            let all = ring.get(start..start + usize::from(len))?;
            (st.pos < len).then(|| (&all[..usize::from(held)], all))
        };
        match self.0 {
            StageKind::LowPass { .. }
            | StageKind::Envelope { .. }
            | StageKind::HighPass { .. }
            | StageKind::Cancel { .. } => st.acc & 1 == 0,
            StageKind::Mean { offset, len, .. } => window(offset, len).is_some_and(|(held, h)| {
                h.iter().all(|&e| i32::try_from(e as i64).is_ok())
                    && held.iter().map(|&e| e as i64).sum::<i64>() == st.acc
            }),
            StageKind::Ste {
                offset,
                len,
                tapered,
                ..
            } => {
                let square_limit = ((STE_INPUT_LIMIT * STE_INPUT_LIMIT) >> 16) as u64;
                window(offset, len).is_some_and(|(held, h)| {
                    // A tapered window weighs its entries afresh each tick: no sum to keep.
                    h.iter().all(|&e| e <= square_limit)
                        && (tapered || held.iter().sum::<u64>() == st.acc as u64 && st.acc >= 0)
                })
            }
            StageKind::Raw(_)
            | StageKind::Abs(_)
            | StageKind::Positive(_)
            | StageKind::Gate { .. }
            | StageKind::Rate { .. }
            | StageKind::Difference { .. }
            | StageKind::Dot(_)
            | StageKind::Magnitude(..) => true,
        }
    }
}

/// The most samples a low-pass warms up over (its sample counter's range).
const WARM_LIMIT: u16 = u16::MAX;

impl Stage {
    /// Compiles a stage whose inputs are already resolved to slots. `pool_used` is the STE
    /// history taken by earlier features and grows by this feature's window; tapered
    /// window weights are written into `weights`.
    pub fn compile(
        spec: &StageSpec<u8>,
        rate_hz: f32,
        pool_used: &mut usize,
        weights: &mut [u32; WINDOW_POOL],
    ) -> Result<Stage, StageError> {
        Ok(Stage(match *spec {
            StageSpec::Raw { input } => StageKind::Raw(input),
            StageSpec::Abs { input } => StageKind::Abs(input),
            StageSpec::Positive { input } => StageKind::Positive(input),
            StageSpec::LowPass {
                input,
                cutoff_hz,
                warm_up_ms,
                ref warm_up_until,
                ref warm_up_longer,
            } => {
                let (until, until_above) = match *warm_up_until {
                    Some(Crossing { feature, above }) => (feature, level_q16(above)?),
                    None => (input, i32::MAX),
                };
                let alpha = low_pass_alpha(rate_hz, cutoff_hz)?;
                let shorter = warm_up_samples(rate_hz, warm_up_ms)?;
                let warm = shorter.min(mean_gain_samples(alpha));
                let carried = match *warm_up_longer {
                    Some(LongerWarmUp {
                        feature,
                        above,
                        warm_up_ms: longer_ms,
                    }) => {
                        // Compared in samples, as the tick counts them; without a warm-up of
                        // its own the stage's is the counter's limit, which none exceeds.
                        let longer = warm_up_samples(rate_hz, Some(longer_ms))?;
                        if longer <= shorter {
                            return Err(StageError::WarmUpLonger {
                                warm_up_ms: warm_up_ms.unwrap_or(f32::NAN),
                                longer_ms,
                            });
                        }
                        let longer = longer.min(mean_gain_samples(alpha));
                        Some((longer, feature, level_q16(above)?))
                    }
                    None => None,
                };
                // Where the filter's own weight ends the mean before the shorter warm-up
                // would, there is nothing to carry on.
                let (longer, watch, watch_above) = match carried {
                    Some((longer, feature, above)) if longer > warm => (longer, feature, above),
                    _ => (warm, input, i32::MAX),
                };
                StageKind::LowPass {
                    input,
                    alpha,
                    warm,
                    until,
                    until_above,
                    longer,
                    watch,
                    watch_above,
                }
            }
            StageSpec::Envelope { input, cutoff_hz } => StageKind::Envelope {
                input,
                alpha: low_pass_alpha(rate_hz, cutoff_hz)?,
            },
            StageSpec::HighPass { input, cutoff_hz } => {
                let alpha = low_pass_alpha(rate_hz, cutoff_hz)?;
                StageKind::HighPass {
                    input,
                    alpha,
                    warm: mean_gain_samples(alpha),
                }
            }
            StageSpec::Cancel {
                input,
                motion,
                gain,
                cutoff_hz,
            } => {
                let alpha = low_pass_alpha(rate_hz, cutoff_hz)?;
                StageKind::Cancel {
                    input,
                    motion,
                    alpha,
                    gain: gain_q16(gain)?,
                    warm: mean_gain_samples(alpha),
                }
            }
            StageSpec::Gate {
                input,
                unless:
                    Shut {
                        feature,
                        above,
                        below,
                    },
                leak,
            } => StageKind::Gate {
                input,
                watch: feature,
                level: level_q16(match (above, below) {
                    (Some(level), None) | (None, Some(level)) => level,
                    _ => return Err(StageError::GateSide),
                })?,
                below: below.is_some(),
                leak: q16(leak)
                    .filter(|q| (0..=1 << 16).contains(q) && (*q != 0 || leak == 0.0))
                    .ok_or(StageError::Leak { leak })?,
            },
            StageSpec::Rate { input } => StageKind::Rate {
                input,
                rate: (rate_hz * 256.0 + 0.5) as u32,
            },
            StageSpec::Difference { a, b, gain } => StageKind::Difference {
                a,
                b,
                gain: gain_q16(gain)?,
            },
            StageSpec::Dot { a, b } => StageKind::Dot([a[0], a[1], b[0], b[1]]),
            StageSpec::Magnitude { of } => StageKind::Magnitude(of[0], of[1]),
            StageSpec::Mean { input, window } => {
                let (offset, _) = take_window(window, pool_used, weights)?;
                StageKind::Mean {
                    input,
                    offset,
                    len: window,
                    recip: window_recip(window),
                }
            }
            StageSpec::Ste {
                input,
                window,
                shape,
            } => {
                let (offset, taps) = take_window(window, pool_used, weights)?;
                let tapered = match shape {
                    Window::Rectangular => false,
                    Window::Triangular => {
                        triangular(taps);
                        true
                    }
                };
                StageKind::Ste {
                    input,
                    offset,
                    len: window,
                    recip: window_recip(window),
                    tapered,
                }
            }
        }))
    }

    /// Feeds one tick: reads input slots from `values`, returns the feature's new value.
    /// `ring` is the detector's STE history, `weights` its tapered window taps.
    #[inline(always)]
    pub(crate) fn update(
        &self,
        st: &mut StageState,
        values: &[i32; MAX_SLOTS],
        ring: &mut [u64; WINDOW_POOL],
        weights: &[u32],
    ) -> i32 {
        // Slots are validated below MAX_SLOTS, a power of two: masking keeps every access
        // in bounds for one instruction.
        let get = |slot: u8| values[usize::from(slot) & (MAX_SLOTS - 1)];
        match self.0 {
            StageKind::Raw(i) => get(i),
            StageKind::Abs(i) => get(i).saturating_abs(),
            StageKind::Positive(i) => get(i).max(0),
            StageKind::LowPass {
                input,
                alpha,
                warm,
                until,
                until_above,
                longer,
                watch,
                watch_above,
            } => {
                // Ends only a warm-up still running, never before the first sample, which
                // primes the filter (at `pos` 0). The level comes first: without a watched
                // slot it is i32::MAX, and generated code drops the test.
                if get(until) > until_above && st.pos != 0 && st.pos < longer {
                    st.pos = WARM_LIMIT;
                }
                // Once the shorter warm-up's samples are in, it ends there unless its watched
                // slot is above the level; past it, `pos` never equals `warm` again. Without a
                // longer warm-up `longer` is `warm`, and generated code drops the test.
                if longer > warm && st.pos == warm && get(watch) <= watch_above {
                    st.pos = WARM_LIMIT;
                }
                low_pass(st, get(input), alpha, longer)
            }
            StageKind::Envelope { input, alpha } => {
                let x = get(input);
                // Compared at the state's full resolution, not the output's: an input
                // between the two decays the state instead of snapping it down.
                if i64::from(x) << 32 >= st.acc {
                    st.acc = i64::from(x) << 32;
                } else {
                    filter_step(st, x, alpha);
                }
                filter_output(st)
            }
            StageKind::HighPass { input, alpha, warm } => {
                let x = get(input);
                x.saturating_sub(low_pass(st, x, alpha, warm))
            }
            StageKind::Cancel {
                input,
                motion,
                alpha,
                gain,
                warm,
            } => {
                let y = low_pass(st, get(motion), alpha, warm);
                // It saturates once, at the end.
                sat32(i64::from(get(input)) - scale_q16(y, gain))
            }
            StageKind::Gate {
                input,
                watch,
                level,
                below,
                leak,
            } => {
                // Generated code knows `below` and keeps one comparison.
                let shut = if below {
                    get(watch) < level
                } else {
                    get(watch) > level
                };
                if shut {
                    // A leak within [0, 1] keeps the product within the input's range.
                    scale_q16(get(input), leak) as i32
                } else {
                    get(input)
                }
            }
            StageKind::Rate { input, rate } => {
                let x = get(input);
                let out = if st.primed {
                    // |d| < 2^32 and rate < 2^24, so the product fits.
                    let d = i64::from(x) - i64::from(st.prev);
                    sat32((d * i64::from(rate)) >> 8)
                } else {
                    0
                };
                st.primed = true;
                st.prev = x;
                out
            }
            StageKind::Difference { a, b, gain } => {
                if gain == 1 << 16 {
                    // Generated code knows a unit gain: one saturating subtraction.
                    get(a).saturating_sub(get(b))
                } else {
                    sat32(i64::from(get(a)) - scale_q16(get(b), gain))
                }
            }
            StageKind::Dot([ax, ay, bx, by]) => {
                let p = i64::from(get(ax)) * i64::from(get(bx));
                let q = i64::from(get(ay)) * i64::from(get(by));
                sat32(p.saturating_add(q) >> 16)
            }
            StageKind::Magnitude(x, y) => {
                let (x, y) = (i64::from(get(x)), i64::from(get(y)));
                let s = (x * x) as u64 + (y * y) as u64;
                isqrt64(s).min(i32::MAX as u32) as i32
            }
            StageKind::Mean {
                input,
                offset,
                len,
                recip,
            } => {
                let x = i64::from(get(input));
                let oldest = push_window(st, ring, offset, len, x as u64) as i64;
                // Exact: what enters now leaves N ticks later, so the sum is the window's
                // (a loaded detector's windows are disjoint, a restored state's sums exact):
                // |sum| ≤ N · 2^31 ≤ 2^38, and with recip ≤ 2^24 / N the product is below 2^56.
                st.acc += x - oldest;
                sat32((st.acc * i64::from(filled_recip(st, len, recip))) >> 24)
            }
            StageKind::Ste {
                input,
                offset,
                len,
                recip,
                tapered,
            } => {
                let x = i64::from(get(input)).clamp(-STE_INPUT_LIMIT, STE_INPUT_LIMIT);
                let sq = ((x * x) >> 16) as u64;
                let newest = usize::from(st.pos);
                let oldest = push_window(st, ring, offset, len, sq);
                if tapered {
                    let start = usize::from(offset);
                    let n = usize::from(len);
                    let (Some(hist), Some(taps)) =
                        (ring.get(start..start + n), weights.get(start..start + n))
                    else {
                        return 0;
                    };
                    if newest >= n {
                        return 0;
                    }
                    // Lag m pairs with taps[m]: lags 0..=newest run back from `newest`, the
                    // remaining lags run back from the end of the ring.
                    // Squares ≤ 2^38 and taps summing to 2^24 keep the sum below 2^62.
                    let (recent, older) = hist.split_at(newest + 1);
                    let (near, far) = taps.split_at(newest + 1);
                    let acc: u64 = recent
                        .iter()
                        .rev()
                        .zip(near)
                        .chain(older.iter().rev().zip(far))
                        .map(|(&s, &w)| s * u64::from(w))
                        .sum();
                    (acc >> 24).min(i32::MAX as u64) as i32
                } else {
                    // Exact, as for a mean: 0 ≤ sum ≤ N · 2^38, and recip ≤ 2^24 / n keeps
                    // the product below 2^63.
                    st.acc += sq as i64 - oldest as i64;
                    let sum = st.acc as u64;
                    let recip = filled_recip(st, len, recip);
                    ((sum * u64::from(recip)) >> 24).min(i32::MAX as u64) as i32
                }
            }
        }
    }
}

/// STE inputs saturate here before squaring: 2048 in raw 16.16 bits.
const STE_INPUT_LIMIT: i64 = 2048 << 16;

/// Writes `entry` at a window's newest position and returns the entry it replaces, the one
/// that leaves the window (zero before the window has filled); advances the position and
/// marks the window full when it wraps.
#[inline(always)]
fn push_window(
    st: &mut StageState,
    ring: &mut [u64; WINDOW_POOL],
    offset: u16,
    len: u16,
    entry: u64,
) -> u64 {
    // A valid stage keeps offset + pos below WINDOW_POOL, a power of two: the mask keeps
    // even a state from another detector in bounds, for one instruction.
    let slot = &mut ring[(usize::from(offset) + usize::from(st.pos)) & (WINDOW_POOL - 1)];
    let oldest = if st.primed { *slot } else { 0 };
    *slot = entry;
    st.pos += 1;
    if st.pos >= len {
        st.pos = 0;
        st.primed = true;
    }
    oldest
}

/// 2²⁴ over the samples a window holds: `recip` (for N) once it has filled, else for the
/// samples that have arrived (one 32-bit division, in hardware on the Cortex-M4).
#[inline(always)]
fn filled_recip(st: &StageState, len: u16, recip: u32) -> u32 {
    if st.primed || st.pos == 0 || st.pos >= len {
        recip
    } else {
        (1u32 << 24) / u32::from(st.pos)
    }
}

/// Takes a window of `window` samples from the history pool: its offset and its taps.
fn take_window<'w>(
    window: u16,
    pool_used: &mut usize,
    weights: &'w mut [u32; WINDOW_POOL],
) -> Result<(u16, &'w mut [u32]), StageError> {
    let n = usize::from(window);
    if n == 0 || n > MAX_WINDOW {
        return Err(StageError::WindowLength { window });
    }
    let offset = *pool_used;
    let needed = offset + n;
    let Some(taps) = weights.get_mut(offset..needed) else {
        return Err(StageError::WindowPool { needed });
    };
    *pool_used = needed;
    Ok((offset as u16, taps))
}

/// 2²⁴ / N, rounded.
fn window_recip(window: u16) -> u32 {
    let n = u64::from(window);
    (((1u64 << 24) + n / 2) / n) as u32
}

impl Stage {
    /// Appends this item to a detector image.
    pub fn write_image(&self, w: &mut impl Sink) {
        match self.0 {
            StageKind::Raw(i) => {
                w.u8(StageTag::Raw as u8);
                w.u8(i);
            }
            StageKind::Abs(i) => {
                w.u8(StageTag::Abs as u8);
                w.u8(i);
            }
            StageKind::Positive(i) => {
                w.u8(StageTag::Positive as u8);
                w.u8(i);
            }
            StageKind::LowPass {
                input,
                alpha,
                warm,
                until,
                until_above,
                longer,
                watch,
                watch_above,
            } => {
                // Without a longer warm-up, the encoding images had before there was one.
                let tag = if longer > warm {
                    StageTag::LowPassLonger
                } else {
                    StageTag::LowPass
                };
                w.u8(tag as u8);
                w.u8(input);
                w.u32(alpha);
                w.u16(warm);
                w.u8(until);
                w.u32(until_above as u32);
                if longer > warm {
                    w.u16(longer);
                    w.u8(watch);
                    w.u32(watch_above as u32);
                }
            }
            StageKind::HighPass { input, alpha, .. } => {
                w.u8(StageTag::HighPass as u8);
                w.u8(input);
                w.u32(alpha);
            }
            StageKind::Envelope { input, alpha } => {
                w.u8(StageTag::Envelope as u8);
                w.u8(input);
                w.u32(alpha);
            }
            StageKind::Cancel {
                input,
                motion,
                alpha,
                gain,
                ..
            } => {
                w.u8(StageTag::Cancel as u8);
                w.u8(input);
                w.u8(motion);
                w.u32(alpha);
                w.u32(gain as u32);
            }
            StageKind::Gate {
                input,
                watch,
                level,
                below,
                leak,
            } => {
                w.u8(if below {
                    StageTag::GateBelow
                } else {
                    StageTag::Gate
                } as u8);
                w.u8(input);
                w.u8(watch);
                w.u32(level as u32);
                w.u32(leak as u32);
            }
            StageKind::Rate { input, rate } => {
                w.u8(StageTag::Rate as u8);
                w.u8(input);
                w.u32(rate);
            }
            StageKind::Difference { a, b, gain } => {
                w.u8(StageTag::Difference as u8);
                w.u8(a);
                w.u8(b);
                w.u32(gain as u32);
            }
            StageKind::Dot(s) => {
                w.u8(StageTag::Dot as u8);
                s.iter().for_each(|&i| w.u8(i));
            }
            StageKind::Magnitude(x, y) => {
                w.u8(StageTag::Magnitude as u8);
                w.u8(x);
                w.u8(y);
            }
            StageKind::Mean {
                input,
                offset,
                len,
                recip,
            } => {
                w.u8(StageTag::Mean as u8);
                w.u8(input);
                w.u16(offset);
                w.u16(len);
                w.u32(recip);
            }
            StageKind::Ste {
                input,
                offset,
                len,
                recip,
                tapered,
            } => {
                w.u8(StageTag::Ste as u8);
                w.u8(input);
                w.u16(offset);
                w.u16(len);
                w.u32(recip);
                w.u8(u8::from(tapered));
            }
        }
    }

    /// Reads a stage from a detector image; inputs must be below `slots`.
    pub(crate) fn read_image(r: &mut Reader<'_>, slots: usize) -> Result<Stage, ImageError> {
        let kind = match StageTag::from_byte(r.u8()?) {
            Some(StageTag::Raw) => StageKind::Raw(r.u8()?),
            Some(StageTag::Abs) => StageKind::Abs(r.u8()?),
            Some(StageTag::Positive) => StageKind::Positive(r.u8()?),
            Some(tag @ (StageTag::LowPass | StageTag::LowPassLonger)) => {
                let (input, alpha) = (r.u8()?, r.u32()?);
                let warm = r.u16()?.min(mean_gain_samples(alpha));
                let (until, until_above) = (r.u8()?, r.u32()? as i32);
                let (longer, watch, watch_above) = if matches!(tag, StageTag::LowPassLonger) {
                    let longer = r.u16()?.min(mean_gain_samples(alpha));
                    (longer, r.u8()?, r.u32()? as i32)
                } else {
                    (warm, input, i32::MAX)
                };
                StageKind::LowPass {
                    input,
                    alpha,
                    warm,
                    until,
                    until_above,
                    longer,
                    watch,
                    watch_above,
                }
            }
            Some(StageTag::HighPass) => {
                let (input, alpha) = (r.u8()?, r.u32()?);
                StageKind::HighPass {
                    input,
                    alpha,
                    warm: mean_gain_samples(alpha),
                }
            }
            Some(StageTag::Envelope) => StageKind::Envelope {
                input: r.u8()?,
                alpha: r.u32()?,
            },
            Some(StageTag::Cancel) => {
                let (input, motion, alpha) = (r.u8()?, r.u8()?, r.u32()?);
                StageKind::Cancel {
                    input,
                    motion,
                    alpha,
                    gain: r.u32()? as i32,
                    warm: mean_gain_samples(alpha),
                }
            }
            Some(tag @ (StageTag::Gate | StageTag::GateBelow)) => StageKind::Gate {
                input: r.u8()?,
                watch: r.u8()?,
                level: r.u32()? as i32,
                below: matches!(tag, StageTag::GateBelow),
                leak: r.u32()? as i32,
            },
            Some(StageTag::Rate) => StageKind::Rate {
                input: r.u8()?,
                rate: r.u32()?,
            },
            Some(StageTag::Difference) => StageKind::Difference {
                a: r.u8()?,
                b: r.u8()?,
                gain: r.u32()? as i32,
            },
            Some(StageTag::Mean) => StageKind::Mean {
                input: r.u8()?,
                offset: r.u16()?,
                len: r.u16()?,
                recip: r.u32()?,
            },
            Some(StageTag::Dot) => StageKind::Dot([r.u8()?, r.u8()?, r.u8()?, r.u8()?]),
            Some(StageTag::Magnitude) => StageKind::Magnitude(r.u8()?, r.u8()?),
            Some(StageTag::Ste) => {
                let input = r.u8()?;
                let (offset, len) = (r.u16()?, r.u16()?);
                let recip = r.u32()?;
                let tapered = match r.u8()? {
                    0 => false,
                    1 => true,
                    _ => return Err(ImageError::Invalid("STE window")),
                };
                StageKind::Ste {
                    input,
                    offset,
                    len,
                    recip,
                    tapered,
                }
            }
            None => return Err(ImageError::Invalid("feature kind")),
        };
        match kind.invalid(slots) {
            Some(what) => Err(ImageError::Invalid(what)),
            None => Ok(Stage(kind)),
        }
    }
}

impl StageKind {
    /// What is out of range, if anything, for a stage that may read slots below `slots`:
    /// the one statement of what [`Stage::compile`] can produce, checked by the image
    /// loader and, at compile time, by generated code's constants.
    pub(crate) const fn invalid(&self, slots: usize) -> Option<&'static str> {
        let inputs_ok = match *self {
            StageKind::Raw(i)
            | StageKind::Abs(i)
            | StageKind::Positive(i)
            | StageKind::Envelope { input: i, .. }
            | StageKind::HighPass { input: i, .. }
            | StageKind::Rate { input: i, .. }
            | StageKind::Mean { input: i, .. }
            | StageKind::Ste { input: i, .. } => (i as usize) < slots,
            StageKind::Difference { a, b, .. }
            | StageKind::Magnitude(a, b)
            | StageKind::Gate {
                input: a, watch: b, ..
            }
            | StageKind::Cancel {
                input: a,
                motion: b,
                ..
            } => (a as usize) < slots && (b as usize) < slots,
            StageKind::LowPass {
                input: a,
                until: b,
                watch: c,
                ..
            } => (a as usize) < slots && (b as usize) < slots && (c as usize) < slots,
            StageKind::Dot([a, b, c, d]) => {
                (a as usize) < slots
                    && (b as usize) < slots
                    && (c as usize) < slots
                    && (d as usize) < slots
            }
        };
        if !inputs_ok {
            return Some("feature input");
        }
        match *self {
            StageKind::LowPass { alpha, .. }
            | StageKind::Envelope { alpha, .. }
            | StageKind::HighPass { alpha, .. }
            | StageKind::Cancel { alpha, .. }
                if alpha == 0 || alpha >= 1 << 31 =>
            {
                Some("low-pass coefficient")
            }
            // Without a longer warm-up, `longer` is `warm` and nothing is watched.
            StageKind::LowPass {
                input,
                warm,
                longer,
                watch,
                watch_above,
                ..
            } if warm == 0
                || longer < warm
                || (longer == warm && (watch != input || watch_above != i32::MAX)) =>
            {
                Some("low-pass warm-up")
            }
            StageKind::Cancel { gain, .. } if gain == i32::MIN => Some("cancellation gain"),
            StageKind::Difference { gain, .. } if gain == i32::MIN => Some("difference gain"),
            StageKind::Gate { leak, .. } if leak < 0 || leak > 1 << 16 => Some("gate leak"),
            StageKind::Rate { rate, .. } if rate >= 1 << 24 => Some("rate"),
            StageKind::Mean {
                offset, len, recip, ..
            }
            | StageKind::Ste {
                offset, len, recip, ..
            } => {
                let end = offset as usize + len as usize;
                // recip · N ≤ 2^24 (plus rounding) keeps the running sum's product in 64 bits.
                let scaled = recip as u64 * len as u64;
                if len == 0
                    || len as usize > MAX_WINDOW
                    || end > WINDOW_POOL
                    || scaled > (1 << 24) + len as u64
                {
                    Some("window")
                } else {
                    None
                }
            }
            _ => None,
        }
    }

    /// A checked stage, for generated code's constants: a value [`Stage::compile`] cannot
    /// make fails the build of the generated code.
    pub const fn checked(self) -> Stage {
        if let Some(what) = self.invalid(MAX_SLOTS) {
            panic!("{}", what);
        }
        Stage(self)
    }
}

/// The tag that starts each stage in an image.
#[derive(Clone, Copy)]
enum StageTag {
    Raw = 0,
    Abs = 1,
    LowPass = 2,
    Rate = 3,
    Difference = 4,
    Dot = 5,
    Magnitude = 6,
    Ste = 7,
    HighPass = 8,
    Cancel = 9,
    Mean = 10,
    Envelope = 11,
    Gate = 12,
    Positive = 13,
    LowPassLonger = 14,
    GateBelow = 15,
}

impl StageTag {
    const ALL: [StageTag; 16] = [
        StageTag::Raw,
        StageTag::Abs,
        StageTag::LowPass,
        StageTag::Rate,
        StageTag::Difference,
        StageTag::Dot,
        StageTag::Magnitude,
        StageTag::Ste,
        StageTag::HighPass,
        StageTag::Cancel,
        StageTag::Mean,
        StageTag::Envelope,
        StageTag::Gate,
        StageTag::Positive,
        StageTag::LowPassLonger,
        StageTag::GateBelow,
    ];

    fn from_byte(b: u8) -> Option<StageTag> {
        StageTag::ALL.into_iter().find(|&t| t as u8 == b)
    }
}

impl core::fmt::Display for crate::expr::Rust<'_, Stage> {
    /// The stage as a Rust expression in generated code's scope (`detector_core::__private`).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "StageKind::")?;
        match self.0.0 {
            StageKind::Raw(i) => write!(f, "Raw({i})"),
            StageKind::Abs(i) => write!(f, "Abs({i})"),
            StageKind::Positive(i) => write!(f, "Positive({i})"),
            StageKind::LowPass {
                input,
                alpha,
                warm,
                until,
                until_above,
                longer,
                watch,
                watch_above,
            } => {
                write!(
                    f,
                    "LowPass {{ input: {input}, alpha: {alpha}, warm: {warm}, until: {until}, until_above: {until_above}, longer: {longer}, watch: {watch}, watch_above: {watch_above} }}"
                )
            }
            StageKind::HighPass { input, alpha, warm } => {
                write!(
                    f,
                    "HighPass {{ input: {input}, alpha: {alpha}, warm: {warm} }}"
                )
            }
            StageKind::Envelope { input, alpha } => {
                write!(f, "Envelope {{ input: {input}, alpha: {alpha} }}")
            }
            StageKind::Cancel {
                input,
                motion,
                alpha,
                gain,
                warm,
            } => write!(
                f,
                "Cancel {{ input: {input}, motion: {motion}, alpha: {alpha}, gain: {gain}, warm: {warm} }}"
            ),
            StageKind::Gate {
                input,
                watch,
                level,
                below,
                leak,
            } => write!(
                f,
                "Gate {{ input: {input}, watch: {watch}, level: {level}, below: {below}, leak: {leak} }}"
            ),
            StageKind::Rate { input, rate } => write!(f, "Rate {{ input: {input}, rate: {rate} }}"),
            StageKind::Difference { a, b, gain } => {
                write!(f, "Difference {{ a: {a}, b: {b}, gain: {gain} }}")
            }
            StageKind::Mean {
                input,
                offset,
                len,
                recip,
            } => write!(
                f,
                "Mean {{ input: {input}, offset: {offset}, len: {len}, recip: {recip} }}"
            ),
            StageKind::Dot([a, b, c, d]) => write!(f, "Dot([{a}, {b}, {c}, {d}])"),
            StageKind::Magnitude(a, b) => write!(f, "Magnitude({a}, {b})"),
            StageKind::Ste {
                input,
                offset,
                len,
                recip,
                tapered,
            } => write!(
                f,
                "Ste {{ input: {input}, offset: {offset}, len: {len}, recip: {recip}, tapered: {tapered} }}"
            ),
        }?;
        write!(f, ".checked()")
    }
}

impl Stage {
    /// This stage as a Rust expression for generated code (see
    /// `detector_build::Compiled::to_rust`).
    pub fn rust(&self) -> crate::expr::Rust<'_, Stage> {
        crate::expr::Rust(self)
    }
}

/// Whether the stages' windows share no entry of the history pool, as [`Stage::compile`]
/// lays them out: each window's running sum then holds exactly its own entries, which keeps
/// every sum, and its product with the window's reciprocal, in range.
pub(crate) fn windows_disjoint(stages: &[Stage]) -> bool {
    let mut taken = [0u32; WINDOW_POOL / 32];
    stages.iter().all(|stage| {
        let (StageKind::Mean { offset, len, .. } | StageKind::Ste { offset, len, .. }) = stage.0
        else {
            return true;
        };
        (usize::from(offset)..usize::from(offset) + usize::from(len)).all(|i| {
            // `invalid` holds every window inside the pool.
            let Some(word) = taken.get_mut(i / 32) else {
                return false;
            };
            let bit = 1 << (i % 32);
            let free = *word & bit == 0;
            *word |= bit;
            free
        })
    })
}

/// Whether a stage's window taps in `weights` are what [`Stage::compile`] makes: a
/// tapered window's sum exactly 2²⁴, which keeps its weighted sum in 64 bits.
pub(crate) fn taps_valid(stage: &Stage, weights: &[u32; WINDOW_POOL]) -> bool {
    match stage.0 {
        StageKind::Ste {
            offset,
            len,
            tapered: true,
            ..
        } => {
            let start = usize::from(offset);
            weights
                .get(start..start + usize::from(len))
                .is_some_and(|taps| taps.iter().map(|&t| u64::from(t)).sum::<u64>() == 1 << 24)
        }
        _ => true,
    }
}

/// α = Δt / (τ + Δt) = 1 / (1 + f_s / (2π f_c)) in Q31, for a cut-off below half the rate.
fn low_pass_alpha(rate_hz: f32, cutoff_hz: f32) -> Result<u32, StageError> {
    let nyquist_hz = rate_hz / 2.0;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyquist_hz) {
        return Err(StageError::Cutoff {
            cutoff_hz,
            nyquist_hz,
        });
    }
    let alpha = 1.0 / (1.0 + rate_hz / (2.0 * core::f32::consts::PI * cutoff_hz));
    // In Q31 through f32 (the chip's FPU, no soft-float f64): 24 significant bits, a
    // relative 6·10⁻⁸, far below the filter's other errors.
    let alpha = (alpha * 2_147_483_648.0) as u64;
    Ok(alpha.clamp(1, (1 << 31) - 1) as u32)
}

/// The most samples a low-pass's warm-up counts: `warm_up_ms` at the detector rate
/// (rounded, at least one), or [`WARM_LIMIT`] when absent.
fn warm_up_samples(rate_hz: f32, warm_up_ms: Option<f32>) -> Result<u16, StageError> {
    let Some(ms) = warm_up_ms else {
        return Ok(WARM_LIMIT);
    };
    let max_ms = f32::from(WARM_LIMIT - 1) * 1000.0 / rate_hz;
    if !(ms.is_finite() && ms > 0.0 && ms <= max_ms) {
        return Err(StageError::WarmUp {
            warm_up_ms: ms,
            max_ms,
        });
    }
    let samples = (ms * rate_hz / 1000.0 + 0.5) as u16;
    Ok(samples.clamp(1, WARM_LIMIT - 1))
}

/// A parameter in Q16.16 ([`Signal::parameter`](crate::Signal::parameter)).
fn q16(v: f32) -> Option<i32> {
    crate::Signal::parameter(v).map(crate::Signal::to_bits)
}

/// A level a low-pass's warm-up or a gate watches, in Q16.16.
fn level_q16(level: f32) -> Result<i32, StageError> {
    q16(level).ok_or(StageError::Level { level })
}

/// A cancellation gain in Q16.16: within the range, and zero or at least one step.
fn gain_q16(gain: f32) -> Result<i32, StageError> {
    q16(gain)
        .filter(|&q| (q != 0 || gain == 0.0) && q != i32::MIN)
        .ok_or(StageError::Gain { gain })
}

/// One tick of the first-order low-pass y += g (x − y), the gain g in Q31: α, or while the
/// filter warms up 1/n for its n-th sample, whichever is larger (the first sample sets y;
/// until 1/n falls below α, y is the mean of the samples so far, to within the rounding of
/// 1/n). `warm` is the last sample the warm-up counts, at most [`mean_gain_samples`]`(α)`.
///
/// A state that has seen no sample (`pos` 0) is primed by the first, so a filter needs no
/// flag of its own; the steady case is tested first.
#[inline(always)]
fn low_pass(st: &mut StageState, x: i32, alpha: u32, warm: u16) -> i32 {
    if st.pos >= warm {
        filter_step(st, x, alpha);
    } else if st.pos == 0 {
        st.pos = 1;
        st.acc = i64::from(x) << 32;
    } else {
        st.pos += 1;
        let d = i64::from(x.saturating_sub(filter_output(st)));
        // Twice the gain, as `filter_step` takes it, is below 2³¹ from the second sample
        // on (½ itself would not be), which the mask tells the compiler: one signed
        // multiply-accumulate on the chip for every n, with no case of its own for ½.
        let twice = mean_gain(u32::from(st.pos)) << 1;
        st.acc += d * i64::from((twice & 0x7fff_ffff) as i32);
    }
    filter_output(st)
}

/// The gain of a low-pass's n-th warm-up sample in Q31: 1/n rounded down from just below 1
/// (one 32-bit division, in hardware on the chip). Exact 1/n but for powers of two, where
/// it is 2⁻³¹ short, so that ½ stays below 2³⁰ and fits a signed step.
#[inline(always)]
const fn mean_gain(n: u32) -> u32 {
    i32::MAX as u32 / n
}

/// The last sample n whose plain-mean gain [`mean_gain`]`(n)` is above α, where a
/// low-pass's warm-up ends unless its own limit ends it sooner: ⌊(2³¹ − 1) / n⌋ > α ⇔
/// n ≤ (2³¹ − 1) / (α + 1). At most [`WARM_LIMIT`].
const fn mean_gain_samples(alpha: u32) -> u16 {
    let n = mean_gain(alpha.saturating_add(1));
    if n > WARM_LIMIT as u32 {
        WARM_LIMIT
    } else {
        n as u16
    }
}

/// Moves a filter's state towards `x` by the Q31 `gain` (0 < g < 1): y += g (x − y) kept
/// exactly as a Q31 accumulator would, acc += 2 g (x − y), the state holding y · 2³² plus
/// twice that accumulator's fraction below y's last bit. Its upper word is y, so neither
/// the difference nor the output needs a shift (on the Cortex-M4, four instructions fewer
/// a step than a Q31 state, whose output straddles its two words).
///
/// y needs no saturation: the difference is an integer d, and g d lies strictly between 0
/// and d, so the new ⌊acc / 2³²⌋ lies between x and the old y, inside the `i32` range (a
/// property test holds it there). The difference saturates only for an input more than
/// 2³¹ steps away; it keeps its sign, so y still moves towards x. The sum's exact value
/// lies between x · 2³² and the old acc, so it fits. Every gain is below 2³¹ (α is checked
/// so); the mask says so.
#[inline(always)]
fn filter_step(st: &mut StageState, x: i32, gain: u32) {
    let diff = x.saturating_sub(filter_output(st));
    let twice = (gain & 0x7fff_ffff) << 1;
    match i32::try_from(twice) {
        // Every cut-off below the detector rate over 2π (α < ½): one signed
        // multiply-accumulate.
        Ok(g) => st.acc = mul_acc(st.acc, diff, g),
        Err(_) => st.acc += i64::from(diff) * i64::from(twice),
    }
}

/// `acc + a · b`, exactly (|a · b| ≤ 2⁶², and the callers' sums are shown to fit). In Rust
/// it is what the chip's SMLAL does, and the compiler writes that instruction whenever it
/// sees both factors as 32-bit signed numbers; but a generated tick names one cut-off's gain
/// in several features, and the compiler then keeps it in a register as a 64-bit number
/// whose sign it no longer knows, and multiplies as if it were unsigned and 64 bits wide
/// (five instructions where one does). On the chip it is that one instruction, written out.
#[inline(always)]
fn mul_acc(acc: i64, a: i32, b: i32) -> i64 {
    #[cfg(smlal)]
    {
        let (mut lo, mut hi) = (acc as u32, (acc >> 32) as u32);
        // SAFETY: SMLAL reads and writes the four registers named, and nothing else: no
        // memory, no stack, no flags.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "smlal {lo}, {hi}, {a}, {b}",
                lo = inout(reg) lo,
                hi = inout(reg) hi,
                a = in(reg) a,
                b = in(reg) b,
                options(pure, nomem, nostack, preserves_flags),
            );
        }
        ((u64::from(hi) << 32) | u64::from(lo)) as i64
    }
    #[cfg(not(smlal))]
    {
        acc + i64::from(a) * i64::from(b)
    }
}

/// A filter's output: its state's upper word.
#[inline(always)]
fn filter_output(st: &StageState) -> i32 {
    (st.acc >> 32) as i32
}

/// `x · gain >> 16` exactly, for a 16.16 `gain`: the gain's whole part and its fraction
/// apart. The product of a whole number is exact, so for a gain such as −1 or 4 the
/// compiler of a generated tick drops the fraction's multiplication and the shift, and a
/// unit gain leaves one saturating addition. |x · gain| < 2^62: the sum fits.
#[inline(always)]
fn scale_q16(x: i32, gain: i32) -> i64 {
    let (whole, fraction) = (i64::from(gain >> 16), i64::from(gain & 0xffff));
    i64::from(x) * whole + ((i64::from(x) * fraction) >> 16)
}

/// Saturates to the `i32` range. The test is whether the upper word is the lower word's sign
/// (one `teq` on the chip, where a clamp compares both ends as 64-bit numbers), and a value
/// out of range takes its bound from its sign: `MAX ^ (v >> 63)` is `MAX` for a positive one
/// and `MIN` for a negative one.
#[inline(always)]
fn sat32(v: i64) -> i32 {
    let low = v as i32;
    if i64::from(low) == v {
        low
    } else {
        i32::MAX ^ (v >> 63) as i32
    }
}

/// Fills `taps` with a symmetric triangular window in Q24 summing to exactly 2²⁴.
fn triangular(taps: &mut [u32]) {
    let n = taps.len() as u64;
    // Unnormalized h(m) = (N + 1) − |2m − (N − 1)|, all positive.
    let raw = |m: u64| (n + 1) - (2 * m).abs_diff(n - 1);
    let total: u64 = (0..n).map(raw).sum();
    let mut given = 0u64;
    for (m, tap) in taps.iter_mut().enumerate() {
        let w = (raw(m as u64) << 24) / total;
        *tap = w as u32;
        given += w;
    }
    // Rounding leaves a few units short of 2^24: give them to the centre tap.
    if let Some(centre) = taps.get_mut((n / 2) as usize) {
        *centre += ((1u64 << 24) - given) as u32;
    }
}

/// Seeds for [`isqrt32`]: √ of the middle of each 2²⁴-wide slice of [2³⁰, 2³²), within
/// 129 of the root anywhere in the slice, so that one Newton step lands on the root or one
/// above it.
const SQRT_SEEDS: [u16; 192] = [
    32896, 33150, 33402, 33652, 33900, 34147, 34392, 34635, 34876, 35116, 35354, 35590, 35825,
    36059, 36291, 36521, 36750, 36978, 37204, 37429, 37652, 37874, 38095, 38315, 38533, 38750,
    38966, 39181, 39394, 39606, 39818, 40028, 40237, 40445, 40652, 40857, 41062, 41266, 41469,
    41671, 41871, 42071, 42270, 42468, 42665, 42861, 43057, 43251, 43445, 43637, 43829, 44020,
    44210, 44400, 44588, 44776, 44963, 45149, 45334, 45519, 45703, 45886, 46069, 46250, 46431,
    46612, 46791, 46970, 47149, 47326, 47503, 47679, 47855, 48030, 48204, 48378, 48551, 48723,
    48895, 49067, 49237, 49407, 49577, 49746, 49914, 50082, 50249, 50416, 50582, 50747, 50912,
    51077, 51241, 51404, 51567, 51730, 51892, 52053, 52214, 52374, 52534, 52694, 52853, 53011,
    53169, 53327, 53484, 53640, 53797, 53952, 54108, 54262, 54417, 54571, 54724, 54877, 55030,
    55182, 55334, 55485, 55636, 55787, 55937, 56087, 56236, 56385, 56534, 56682, 56830, 56977,
    57124, 57271, 57417, 57563, 57709, 57854, 57999, 58143, 58287, 58431, 58574, 58717, 58860,
    59002, 59144, 59286, 59427, 59568, 59709, 59849, 59989, 60129, 60268, 60407, 60546, 60684,
    60822, 60960, 61098, 61235, 61372, 61508, 61644, 61780, 61916, 62051, 62186, 62321, 62456,
    62590, 62724, 62857, 62991, 63124, 63256, 63389, 63521, 63653, 63785, 63916, 64047, 64178,
    64309, 64439, 64569, 64699, 64828, 64957, 65086, 65215, 65344, 65472,
];

/// ⌊√n⌋ for a 32-bit `n`: `n` shifted left by an even count into [2³⁰, 2³²), its root
/// there ([`normal_root`]), shifted back.
#[inline]
fn isqrt32(n: u32) -> u32 {
    if n == 0 {
        return 0;
    }
    let shift = n.leading_zeros() & !1;
    // ⌊⌊√m⌋ / 2^k⌋ = ⌊√m / 2^k⌋ = ⌊√n⌋ for m = n · 2^(2k), k = shift / 2.
    normal_root(n << shift) >> (shift / 2)
}

/// ⌊√m⌋ for `m` in [2³⁰, 2³²): a seed from [`SQRT_SEEDS`], one Newton step with 32-bit
/// division (in hardware on the Cortex-M4), which leaves the root or one above it (the
/// step never falls below ⌊√m⌋, and overshoots by at most 129² / 2¹⁶ < 1), and a final
/// correction.
#[inline]
fn normal_root(m: u32) -> u32 {
    // m ≥ 2^30, so the index is 64..=255 and `min` only spares a bounds check.
    let mut x = u32::from(SQRT_SEEDS[((m >> 24) as usize).wrapping_sub(64).min(191)]);
    // x ≥ 2^15, so the division never meets zero.
    x = (x + m.checked_div(x).unwrap_or(0)) / 2;
    if u64::from(x) * u64::from(x) > u64::from(m) {
        x -= 1;
    }
    x
}

/// √n for a 64-bit `n`, within a relative 2⁻¹⁵ of ⌊√n⌋ (exact below 2³²): from 2³² on, its
/// top 32 bits after a shift left by an even count, whose root [`normal_root`] takes once
/// (the 32 bits are in [2³⁰, 2³²) already), shifted back.
#[inline]
pub(crate) fn isqrt64(n: u64) -> u32 {
    let (high, low) = ((n >> 32) as u32, n as u32);
    if high == 0 {
        return isqrt32(low);
    }
    let shift = high.leading_zeros() & !1; // even, at most 30
    // Bits 32 - shift .. 64 - shift of n; `low` goes in two steps, as a shift by 32 would.
    let m = (high << shift) | ((low >> 1) >> (31 - shift));
    // √n ≈ √m · 2^(16 - shift / 2).
    normal_root(m) << (16 - shift / 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::num::Signal;

    fn run(spec: StageSpec<u8>, inputs: &[&[f64]]) -> Vec<f64> {
        let mut weights = [0u32; WINDOW_POOL];
        let mut used = 0;
        let stage = Stage::compile(&spec, 1000.0, &mut used, &mut weights).expect("valid stage");
        let mut st = stage.fresh_state();
        let mut ring = [0u64; WINDOW_POOL];
        (0..inputs[0].len())
            .map(|k| {
                let mut values = [0i32; MAX_SLOTS];
                for (v, c) in values.iter_mut().zip(inputs) {
                    *v = Signal::from_f64(c[k]).to_bits();
                }
                Signal::from_bits(stage.update(&mut st, &values, &mut ring, &weights)).to_f64()
            })
            .collect()
    }

    /// Every 32-bit input (a minute in release: `cargo test --release -p detector-core --
    /// --ignored isqrt32_exhaustive`).
    #[test]
    #[ignore]
    fn isqrt32_exhaustive() {
        for n in 0..=u32::MAX {
            let r = u64::from(isqrt32(n));
            assert!(
                r * r <= u64::from(n) && (r + 1) * (r + 1) > u64::from(n),
                "n = {n}"
            );
        }
    }

    #[test]
    fn isqrt_is_floor_below_2_pow_32_and_close_above() {
        let is_floor = |n: u64| {
            let r = isqrt64(n) as u64;
            r * r <= n && (r + 1) * (r + 1) > n
        };
        for n in [0u64, 1, 2, 3, 4, 15, 16, 17, 1 << 20, (1 << 32) - 1] {
            assert!(is_floor(n), "n = {n}");
        }
        // Every seed slice's ends and middle, at every even shift, and around every square
        // of a sparse sweep of roots (the correction step's edge).
        for shift in (0..32).step_by(2) {
            for k in 64u64..=256 {
                for m in [(k << 24) - 1, k << 24, (k << 24) + (1 << 23)] {
                    let n = (m >> shift).min(u32::MAX as u64);
                    assert!(is_floor(n), "n = {n}");
                }
            }
        }
        for r in (1u64..65536).step_by(7) {
            for n in [r * r - 1, r * r, r * r + r, (r + 1) * (r + 1) - 1] {
                assert!(is_floor(n.min(u32::MAX as u64)), "n = {n}");
            }
        }
        for n in [1u64 << 32, 1 << 40, u64::MAX / 3, u64::MAX] {
            let exact = (n as f64).sqrt();
            let r = isqrt64(n) as f64;
            assert!(
                r <= exact + 1.0 && (exact - r) / exact < 1.0 / 32768.0,
                "n = {n}"
            );
        }
    }

    /// The prediction may exceed the signal range while the difference does not, or
    /// overshoot it on the other side: only the difference saturates.
    #[test]
    fn cancel_saturates_the_difference_only() {
        let cancel = |gain: f32| StageSpec::Cancel {
            input: 0,
            motion: 1,
            gain,
            cutoff_hz: 10.0,
        };
        let (floor, ceiling) = (Signal::MIN.to_f64(), Signal::MAX.to_f64());
        // 20000 − 2·30000 = −40000: the floor, not 20000 − 32768.
        assert_eq!(
            run(cancel(2.0), &[&[20000.0; 3], &[30000.0; 3]]),
            [floor; 3]
        );
        assert_eq!(
            run(cancel(-2.0), &[&[-20000.0; 3], &[30000.0; 3]]),
            [ceiling; 3]
        );
        // 30000 − 2·20000 = −10000 lies inside although the prediction, 40000, does not.
        assert_eq!(
            run(cancel(2.0), &[&[30000.0; 3], &[20000.0; 3]]),
            [-10000.0; 3]
        );
    }

    #[test]
    fn low_pass_starts_at_the_first_sample_and_settles() {
        let x = [2.0; 200];
        let y = run(
            StageSpec::LowPass {
                input: 0,
                cutoff_hz: 50.0,
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            },
            &[&x],
        );
        assert_eq!(y[0], 2.0);
        assert!((y[199] - 2.0).abs() < 1e-4);
        let mut step = vec![0.0; 1];
        step.extend([1.0; 300]);
        let y = run(
            StageSpec::LowPass {
                input: 0,
                cutoff_hz: 50.0,
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            },
            &[&step],
        );
        // α = 0.239: the warm-up's 1/n weighs more for the 2nd to 4th samples, so y is
        // the mean so far (½, ⅔, ¾), then α takes over.
        let alpha = 1.0 / (1.0 + 1000.0 / (2.0 * std::f64::consts::PI * 50.0));
        for (k, mean) in [(1, 0.5), (2, 2.0 / 3.0), (3, 0.75)] {
            assert!((y[k] - mean).abs() < 1e-4, "{k}: {} vs {mean}", y[k]);
        }
        let next = 0.75 + alpha * 0.25;
        assert!((y[4] - next).abs() < 1e-4, "{} vs {next}", y[4]);
        assert!((y[300] - 1.0).abs() < 2.0 / 65536.0);
    }

    /// The warm-up's end, worked out once from α, is the last sample whose plain-mean gain
    /// [`mean_gain`] is still above α, for coefficients from the smallest to the largest.
    #[test]
    fn the_warm_up_ends_where_the_mean_gain_falls_to_alpha() {
        let gain = |n: u32| (f64::from(i32::MAX) / f64::from(n)).floor() as u32;
        for alpha in [
            1u32,
            32_767,
            32_768,
            65_536,
            3_000_000,
            13_400_000,
            (1 << 30) - 1,
            1 << 30,
            (1 << 31) - 1,
        ] {
            let end = u32::from(mean_gain_samples(alpha));
            if end < u32::from(WARM_LIMIT) {
                assert!(
                    gain(end) > alpha && gain(end + 1) <= alpha,
                    "α {alpha}: {end}"
                );
            } else {
                assert!(gain(end) > alpha, "α {alpha}: {end}");
            }
        }
        assert_eq!(
            mean_gain_samples(u32::MAX),
            0,
            "a corrupt α ends it at once"
        );
    }

    /// A warm-up limited to `warm_up_ms` is the plain mean of that many samples, then the
    /// filter at its cut-off: what comes after is not averaged in at the mean's weight.
    #[test]
    fn low_pass_warm_up_ends_after_its_limit() {
        // 1 Hz at 1 kHz: α = 0.0062, below 1/n for the first 160 samples.
        let spec = |warm_up_ms| StageSpec::LowPass {
            input: 0,
            cutoff_hz: 1.0,
            warm_up_ms,
            warm_up_until: None,
            warm_up_longer: None,
        };
        let mut x = vec![0.0; 10];
        x.extend([100.0; 30]);
        let limited = run(spec(Some(10.0)), &[&x]);
        let unlimited = run(spec(None), &[&x]);
        let alpha = 1.0 / (1.0 + 1000.0 / (2.0 * std::f64::consts::PI));
        // The first ten samples: the mean (zero) either way.
        assert_eq!(limited[9], 0.0);
        assert_eq!(unlimited[9], 0.0);
        // Then the limited filter forgets at α, the unlimited one still at 1/n.
        let expected = 100.0 * (1.0 - (1.0 - alpha).powi(30));
        assert!(
            (limited[39] - expected).abs() < 1e-3,
            "{} vs {expected}",
            limited[39]
        );
        assert!((unlimited[39] - 75.0).abs() < 1e-3, "{}", unlimited[39]);
    }

    /// A watched feature rising above its level ends the warm-up's plain mean: what comes
    /// after is learnt at α, as after `warm_up_ms`. Before it rises, and on the first
    /// sample, the mean goes on.
    #[test]
    fn low_pass_warm_up_ends_when_its_watched_feature_rises() {
        // 1 Hz at 1 kHz: α = 0.0062, below 1/n for the first 160 samples.
        let spec = StageSpec::LowPass {
            input: 0,
            cutoff_hz: 1.0,
            warm_up_ms: None,
            warm_up_until: Some(Crossing {
                feature: 1,
                above: 0.5,
            }),
            warm_up_longer: None,
        };
        let mut x = vec![0.0; 10];
        x.extend([100.0; 30]);
        let alpha = 1.0 / (1.0 + 1000.0 / (2.0 * std::f64::consts::PI));
        // The watched input rises with the step (exactly 0.5 is not above the level).
        let mut rises = vec![0.5; 10];
        rises.extend([1.0; 30]);
        let ended = run(spec.clone(), &[&x, &rises]);
        assert_eq!(ended[9], 0.0);
        let expected = 100.0 * (1.0 - (1.0 - alpha).powi(30));
        assert!(
            (ended[39] - expected).abs() < 1e-3,
            "{} vs {expected}",
            ended[39]
        );
        // Never above its level: the plain mean of all 40 samples.
        let quiet = run(spec.clone(), &[&x, &[0.0; 40]]);
        assert!((quiet[39] - 75.0).abs() < 1e-3, "{}", quiet[39]);
        // Above it from the first sample: the first sample still sets the output.
        let at_once = run(spec, &[&[3.0; 2], &[1.0; 2]]);
        assert_eq!(at_once[0], 3.0);
    }

    /// A longer warm-up is taken on what its watched feature reads on the tick after the
    /// shorter one's last sample, and on that tick only: 2 samples, or 4 when the watched
    /// input is above its level then (exactly the level is not above it), whatever it reads
    /// before or after. The longer mean is ended early by `warm_up_until` as the shorter
    /// one is.
    #[test]
    fn low_pass_warm_up_goes_on_when_its_watched_feature_is_above() {
        // 1 Hz at 1 kHz: α = 0.0062, below 1/n for the first 160 samples.
        let spec = |until| StageSpec::LowPass {
            input: 0,
            cutoff_hz: 1.0,
            warm_up_ms: Some(2.0),
            warm_up_until: until,
            warm_up_longer: Some(LongerWarmUp {
                feature: 1,
                above: 0.5,
                warm_up_ms: 4.0,
            }),
        };
        let alpha = 1.0 / (1.0 + 1000.0 / (2.0 * std::f64::consts::PI));
        let x = [1.0, 3.0, 5.0, 7.0, 9.0];
        let short = [1.0, 2.0, 2.0 + 3.0 * alpha, 0.0, 0.0];
        let long = [1.0, 2.0, 3.0, 4.0, 4.0 + 5.0 * alpha];
        let close = |got: &[f64], want: &[f64], n: usize| {
            for k in 0..n {
                assert!((got[k] - want[k]).abs() < 1e-3, "tick {k}: {got:?}");
            }
        };
        for (watched, want, n) in [
            ([0.0; 5], &short, 3),
            ([1.0, 1.0, 0.5, 1.0, 1.0], &short, 3),
            ([0.0, 0.0, 0.6, 0.0, 0.0], &long, 5),
            ([1.0; 5], &long, 5),
        ] {
            close(&run(spec(None), &[&x, &watched]), want, n);
        }
        // Where the filter's own weight ends the mean first (α = 1/3 at 1 kHz: after 2
        // samples), there is nothing to carry on: the stage is the one without it.
        let fast = |longer| StageSpec::LowPass {
            input: 0,
            cutoff_hz: 1000.0 / (4.0 * std::f32::consts::PI),
            warm_up_ms: Some(5.0),
            warm_up_until: None,
            warm_up_longer: longer,
        };
        let compile = |spec| {
            let mut weights = [0u32; WINDOW_POOL];
            Stage::compile(&spec, 1000.0, &mut 0, &mut weights).expect("valid stage")
        };
        let watched = LongerWarmUp {
            feature: 1,
            above: 0.5,
            warm_up_ms: 10.0,
        };
        assert_eq!(compile(fast(Some(watched))), compile(fast(None)));
        // Nor does a loaded image say otherwise: a stage that carries nothing on watches
        // nothing.
        let StageKind::LowPass { warm, .. } = compile(fast(None)).0 else {
            unreachable!()
        };
        for (longer, watch, watch_above) in
            [(warm - 1, 0, i32::MAX), (warm, 1, i32::MAX), (warm, 0, 5)]
        {
            let kind = StageKind::LowPass {
                input: 0,
                alpha: 1 << 29,
                warm,
                until: 0,
                until_above: i32::MAX,
                longer,
                watch,
                watch_above,
            };
            assert_eq!(
                kind.invalid(MAX_SLOTS),
                Some("low-pass warm-up"),
                "{kind:?}"
            );
        }
        // Ended early while carried on: from the fourth sample the filter forgets at α.
        let until = Some(Crossing {
            feature: 2,
            above: 0.5,
        });
        let ends = [0.0, 0.0, 0.0, 1.0, 0.0];
        let got = run(spec(until), &[&x, &[1.0; 5], &ends]);
        close(&got, &[1.0, 2.0, 3.0, 3.0 + 4.0 * alpha], 4);
    }

    /// The gain taken apart into its whole part and its fraction scales exactly as the
    /// whole product shifted down: every sign, the extremes, whole and fractional gains.
    #[test]
    fn scaling_by_parts_is_the_whole_product() {
        let values = [
            i32::MIN,
            i32::MIN + 1,
            -65_537,
            -65_536,
            -1,
            0,
            1,
            65_535,
            i32::MAX,
        ];
        let gains = [
            i32::MIN + 1,
            -6_553_600,
            -229_376,
            -65_536,
            -983,
            -1,
            0,
            1,
            983,
            65_535,
            65_536,
            262_144,
            8_692,
            i32::MAX,
        ];
        for x in values {
            for gain in gains {
                assert_eq!(
                    scale_q16(x, gain),
                    (i64::from(x) * i64::from(gain)) >> 16,
                    "{x} · {gain}"
                );
            }
        }
    }

    /// The low-pass output lies between its input and its last output, so it needs no
    /// saturation: full-range jumps, every α from the smallest to the largest.
    #[test]
    fn low_pass_stays_between_its_input_and_its_last_output() {
        let mut seed = 0x2545_f491_u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        let extremes = [i32::MIN, i32::MIN + 1, -1, 0, 1, i32::MAX - 1, i32::MAX];
        for alpha in [1, 2, 1 << 20, 1 << 30, (1 << 31) - 2, (1 << 31) - 1] {
            let mut st = StageState::default();
            let mut last = low_pass(&mut st, 0, alpha, WARM_LIMIT);
            for k in 0..20_000 {
                let x = if k % 3 == 0 {
                    extremes[next() as usize % extremes.len()]
                } else {
                    next() as i32
                };
                let y = low_pass(&mut st, x, alpha, WARM_LIMIT);
                assert_eq!(
                    i64::from(y),
                    st.acc >> 32,
                    "alpha {alpha}: the state left the range"
                );
                assert_eq!(
                    st.acc & 1,
                    0,
                    "alpha {alpha}: the state is not a doubled Q31 one"
                );
                assert!(
                    (last.min(x)..=last.max(x)).contains(&y),
                    "alpha {alpha}: {last} -> {y} for input {x}"
                );
                last = y;
            }
        }
    }

    #[test]
    fn rate_scales_by_the_detector_rate() {
        let y = run(StageSpec::Rate { input: 0 }, &[&[1.0, 1.5, 1.25]]);
        assert_eq!(y, vec![0.0, 500.0, -250.0]);
    }

    #[test]
    fn vector_stages() {
        let dot = run(
            StageSpec::Dot {
                a: [0, 1],
                b: [2, 3],
            },
            &[&[3.0, -300.0], &[4.0, 0.0], &[-0.5, 300.0], &[0.25, 0.0]],
        );
        assert_eq!(dot, vec![-0.5, Signal::MIN.to_f64()]);
        let mag = run(
            StageSpec::Magnitude { of: [0, 1] },
            &[&[3.0, -0.003], &[-4.0, 0.004]],
        );
        assert_eq!(mag[0], 5.0);
        assert!((mag[1] - 0.005).abs() < 2.0 / 65536.0);
        let diff = run(
            StageSpec::Difference {
                a: 0,
                b: 1,
                gain: 1.0,
            },
            &[&[1.0, -30000.0], &[3.0, 30000.0]],
        );
        assert_eq!(diff, vec![-2.0, Signal::MIN.to_f64()]);
        // a − 0.7 b: 10 − 7 = 3; saturates low.
        let scaled = run(
            StageSpec::Difference {
                a: 0,
                b: 1,
                gain: 0.7,
            },
            &[&[10.0, -30000.0], &[10.0, 30000.0]],
        );
        // 0.7 in Q16.16 is 0.699997: 10 − 6.99997.
        assert!((scaled[0] - 3.0).abs() < 1e-4, "{scaled:?}");
        assert_eq!(scaled[1], Signal::MIN.to_f64());
        assert_eq!(
            run(StageSpec::Abs { input: 0 }, &[&[-1.5, 2.0]]),
            vec![1.5, 2.0]
        );
        assert_eq!(
            run(StageSpec::Positive { input: 0 }, &[&[-1.5, 2.0, 0.0]]),
            vec![0.0, 2.0, 0.0]
        );
    }

    #[test]
    fn ste_matches_its_definition() {
        let x: Vec<f64> = (0..40).map(|k| ((k * 7) % 11) as f64 - 5.0).collect();
        for shape in [Window::Rectangular, Window::Triangular] {
            let n = 8usize;
            let y = run(
                StageSpec::Ste {
                    input: 0,
                    window: n as u16,
                    shape,
                },
                &[&x],
            );
            let h: Vec<f64> = (0..n)
                .map(|m| match shape {
                    Window::Rectangular => 1.0,
                    Window::Triangular => (n + 1) as f64 - ((2 * m) as f64 - (n - 1) as f64).abs(),
                })
                .collect();
            // Before n samples, the rectangular window is the mean square of those that
            // have arrived; the triangular one counts the missing as zero.
            let total = |k: usize| match shape {
                Window::Rectangular => (k + 1).min(n) as f64,
                Window::Triangular => h.iter().sum(),
            };
            for k in 0..x.len() {
                let expect: f64 = (0..n)
                    .filter(|&m| m <= k)
                    .map(|m| x[k - m] * x[k - m] * h[m] / total(k))
                    .sum();
                assert!(
                    (y[k] - expect).abs() < 1e-3,
                    "{shape:?} k={k}: {} vs {expect}",
                    y[k]
                );
            }
        }
    }

    #[test]
    fn triangular_taps_sum_to_one() {
        for n in [1usize, 2, 3, 32, 64, 127, 128] {
            let mut taps = vec![0u32; n];
            triangular(&mut taps);
            assert_eq!(
                taps.iter().map(|&t| t as u64).sum::<u64>(),
                1 << 24,
                "n = {n}"
            );
            assert!(taps.iter().all(|&t| t > 0));
        }
    }

    /// An envelope starts at its first sample, whatever its sign, with no flag: a fresh
    /// state lifts to it at once and decays from there. From an all-zero state instead, a
    /// negative first sample would be lost.
    #[test]
    fn an_envelope_starts_at_its_first_sample_whatever_its_sign() {
        let spec = StageSpec::Envelope {
            input: 0,
            cutoff_hz: 50.0,
        };
        let mut weights = [0u32; WINDOW_POOL];
        let stage = Stage::compile(&spec, 1000.0, &mut 0, &mut weights).expect("valid stage");
        let feed = |mut st: StageState, xs: &[i32]| -> Vec<i32> {
            let mut ring = [0u64; WINDOW_POOL];
            xs.iter()
                .map(|&x| {
                    let mut values = [0i32; MAX_SLOTS];
                    values[0] = x;
                    stage.update(&mut st, &values, &mut ring, &[])
                })
                .collect()
        };
        for first in [i32::MIN, -5 << 16, -1, 0, 1, 7 << 16, i32::MAX] {
            // Then the least value, which only decays it.
            let ys = feed(stage.fresh_state(), &[first, i32::MIN, i32::MIN]);
            assert_eq!(ys[0], first);
            if first > i32::MIN + 1 {
                assert!(ys[1] < first && ys[1] > i32::MIN && ys[2] < ys[1], "{ys:?}");
            }
        }
        assert_eq!(feed(stage.fresh_state(), &[i32::MIN; 3]), [i32::MIN; 3]);
        let from_zero = feed(StageState::default(), &[-5 << 16]);
        assert!(from_zero[0] > -5 << 16, "{from_zero:?}");
        // Every other stage starts all zero.
        assert_eq!(
            Stage(StageKind::Abs(0)).fresh_state(),
            StageState::default()
        );
    }

    /// An image's gate whose leak is out of [0, 1] is refused, naming it; one within it
    /// reads back as written, shut on the same side of its level.
    #[test]
    fn an_image_gate_leaks_within_its_range() {
        use crate::image::Bytes;
        for below in [false, true] {
            for (leak, ok) in [
                (0, true),
                (1 << 16, true),
                (6554, true),
                (-1, false),
                ((1 << 16) + 1, false),
            ] {
                let stage = Stage(StageKind::Gate {
                    input: 0,
                    watch: 1,
                    level: -3 << 16,
                    below,
                    leak,
                });
                let mut w = Bytes(std::vec::Vec::new());
                stage.write_image(&mut w);
                let read = Stage::read_image(&mut Reader::new(&w.0), MAX_SLOTS);
                if ok {
                    assert_eq!(read, Ok(stage), "{leak} {below}");
                } else {
                    assert_eq!(read, Err(ImageError::Invalid("gate leak")), "{leak}");
                }
            }
        }
    }

    #[test]
    fn bad_stage_parameters() {
        let mut weights = [0u32; WINDOW_POOL];
        let mut used = 0;
        let mut compile = |s| Stage::compile(&s, 1000.0, &mut used, &mut weights);
        assert_eq!(
            compile(StageSpec::LowPass {
                input: 0,
                cutoff_hz: 600.0,
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            }),
            Err(StageError::Cutoff {
                cutoff_hz: 600.0,
                nyquist_hz: 500.0
            })
        );
        assert!(
            compile(StageSpec::LowPass {
                input: 0,
                cutoff_hz: f32::NAN,
                warm_up_ms: None,
                warm_up_until: None,
                warm_up_longer: None,
            })
            .is_err()
        );
        // 65,534 samples at 1 kHz are 65.534 s.
        for warm_up_ms in [0.0, -1.0, f32::NAN, f32::INFINITY, 65_535.0] {
            assert_eq!(
                compile(StageSpec::LowPass {
                    input: 0,
                    cutoff_hz: 1.0,
                    warm_up_ms: Some(warm_up_ms),
                    warm_up_until: None,
                    warm_up_longer: None,
                })
                .map_err(|e| matches!(e, StageError::WarmUp { max_ms, .. } if max_ms == 65_534.0)),
                Err(true),
                "{warm_up_ms}"
            );
        }
        for above in [f32::NAN, f32::INFINITY, 32_768.0, -32_768.0] {
            assert_eq!(
                compile(StageSpec::LowPass {
                    input: 0,
                    cutoff_hz: 1.0,
                    warm_up_ms: None,
                    warm_up_until: Some(Crossing { feature: 1, above }),
                    warm_up_longer: None,
                })
                .map_err(|e| matches!(e, StageError::Level { .. })),
                Err(true),
                "{above}"
            );
        }
        assert!(
            compile(StageSpec::LowPass {
                input: 0,
                cutoff_hz: 1.0,
                warm_up_ms: Some(65_534.0),
                warm_up_until: None,
                warm_up_longer: None,
            })
            .is_ok()
        );
        let gate = |leak| StageSpec::Gate {
            input: 0,
            unless: Shut::above(1, 0.0),
            leak,
        };
        for leak in [-0.1, 1.01, f32::NAN, f32::INFINITY, 1e-6] {
            assert!(
                matches!(compile(gate(leak)), Err(StageError::Leak { .. })),
                "{leak}"
            );
        }
        for leak in [0.0, 2e-5, 0.1, 1.0] {
            assert!(compile(gate(leak)).is_ok(), "{leak}");
        }
        assert_eq!(
            compile(StageSpec::Ste {
                input: 0,
                window: 0,
                shape: Window::Rectangular
            }),
            Err(StageError::WindowLength { window: 0 })
        );
        assert_eq!(
            compile(StageSpec::Ste {
                input: 0,
                window: MAX_WINDOW as u16 + 1,
                shape: Window::Rectangular
            }),
            Err(StageError::WindowLength {
                window: MAX_WINDOW as u16 + 1
            })
        );
        for _ in 0..2 {
            assert!(
                compile(StageSpec::Ste {
                    input: 0,
                    window: MAX_WINDOW as u16,
                    shape: Window::Triangular
                })
                .is_ok()
            );
        }
        assert_eq!(
            compile(StageSpec::Ste {
                input: 0,
                window: 1,
                shape: Window::Rectangular
            }),
            Err(StageError::WindowPool {
                needed: WINDOW_POOL + 1
            })
        );
    }
}
