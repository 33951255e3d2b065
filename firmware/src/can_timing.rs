//! CAN bit timing for the FDCAN, computed for a kernel clock and the bit rates of both
//! phases: nominal (arbitration) and data (CAN FD with bit-rate switching).
//!
//! The HAL's own calculation aims at few time quanta (at most 10 per bit at 1 Mbit/s),
//! which from the 85 MHz kernel clock gives 5 quanta and a single-quantum resynchronization
//! jump. Here the bit gets as many quanta as the FDCAN's fields allow (prescaler 1 when
//! possible), the sample point sits where asked (87.5 % nominal by default, CiA's
//! recommendation; about 75 % in the data phase), and the resynchronization jump width
//! equals phase segment 2, the most clock tolerance the bit allows.
//!
//! The data phase uses the nominal phase's time quantum ([`data`] keeps its prescaler),
//! as CiA 601-3 recommends, so both phases resynchronize on the same grid. That needs a
//! kernel clock that divides into both rates: 85 MHz makes 1 Mbit/s (85 quanta) and
//! 5 Mbit/s (17 quanta), not 2, 4 or 8 Mbit/s; 80 MHz (a 160 MHz core) would make all.
//! The transceiver delay compensation offset for the data phase is [`BitTiming::tdc_offset`].

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

    /// The transceiver delay compensation offset (TDCR.TDCO), in kernel clocks: the
    /// secondary sample point sits this far after the measured transmitter-to-receiver
    /// delay, at the bit's own sample point (the prescaler times phase segment 1, as ST's
    /// application note AN5348 sets it). At most 127.
    pub const fn tdc_offset(&self) -> u8 {
        let o = self.prescaler as u32 * self.seg1 as u32;
        if o > 127 { 127 } else { o as u8 }
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

/// The data phase's field limits (DBTP): DTSEG1 1..=32, DTSEG2 1..=16 quanta (the HAL's
/// types stop one short: 31 and 15).
const MAX_DATA_SEG1: u32 = 31;
const MAX_DATA_SEG2: u32 = 15;

/// The sample point as a number, if within 50.0 %..=95.0 %.
const fn sample_point(permille: u16) -> Result<u32, BitTimingError> {
    if permille < 500 || permille > 950 {
        Err(BitTimingError::SamplePoint(permille))
    } else {
        Ok(permille as u32)
    }
}

/// Phase segments 1 and 2 for `quanta` per bit and a sample point of `sp` per mille:
/// seg2 = round(quanta × (1 − sample point)), kept within both fields' ranges (seg1 may
/// still exceed `max_seg1` when `quanta` is too large for the fields).
const fn split(quanta: u32, sp: u32, max_seg1: u32, max_seg2: u32) -> (u32, u32) {
    let mut seg2 = (quanta * (1000 - sp) + 500) / 1000;
    if seg2 < 1 {
        seg2 = 1;
    }
    if seg2 > max_seg2 {
        seg2 = max_seg2;
    }
    if quanta > 1 + max_seg1 + seg2 {
        seg2 = quanta - 1 - max_seg1;
    }
    (quanta - 1 - seg2, seg2)
}

/// The timing with the most quanta per bit (smallest prescaler) that divides `clock_hz`
/// exactly into `bitrate`, with the sample point nearest `sample_point_permille`.
/// `const`, so the firmware's timing is computed (and checked) at compile time.
pub const fn nominal(
    clock_hz: u32,
    bitrate: u32,
    sample_point_permille: u16,
) -> Result<BitTiming, BitTimingError> {
    let sp = match sample_point(sample_point_permille) {
        Ok(sp) => sp,
        Err(e) => return Err(e),
    };
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
            let (seg1, seg2) = split(quanta, sp, MAX_SEG1, MAX_SEG2);
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

/// The data-phase timing for `bitrate` from `clock_hz`, with the nominal timing's
/// prescaler `prescaler` (the same time quantum in both phases) and the sample point
/// nearest `sample_point_permille`. `const`, so the firmware's timing is computed (and
/// checked) at compile time.
pub const fn data(
    clock_hz: u32,
    bitrate: u32,
    prescaler: u16,
    sample_point_permille: u16,
) -> Result<BitTiming, BitTimingError> {
    let sp = match sample_point(sample_point_permille) {
        Ok(sp) => sp,
        Err(e) => return Err(e),
    };
    let no = BitTimingError::NoDivisor { clock_hz, bitrate };
    let p = prescaler as u32;
    if bitrate == 0 || p == 0 || p > 32 || !clock_hz.is_multiple_of(bitrate) {
        return Err(no);
    }
    let clocks_per_bit = clock_hz / bitrate;
    if !clocks_per_bit.is_multiple_of(p) {
        return Err(no);
    }
    let quanta = clocks_per_bit / p;
    if quanta < 4 || quanta > 1 + MAX_DATA_SEG1 + MAX_DATA_SEG2 {
        return Err(no);
    }
    let (seg1, seg2) = split(quanta, sp, MAX_DATA_SEG1, MAX_DATA_SEG2);
    Ok(BitTiming {
        prescaler,
        seg1: seg1 as u8,
        seg2: seg2 as u8,
        sjw: seg2 as u8,
    })
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
    fn five_megabit_data_phase_from_85_mhz_with_the_nominal_quantum() {
        let n = nominal(85_000_000, 1_000_000, 875).unwrap();
        let d = data(85_000_000, 5_000_000, n.prescaler, 750).unwrap();
        assert_eq!(
            d,
            BitTiming {
                prescaler: 1,
                seg1: 12,
                seg2: 4,
                sjw: 4
            }
        );
        assert_eq!((d.quanta(), d.sample_point_permille()), (17, 764));
        assert_eq!(d.tdc_offset(), 12);
        // 2, 4 and 8 Mbit/s do not divide 85 MHz; 80 MHz makes every one.
        for rate in [2_000_000, 4_000_000, 8_000_000] {
            assert!(data(85_000_000, rate, 1, 750).is_err(), "{rate}");
            let t = data(80_000_000, rate, 1, 750).unwrap();
            assert_eq!(t.quanta() * rate, 80_000_000);
        }
        // A quantum too long for the data rate: 2 clocks per quantum leave 8.5.
        assert!(data(85_000_000, 5_000_000, 2, 750).is_err());
        assert!(
            data(85_000_000, 1_000_000, 1, 750).is_err(),
            "85 quanta: too many"
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
