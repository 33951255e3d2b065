//! What a tick generated at build time (`detector_build::Compiled::to_rust`) is made of:
//! the steps of a tick one item at a time and the arithmetic of eq. 14 (shared with the
//! interpreter, [`Detector`](crate::Detector)), the compiled item types and the checked
//! `const fn`s its constants are written with, so a generated tick computes bit for bit
//! what the interpreter computes for the detector it was generated from. Not an API: it
//! changes with the generator.

pub use crate::cdf::{Cdf, Ramp, Shape};
pub use crate::expr::Rust;
pub use crate::feature::{Stage, StageKind};
pub use crate::num::{ChannelMask, Confidence, Tick};
pub use crate::state::{
    Inputs, LevelParams, ONE, Output, State, clear_psi, confirmed, decide_event, eq14, eval_psi,
    load_sample, mirror_psi, product, psi_value, reset_event, step_feature,
};
pub use crate::tick::DetectorTick;
