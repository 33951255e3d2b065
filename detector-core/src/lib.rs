#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
// One instruction is written in assembly, a filter step's multiply-accumulate on the chip
// (`feature::mul_acc`); nothing else is unsafe.
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod cdf;
pub mod detector;
mod expr;
pub mod feature;
pub mod image;
pub mod num;
pub mod state;
mod tick;

#[doc(hidden)]
#[path = "private.rs"]
pub mod __private;

pub use cdf::{Cdf, CdfError, CdfSpec};
pub use detector::{Detector, TermConfidences};
pub use feature::{Crossing, LongerWarmUp, Shut, Stage, StageError, StageSpec, Window};
pub use image::{ImageError, Sink};
pub use num::{ChannelMask, Confidence, EventMask, Signal, Tick};
pub use state::{
    Decision, Early, EventId, Inputs, Level, LevelParams, LevelState, Output, PhaseId, SAVED_MAGIC,
    State, StateError,
};
pub use tick::DetectorTick;

/// A name of a channel, feature, event or phase: 1 to [`NAME_LEN`] bytes.
pub type Name = heapless::String<NAME_LEN>;

/// Most input channels a configuration may declare.
pub const MAX_CHANNELS: usize = 16;
/// Most features a configuration may declare.
pub const MAX_FEATURES: usize = 128;
/// Most events a configuration may declare.
pub const MAX_EVENTS: usize = 8;
/// Most phases a configuration may declare.
pub const MAX_PHASES: usize = 8;
/// Most context terms, and most sensor terms, per event.
pub const MAX_TERMS: usize = 8;
/// Most distinct (feature, CDF) pairs among all events' terms together: terms that judge
/// the same feature with the same CDF, in one event or several, count once (and are
/// evaluated once per tick).
pub const MAX_DISTINCT_TERMS: usize = 64;
/// Longest name of a channel, feature, event or phase, in bytes.
pub const NAME_LEN: usize = 24;
/// Most an event's sensor weights may sum to, in Q15 (3, and three units of rounding): eq. 14
/// saturates the weighted sum at 1, so terms whose weights together exceed 1 are each
/// sufficient to the extent of their weight (three terms of weight 1 are each sufficient:
/// three paths to the same physical evidence). The weighted sum then stays below 2³².
pub const MAX_WEIGHT_SUM_Q15: u32 = 3 * (1 << 15) + 3;
/// Longest window of a short-time-energy or mean feature, in samples. All such features
/// together hold at most twice this much history.
pub const MAX_WINDOW: usize = 128;

const _: () = assert!(MAX_CHANNELS <= ChannelMask::BITS as usize);
const _: () = assert!(MAX_EVENTS <= EventMask::BITS as usize);
const _: () = assert!(MAX_CHANNELS + MAX_FEATURES <= u8::MAX as usize);
