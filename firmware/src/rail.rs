//! Stuck-at-rail detection for the analog channels.
//!
//! A broken wire, a dead amplifier or a shorted sensor pins an ADC input at 0 or at full
//! scale. A real signal can touch a rail too (a hard impact saturates the skin
//! accelerometer) but only briefly, so a channel is declared faulty when it has read
//! within a few counts of a rail for a sustained time (50 ms by default), and healthy
//! again after it has read clear of both rails for a while (10 ms). A channel pinned at a
//! rail carries no information about the quantity anyway, so feeding it to the detector
//! as faulty is honest even when the cause is a genuine overload.

use crate::calib::ADC_MAX;

/// When a channel counts as stuck, and when as recovered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RailLimits {
    /// Readings at or below this many counts are at the low rail.
    pub low: u16,
    /// Readings at or above this many counts are at the high rail.
    pub high: u16,
    /// Consecutive rail readings that make the channel faulty (≥ 1).
    pub trip_samples: u16,
    /// Consecutive clear readings that make a faulty channel healthy again (≥ 1).
    pub clear_samples: u16,
}

impl RailLimits {
    /// Readings within 4 counts of either rail of the 12-bit ADC; faulty after 50 ms at a
    /// rail, healthy after 10 ms clear, at the sample rate `rate_hz` (at least one
    /// sample each, at most 65535).
    pub fn for_rate(rate_hz: u32) -> RailLimits {
        let samples =
            |ms: u32| (rate_hz.saturating_mul(ms) / 1000).clamp(1, u32::from(u16::MAX)) as u16;
        RailLimits {
            low: 4,
            high: ADC_MAX - 4,
            trip_samples: samples(50),
            clear_samples: samples(10),
        }
    }

    /// Whether a reading of `counts` is at a rail.
    #[inline]
    pub fn at_rail(&self, counts: u16) -> bool {
        counts <= self.low || counts >= self.high
    }
}

/// One channel's rail watch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RailMonitor {
    /// Consecutive readings contradicting the current verdict.
    run: u16,
    stuck: bool,
    episodes: u32,
}

impl RailMonitor {
    /// A healthy channel.
    pub const fn new() -> RailMonitor {
        RailMonitor {
            run: 0,
            stuck: false,
            episodes: 0,
        }
    }

    /// Takes one reading; returns whether the channel is faulty after it.
    #[inline]
    pub fn update(&mut self, limits: &RailLimits, counts: u16) -> bool {
        let at_rail = limits.at_rail(counts);
        if at_rail == self.stuck {
            // The reading agrees with the verdict: any contrary run is broken.
            self.run = 0;
        } else {
            self.run = self.run.saturating_add(1);
            let needed = if self.stuck {
                limits.clear_samples
            } else {
                limits.trip_samples
            };
            if self.run >= needed.max(1) {
                self.stuck = at_rail;
                self.run = 0;
                if at_rail {
                    self.episodes = self.episodes.saturating_add(1);
                }
            }
        }
        self.stuck
    }

    /// Whether the channel is faulty.
    pub const fn is_stuck(&self) -> bool {
        self.stuck
    }

    /// Times the channel became faulty since boot (saturating).
    pub const fn episodes(&self) -> u32 {
        self.episodes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn limits() -> RailLimits {
        RailLimits::for_rate(5000)
    }

    #[test]
    fn limits_scale_with_rate() {
        let l = limits();
        assert_eq!((l.trip_samples, l.clear_samples), (250, 50));
        assert_eq!(RailLimits::for_rate(10).trip_samples, 1);
        assert_eq!(RailLimits::for_rate(10).clear_samples, 1);
        assert_eq!(RailLimits::for_rate(u32::MAX).trip_samples, u16::MAX);
    }

    #[test]
    fn a_channel_stuck_at_either_rail_trips_after_the_trip_time() {
        for rail in [0, 3, 4, 4091, 4095] {
            let mut m = RailMonitor::new();
            for i in 1..250 {
                assert!(
                    !m.update(&limits(), rail),
                    "rail {rail}: faulty after {i} samples"
                );
            }
            assert!(m.update(&limits(), rail), "rail {rail}");
            assert_eq!(m.episodes(), 1);
        }
    }

    #[test]
    fn brief_saturation_is_not_a_fault() {
        let mut m = RailMonitor::new();
        for _ in 0..20 {
            // 40 ms at the rail, then one real reading: never trips.
            for _ in 0..200 {
                assert!(!m.update(&limits(), 4095));
            }
            assert!(!m.update(&limits(), 2000));
        }
        assert_eq!(m.episodes(), 0);
    }

    #[test]
    fn recovery_needs_a_sustained_clear_run() {
        let mut m = RailMonitor::new();
        for _ in 0..250 {
            m.update(&limits(), 0);
        }
        assert!(m.is_stuck());
        // Clear readings interrupted by a rail reading restart the count.
        for _ in 0..49 {
            assert!(m.update(&limits(), 2048));
        }
        assert!(m.update(&limits(), 0));
        for _ in 0..49 {
            assert!(m.update(&limits(), 2048));
        }
        assert!(!m.update(&limits(), 2048));
        // A second episode is counted.
        for _ in 0..250 {
            m.update(&limits(), 4095);
        }
        assert_eq!(m.episodes(), 2);
    }

    #[test]
    fn readings_near_but_not_at_the_rail_are_fine() {
        let mut m = RailMonitor::new();
        for _ in 0..10_000 {
            assert!(!m.update(&limits(), 5));
            assert!(!m.update(&limits(), 4090));
        }
    }
}
