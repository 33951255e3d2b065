//! What the firmware is built with, and the detector it starts: the configuration
//! embedded by `build.rs` (postcard bytes of `configs/approach.toml`, validated at build
//! time), its checksum, and the CAN node id.

use detector_core::can::NodeId;
use detector_core::{Config, ConfigError, Detector};

mod consts {
    include!(concat!(env!("OUT_DIR"), "/build_consts.rs"));
}

pub use consts::{CONFIG_CHECKSUM, CONFIG_SOURCE, TRIGGER_CLOCKS, TRIGGER_RATE_MHZ};

/// The detector configuration, postcard-encoded by `build.rs`.
pub static CONFIG_POSTCARD: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/config.postcard"));

/// The node id the firmware was built for (`FINGERTIP_NODE_ID` at build time, 0..=15,
/// checked by `build.rs`).
pub const NODE_ID: NodeId = match NodeId::new(consts::NODE_ID) {
    Some(n) => n,
    None => panic!("build.rs checks the node id"),
};

/// The embedded configuration could not be used (cannot happen with a firmware built by
/// `build.rs`, which checks both; reported rather than assumed).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum BootError {
    /// The bytes do not decode as a configuration.
    Decode,
    /// The configuration decoded but does not build.
    Invalid(ConfigError),
}

impl core::fmt::Display for BootError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            BootError::Decode => write!(f, "the embedded configuration does not decode"),
            BootError::Invalid(e) => write!(f, "the embedded configuration is invalid: {e}"),
        }
    }
}

/// Decodes the embedded configuration.
pub fn config() -> Result<Config, BootError> {
    postcard::from_bytes(CONFIG_POSTCARD).map_err(|_| BootError::Decode)
}

/// Builds the detector from the embedded configuration.
///
/// Kept out of line so that its frame is gone before the tasks start. On the chip that
/// frame is the problem: the decoded [`Config`] is 11.7 KiB, and serde's decoding plus
/// `Detector::build` keep several copies of it and of the 8.4 KiB `Detector` on the
/// stack (about 62 KiB measured, far above the G431's RAM). Until the core can build a
/// detector in place from a compact encoding, this boots on the PC and in QEMU only
/// (see the README, "Size").
#[inline(never)]
pub fn load_detector() -> Result<Detector, BootError> {
    let config = config()?;
    Detector::build(&config).map_err(BootError::Invalid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checksum::crc32;

    #[test]
    fn the_embedded_configuration_is_the_approach_file() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../configs/approach.toml"
        ))
        .unwrap();
        if CONFIG_SOURCE == "configs/approach.toml" {
            assert_eq!(config().unwrap(), Config::from_toml(&text).unwrap());
        }
        let d = load_detector().unwrap();
        assert_eq!(d.rate_hz(), config().unwrap().rate_hz);
    }

    #[test]
    fn the_checksum_is_zlibs_crc32_of_the_bytes() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        assert_eq!(CONFIG_CHECKSUM, crc32(CONFIG_POSTCARD));
    }

    #[test]
    fn corrupt_bytes_are_reported() {
        let r: Result<Config, _> = postcard::from_bytes(&CONFIG_POSTCARD[..10]);
        assert!(r.is_err());
        assert_eq!(
            format!("{}", BootError::Decode),
            "the embedded configuration does not decode"
        );
    }

    #[test]
    fn the_trigger_period_is_the_configurations_rate() {
        use crate::trigger::TriggerPeriod;
        use crate::wiring::{MAX_RATE_ERROR_PPM, SAMPLE_TIMER_CLOCK_HZ};
        let rate = config().unwrap().rate_hz;
        let p = TriggerPeriod::new(SAMPLE_TIMER_CLOCK_HZ, rate, MAX_RATE_ERROR_PPM).unwrap();
        assert_eq!((p.clocks, p.actual_mhz), (TRIGGER_CLOCKS, TRIGGER_RATE_MHZ));
    }

    #[test]
    fn the_node_id_is_in_range() {
        assert!(NODE_ID.get() <= NodeId::MAX);
    }
}
