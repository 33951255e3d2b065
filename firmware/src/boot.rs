//! What the firmware is built with, and the detector it starts: the detector image made
//! by `build.rs` from `configs/approach.toml` (built and validated on the PC at build
//! time), its checksum, and the CAN node id.

use detector_core::can::NodeId;
use detector_core::{Detector, ImageError};

mod consts {
    include!(concat!(env!("OUT_DIR"), "/build_consts.rs"));
}

pub use consts::{CONFIG_CHECKSUM, CONFIG_SOURCE, TRIGGER_CLOCKS, TRIGGER_RATE_MHZ};

/// The built detector as an image (see `detector_core::image`), made by `build.rs`.
pub static DETECTOR_IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/detector.image"));

/// The node id the firmware was built for (`FINGERTIP_NODE_ID` at build time, 0..=15,
/// checked by `build.rs`).
pub const NODE_ID: NodeId = match NodeId::new(consts::NODE_ID) {
    Some(n) => n,
    None => panic!("build.rs checks the node id"),
};

/// Loads the embedded detector into `detector` (typically a static made with
/// [`Detector::empty`]), in place: the stack holds one event at a time, never a whole
/// detector or configuration. An error cannot happen with a firmware built by `build.rs`,
/// which loads the same bytes back, but is reported rather than assumed.
#[inline(never)]
pub fn load_detector(detector: &mut Detector) -> Result<(), ImageError> {
    detector.load_image(DETECTOR_IMAGE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::checksum::crc32;

    fn approach() -> Detector {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/approach.toml");
        let text = std::fs::read_to_string(path).unwrap();
        Detector::build(&detector_core::Config::from_toml(&text).unwrap()).unwrap()
    }

    #[test]
    fn the_embedded_detector_is_the_approach_files() {
        let mut d = Box::new(Detector::empty());
        load_detector(&mut d).unwrap();
        if CONFIG_SOURCE == "configs/approach.toml" {
            assert_eq!(*d, approach());
        }
        assert_eq!(d.to_image(), DETECTOR_IMAGE);
    }

    #[test]
    fn the_checksum_is_zlibs_crc32_of_the_bytes() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
        assert_eq!(CONFIG_CHECKSUM, crc32(DETECTOR_IMAGE));
    }

    #[test]
    fn a_corrupt_image_is_reported_and_leaves_nothing() {
        let mut d = Box::new(approach());
        assert_eq!(
            d.load_image(&DETECTOR_IMAGE[..10]),
            Err(ImageError::Truncated)
        );
        assert_eq!(*d, Detector::empty());
    }

    #[test]
    fn the_trigger_period_is_the_configurations_rate() {
        use crate::trigger::TriggerPeriod;
        use crate::wiring::{MAX_RATE_ERROR_PPM, SAMPLE_TIMER_CLOCK_HZ};
        let rate = approach().rate_hz();
        let p = TriggerPeriod::new(SAMPLE_TIMER_CLOCK_HZ, rate, MAX_RATE_ERROR_PPM).unwrap();
        assert_eq!((p.clocks, p.actual_mhz), (TRIGGER_CLOCKS, TRIGGER_RATE_MHZ));
    }

    #[test]
    fn the_node_id_is_in_range() {
        assert!(NODE_ID.get() <= NodeId::MAX);
    }
}
