//! Calibration: raw ADC counts to the core's [`Signal`] in the channel's SI unit.
//!
//! Each analog channel is linear: `value = (counts − zero(T)) × gain`, where the zero
//! (the counts read at a zero of the quantity) drifts with the board temperature `T`:
//! `zero(T) = zero_ref + zero_drift × (T − T_ref)`. The strain-gauge bridges of the force
//! channels drift this way; the temperature comes from the TMP117 next to them
//! ([`crate::tmp117`]). Without a temperature (sensor not answering) the zero holds its
//! last compensated value.
//!
//! Fixed point, no division: the gain is Q24 units per count ([`I8F24`]), the zero and its
//! drift Q8 counts ([`I24F8`]). One 32×32→64 multiply per sample (a single `SMULL` on the
//! Cortex-M4). Results saturate at the ends of the [`Signal`] range.

use detector_core::Signal;
use fixed::types::{I8F24, I24F8};

use crate::wiring::ADC_CHANNELS;

/// Full scale of the 12-bit ADC, in counts (`0..=4095`).
pub const ADC_MAX: u16 = 4095;

/// A calibration parameter that cannot be represented.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum CalibrationError {
    /// `|gain|` must be finite, non-zero and below 128 units per count (Q24 in an `i32`).
    Gain(f32),
    /// The zero must be finite and within `0..=65535` counts.
    Zero(f32),
    /// The zero drift must be finite and within ±1000 counts per °C.
    Drift(f32),
    /// The reference temperature must be finite and within ±1000 °C.
    Reference(f32),
}

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CalibrationError::Gain(g) => {
                write!(
                    f,
                    "gain {g} per count is not finite, non-zero and below 128"
                )
            }
            CalibrationError::Zero(z) => write!(f, "zero {z} counts is not within 0..=65535"),
            CalibrationError::Drift(d) => {
                write!(f, "zero drift {d} counts/°C is not within ±1000")
            }
            CalibrationError::Reference(t) => {
                write!(f, "reference temperature {t} °C is not within ±1000")
            }
        }
    }
}

/// One channel's calibration, as characterized on the bench.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibration {
    /// Units per count (2⁻²⁴ units per count resolution, |gain| < 128).
    gain: I8F24,
    /// Counts at zero of the quantity at the reference temperature.
    zero: I24F8,
    /// Zero drift, counts per °C.
    drift: I24F8,
    /// The reference temperature, °C.
    t_ref: Signal,
}

const fn round(v: f32) -> f32 {
    // `f32::round` is not const; symmetric rounding half away from zero.
    if v >= 0.0 { v + 0.5 } else { v - 0.5 }
}

impl Calibration {
    /// A calibration: `gain` units per count (e.g. N/count), `zero` the counts read at a
    /// zero of the quantity at `t_ref` °C, `drift` the change of that zero in counts per
    /// °C. Usable in `const` context, so a bad table entry fails the build.
    pub const fn new(
        gain: f32,
        zero: f32,
        drift: f32,
        t_ref: f32,
    ) -> Result<Self, CalibrationError> {
        let g = gain * 16_777_216.0;
        if !gain.is_finite() || gain == 0.0 || g >= 2_147_483_520.0 || g <= -2_147_483_520.0 {
            return Err(CalibrationError::Gain(gain));
        }
        if !zero.is_finite() || zero < 0.0 || zero > 65_535.0 {
            return Err(CalibrationError::Zero(zero));
        }
        if !drift.is_finite() || drift > 1000.0 || drift < -1000.0 {
            return Err(CalibrationError::Drift(drift));
        }
        if !t_ref.is_finite() || t_ref > 1000.0 || t_ref < -1000.0 {
            return Err(CalibrationError::Reference(t_ref));
        }
        Ok(Calibration {
            gain: I8F24::from_bits(round(g) as i32),
            zero: I24F8::from_bits(round(zero * 256.0) as i32),
            drift: I24F8::from_bits(round(drift * 256.0) as i32),
            t_ref: Signal::from_bits(round(t_ref * 65_536.0) as i32),
        })
    }

    /// The calibration to apply at board temperature `temperature` (°C); `None` (no
    /// reading) uses the reference temperature, i.e. no drift compensation.
    pub fn at(&self, temperature: Option<Signal>) -> ActiveCalibration {
        let shift = match temperature {
            Some(t) => {
                // Q8 counts/°C × Q16 °C = Q24 counts; back to Q8. i64: |drift| ≤ 2^18,
                // |ΔT| < 2^32.
                let dt = i64::from(t.to_bits()) - i64::from(self.t_ref.to_bits());
                (i64::from(self.drift.to_bits()) * dt) >> 16
            }
            None => 0,
        };
        let zero = (i64::from(self.zero.to_bits()) + shift)
            .clamp(i64::from(i32::MIN), i64::from(i32::MAX));
        ActiveCalibration {
            gain: self.gain,
            zero: I24F8::from_bits(zero as i32),
        }
    }

    // The parameters as `new` takes them, in single precision, rounded once (each
    // division is by a power of two, which is exact).

    /// The gain, units per count.
    pub fn gain(&self) -> f32 {
        self.gain.to_bits() as f32 / 16_777_216.0
    }

    /// The zero at the reference temperature, counts.
    pub fn zero(&self) -> f32 {
        self.zero.to_bits() as f32 / 256.0
    }

    /// The zero's drift, counts per °C.
    pub fn drift(&self) -> f32 {
        self.drift.to_bits() as f32 / 256.0
    }

    /// The reference temperature, °C.
    pub fn t_ref(&self) -> f32 {
        self.t_ref.to_f32()
    }
}

/// A calibration with its zero compensated for the current temperature: what the
/// sampler applies to every sample until the next temperature reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ActiveCalibration {
    /// Units per count.
    gain: I8F24,
    /// Counts at zero of the quantity, compensated.
    zero: I24F8,
}

impl ActiveCalibration {
    /// The value of a raw reading, in the channel's unit; saturates at the [`Signal`]
    /// range ends. Error against exact arithmetic: below 2⁻¹⁶ of the unit plus the
    /// representation error of the gain (relative 2⁻²⁴/|gain|).
    #[inline]
    pub fn apply(&self, counts: u16) -> Signal {
        // Q8 counts × Q24 units/count = Q32 units; >> 16 gives Signal's Q16.
        let diff = (i64::from(counts) << 8) - i64::from(self.zero.to_bits());
        let q32 = diff * i64::from(self.gain.to_bits());
        // Round to nearest: add half an LSB of the result before the shift.
        let q16 = (q32 + (1 << 15)) >> 16;
        Signal::from_bits(q16.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32)
    }
}

/// The nominal calibration of the fingertip board's analog front ends, in
/// [`ADC_CHANNELS`] order. Per-unit values replace these after a bench calibration.
///
/// | channel | front end | full scale (0..3.3 V) | gain | zero | drift |
/// |---|---|---|---|---|---|
/// | `force_x`, `force_y` | strain-gauge bridge, instrumentation amplifier, mid-rail zero | ±10 N | 20/4096 N/count | 2048 | +0.5 counts/°C |
/// | `skin_accel` | analog MEMS accelerometer, ±50 g, mid-rail zero | ±490 m/s² | 980.7/4096 m/s²/count | 2048 | 0 |
/// | `stress_rate` | PVDF film, charge amplifier, mid-rail zero | ±50 N/s | 100/4096 (N/s)/count | 2048 | 0 |
///
/// The reference temperature is 25 °C.
pub const NOMINAL: [Calibration; ADC_CHANNELS.len()] = {
    const fn ok(c: Result<Calibration, CalibrationError>) -> Calibration {
        match c {
            Ok(c) => c,
            Err(_) => panic!("invalid nominal calibration"),
        }
    }
    [
        ok(Calibration::new(20.0 / 4096.0, 2048.0, 0.5, 25.0)),
        ok(Calibration::new(20.0 / 4096.0, 2048.0, 0.5, 25.0)),
        ok(Calibration::new(980.665 / 4096.0, 2048.0, 0.0, 25.0)),
        ok(Calibration::new(100.0 / 4096.0, 2048.0, 0.0, 25.0)),
    ]
};

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn reference(c: &Calibration, t: Option<f64>, counts: u16) -> f64 {
        let drift = f64::from(c.drift.to_bits()) / 256.0;
        let t_ref = c.t_ref.to_f64();
        let zero = f64::from(c.zero.to_bits()) / 256.0 + t.map_or(0.0, |t| drift * (t - t_ref));
        (f64::from(counts) - zero) * f64::from(c.gain.to_bits()) / 16_777_216.0
    }

    /// The parameters read back are those given, to single precision, whatever they went
    /// through in fixed point.
    #[test]
    fn parameters_read_back_as_given() {
        let c = Calibration::new(20.0 / 4096.0, 2048.5, -0.25, 31.5).unwrap();
        assert_eq!(c.gain(), 20.0 / 4096.0);
        assert_eq!((c.zero(), c.drift(), c.t_ref()), (2048.5, -0.25, 31.5));
        let again = Calibration::new(c.gain(), c.zero(), c.drift(), c.t_ref()).unwrap();
        assert_eq!(again, c);
    }

    #[test]
    fn mid_rail_reads_zero_and_full_scale_reads_the_range() {
        let force = NOMINAL[0].at(None);
        assert_eq!(force.apply(2048), Signal::ZERO);
        assert!((force.apply(0).to_f64() + 10.0).abs() < 1e-4);
        assert!((force.apply(ADC_MAX).to_f64() - 9.9951).abs() < 1e-3);
        let accel = NOMINAL[2].at(None);
        assert!((accel.apply(4095).to_f64() - 490.09).abs() < 0.05);
    }

    #[test]
    fn temperature_moves_the_zero_by_the_drift() {
        let force = NOMINAL[0];
        // +10 °C above the reference: the zero moves up by 5 counts.
        let warm = force.at(Some(Signal::from_f64(35.0)));
        assert_eq!(warm.apply(2053), Signal::ZERO);
        let cold = force.at(Some(Signal::from_f64(15.0)));
        assert_eq!(cold.apply(2043), Signal::ZERO);
        // No reading: the reference zero.
        assert_eq!(force.at(None), force.at(Some(Signal::from_f64(25.0))));
    }

    #[test]
    fn bad_parameters_are_rejected_with_their_value() {
        assert_eq!(
            Calibration::new(0.0, 1.0, 0.0, 25.0),
            Err(CalibrationError::Gain(0.0))
        );
        assert_eq!(
            Calibration::new(200.0, 1.0, 0.0, 25.0),
            Err(CalibrationError::Gain(200.0))
        );
        assert!(Calibration::new(f32::NAN, 1.0, 0.0, 25.0).is_err());
        assert_eq!(
            Calibration::new(1.0, -1.0, 0.0, 25.0),
            Err(CalibrationError::Zero(-1.0))
        );
        assert_eq!(
            Calibration::new(1.0, 1.0, 2000.0, 25.0),
            Err(CalibrationError::Drift(2000.0))
        );
        assert_eq!(
            Calibration::new(1.0, 1.0, 0.0, f32::INFINITY),
            Err(CalibrationError::Reference(f32::INFINITY))
        );
        assert!(format!("{}", CalibrationError::Gain(0.0)).contains("gain 0"));
    }

    #[test]
    fn results_saturate_instead_of_wrapping() {
        // 100 units per count × 4095 counts is far above Signal's 32768.
        let big = Calibration::new(100.0, 0.0, 0.0, 25.0).unwrap().at(None);
        assert_eq!(big.apply(4095), Signal::MAX);
        let neg = Calibration::new(-100.0, 0.0, 0.0, 25.0).unwrap().at(None);
        assert_eq!(neg.apply(4095), Signal::MIN);
    }

    proptest! {
        /// Fixed point against f64, for any gain the board could have (|gain| in
        /// [1e-4, 10] units/count), any zero and drift, temperatures −40..125 °C: the
        /// error is below 2 LSB of Signal plus the gain's Q24 representation error.
        #[test]
        fn matches_f64_reference(
            gain in prop_oneof![1e-4f32..10.0, -10.0f32..-1e-4],
            zero in 0.0f32..4095.0,
            drift in -5.0f32..5.0,
            t in prop::option::of(-40.0f64..125.0),
            counts in 0u16..=ADC_MAX,
        ) {
            let c = Calibration::new(gain, zero, drift, 25.0).unwrap();
            let got = c.at(t.map(Signal::from_f64)).apply(counts).to_f64();
            let want = reference(&c, t.map(|t| Signal::from_f64(t).to_f64()), counts);
            prop_assume!(want.abs() < 32_000.0);
            // The zero's compensation is truncated to Q8 counts: at most 1/256 count.
            let bound = 2.0 / 65_536.0 + f64::from(c.gain().abs()) / 256.0;
            prop_assert!((got - want).abs() <= bound, "got {got}, want {want}, bound {bound}");
        }
    }
}
