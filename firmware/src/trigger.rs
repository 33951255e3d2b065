//! The ADC trigger timer's period for a detector rate: a whole number of timer clocks,
//! and how far the rate it makes is from the one asked for.
//!
//! Shared, as source, by the lib and by `build.rs`, which runs it on the configuration's
//! rate (failing the build when the timer cannot make it) and embeds the period, so the
//! chip does no rate arithmetic at boot. `core` only, so both can include it.

/// A sample rate the trigger timer cannot make.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum RateError {
    /// The rate is not finite and positive, or above the timer clock.
    OutOfRange {
        /// The requested rate, Hz.
        rate_hz: f32,
    },
    /// The nearest rate the timer makes is off by more than allowed.
    Inexact {
        /// The requested rate, Hz.
        rate_hz: f32,
        /// The error of the nearest rate, parts per million.
        error_ppm: u32,
    },
}

/// The ADC trigger timer's period for a detector rate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TriggerPeriod {
    /// Timer clocks per trigger (the timer counts this many clocks per period).
    pub clocks: u32,
    /// The rate this period makes, in mHz (millihertz).
    pub actual_mhz: u64,
    /// Its error against the requested rate, parts per million (rounded up).
    pub error_ppm: u32,
}

impl TriggerPeriod {
    /// The period nearest to `rate_hz` on a timer clocked at `timer_hz`; an error if its
    /// rate is off by more than `max_error_ppm`. Integer arithmetic (in millihertz) once
    /// the rate is read, so no soft-float `f64` code lands in the image.
    pub fn new(
        timer_hz: u32,
        rate_hz: f32,
        max_error_ppm: u32,
    ) -> Result<TriggerPeriod, RateError> {
        if !(rate_hz.is_finite() && rate_hz >= 0.001 && rate_hz <= timer_hz as f32) {
            return Err(RateError::OutOfRange { rate_hz });
        }
        // f32 holds every whole number of mHz below 16.7 kHz exactly, and rates up to
        // the core's 50 kHz to within 4 mHz.
        let rate_mhz = (rate_hz * 1000.0 + 0.5) as u64;
        let timer_mhz = u64::from(timer_hz) * 1000;
        let clocks = ((timer_mhz + rate_mhz / 2) / rate_mhz).clamp(1, u64::from(u32::MAX));
        // |timer − rate × clocks| / (rate × clocks), in ppm, rounded up.
        let made = rate_mhz * clocks;
        let diff = timer_mhz.abs_diff(made);
        let error_ppm = (diff * 1_000_000).div_ceil(made);
        let error_ppm = u32::try_from(error_ppm).unwrap_or(u32::MAX);
        if error_ppm > max_error_ppm {
            return Err(RateError::Inexact { rate_hz, error_ppm });
        }
        Ok(TriggerPeriod {
            clocks: clocks as u32,
            actual_mhz: (timer_mhz + clocks / 2) / clocks,
            error_ppm,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_rate_is_exact_on_the_170_mhz_timer() {
        let p = TriggerPeriod::new(170_000_000, 5000.0, 100).unwrap();
        assert_eq!(p.clocks, 34_000);
        assert_eq!(p.actual_mhz, 5_000_000);
        assert_eq!(p.error_ppm, 0);
    }

    #[test]
    fn inexact_and_impossible_rates_are_refused() {
        // 170 MHz / 7 kHz = 24285.71 clocks: 24286 gives 6999.918 Hz, 12 ppm off.
        let p = TriggerPeriod::new(170_000_000, 7000.0, 100).unwrap();
        assert_eq!(p.clocks, 24_286);
        assert_eq!(p.error_ppm, 12);
        assert_eq!(
            TriggerPeriod::new(170_000_000, 7000.0, 10),
            Err(RateError::Inexact {
                rate_hz: 7000.0,
                error_ppm: 12
            })
        );
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY, 2e8] {
            assert!(matches!(
                TriggerPeriod::new(170_000_000, bad, 100),
                Err(RateError::OutOfRange { .. })
            ));
        }
    }
}
