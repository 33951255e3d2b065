//! What a tick generated for one detector at build time (`Detector::to_rust`, feature `std`) is made
//! of: the arithmetic of eq. 14, shared with the interpreter ([`Detector::tick_into`]), and
//! the compiled forms its constants are written in. A generated tick computes bit for bit
//! what the interpreter computes for the detector it was generated from; it is not meant
//! to be written by hand.

pub use crate::cdf::{Cdf, Ramp, Shape};
pub use crate::detector::{Detector, Inputs, LevelParams, Output, State};
pub use crate::feature::Stage;
pub use crate::num::{Confidence, Tick};

/// A context product's starting value, 1 in Q15.
pub const ONE: u32 = 1 << 15;

/// One step of an event's context product: `acc · q` in Q15, rounded to nearest. Both are at
/// most 2¹⁵, so the result is too.
#[inline(always)]
pub const fn product(acc: u32, q: u32) -> u32 {
    (acc * q + (1 << 14)) >> 15
}

/// Eq. 14 from an event's context `product` (Q15) and the sum of its sensor terms'
/// weight (Q15) × ψ (Q15): product × min(1, Σ w ψ), rounded to nearest. Weights sum to at
/// most 2¹⁵ + 2, so the sum stays below 2³¹.
#[inline(always)]
pub const fn eq14(product: u32, weighted_sum: u32) -> Confidence {
    let sum = (weighted_sum + (1 << 14)) >> 15;
    let sum = if sum > 1 << 15 { 1 << 15 } else { sum };
    Confidence::from_bits_clamped((product * sum + (1 << 14)) >> 15)
}
