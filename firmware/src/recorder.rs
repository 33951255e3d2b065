//! The flight recorder: the detector's inputs tick by tick, as the core saw them, with
//! the detector's state at the start, frozen some time after a confirmation or a fault
//! and read out over the service channel, so that the PC replays what the chip did bit
//! for bit (`fingertip fetch-recording`).
//!
//! The ring is [`SEGMENTS`] segments of up to [`SEGMENT_MS`] each. A segment starts with
//! the detector's state saved before its first tick ([`State::save`], 3 KiB) and holds
//! one row per tick: the phase, the withheld channels, each channel's sample as the core
//! read it. When a segment is full the next begins, over the oldest. A confirmation, or
//! a channel going bad, arms the freeze: [`AFTER_MS`] later recording stops, and what the
//! segments hold stays until the tool reads it and re-arms the recorder. With three
//! segments of 50 ms, a frozen recording reaches at least 100 ms back from the freeze:
//! 50 ms before the trigger and 50 ms after it (with the default detector's 10 channels
//! at 5 kHz; a detector whose rows do not fit 50 ms in a segment gets shorter segments,
//! and [`RecordingInfo`] says how far back a recording goes).
//!
//! A recording is one run of one detector: a detector put in service, the service state
//! (which restarts the detector from a fresh state) or a skipped tick ends the run, and
//! the next starts with a new saved state; a run that ends after its trigger freezes then,
//! with what it holds.
//!
//! The readout ([`Recorder::read`]) is the saved state of the oldest segment kept, then
//! the rows of the kept segments, oldest first: docs/can-protocol.md gives the layout.

use core::cell::RefCell;

use detector_core::{DetectorTick, EventMask, Inputs, State, Tick};
use embassy_sync::blocking_mutex::Mutex;
use fingertip_can::service::{RecordingCause, RecordingInfo};

use crate::engine::Service;
use crate::shared::RawMutex;

/// Segments in the ring.
pub const SEGMENTS: usize = 3;
/// The longest a segment lasts, ms.
pub const SEGMENT_MS: u32 = 50;
/// How long after its trigger a recording freezes, ms.
pub const AFTER_MS: u32 = 50;
/// Bytes of rows a segment holds.
pub const SEGMENT_BYTES: usize = 12 * 1024;
/// Bytes of a row before its samples: the phase (`u8`) and the withheld channels (`u16`,
/// bit `i` for channel `i`).
pub const ROW_HEAD: usize = 3;

/// What the last tick of a running detector gave the recorder.
#[derive(Clone, Copy, Debug)]
pub struct Ticked<'a> {
    /// The tick.
    pub now: Tick,
    /// The detector rate, Hz.
    pub rate_hz: u32,
    /// Its image's CRC-32.
    pub crc: u32,
    /// Changes whenever the detector's state starts afresh (another detector, the
    /// service state left).
    pub generation: u32,
    /// The detector's channel count.
    pub channels: usize,
    /// The tick's inputs.
    pub inputs: &'a Inputs,
    /// The state after the tick (so before the next), its phase the tick's.
    pub state: &'a State,
    /// Events confirmed at this tick.
    pub confirmed: EventMask,
}

struct Segment {
    saved: [u8; State::SAVED_BYTES],
    /// The tick of its first row.
    start: Tick,
    rows: u16,
    data: [u8; SEGMENT_BYTES],
}

impl Segment {
    const EMPTY: Segment = Segment {
        saved: [0; State::SAVED_BYTES],
        start: 0,
        rows: 0,
        data: [0; SEGMENT_BYTES],
    };
}

/// The ring, the run and its trigger. Every field starts at zero, so that the board's
/// recorder (51 KiB) is zero-initialised memory, not an image in flash.
pub struct Recorder {
    segments: [Segment; SEGMENTS],
    /// The segment being filled.
    current: usize,
    /// Segments of the run kept, the current one included (0 before the first): a run is
    /// going on while some are and it is not frozen.
    kept: usize,
    /// Stopped; kept until re-armed.
    frozen: bool,
    /// The tick the run's next row is.
    next: Tick,
    crc: u32,
    generation: u32,
    rate_hz: u32,
    channels: u8,
    /// Rows a segment takes for this run's detector.
    segment_rows: u16,
    /// The withheld channels at the last tick (a fault's onset triggers).
    last_faults: u32,
    trigger: Trigger,
}

/// What armed the freeze, and when, in a form whose "nothing" is zero.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Trigger {
    /// 0 none, 1 a confirmation, 2 a fault.
    kind: u8,
    /// The event's index, or the channels that went bad.
    value: u16,
    /// Its tick.
    tick: Tick,
}

impl Trigger {
    const NONE: Trigger = Trigger {
        kind: 0,
        value: 0,
        tick: 0,
    };

    fn cause(self) -> Option<RecordingCause> {
        match self.kind {
            1 => Some(RecordingCause::Confirmed(self.value as u8)),
            2 => Some(RecordingCause::Fault(self.value)),
            _ => None,
        }
    }
}

impl Default for Recorder {
    fn default() -> Self {
        Recorder::new()
    }
}

impl Recorder {
    /// Empty and armed.
    pub const fn new() -> Recorder {
        Recorder {
            segments: [Segment::EMPTY, Segment::EMPTY, Segment::EMPTY],
            current: 0,
            kept: 0,
            frozen: false,
            next: 0,
            crc: 0,
            generation: 0,
            rate_hz: 0,
            channels: 0,
            segment_rows: 0,
            last_faults: 0,
            trigger: Trigger::NONE,
        }
    }

    /// Bytes of one row for `channels` channels.
    const fn row_bytes(channels: u8) -> usize {
        ROW_HEAD + 4 * channels as usize
    }

    /// After a tick of the detector in service (`None`: no detector ran, as in the
    /// service state): records it, and arms or carries out the freeze.
    pub fn record(&mut self, tick: Option<&Ticked<'_>>) {
        let Some(t) = tick else { return };
        if self.frozen {
            return;
        }
        let recording = self.kept > 0;
        let continues =
            recording && self.next == t.now && t.generation == self.generation && t.crc == self.crc;
        if !continues {
            if recording && self.trigger != Trigger::NONE {
                // The run ends before its freeze: what it holds around the trigger is kept.
                self.frozen = true;
            } else {
                self.begin(t);
            }
            return;
        }
        self.put_row(t);
        let faults = t.inputs.faults;
        if self.trigger == Trigger::NONE {
            let (kind, value) = if t.confirmed != 0 {
                (1, t.confirmed.trailing_zeros() as u16)
            } else if faults != 0 && self.last_faults == 0 {
                (2, faults as u16)
            } else {
                (0, 0)
            };
            if kind != 0 {
                self.trigger = Trigger {
                    kind,
                    value,
                    tick: t.now,
                };
            }
        }
        self.last_faults = faults;
        if self.trigger != Trigger::NONE
            && t.now.wrapping_sub(self.trigger.tick) >= self.rate_hz * AFTER_MS / 1000
        {
            self.frozen = true;
            return;
        }
        self.next = t.now.wrapping_add(1);
        if self.segments[self.current].rows >= self.segment_rows {
            self.current = (self.current + 1) % SEGMENTS;
            self.kept = (self.kept + 1).min(SEGMENTS);
            self.open_segment(t);
        }
    }

    /// A new run from tick `t`'s state: its first row is the next tick's.
    fn begin(&mut self, t: &Ticked<'_>) {
        let channels = t.channels.min(detector_core::MAX_CHANNELS) as u8;
        self.crc = t.crc;
        self.generation = t.generation;
        self.rate_hz = t.rate_hz;
        self.channels = channels;
        let fit = SEGMENT_BYTES / Recorder::row_bytes(channels);
        let per_ms = (t.rate_hz * SEGMENT_MS / 1000) as usize;
        self.segment_rows = fit.min(per_ms).clamp(1, usize::from(u16::MAX)) as u16;
        self.trigger = Trigger::NONE;
        self.last_faults = t.inputs.faults;
        self.current = 0;
        self.kept = 1;
        self.open_segment(t);
        self.next = t.now.wrapping_add(1);
    }

    /// Starts the current segment with the state after tick `t`.
    fn open_segment(&mut self, t: &Ticked<'_>) {
        let s = &mut self.segments[self.current];
        t.state.save(&mut s.saved);
        s.start = t.now.wrapping_add(1);
        s.rows = 0;
    }

    fn put_row(&mut self, t: &Ticked<'_>) {
        let n = usize::from(self.channels);
        let size = Recorder::row_bytes(self.channels);
        let s = &mut self.segments[self.current];
        let at = usize::from(s.rows) * size;
        let Some(row) = s.data.get_mut(at..at + size) else {
            return;
        };
        let (head, samples) = row.split_at_mut(ROW_HEAD);
        head[0] = t.state.phase().index();
        head[1..3].copy_from_slice(&(t.inputs.faults as u16).to_le_bytes());
        for (dst, v) in samples.chunks_exact_mut(4).zip(&t.inputs.samples[..n]) {
            dst.copy_from_slice(&v.to_bits().to_le_bytes());
        }
        s.rows += 1;
    }

    /// The kept segments, oldest first.
    fn kept_segments(&self) -> impl Iterator<Item = &Segment> {
        let oldest = (self.current + SEGMENTS + 1 - self.kept) % SEGMENTS;
        (0..self.kept).map(move |k| &self.segments[(oldest + k) % SEGMENTS])
    }

    /// What the recorder holds.
    pub fn info(&self) -> RecordingInfo {
        let rows: u32 = self.kept_segments().map(|s| u32::from(s.rows)).sum();
        let size = Recorder::row_bytes(self.channels) as u32;
        RecordingInfo {
            frozen: self.frozen,
            cause: self.trigger.cause(),
            trigger_tick: self.trigger.tick,
            first_tick: self.kept_segments().next().map_or(0, |s| s.start),
            rows,
            channels: self.channels,
            rate_hz: self.rate_hz,
            detector_crc: self.crc,
            bytes: if self.kept == 0 {
                0
            } else {
                State::SAVED_BYTES as u32 + rows * size
            },
        }
    }

    /// Copies the readout from byte `offset` into `out`, as much as fits and is left;
    /// returns the bytes copied (0 at the end). Only a frozen recording is read: one
    /// still recording changes under the reader.
    pub fn read(&self, offset: u32, out: &mut [u8]) -> Option<usize> {
        if !self.frozen {
            return None;
        }
        let size = Recorder::row_bytes(self.channels);
        let saved = self.kept_segments().next().map(|s| &s.saved[..]);
        let parts = saved.into_iter().chain(
            self.kept_segments()
                .map(|s| s.data.get(..usize::from(s.rows) * size).unwrap_or(&[])),
        );
        let mut skip = offset as usize;
        let mut copied = 0;
        for part in parts {
            if skip >= part.len() {
                skip -= part.len();
                continue;
            }
            let from = &part[skip..];
            skip = 0;
            let n = from.len().min(out.len() - copied);
            out[copied..copied + n].copy_from_slice(&from[..n]);
            copied += n;
            if copied == out.len() {
                break;
            }
        }
        Some(copied)
    }

    /// Drops what is held and records again from the next tick.
    pub fn rearm(&mut self) {
        self.frozen = false;
        self.kept = 0;
        self.trigger = Trigger::NONE;
    }
}

/// The recorder, shared by the detector task (which records) and the service channel
/// (which reads it out), under a critical section: a row is a few dozen bytes, and a
/// segment's saved state, once every [`SEGMENT_MS`], 3 KiB.
pub struct RecorderCell(Mutex<RawMutex, RefCell<Recorder>>);

impl Default for RecorderCell {
    fn default() -> Self {
        RecorderCell::new()
    }
}

impl RecorderCell {
    /// Empty and armed.
    pub const fn new() -> RecorderCell {
        RecorderCell(Mutex::new(RefCell::new(Recorder::new())))
    }

    /// Runs `f` on the recorder.
    pub fn with<R>(&self, f: impl FnOnce(&mut Recorder) -> R) -> R {
        self.0.lock(|r| f(&mut r.borrow_mut()))
    }

    /// From the detector task, after a tick's frames are queued: records the tick the
    /// detector in service ran, if it ran one.
    pub fn record<T: DetectorTick>(&self, service: &Service<'_, T>) {
        if let Service::Running(engine) = service {
            let ticked = engine.ticked();
            self.with(|r| r.record(ticked.as_ref()));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use detector_core::Signal;

    fn state_in_phase(detector: &detector_core::Detector) -> State {
        detector.new_state()
    }

    fn detector() -> detector_core::Detector {
        let config = detector_build::Config::from_toml(include_str!("../../configs/approach.toml"))
            .expect("parses");
        detector_build::build(&config).expect("builds")
    }

    /// Records ticks `from..to` with tick `k`'s force sample `k` and the channels `faults`
    /// withheld, confirming at `confirm_at`.
    fn feed_withheld(
        r: &mut Recorder,
        state: &State,
        ticks: core::ops::Range<Tick>,
        confirm_at: Option<Tick>,
        generation: u32,
        faults: u32,
    ) {
        for k in ticks {
            let mut inputs = Inputs {
                faults,
                ..Inputs::default()
            };
            inputs.samples[0] = Signal::from_bits(k as i32);
            r.record(Some(&Ticked {
                now: k,
                rate_hz: 5000,
                crc: 0xABCD,
                generation,
                channels: 10,
                inputs: &inputs,
                state,
                confirmed: if confirm_at == Some(k) { 0b100 } else { 0 },
            }));
        }
    }

    /// [`feed_withheld`] with every channel fed.
    fn feed(
        r: &mut Recorder,
        state: &State,
        ticks: core::ops::Range<Tick>,
        confirm_at: Option<Tick>,
        generation: u32,
    ) {
        feed_withheld(r, state, ticks, confirm_at, generation, 0);
    }

    fn first_samples(r: &Recorder) -> std::vec::Vec<i32> {
        let info = r.info();
        let mut all = std::vec![0u8; info.bytes as usize];
        let mut at = 0;
        while let Some(n) = r.read(at as u32, &mut all[at..(at + 52).min(info.bytes as usize)]) {
            if n == 0 {
                break;
            }
            at += n;
        }
        assert_eq!(at, info.bytes as usize, "paged reads give every byte");
        all[State::SAVED_BYTES..]
            .chunks_exact(ROW_HEAD + 40)
            .map(|row| i32::from_le_bytes(row[3..7].try_into().unwrap()))
            .collect()
    }

    #[test]
    fn a_confirmation_freezes_the_recording_after_its_time_keeping_the_time_before() {
        let d = detector();
        let state = state_in_phase(&d);
        let mut r = Recorder::new();
        feed(&mut r, &state, 0..2000, Some(1500), 0);
        let info = r.info();
        assert!(info.frozen);
        assert_eq!(info.cause, Some(RecordingCause::Confirmed(2)));
        assert_eq!(info.trigger_tick, 1500);
        // 50 ms after at 5 kHz: the last row is the trigger's tick + 250.
        let rows = first_samples(&r);
        assert_eq!(*rows.last().unwrap(), 1750);
        assert_eq!(info.first_tick as i32, rows[0]);
        // Consecutive ticks from the saved state on.
        assert!(rows.windows(2).all(|w| w[1] == w[0] + 1));
        // At least 50 ms before the trigger.
        assert!(
            info.first_tick <= 1500 - 250,
            "first tick {}",
            info.first_tick
        );
        assert_eq!(info.rows as usize, rows.len());
        // Frozen: later ticks change nothing.
        feed(&mut r, &state, 2000..2500, Some(2100), 0);
        assert_eq!(r.info(), info);
        // Re-armed: a new run, a new saved state.
        r.rearm();
        assert_eq!(
            r.read(0, &mut [0; 8]),
            None,
            "nothing to read while recording"
        );
        feed(&mut r, &state, 2500..2600, None, 0);
        let again = r.info();
        assert!(!again.frozen && again.cause.is_none());
        assert_eq!(again.first_tick, 2501);
        assert_eq!(again.rows, 99);
    }

    #[test]
    fn a_fault_onset_triggers_and_a_skipped_tick_or_a_new_detector_starts_a_new_run() {
        let d = detector();
        let state = state_in_phase(&d);
        let mut r = Recorder::new();
        feed(&mut r, &state, 0..400, None, 0);
        // A skipped tick (400 never ran).
        feed(&mut r, &state, 401..500, None, 0);
        assert_eq!(r.info().first_tick, 402);
        // Another detector generation.
        feed(&mut r, &state, 500..600, None, 1);
        assert_eq!(r.info().first_tick, 501);
        feed_withheld(&mut r, &state, 600..900, None, 1, 1 << 2);
        let info = r.info();
        assert!(info.frozen);
        assert_eq!(info.cause, Some(RecordingCause::Fault(1 << 2)));
        assert_eq!(info.trigger_tick, 600);

        // A run that ends 10 ms after its confirmation (a skipped tick) freezes there.
        r.rearm();
        feed(&mut r, &state, 1000..1400, Some(1350), 0);
        feed(&mut r, &state, 1401..1500, None, 0);
        let info = r.info();
        assert!(info.frozen);
        assert_eq!(info.cause, Some(RecordingCause::Confirmed(2)));
        assert_eq!((info.first_tick, info.rows), (1001, 399));
    }

    #[test]
    fn the_ring_keeps_the_newest_segments() {
        let d = detector();
        let state = state_in_phase(&d);
        let mut r = Recorder::new();
        feed(&mut r, &state, 0..4000, None, 0);
        assert!(!r.info().frozen);
        assert_eq!(
            r.info().rows,
            3 * 250 - 1,
            "three segments' worth, the newest partly"
        );
        feed(&mut r, &state, 4000..5200, Some(4900), 0);
        let rows = first_samples(&r);
        assert_eq!(*rows.last().unwrap(), 5150);
        assert!(rows.len() <= SEGMENTS * 250 && rows.len() > 2 * 250);
    }
}
