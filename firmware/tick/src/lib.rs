//! The detector the chip runs, generated at build time by `build.rs` from
//! `configs/approach.toml` (or the file `FINGERTIP_CONFIG` names): its image, which the
//! firmware loads in place at boot, and its tick with the tables written in as constants.
//!
//! It is a crate of its own so that the tick is compiled for speed (opt-level 3, the
//! workspace's `firmware` profile) while the rest of the firmware is compiled for size: the
//! tick runs every sample, the rest mostly waits. The generated code inlines into whatever
//! calls it, and code takes the optimization of the function it is inlined into, so
//! [`ApproachTick`]'s methods are never inlined: they are compiled here, at this crate's
//! level, whichever crate calls them. The QEMU program (`host-tests/qemu`) measures these
//! same functions, built with the same profile.
#![no_std]
#![forbid(unsafe_code)]

use detector_core::{ChannelMask, DetectorTick, Inputs, Output, State, Tick};

/// The detector's image (see `detector_core::image`), made by `build.rs`.
pub static IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/detector.image"));

/// The configuration file the image and the tick were generated from, as given (relative
/// to the workspace root).
pub const CONFIG_SOURCE: &str = env!("FINGERTIP_TICK_CONFIG_SOURCE");

mod generated {
    #![allow(missing_docs, clippy::all)]
    include!(concat!(env!("OUT_DIR"), "/detector_tick.rs"));
}

use generated::GeneratedTick;

/// The tick generated for [`IMAGE`]'s detector, its tables written in as constants: bit
/// for bit the interpreter's (`detector_core::Detector` as a [`DetectorTick`]), in about a
/// third of the instructions. It records the CRC-32 of [`IMAGE`]
/// ([`DetectorTick::image_crc`]); an engine refuses it for any other detector.
///
/// Each method is one function compiled in this crate (see the crate's documentation);
/// [`DetectorTick::tick_into`] runs the four stages as one.
#[derive(Clone, Copy, Debug, Default)]
pub struct ApproachTick;

impl DetectorTick for ApproachTick {
    fn image_crc(&self) -> Option<u32> {
        GeneratedTick.image_crc()
    }

    #[inline(never)]
    fn update_features(&self, state: &mut State, inputs: &Inputs) {
        GeneratedTick.update_features(state, inputs);
    }

    #[inline(never)]
    fn term_confidences(&self, state: &mut State, faults: ChannelMask, out: &mut Output) {
        GeneratedTick.term_confidences(state, faults, out);
    }

    #[inline(never)]
    fn combine(&self, state: &State, out: &mut Output) {
        GeneratedTick.combine(state, out);
    }

    #[inline(never)]
    fn decide(&self, state: &mut State, now: Tick, out: &mut Output) {
        GeneratedTick.decide(state, now, out);
    }

    #[inline(never)]
    fn tick_into(&self, state: &mut State, now: Tick, inputs: &Inputs, out: &mut Output) {
        GeneratedTick.tick_into(state, now, inputs, out);
    }
}
