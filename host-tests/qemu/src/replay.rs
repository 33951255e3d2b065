//! The replay loop both sides run: decode each record, call a step function (the tick, or
//! the four stages, timed or not), and digest the result.

use detector_core::{
    Detector, DetectorTick, Inputs, Level, MAX_EVENTS, Output, Signal, State, Tick,
};

use crate::digest::{Digest, Digester};
use crate::trace::{Segment, Trace};

/// Where a tick is in the trace, for the step function's bookkeeping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Position {
    /// Segment index.
    pub segment: u32,
    /// Record index inside the segment.
    pub record: u32,
}

/// What happened in one segment: for each event and level, the first record (relative to
/// the segment's start) at which it was raised, and how many times.
#[derive(Clone, Copy, Debug)]
pub struct SegmentReport<'a> {
    /// The segment.
    pub segment: Segment<'a>,
    /// Its index.
    pub index: u32,
    /// By event then level (alert, confirm): the first record index at which it was raised.
    pub first: [[Option<u32>; 2]; MAX_EVENTS],
    /// By event then level: how many times it was raised.
    pub raised: [[u32; 2]; MAX_EVENTS],
}

/// Replays every segment of `trace` with a fresh state each, calling `step` for every
/// tick and `on_segment` after each segment, and returns the digest of the whole run.
///
/// `step` must run one detector tick (as [`Detector::tick`] does) and return its output.
pub fn replay<'a, F, G>(
    detector: &Detector,
    trace: &Trace<'a>,
    mut step: F,
    mut on_segment: G,
) -> Digest
where
    F: FnMut(&mut State, Tick, &Inputs, Position) -> Output,
    G: FnMut(&SegmentReport<'a>),
{
    let channels = trace.channels().min(detector.channels().len());
    let mut digester = Digester::new();
    for (index, segment) in trace.segments().enumerate() {
        let index = index as u32;
        let mut state = detector.new_state();
        let mut report = SegmentReport {
            segment,
            index,
            first: [[None; 2]; MAX_EVENTS],
            raised: [[0; 2]; MAX_EVENTS],
        };
        let mut now = segment.start_tick();
        for (record, r) in (0u32..).zip(segment.records()) {
            let mut inputs = Inputs {
                faults: r.faults,
                ..Inputs::default()
            };
            for (s, &raw) in inputs.samples.iter_mut().zip(&r.samples).take(channels) {
                *s = Signal::from_bits(raw);
            }
            let out = step(
                &mut state,
                now,
                &inputs,
                Position {
                    segment: index,
                    record,
                },
            );
            digester.tick(detector, channels, &inputs, &state, &out);
            for d in &out.decisions {
                let level = match d.level {
                    Level::Alert => 0,
                    Level::Confirm => 1,
                };
                if let Some(e) = report.first.get_mut(usize::from(d.event.0)) {
                    e[level].get_or_insert(record);
                }
                if let Some(e) = report.raised.get_mut(usize::from(d.event.0)) {
                    e[level] += 1;
                }
            }
            now = now.wrapping_add(1);
        }
        on_segment(&report);
    }
    digester.digest()
}

/// The plain host-side step: [`Detector::tick`].
pub fn plain_tick(
    detector: &Detector,
) -> impl FnMut(&mut State, Tick, &Inputs, Position) -> Output + '_ {
    move |state, now, inputs, _| detector.tick(state, now, inputs)
}

/// One tick run stage by stage through the four stages of a [`DetectorTick`], exactly as
/// [`DetectorTick::tick_into`] composes them; a profiler times each call.
pub fn staged_tick(
    tick: &impl DetectorTick,
    state: &mut State,
    now: Tick,
    inputs: &Inputs,
) -> Output {
    let mut out = Output::default();
    tick.update_features(state, inputs);
    tick.term_confidences(state, inputs.faults, &mut out);
    tick.combine(state, &mut out);
    tick.decide(state, now, &mut out);
    out
}

/// A segment's one-line summary, as both sides print it: `segment <index> <name>
/// start=<tick> ticks=<n>` then, per event, the records at which its alert and confirm
/// levels were first raised (`-` if never) and how often.
pub struct SegmentLine<'r, 'a> {
    /// The segment's report.
    pub report: &'r SegmentReport<'a>,
    /// The detector, for event names.
    pub detector: &'r Detector,
}

impl core::fmt::Display for SegmentLine<'_, '_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let r = self.report;
        write!(
            f,
            "segment {} {} start={} ticks={}",
            r.index,
            r.segment.name(),
            r.segment.start_tick(),
            r.segment.ticks()
        )?;
        for (name, (first, raised)) in self
            .detector
            .events()
            .iter()
            .zip(r.first.iter().zip(&r.raised))
        {
            write!(f, " {name}=")?;
            for (k, level) in ["alert", "confirm"].iter().enumerate() {
                if k > 0 {
                    write!(f, ",")?;
                }
                match first[k] {
                    Some(at) => write!(f, "{level}@{at}x{}", raised[k])?,
                    None => write!(f, "{level}@-")?,
                }
            }
        }
        Ok(())
    }
}
