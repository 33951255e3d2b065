//! Detector images: what the PC makes the chip loads to the same detector, and a corrupt
//! image is rejected with a reason, leaves the detector empty, and never panics.

use detector_build::Config;
use detector_core::image::{MAGIC, Section};
use detector_core::{Detector, ImageError, Inputs, Signal};
use proptest::prelude::*;

fn config() -> Config {
    Config::from_toml(fingertip::APPROACH_TOML).expect("approach config")
}

fn approach() -> Detector {
    detector_build::build(&config()).expect("builds")
}

fn approach_image() -> Vec<u8> {
    detector_build::compile(&config())
        .expect("compiles")
        .image()
}

#[test]
fn an_image_loads_to_the_detector_its_configuration_describes() {
    let config = config();
    let image = approach_image();
    assert_eq!(image, approach_image(), "compiling is deterministic");
    let mut loaded = Detector::empty();
    loaded.load_image(&image).expect("loads");
    assert_eq!(loaded, approach());
    assert_eq!(loaded.rate_hz(), config.rate_hz);
    let names =
        |list: &[detector_core::Name]| list.iter().map(|n| n.to_string()).collect::<Vec<_>>();
    assert_eq!(
        names(loaded.channels()),
        config
            .channels
            .iter()
            .map(|c| c.name.to_string())
            .collect::<Vec<_>>()
    );
    assert_eq!(
        loaded.channel_scales(),
        config.channels.iter().map(|c| c.scale).collect::<Vec<_>>()
    );
    assert_eq!(
        names(loaded.features()),
        config
            .features
            .iter()
            .map(|f| f.name.to_string())
            .collect::<Vec<_>>()
    );
    assert_eq!(
        names(loaded.events()),
        config
            .events
            .iter()
            .map(|e| e.name.to_string())
            .collect::<Vec<_>>()
    );
    assert_eq!(
        names(loaded.phases()),
        config
            .phases
            .iter()
            .map(|p| p.name.to_string())
            .collect::<Vec<_>>()
    );
    // Loading again in place gives the same detector, and it runs the same.
    let d = approach();
    loaded.load_image(&image).expect("loads again");
    assert_eq!(loaded, d);
    let (mut a, mut b) = (d.new_state(), loaded.new_state());
    let mut inputs = Inputs::default();
    let mut confirmed = 0;
    for k in 0..200u32 {
        inputs.samples[0] = Signal::from_f32(-0.01 * k as f32);
        inputs.samples[3] = Signal::from_f32(if k > 100 { 400.0 } else { 0.0 });
        inputs.samples[6] = Signal::from_f32(0.05);
        let out = d.tick(&mut a, k, &inputs);
        confirmed |= out.evaluated;
        assert_eq!(out, loaded.tick(&mut b, k, &inputs));
    }
    assert_ne!(confirmed, 0, "the comparison evaluated events");
}

#[test]
fn every_truncation_and_trailing_byte_is_rejected() {
    let image = approach_image();
    let mut d = approach();
    for n in 0..image.len() {
        let e = d
            .load_image(&image[..n])
            .expect_err("truncated image accepted");
        assert!(
            matches!(e, ImageError::Truncated | ImageError::Magic),
            "{n}: {e}"
        );
        assert_eq!(
            d,
            Detector::empty(),
            "a rejected image left something behind"
        );
    }
    let mut longer = image.clone();
    longer.push(0);
    assert_eq!(d.load_image(&longer), Err(ImageError::TrailingBytes));
    let mut old = image;
    old[3] = b'0';
    assert_eq!(d.load_image(&old), Err(ImageError::Magic));
}

#[test]
fn out_of_range_values_are_named() {
    let image = approach_image();
    // The magic, the rate section's tag, the rate; the channels section's tag, the count.
    let mut bad_rate = image.clone();
    bad_rate[5..9].copy_from_slice(&f32::NAN.to_le_bytes());
    let mut d = Detector::empty();
    assert_eq!(
        d.load_image(&bad_rate),
        Err(ImageError::Invalid("detector rate"))
    );
    let mut many_channels = image.clone();
    many_channels[10] = 200;
    assert_eq!(
        d.load_image(&many_channels),
        Err(ImageError::Invalid("channel count"))
    );
    let mut no_channels_tag = image;
    no_channels_tag[9] = Section::Phases as u8;
    assert_eq!(
        d.load_image(&no_channels_tag),
        Err(ImageError::Section("channels"))
    );
    assert_eq!(
        ImageError::Section("channels").to_string(),
        "the image's channels section is missing or out of place"
    );
    assert_eq!(
        ImageError::Invalid("detector rate").to_string(),
        "the image's detector rate is out of range"
    );
}

#[test]
fn windows_that_share_history_are_refused() {
    // The default's two 100-sample means follow its 24-sample STE in the history pool:
    // `accel_mean` at 124 (its offset, length and 2^24 / 100 as the image writes them).
    let image = approach_image();
    let recip = ((1u32 << 24) + 50) / 100;
    let at_124: Vec<u8> = [
        &124u16.to_le_bytes()[..],
        &100u16.to_le_bytes(),
        &recip.to_le_bytes(),
    ]
    .concat();
    let found: Vec<usize> = image
        .windows(at_124.len())
        .enumerate()
        .filter(|(_, w)| *w == at_124.as_slice())
        .map(|(i, _)| i)
        .collect();
    assert_eq!(found.len(), 1, "the window found once in the image");
    let mut d = Detector::empty();
    // Moved back onto `stress_mean`'s last 24 entries, or just past them.
    for (offset, expected) in [
        (100u16, Err(ImageError::Invalid("window placement"))),
        (123, Err(ImageError::Invalid("window placement"))),
        (156, Ok(())),
    ] {
        let mut moved = image.clone();
        moved[found[0]..found[0] + 2].copy_from_slice(&offset.to_le_bytes());
        assert_eq!(d.load_image(&moved), expected, "accel_mean at {offset}");
        if expected.is_err() {
            assert_eq!(
                d,
                Detector::empty(),
                "a rejected image left something behind"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 4096, ..ProptestConfig::default() })]

    /// Any corruption of a real image (a few bytes overwritten) either loads a detector
    /// that then ticks without panicking, or is rejected leaving the detector empty.
    #[test]
    fn corrupt_images_never_panic(edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
                                  samples in prop::collection::vec(any::<i32>(), 16)) {
        let mut image = approach_image();
        for (at, byte) in edits {
            let i = at.index(image.len());
            image[i] = byte;
        }
        let mut d = Detector::empty();
        match d.load_image(&image) {
            Ok(()) => {
                let mut state = d.new_state();
                let mut inputs = Inputs::default();
                for (s, v) in inputs.samples.iter_mut().zip(&samples) {
                    *s = Signal::from_bits(*v);
                }
                for k in 0..8 {
                    let out = d.tick(&mut state, k, &inputs);
                    prop_assert!(out.confidences.iter().all(|c| c.to_bits() <= 32768));
                }
            }
            Err(_) => prop_assert_eq!(&d, &Detector::empty()),
        }
    }

    /// Arbitrary bytes after a valid magic are rejected or load, never panic.
    #[test]
    fn arbitrary_images_never_panic(tail in prop::collection::vec(any::<u8>(), 0..600)) {
        let mut image = MAGIC.to_vec();
        image.extend(tail);
        let mut d = Detector::empty();
        let _ = d.load_image(&image);
    }
}
