//! Sample scheduling: the ADC trigger period, tick numbering of the DMA's scans, lost
//! sample accounting, and the per-scan front end (calibration and rail watch).
//!
//! On the chip, TIM6 triggers one ADC scan of the [`ADC_CHANNELS`] per detector tick, and
//! the DMA writes the scans into a circular buffer; the sampler task receives them a
//! half-buffer ([`BLOCK_SCANS`] scans) at a time. The hardware timer is the detector's
//! clock: ticks are numbered by counting scans, so they cannot drift from the sample
//! instants. When scans are lost (the DMA overwrote a half the task had not read yet),
//! the count is resynchronized from the system clock, which runs from the same crystal,
//! and the gap is counted as lost samples.
//!
//! Each scan goes through the front end: calibration, the rail watch ([`crate::rail`])
//! and the stuck-value watch ([`crate::stuck`]); a channel either watch flags is faulty.

use detector_core::{Signal, Tick};

use crate::calib::{ActiveCalibration, Calibration};
use crate::channel_set::ChannelSet;
use crate::rail::{RailLimits, RailMonitor};
use crate::stuck::{StuckLimits, StuckMonitor};
use crate::wiring::ADC_CHANNELS;

/// Analog channels per scan.
pub const SCAN_LEN: usize = ADC_CHANNELS.len();

/// Scans per DMA half-buffer: the sampler wakes once per block (1 ms at 5 kHz). Small
/// enough to keep the latency low, large enough that waking costs little.
pub const BLOCK_SCANS: usize = 5;

/// Samples (u16) in one DMA half-buffer.
pub const BLOCK_LEN: usize = BLOCK_SCANS * SCAN_LEN;

/// Samples (u16) in the circular DMA buffer: two halves.
pub const DMA_LEN: usize = 2 * BLOCK_LEN;

/// Numbers the scans with detector ticks and counts the ones lost.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickClock {
    /// Ticks per second.
    rate_hz: u32,
    /// The tick of the next scan to arrive.
    next: Tick,
    /// System time of tick 0, µs; `None` before the first block.
    origin_us: Option<u64>,
    /// A block was lost: the next one resynchronizes from the system clock.
    resync: bool,
    lost: u32,
}

impl TickClock {
    /// A clock for scans at `rate_hz` (≥ 1); the first scan is tick 0.
    pub const fn new(rate_hz: u32) -> TickClock {
        TickClock {
            rate_hz: if rate_hz == 0 { 1 } else { rate_hz },
            next: 0,
            origin_us: None,
            resync: false,
            lost: 0,
        }
    }

    /// `scans` new scans arrived, the last of them completed at about `now_us` (system
    /// time, µs). Returns the tick of the first of them; the others follow one tick apart.
    pub fn on_block(&mut self, scans: u32, now_us: u64) -> Tick {
        let span_us = u64::from(scans) * 1_000_000 / u64::from(self.rate_hz);
        let origin = *self.origin_us.get_or_insert_with(|| {
            // The block's first scan is tick 0.
            now_us.saturating_sub(span_us)
        });
        if self.resync {
            self.resync = false;
            // Where the block's first scan falls on the system clock, rounded to a tick.
            let first_us = now_us.saturating_sub(span_us).saturating_sub(origin);
            let first = (first_us * u64::from(self.rate_hz) + 500_000) / 1_000_000;
            let first = first as Tick; // Ticks wrap, as the core expects.
            let gap = first.wrapping_sub(self.next);
            // A gap that is "negative" (wake-up jitter made the estimate early) loses
            // nothing: keep counting from where we were.
            if (gap as i32) > 0 {
                self.lost = self.lost.saturating_add(gap);
                self.next = first;
            }
        }
        let first = self.next;
        self.next = self.next.wrapping_add(scans);
        first
    }

    /// The DMA overran the reader: some scans were lost; the next block resynchronizes.
    pub fn on_overrun(&mut self) {
        self.resync = true;
    }

    /// `n` scans were received but dropped downstream (the detector's queue was full);
    /// their ticks are gone.
    pub fn on_dropped(&mut self, n: u32) {
        self.lost = self.lost.saturating_add(n);
    }

    /// The tick the next scan will get.
    pub const fn next_tick(&self) -> Tick {
        self.next
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

/// The sampler task's work for one DMA block: tick numbering, calibration, the rail
/// watch, and the hand-over to the detector's queue.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sampler {
    /// Tick numbering and lost-scan accounting.
    pub clock: TickClock,
    /// Calibration and rail watch.
    pub front_end: FrontEnd,
}

impl Sampler {
    /// A sampler at `rate_hz` with these calibrations.
    pub fn new(calibration: [Calibration; SCAN_LEN], rate_hz: u32) -> Sampler {
        Sampler {
            clock: TickClock::new(rate_hz),
            front_end: FrontEnd::new(calibration, rate_hz),
        }
    }

    /// A block of [`BLOCK_SCANS`] scans, completed at about `now_us`, with the board
    /// temperature `temperature`; each calibrated sample goes to `queue`, which returns
    /// `false` when it is full (that tick is then lost and counted). Returns the tick of
    /// the block's last scan.
    pub fn on_block(
        &mut self,
        block: &[u16; BLOCK_LEN],
        now_us: u64,
        temperature: Option<Signal>,
        mut queue: impl FnMut(AdcSample) -> bool,
    ) -> Tick {
        let mut tick = self.clock.on_block(BLOCK_SCANS as u32, now_us);
        self.front_end.set_temperature(temperature);
        for scan in block.chunks_exact(SCAN_LEN) {
            let mut raw = [0u16; SCAN_LEN];
            raw.copy_from_slice(scan);
            if !queue(self.front_end.process(tick, &raw)) {
                self.clock.on_dropped(1);
            }
            tick = tick.wrapping_add(1);
        }
        tick.wrapping_sub(1)
    }

    /// The DMA overran the reader.
    pub fn on_overrun(&mut self) {
        self.clock.on_overrun();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calib::NOMINAL;

    #[test]
    fn ticks_count_scans_without_drift() {
        let mut c = TickClock::new(5000);
        // Blocks of 5 scans every 1 ms, with wake-up jitter up to 0.6 ms: tick numbers
        // depend on the count alone.
        let mut expected = 0;
        for k in 0..10_000u64 {
            let jitter = (k * 7919) % 600;
            let first = c.on_block(5, 1_000 + k * 1_000 + jitter);
            assert_eq!(first, expected);
            expected += 5;
        }
        assert_eq!(c.lost(), 0);
    }

    #[test]
    fn an_overrun_resynchronizes_from_the_clock_and_counts_the_gap() {
        let mut c = TickClock::new(5000);
        assert_eq!(c.on_block(5, 1_000), 0);
        assert_eq!(c.on_block(5, 2_000), 5);
        // Blocks at 3 and 4 ms were overwritten; the one completing at 5 ms arrives late,
        // at 5.3 ms.
        c.on_overrun();
        assert_eq!(c.on_block(5, 5_300), 22);
        // 10..20 lost, plus the 0.3 ms late wake-up read as 1.5 ticks → 2.
        assert_eq!(c.lost(), 12);
        assert_eq!(c.next_tick(), 27);
    }

    #[test]
    fn an_early_estimate_never_moves_the_count_back() {
        let mut c = TickClock::new(5000);
        c.on_block(5, 1_000);
        c.on_overrun();
        // The clock says the block is where we already are: nothing lost.
        assert_eq!(c.on_block(5, 1_900), 5);
        assert_eq!(c.lost(), 0);
        c.on_dropped(3);
        assert_eq!(c.lost(), 3);
    }

    #[test]
    fn ticks_wrap_like_the_core_expects() {
        let mut c = TickClock::new(5000);
        c.next = u32::MAX - 2;
        c.origin_us = Some(0);
        assert_eq!(c.on_block(5, 10), u32::MAX - 2);
        assert_eq!(c.next_tick(), 2);
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

    #[test]
    fn a_block_becomes_five_calibrated_samples_and_a_full_queue_loses_ticks() {
        let mut s = Sampler::new(NOMINAL, 5000);
        let mut block = [2048u16; BLOCK_LEN];
        block[SCAN_LEN] = 2048 + 205; // force_x of the second scan: +1 N
        let mut got = Vec::new();
        let last = s.on_block(&block, 1_000, None, |x| {
            got.push(x);
            true
        });
        assert_eq!(last, 4);
        assert_eq!(
            got.iter().map(|x| x.tick).collect::<Vec<_>>(),
            [0, 1, 2, 3, 4]
        );
        assert!((got[1].values[0].to_f64() - 1.0).abs() < 0.01);
        // The queue takes two and is full: three ticks lost, numbering goes on.
        let mut room = 2;
        let last = s.on_block(&block, 2_000, None, |_| {
            room -= 1;
            room >= 0
        });
        assert_eq!((last, s.clock.lost()), (9, 3));
        s.on_overrun();
        assert_eq!(s.on_block(&block, 5_000, None, |_| true), 24);
        assert_eq!(s.clock.lost(), 3 + 10);
    }
}
