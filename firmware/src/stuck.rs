//! Stuck-value detection for the analog channels: an input frozen mid-scale.
//!
//! A live channel is never perfectly still: its sensor's and amplifier's noise, and the
//! ADC's own, move its reading by a count now and then, however still the quantity it
//! measures. A reading that repeats the very same code for a long run means nothing moves
//! it any more (a buffered amplifier holding its output after its input wire broke, a
//! conversion that no longer follows its input). So a channel is declared faulty after
//! [`StuckLimits::trip_samples`] consecutive identical readings away from the rails
//! (readings at a rail are the rail watch's, [`crate::rail`]), and healthy again once it
//! has moved: after [`StuckLimits::clear_moves`] changes of value, so that a single
//! glitch on a frozen input (two changes: away and back) does not end the fault.
//!
//! The check needs the code to repeat exactly: an input held steady on which the ADC's
//! own noise still flips the last bit now and then is not caught by it.
//!
//! The window is a number of samples, not a time: what makes a false trip improbable is
//! the number of independent conversions that must all agree (see the crate's
//! documentation, "Faults", for the figures).

use crate::rail::RailLimits;

/// When a channel counts as stuck, and when as recovered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StuckLimits {
    /// Consecutive identical readings (away from the rails) that make the channel faulty
    /// (≥ 1).
    pub trip_samples: u16,
    /// Changes of value that make a faulty channel healthy again (≥ 1).
    pub clear_moves: u16,
}

impl StuckLimits {
    /// Faulty after 1000 identical readings in a row (200 ms at 5 kHz), healthy again
    /// after 8 changes of value.
    pub const DEFAULT: StuckLimits = StuckLimits {
        trip_samples: 1000,
        clear_moves: 8,
    };
}

/// One channel's stuck-value watch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StuckMonitor {
    /// The previous reading.
    last: u16,
    /// Consecutive readings equal to `last`, away from the rails (0 after a rail reading).
    same: u16,
    /// Changes of value since the channel became faulty (or froze again).
    moves: u16,
    stuck: bool,
    episodes: u32,
}

impl StuckMonitor {
    /// A healthy channel.
    pub const fn new() -> StuckMonitor {
        StuckMonitor {
            last: 0,
            same: 0,
            moves: 0,
            stuck: false,
            episodes: 0,
        }
    }

    /// Takes one reading; `rails` tells which readings belong to the rail watch (they
    /// break a run of identical readings). Returns whether the channel is faulty after
    /// it.
    #[inline]
    pub fn update(&mut self, limits: &StuckLimits, rails: &RailLimits, counts: u16) -> bool {
        let moved = counts != self.last;
        self.last = counts;
        self.same = if rails.at_rail(counts) {
            0
        } else if moved || self.same == 0 {
            1
        } else {
            self.same.saturating_add(1)
        };
        let frozen = self.same >= limits.trip_samples.max(1);
        if self.stuck {
            if frozen {
                // Frozen again before it had moved enough: start the count over.
                self.moves = 0;
            } else if moved {
                self.moves = self.moves.saturating_add(1);
                if self.moves >= limits.clear_moves.max(1) {
                    self.stuck = false;
                    self.moves = 0;
                }
            }
        } else if frozen {
            self.stuck = true;
            self.moves = 0;
            self.episodes = self.episodes.saturating_add(1);
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
    use proptest::prelude::*;

    const LIMITS: StuckLimits = StuckLimits::DEFAULT;

    fn rails() -> RailLimits {
        RailLimits::for_rate(5000)
    }

    /// Feeds `readings`; returns the verdict after each.
    fn feed(m: &mut StuckMonitor, readings: impl IntoIterator<Item = u16>) -> Vec<bool> {
        readings
            .into_iter()
            .map(|c| m.update(&LIMITS, &rails(), c))
            .collect()
    }

    #[test]
    fn a_channel_frozen_mid_scale_trips_after_the_window() {
        for value in [5, 1000, 2048, 4090] {
            let mut m = StuckMonitor::new();
            let verdicts = feed(&mut m, [value; 1000]);
            assert_eq!(
                verdicts.iter().position(|&v| v),
                Some(999),
                "value {value}: faulty at the 1000th identical reading"
            );
            assert_eq!(m.episodes(), 1);
            // Staying frozen is the same episode.
            assert!(feed(&mut m, [value; 5000]).iter().all(|&v| v));
            assert_eq!(m.episodes(), 1);
        }
    }

    #[test]
    fn readings_at_a_rail_are_left_to_the_rail_watch() {
        let mut m = StuckMonitor::new();
        for rail in [0, 4, 4091, 4095] {
            assert!(
                feed(&mut m, [rail; 3000]).iter().all(|&v| !v),
                "rail {rail}"
            );
        }
        // A rail reading breaks a run: 999 + rail + 999 never trips.
        let run = [2000; 999].into_iter().chain([4095]).chain([2000; 999]);
        assert!(feed(&mut m, run).iter().all(|&v| !v));
        assert_eq!(m.episodes(), 0);
    }

    #[test]
    fn it_recovers_once_it_moves_and_a_glitch_is_not_moving() {
        let mut m = StuckMonitor::new();
        feed(&mut m, [2100; 1000]);
        assert!(m.is_stuck());
        // One glitch away and back: two changes, still faulty.
        assert!(feed(&mut m, [2101, 2100]).iter().all(|&v| v));
        // Frozen again: the changes so far no longer count.
        feed(&mut m, [2100; 1000]);
        assert!(
            feed(&mut m, [2101, 2100, 2101, 2100, 2101, 2100, 2101])
                .iter()
                .all(|&v| v)
        );
        // The eighth change since it froze ends the fault.
        assert!(!m.update(&LIMITS, &rails(), 2102));
        assert_eq!(m.episodes(), 1);
        // A second freeze is a second episode.
        feed(&mut m, [2102; 1000]);
        assert!(m.is_stuck());
        assert_eq!(m.episodes(), 2);
    }

    #[test]
    fn a_degenerate_window_still_needs_one_reading() {
        let zero = StuckLimits {
            trip_samples: 0,
            clear_moves: 0,
        };
        let mut m = StuckMonitor::new();
        assert!(m.update(&zero, &rails(), 2048));
        assert!(!m.update(&zero, &rails(), 4095), "a rail reading is a move");
    }

    /// A small deterministic generator for the noise (xorshift64*).
    struct Noise(u64);

    impl Noise {
        fn unit(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }

        /// About normal, standard deviation 1 (sum of 12 uniforms).
        fn normal(&mut self) -> f64 {
            (0..12).map(|_| self.unit()).sum::<f64>() - 6.0
        }
    }

    proptest! {
        /// Whatever a channel reads, it is faulty only after a run of the window's length:
        /// readings whose identical runs are all shorter never trip.
        #[test]
        fn runs_shorter_than_the_window_never_trip(
            runs in prop::collection::vec((5u16..=4090, 1u16..1000), 1..40),
        ) {
            let mut m = StuckMonitor::new();
            let mut previous = None;
            for (value, len) in runs {
                // Successive runs differ, so each run is exactly `len` long.
                let value = if previous == Some(value) { value + 1 } else { value };
                previous = Some(value);
                for _ in 0..len {
                    prop_assert!(!m.update(&LIMITS, &rails(), value));
                }
            }
            prop_assert_eq!(m.episodes(), 0);
        }

        /// A live channel: any level mid-scale, drifting or still, with 0.3 count rms of
        /// noise (less than the ADC's own), for 10 s at 5 kHz: never faulty.
        #[test]
        fn a_noisy_live_channel_is_never_flagged(
            level in 100.0f64..3995.0,
            drift in -0.01f64..0.01,
            seed in 1u64..,
        ) {
            let mut m = StuckMonitor::new();
            let mut noise = Noise(seed);
            for k in 0..50_000 {
                let v = level + drift * f64::from(k) + 0.3 * noise.normal();
                let counts = v.round().clamp(0.0, 4095.0) as u16;
                prop_assert!(!m.update(&LIMITS, &rails(), counts), "faulty at sample {}", k);
            }
        }
    }
}
