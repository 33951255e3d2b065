//! CAN nominal bit timing for the FDCAN, computed for a kernel clock and a bit rate.
//!
//! The HAL's own calculation aims at few time quanta (at most 10 per bit at 1 Mbit/s),
//! which from the 85 MHz kernel clock gives 5 quanta and a single-quantum resynchronization
//! jump. Here the bit gets as many quanta as the FDCAN's fields allow (prescaler 1 when
//! possible), the sample point sits where asked (87.5 % by default, CiA's recommendation),
//! and the resynchronization jump width equals phase segment 2, the most clock tolerance
//! the bit allows.

/// A bit timing in the FDCAN's terms (NBTP): the bit is `1 + seg1 + seg2` time quanta of
/// `prescaler` kernel clocks each.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BitTiming {
    /// Kernel clocks per time quantum, 1..=512.
    pub prescaler: u16,
    /// Propagation plus phase segment 1, time quanta, 1..=255 (the HAL's type limit; the
    /// register takes 256).
    pub seg1: u8,
    /// Phase segment 2, time quanta, 1..=128.
    pub seg2: u8,
    /// Resynchronization jump width, time quanta, 1..=seg2.
    pub sjw: u8,
}

impl BitTiming {
    /// Time quanta per bit.
    pub const fn quanta(&self) -> u32 {
        1 + self.seg1 as u32 + self.seg2 as u32
    }

    /// The sample point, per mille of the bit.
    pub const fn sample_point_permille(&self) -> u32 {
        (1 + self.seg1 as u32) * 1000 / self.quanta()
    }
}

/// No bit timing fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BitTimingError {
    /// The kernel clock is not a whole multiple of the bit rate with 4..=384 quanta per
    /// bit and a prescaler up to 512.
    NoDivisor {
        /// The kernel clock, Hz.
        clock_hz: u32,
        /// The bit rate, bit/s.
        bitrate: u32,
    },
    /// The sample point must be within 50.0 %..=95.0 % (500..=950 per mille).
    SamplePoint(u16),
}

const MAX_SEG1: u32 = 255;
const MAX_SEG2: u32 = 128;

/// The timing with the most quanta per bit (smallest prescaler) that divides `clock_hz`
/// exactly into `bitrate`, with the sample point nearest `sample_point_permille`.
/// `const`, so the firmware's timing is computed (and checked) at compile time.
pub const fn nominal(
    clock_hz: u32,
    bitrate: u32,
    sample_point_permille: u16,
) -> Result<BitTiming, BitTimingError> {
    let sp = sample_point_permille as u32;
    if sp < 500 || sp > 950 {
        return Err(BitTimingError::SamplePoint(sample_point_permille));
    }
    let no = BitTimingError::NoDivisor { clock_hz, bitrate };
    if bitrate == 0 || !clock_hz.is_multiple_of(bitrate) {
        return Err(no);
    }
    let clocks_per_bit = clock_hz / bitrate;
    let mut prescaler = 1u32;
    while prescaler <= 512 {
        let quanta = clocks_per_bit / prescaler;
        let fits = clocks_per_bit.is_multiple_of(prescaler)
            && quanta >= 4
            && quanta <= 1 + MAX_SEG1 + MAX_SEG2;
        if fits {
            // seg2 = round(quanta × (1 − sample point)), kept within both fields' ranges.
            let mut seg2 = (quanta * (1000 - sp) + 500) / 1000;
            if seg2 < 1 {
                seg2 = 1;
            }
            if seg2 > MAX_SEG2 {
                seg2 = MAX_SEG2;
            }
            if quanta > 1 + MAX_SEG1 + seg2 {
                seg2 = quanta - 1 - MAX_SEG1;
            }
            let seg1 = quanta - 1 - seg2;
            if seg1 >= 1 && seg1 <= MAX_SEG1 && seg2 <= MAX_SEG2 {
                let t = BitTiming {
                    prescaler: prescaler as u16,
                    seg1: seg1 as u8,
                    seg2: seg2 as u8,
                    sjw: seg2 as u8,
                };
                // The field limits may have pushed the sample point away: then fewer,
                // longer quanta (the next prescaler) do better.
                let got = t.sample_point_permille();
                let off = got.abs_diff(sp);
                if off * quanta <= 1000 {
                    return Ok(t);
                }
            }
        }
        prescaler += 1;
    }
    Err(no)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_megabit_from_85_mhz() {
        let t = nominal(85_000_000, 1_000_000, 875).unwrap();
        assert_eq!(
            t,
            BitTiming {
                prescaler: 1,
                seg1: 73,
                seg2: 11,
                sjw: 11
            }
        );
        assert_eq!(t.quanta(), 85);
        assert_eq!(t.sample_point_permille(), 870);
    }

    #[test]
    fn other_rates_and_clocks() {
        let t = nominal(85_000_000, 500_000, 875).unwrap();
        // 170 quanta at prescaler 1 fit (1 + 148 + 21).
        assert_eq!((t.prescaler, t.quanta()), (1, 170));
        let t = nominal(170_000_000, 125_000, 875).unwrap();
        assert_eq!(t.prescaler * t.quanta() as u16, 1360);
        assert!(t.quanta() <= 384 && t.seg2 <= 128);
        let t = nominal(80_000_000, 1_000_000, 800).unwrap();
        assert_eq!(
            t,
            BitTiming {
                prescaler: 1,
                seg1: 63,
                seg2: 16,
                sjw: 16
            }
        );
    }

    #[test]
    fn impossible_requests_are_refused() {
        assert_eq!(
            nominal(85_000_000, 1_500_000, 875),
            Err(BitTimingError::NoDivisor {
                clock_hz: 85_000_000,
                bitrate: 1_500_000
            })
        );
        assert!(nominal(85_000_000, 0, 875).is_err());
        assert_eq!(
            nominal(85_000_000, 1_000_000, 990),
            Err(BitTimingError::SamplePoint(990))
        );
        // 3 clocks per bit: too few quanta whatever the prescaler.
        assert!(nominal(3_000_000, 1_000_000, 875).is_err());
    }

    #[test]
    fn every_result_is_exact_and_within_the_fields() {
        for clock in [
            16_000_000u32,
            24_000_000,
            42_500_000,
            80_000_000,
            85_000_000,
            170_000_000,
        ] {
            for rate in [125_000u32, 250_000, 500_000, 1_000_000] {
                for sp in [750u16, 800, 875] {
                    if let Ok(t) = nominal(clock, rate, sp) {
                        assert_eq!(u32::from(t.prescaler) * t.quanta() * rate, clock);
                        assert!((1..=512).contains(&t.prescaler));
                        assert!(t.seg1 >= 1 && (1..=128).contains(&t.seg2));
                        assert!(t.sjw >= 1 && t.sjw <= t.seg2);
                        let err = t.sample_point_permille().abs_diff(u32::from(sp));
                        assert!(err * t.quanta() <= 1000, "{clock} {rate} {sp}: {t:?}");
                    }
                }
            }
        }
    }
}
