//! The fingertip detector's PC tool, as a library: the simulator, the trace format,
//! replay, scoring, plots, the identification of self-motion cancellations and the CAN
//! tools behind the `fingertip` command.

pub mod can_tools;
pub mod identify;
pub mod output;
pub mod plot;
pub mod replay;
pub mod score;
pub mod sim;
pub mod trace;

/// The paper's approach-phase detector, `configs/approach.toml`: the default configuration
/// of every tool, and the firmware's (built from the same file).
pub const APPROACH_TOML: &str = include_str!("../../configs/approach.toml");

/// A number as a person reads it in a message: plain in the everyday range, in scientific
/// notation far outside it, so that a huge input is never echoed with 300 digits.
pub fn readable(v: f64) -> String {
    if v == 0.0 || (1e-3..1e7).contains(&v.abs()) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}
