//! [`DetectorTick`]: one tick of a detector, run either by the interpreter
//! ([`Detector`](crate::Detector),
//! which runs any detector it has loaded) or by code generated for one detector at build
//! time (`detector_build::Compiled::to_rust`: its tables written in as constants).

use crate::num::{ChannelMask, Tick};
use crate::state::{Inputs, Output, State};

/// One tick of a detector, stage by stage (so a profiler can time each), and whole.
///
/// Both implementations compute bit for bit the same results for the detector a
/// generated tick was generated from. An engine pairs a tick with the
/// [`Detector`](crate::Detector) it
/// loaded (for names, phases and channel scales) and checks [`DetectorTick::image_crc`]
/// against that detector's image before it runs.
pub trait DetectorTick {
    /// The CRC-32 of the detector image this tick was generated with, or `None` for a tick
    /// that runs whatever detector it is given (the interpreter).
    fn image_crc(&self) -> Option<u32>;

    /// Stage 1: stores the samples and updates every feature, in order. Features run in
    /// every phase so they are warm when the phase changes.
    fn update_features(&self, state: &mut State, inputs: &Inputs);

    /// Stage 2: the confidence of every term of the active phase's events; terms reading a
    /// faulty channel get 0. Sets `evaluated`, `unjudgeable` and `degraded` in `out`.
    fn term_confidences(&self, state: &mut State, faults: ChannelMask, out: &mut Output);

    /// Stage 3: eq. 14 for every judgeable event of the active phase.
    fn combine(&self, state: &State, out: &mut Output);

    /// Stage 4: decision levels and onsets of the active phase's events; an unjudgeable
    /// event has every level lowered.
    fn decide(&self, state: &mut State, now: Tick, out: &mut Output);

    /// One whole tick into `out`, which is cleared first.
    #[inline(always)]
    fn tick_into(&self, state: &mut State, now: Tick, inputs: &Inputs, out: &mut Output) {
        out.clear();
        self.update_features(state, inputs);
        self.term_confidences(state, inputs.faults, out);
        self.combine(state, out);
        self.decide(state, now, out);
    }
}
