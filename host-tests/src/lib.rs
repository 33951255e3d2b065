//! The PC side of the fingertip detector.

pub mod can_tools;
pub mod plot;
pub mod reference;
pub mod replay;
pub mod score;
pub mod sim;
pub mod trace;

/// The paper's approach-phase detector, `configs/approach.toml`: the default configuration
/// of every tool, and the firmware's (built from the same file).
pub const APPROACH_TOML: &str = include_str!("../../configs/approach.toml");
