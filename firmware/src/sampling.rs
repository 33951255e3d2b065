//! Sample scheduling: the numbering of the DMA's scans as detector ticks, lost scan
//! accounting, and the per-scan front end (calibration and rail watch).
//!
//! On the chip, TIM6 triggers one ADC scan of the [`ADC_CHANNELS`] per detector tick, and
//! the DMA writes the scans into a circular buffer of [`DMA_SCANS`] scans, one per half:
//! its half-transfer and transfer-complete interrupts come once per scan. At each, the
//! board hands the DMA's position (its remaining-transfers register) to
//! [`ScanProgress::on_dma`], which counts the scans completed: **tick numbers come from the
//! DMA's position**, so they cannot drift from the sample instants and never depend on
//! when a task woke up. The DMA interrupt runs above everything else and takes a
//! microsecond; it is never held back for a whole scan, so no position is missed.
//!
//! The detector task, woken per scan, reads the newest complete scan ([`ScanPicker`]): if it
//! fell behind, the scans it can no longer read (the ring holds two) are counted lost, and
//! it goes on from the DMA's count.
//!
//! Each scan goes through the front end: calibration, the rail watch ([`crate::rail`])
//! and the stuck-value watch ([`crate::stuck`]); a channel either watch flags is faulty.

use core::sync::atomic::{AtomicU8, AtomicU16, AtomicU32, Ordering};

use detector_core::{Signal, Tick};

use crate::calib::{ActiveCalibration, Calibration};
use crate::channel_set::ChannelSet;
use crate::rail::{RailLimits, RailMonitor};
use crate::stuck::{StuckLimits, StuckMonitor};
use crate::wiring::ADC_CHANNELS;

/// Analog channels per scan.
pub const SCAN_LEN: usize = ADC_CHANNELS.len();

/// Scans in the DMA's circular buffer: one per half, so the DMA interrupts once per scan.
pub const DMA_SCANS: usize = 2;

/// Samples (u16) in the circular DMA buffer.
pub const DMA_LEN: usize = DMA_SCANS * SCAN_LEN;

/// The DMA's progress through its circular buffer, counted in scans: written by the DMA's
/// interrupt (one writer), read by the detector task. Atomics only: no lock between the
/// two.
#[derive(Debug, Default)]
pub struct ScanProgress {
    /// The DMA's position at its last interrupt, `0..DMA_LEN`.
    pos: AtomicU16,
    /// Samples of the scan in progress already written, `0..SCAN_LEN`.
    partial: AtomicU8,
    /// Scans completed since the DMA started: the tick of the next scan, wrapping.
    scans: AtomicU32,
    /// The cycle count when each slot's latest scan was seen complete.
    done_at: [AtomicU32; DMA_SCANS],
}

impl ScanProgress {
    /// Nothing written yet.
    pub const fn new() -> ScanProgress {
        ScanProgress {
            pos: AtomicU16::new(0),
            partial: AtomicU8::new(0),
            scans: AtomicU32::new(0),
            done_at: [AtomicU32::new(0), AtomicU32::new(0)],
        }
    }

    /// From the DMA's interrupt: the DMA has `remaining` transfers left before it wraps
    /// (its CNDTR, `1..=DMA_LEN`), at cycle count `now`. Returns whether scans completed
    /// since the last call. Called more often than once per half buffer, as the DMA's
    /// interrupts are, it misses nothing.
    pub fn on_dma(&self, remaining: u16, now: u32) -> bool {
        let cap = DMA_LEN as u16;
        let pos = cap.wrapping_sub(remaining.min(cap)) % cap;
        let last = self.pos.swap(pos, Ordering::Relaxed);
        let written = (pos + cap - last) % cap;
        let partial = u16::from(self.partial.load(Ordering::Relaxed)) + written;
        let done = u32::from(partial / SCAN_LEN as u16);
        self.partial
            .store((partial % SCAN_LEN as u16) as u8, Ordering::Relaxed);
        if done == 0 {
            return false;
        }
        let scans = self.scans.load(Ordering::Relaxed).wrapping_add(done);
        // The newest complete scan's slot gets the time; an older one completed at the
        // same interrupt was already late.
        let slot = scans.wrapping_sub(1) as usize % DMA_SCANS;
        if let Some(at) = self.done_at.get(slot) {
            at.store(now, Ordering::Relaxed);
        }
        self.scans.store(scans, Ordering::Release);
        true
    }

    /// Scans completed so far: the tick of the scan the DMA writes next.
    pub fn completed(&self) -> Tick {
        self.scans.load(Ordering::Acquire)
    }

    /// The cycle count when scan `tick` was seen complete (while its slot holds it).
    pub fn completed_at(&self, tick: Tick) -> u32 {
        self.done_at
            .get(tick as usize % DMA_SCANS)
            .map_or(0, |a| a.load(Ordering::Relaxed))
    }
}

/// Which scan the detector reads next, and the scans it lost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ScanPicker {
    /// The tick of the first scan not yet read.
    next: Tick,
    lost: u32,
}

impl ScanPicker {
    /// Nothing read yet; the first scan is tick 0.
    pub const fn new() -> ScanPicker {
        ScanPicker { next: 0, lost: 0 }
    }

    /// With `completed` scans done, the tick of the scan to read now: the newest complete
    /// one (older unread ones are counted lost: their slots are being written again), or
    /// `None` when none is new.
    pub fn pick(&mut self, completed: Tick) -> Option<Tick> {
        let ahead = completed.wrapping_sub(self.next);
        if ahead == 0 || ahead as i32 <= 0 {
            return None;
        }
        self.lost = self.lost.saturating_add(ahead - 1);
        self.next = completed;
        Some(completed.wrapping_sub(1))
    }

    /// Whether scan `tick`, read while `completed` scans were done, may have been
    /// overwritten during the read: the scan after it completed, so the one after that
    /// may have started in its slot. Such a scan is counted lost.
    pub fn torn(&mut self, tick: Tick, completed: Tick) -> bool {
        let torn = completed.wrapping_sub(tick) > 1;
        if torn {
            self.lost = self.lost.saturating_add(1);
        }
        torn
    }

    /// Scans lost since boot (saturating).
    pub const fn lost(&self) -> u32 {
        self.lost
    }
}

/// One tick's analog inputs, calibrated: what the sampler hands the detector.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcSample {
    /// The tick of the scan.
    pub tick: Tick,
    /// The cycle count when the scan's conversion was seen complete (the DMA's interrupt):
    /// where the tick's lateness is measured from.
    pub converted_at: u32,
    /// Calibrated values, in [`ADC_CHANNELS`] order and units.
    pub values: [Signal; SCAN_LEN],
    /// Channels currently faulty (stuck at a rail or frozen mid-scale), by their place in
    /// [`ADC_CHANNELS`].
    pub faults: ChannelSet,
}

/// The per-channel processing of each scan: calibration, the rail watch and the
/// stuck-value watch.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrontEnd {
    calibration: [Calibration; SCAN_LEN],
    active: [ActiveCalibration; SCAN_LEN],
    limits: RailLimits,
    rails: [RailMonitor; SCAN_LEN],
    stuck_limits: StuckLimits,
    stuck: [StuckMonitor; SCAN_LEN],
}

impl FrontEnd {
    /// A front end with these calibrations, no temperature yet, rail limits for
    /// `rate_hz`, the default stuck-value window ([`StuckLimits::DEFAULT`]).
    pub fn new(calibration: [Calibration; SCAN_LEN], rate_hz: u32) -> FrontEnd {
        FrontEnd {
            calibration,
            active: calibration.map(|c| c.at(None)),
            limits: RailLimits::for_rate(rate_hz),
            rails: [RailMonitor::new(); SCAN_LEN],
            stuck_limits: StuckLimits::DEFAULT,
            stuck: [StuckMonitor::new(); SCAN_LEN],
        }
    }

    /// A new board temperature (°C), or `None` while the sensor is not answering, in
    /// which case the last compensation holds (temperature changes slowly).
    pub fn set_temperature(&mut self, temperature: Option<Signal>) {
        if let Some(t) = temperature {
            for (a, c) in self.active.iter_mut().zip(&self.calibration) {
                *a = c.at(Some(t));
            }
        }
    }

    /// One raw scan (ADC counts in [`ADC_CHANNELS`] order) taken at `tick`.
    #[inline]
    pub fn process(&mut self, tick: Tick, raw: &[u16; SCAN_LEN]) -> AdcSample {
        let mut sample = AdcSample {
            tick,
            ..AdcSample::default()
        };
        for (i, &counts) in raw.iter().enumerate() {
            // Indices are 0..SCAN_LEN on arrays of SCAN_LEN: the compiler drops the checks.
            if let (Some(v), Some(a), Some(r), Some(s)) = (
                sample.values.get_mut(i),
                self.active.get(i),
                self.rails.get_mut(i),
                self.stuck.get_mut(i),
            ) {
                *v = a.apply(counts);
                let at_rail = r.update(&self.limits, counts);
                let frozen = s.update(&self.stuck_limits, &self.limits, counts);
                if at_rail || frozen {
                    sample.faults.insert(i);
                }
            }
        }
        sample
    }

    /// Stuck-at-rail episodes since boot, all channels together (saturating).
    pub fn rail_episodes(&self) -> u32 {
        self.rails
            .iter()
            .fold(0u32, |n, r| n.saturating_add(r.episodes()))
    }

    /// Stuck-value episodes since boot, all channels together (saturating).
    pub fn stuck_episodes(&self) -> u32 {
        self.stuck
            .iter()
            .fold(0u32, |n, s| n.saturating_add(s.episodes()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::NOMINAL;

    /// Feeds `progress` the DMA's remaining count after `written` more samples.
    fn advance(progress: &ScanProgress, remaining: &mut u16, written: u16, now: u32) -> bool {
        let cap = DMA_LEN as u16;
        let pos = (cap - *remaining + written) % cap;
        *remaining = cap - pos;
        progress.on_dma(*remaining, now)
    }

    #[test]
    fn scans_are_counted_from_the_dmas_position() {
        let p = ScanProgress::new();
        let mut remaining = DMA_LEN as u16;
        // Each scan in two interrupts' worth of samples (a half-transfer comes mid-way
        // through no scan here, but the counting must not care), across many wraps.
        for k in 0..10_000u32 {
            assert!(!advance(&p, &mut remaining, 3, 10 * k));
            assert!(advance(&p, &mut remaining, 1, 10 * k + 5));
            assert_eq!(p.completed(), k + 1);
            assert_eq!(p.completed_at(k), 10 * k + 5);
        }
        // Two scans at one interrupt (a late interrupt): both counted, the newest stamped.
        assert!(advance(&p, &mut remaining, 2 * SCAN_LEN as u16 - 1, 7));
        assert_eq!(p.completed(), 10_001);
        assert!(advance(&p, &mut remaining, 1, 9));
        assert_eq!((p.completed(), p.completed_at(10_001)), (10_002, 9));
    }

    #[test]
    fn ticks_wrap_like_the_core_expects() {
        let p = ScanProgress::new();
        p.scans
            .store(u32::MAX, core::sync::atomic::Ordering::Relaxed);
        let mut remaining = DMA_LEN as u16;
        assert!(advance(&p, &mut remaining, SCAN_LEN as u16, 1));
        assert_eq!(p.completed(), 0);
        let mut picker = ScanPicker {
            next: u32::MAX,
            lost: 0,
        };
        assert_eq!(picker.pick(0), Some(u32::MAX));
    }

    #[test]
    fn the_picker_reads_the_newest_scan_and_counts_the_ones_it_missed() {
        let mut picker = ScanPicker::new();
        assert_eq!(picker.pick(0), None);
        assert_eq!(picker.pick(1), Some(0));
        assert_eq!(picker.pick(1), None, "nothing new");
        assert_eq!(picker.pick(2), Some(1));
        // Woken late: scans 2, 3 and 4 complete, 2 and 3 are gone.
        assert_eq!(picker.pick(5), Some(4));
        assert_eq!(picker.lost(), 2);
        // Read while the next scan completed: fine; two scans later: torn.
        assert!(!picker.torn(4, 5));
        assert!(picker.torn(4, 6));
        assert_eq!(picker.lost(), 3);
        assert_eq!(picker.pick(6), Some(5));
    }

    #[test]
    fn the_front_end_calibrates_and_flags_stuck_channels() {
        let mut fe = FrontEnd::new(NOMINAL, 5000);
        let s = fe.process(7, &[2048, 2048 + 205, 2048, 2048]);
        assert_eq!(s.tick, 7);
        assert_eq!(s.values[0], Signal::ZERO);
        assert!((s.values[1].to_f64() - 1.0).abs() < 0.01, "{}", s.values[1]);
        assert!(s.faults.is_empty());
        // stress_rate pinned at 0 counts: faulty after 50 ms, the others are not.
        let mut last = s;
        for t in 0..250 {
            last = fe.process(t, &[2048, 2048, 2048, 0]);
        }
        assert_eq!(last.faults, ChannelSet::from_bits(0b1000));
        assert_eq!(fe.rail_episodes(), 1);
        assert_eq!(fe.stuck_episodes(), 0, "a rail is the rail watch's alone");
    }

    #[test]
    fn a_channel_frozen_mid_scale_is_faulty_until_it_moves() {
        let mut fe = FrontEnd::new(NOMINAL, 5000);
        // force_y frozen at 2100 counts, the others live (a count of noise).
        let scan = |t: u32, y: u16| {
            let n = (t % 3) as u16;
            [2047 + n, y, 2048 + n, 2049 - n]
        };
        let mut faulty_from = None;
        for t in 0..1200 {
            let s = fe.process(t, &scan(t, 2100));
            if faulty_from.is_none() && !s.faults.is_empty() {
                faulty_from = Some(t);
                assert_eq!(s.faults, ChannelSet::from_bits(0b0010));
            }
        }
        assert_eq!(faulty_from, Some(999));
        assert_eq!((fe.stuck_episodes(), fe.rail_episodes()), (1, 0));
        // It moves again: healthy after eight changes.
        let mut faults = Vec::new();
        for t in 1201..1211 {
            faults.push(fe.process(t, &scan(t, 2100 + (t % 2) as u16)).faults);
        }
        assert!(
            faults[..7]
                .iter()
                .all(|f| *f == ChannelSet::from_bits(0b0010))
        );
        assert!(faults[7..].iter().all(|f| f.is_empty()));
        assert_eq!(fe.stuck_episodes(), 1);
    }

    #[test]
    fn temperature_compensates_the_force_zero_and_holds_without_a_reading() {
        let mut fe = FrontEnd::new(NOMINAL, 5000);
        fe.set_temperature(Some(Signal::from_f64(45.0)));
        // +20 °C: force zero moved 10 counts up.
        assert_eq!(
            fe.process(0, &[2058, 2058, 2048, 2048]).values[0],
            Signal::ZERO
        );
        fe.set_temperature(None);
        assert_eq!(
            fe.process(1, &[2058, 2058, 2048, 2048]).values[1],
            Signal::ZERO
        );
    }
}
