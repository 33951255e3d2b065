//! Detectors loaded at run time: a detector image received over the bus is checked
//! completely here, into a spare detector, before anything runs it; the engine then puts
//! it in service at a phase boundary ([`crate::engine::Engine::stage`]).
//!
//! The checks, in order, each refusal naming what was wrong and leaving the spare empty
//! (nothing half-loaded is ever handed on):
//!
//! 1. the loader's own (`Detector::load_image`): every tag, count, index, shift, level;
//! 2. the channel map against the board: every channel the detector names must be one the
//!    board feeds ([`crate::wiring::ALL_CHANNELS`]), since a channel nobody writes would
//!    sit at zero and look like a real measurement;
//! 3. the rate: within [`crate::wiring::MAX_RATE_ERROR_PPM`] of the sample timer's, which
//!    a detector cannot change.
//!
//! The CRC-32 of the image is computed here and reported back: the tool that sent it
//! compares it with its own.

use detector_core::{Detector, ImageError, Name};
use fingertip_can::service::{DetectorName, NAME_MAX};

use crate::checksum::crc32;
use crate::wiring::{ALL_CHANNELS, MAX_RATE_ERROR_PPM};

/// A detector checked and loaded, waiting for its phase boundary.
#[derive(Debug)]
pub struct Staged<'d> {
    /// The detector, loaded in place.
    pub detector: &'d mut Detector,
    /// The CRC-32 of its image.
    pub crc: u32,
    /// Its name as the sender gave it.
    pub name: DetectorName,
}

/// Why an image was not staged.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LoadError {
    /// No spare detector to load into: a staged one has not gone into service yet and
    /// the one it replaces has not come back.
    Busy,
    /// The name is longer than [`NAME_MAX`] bytes.
    Name,
    /// The loader rejected the image.
    Image(ImageError),
    /// The detector reads a channel the board does not feed.
    Channel(Name),
    /// The detector's rate is not the board's sample rate (Hz).
    Rate(f32),
}

impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LoadError::Busy => write!(f, "a detector is already waiting for its phase boundary"),
            LoadError::Name => write!(f, "the name is longer than {NAME_MAX} bytes"),
            LoadError::Image(e) => write!(f, "{e}"),
            LoadError::Channel(c) => write!(f, "channel `{c}` has no source on the board"),
            // Whole hertz: float formatting would cost the firmware 10 KiB of flash.
            LoadError::Rate(r) => write!(
                f,
                "rate {} Hz is not the board's sample rate",
                (*r + 0.5) as u32
            ),
        }
    }
}

/// Checks and loads images into its spare detector.
#[derive(Debug)]
pub struct Loader<'d> {
    spare: Option<&'d mut Detector>,
    /// The board's sample rate, Hz.
    rate_hz: f32,
}

impl<'d> Loader<'d> {
    /// A loader with `spare` to load into, for a board sampling at `rate_hz`.
    pub fn new(spare: &'d mut Detector, rate_hz: f32) -> Loader<'d> {
        Loader {
            spare: Some(spare),
            rate_hz,
        }
    }

    /// Whether it has a detector to load into.
    pub fn is_ready(&self) -> bool {
        self.spare.is_some()
    }

    /// Takes back a detector the engine no longer runs, as the next spare.
    pub fn give_back(&mut self, detector: &'d mut Detector) {
        self.spare = Some(detector);
    }

    /// Checks `image` completely and loads it into the spare detector, named `name`.
    /// On error the spare stays here, empty.
    pub fn stage(&mut self, name: &str, image: &[u8]) -> Result<Staged<'d>, LoadError> {
        let mut n = DetectorName::new();
        n.push_str(name).map_err(|_| LoadError::Name)?;
        let detector = self.spare.take().ok_or(LoadError::Busy)?;
        match check(detector, image, self.rate_hz) {
            Ok(()) => Ok(Staged {
                crc: crc32(image),
                detector,
                name: n,
            }),
            Err(e) => {
                self.spare = Some(detector);
                Err(e)
            }
        }
    }
}

/// Loads `image` into `detector` in place and checks it for a board sampling at
/// `rate_hz` (see the module's header); on error `detector` is left empty.
pub fn check(detector: &mut Detector, image: &[u8], rate_hz: f32) -> Result<(), LoadError> {
    let result = detector
        .load_image(image)
        .map_err(LoadError::Image)
        .and_then(|()| {
            if let Some(c) = detector
                .channels()
                .iter()
                .find(|c| !ALL_CHANNELS.contains(&c.as_str()))
            {
                return Err(LoadError::Channel(c.clone()));
            }
            // In single precision: the difference of two rates within a factor of two
            // is exact, and the products are rounded far below a ppm.
            let rate = detector.rate_hz();
            let error = (rate - rate_hz).abs();
            if error * 1e6 > MAX_RATE_ERROR_PPM as f32 * rate_hz {
                return Err(LoadError::Rate(rate));
            }
            Ok(())
        });
    if result.is_err() {
        *detector = Detector::empty();
    }
    result
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::boot::DETECTOR_IMAGE;

    /// The image of a small detector of the board's, other than the embedded one.
    pub(crate) fn small_image() -> Vec<u8> {
        image_of(SMALL)
    }

    fn image_of(toml: &str) -> Vec<u8> {
        let config = detector_build::Config::from_toml(toml).unwrap();
        detector_build::compile(&config).unwrap().image()
    }

    const SMALL: &str = r#"
        rate_hz = 5000.0
        channel = [{ name = "force_x", unit = "N" }]
        feature = [{ name = "push", stage = { raw = { input = "force_x" } } }]
        [[event]]
        name = "press"
        sensor = [{ feature = "push", weight = 1.0, cdf = { binary = { threshold = -0.5, above = false } } }]
        alert = { on = 0.5, off = 0.3 }
        confirm = { on = 0.75, off = 0.5 }
        [[phase]]
        name = "approach"
        events = ["press"]
    "#;

    #[test]
    fn a_good_image_is_staged_with_its_crc_and_name() {
        let mut spare = Box::new(Detector::empty());
        let mut loader = Loader::new(&mut spare, 5000.0);
        let s = loader.stage("approach", DETECTOR_IMAGE).unwrap();
        assert_eq!(s.crc, crc32(DETECTOR_IMAGE));
        assert_eq!(s.name.as_str(), "approach");
        assert!(!s.detector.events().is_empty());
        // Nothing to load into until a detector comes back.
        assert!(!loader.is_ready());
        assert_eq!(
            loader.stage("again", DETECTOR_IMAGE).err(),
            Some(LoadError::Busy)
        );
        loader.give_back(s.detector);
        assert!(loader.stage("again", DETECTOR_IMAGE).is_ok());
    }

    #[test]
    fn every_refusal_names_its_cause_and_keeps_the_spare_empty() {
        let mut spare = Box::new(Detector::empty());
        let mut loader = Loader::new(&mut spare, 5000.0);
        let mut bad = DETECTOR_IMAGE.to_vec();
        bad.truncate(bad.len() - 3);
        assert_eq!(
            loader.stage("cut", &bad).err(),
            Some(LoadError::Image(ImageError::Truncated))
        );
        let wrist = image_of(&SMALL.replace("force_x", "wrist_torque"));
        let e = loader.stage("wrist", &wrist).unwrap_err();
        assert_eq!(
            e,
            LoadError::Channel(Name::try_from("wrist_torque").unwrap())
        );
        assert!(e.to_string().contains("wrist_torque"));
        let slow = image_of(&SMALL.replace("rate_hz = 5000.0", "rate_hz = 2500.0"));
        assert_eq!(
            loader.stage("slow", &slow).err(),
            Some(LoadError::Rate(2500.0))
        );
        assert_eq!(
            loader
                .stage(&"n".repeat(NAME_MAX + 1), DETECTOR_IMAGE)
                .err(),
            Some(LoadError::Name)
        );
        // The spare is still there, and empty.
        assert!(loader.is_ready());
        assert_eq!(loader.spare.as_deref(), Some(&Detector::empty()));
        // A rate within 100 ppm is the board's.
        let near = image_of(&SMALL.replace("rate_hz = 5000.0", "rate_hz = 5000.4"));
        assert!(loader.stage("near", &near).is_ok());
    }
}
