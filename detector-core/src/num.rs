//! The core's numbers: one named type per quantity, each with its unit and range.
//!
//! Everything the tick computes is integer arithmetic on these types, so the chip and
//! the PC produce bit-identical results. Values that can overflow saturate; nothing wraps
//! except [`Tick`], which is a free-running counter.

use fixed::types::I16F16;

/// A channel sample or a feature value, in the SI unit of that channel or feature
/// (N, m/s², N/s, m, m/s, W, (m/s²)², ...).
///
/// Signed 16.16 fixed point: range [-32768, 32768 - 2⁻¹⁶], resolution 2⁻¹⁶ ≈ 1.5·10⁻⁵ of the
/// unit (15 µm for a position in metres, 15 µN for a force in newtons). Conversions from
/// floating point round to nearest and saturate at the range ends; NaN becomes zero.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct Signal(i32);

impl Signal {
    /// Zero in any unit.
    pub const ZERO: Signal = Signal(0);
    /// The largest representable value, 32768 - 2⁻¹⁶.
    pub const MAX: Signal = Signal(i32::MAX);
    /// The smallest representable value, -32768.
    pub const MIN: Signal = Signal(i32::MIN);
    /// Number of fraction bits.
    pub const FRAC_BITS: u32 = 16;

    /// From the raw 16.16 bits.
    pub const fn from_bits(bits: i32) -> Signal {
        Signal(bits)
    }

    /// The raw 16.16 bits.
    pub const fn to_bits(self) -> i32 {
        self.0
    }

    /// From an `f32`, rounding to nearest and saturating; NaN gives zero.
    pub fn from_f32(v: f32) -> Signal {
        if v.is_nan() {
            return Signal::ZERO;
        }
        Signal(I16F16::saturating_from_num(v).to_bits())
    }

    /// A configuration's parameter in a feature's unit, as the detector holds it: the
    /// nearest value when it is finite and below 32768 in magnitude, `None` otherwise.
    pub fn parameter(v: f32) -> Option<Signal> {
        (v.is_finite() && v.abs() < 32768.0).then(|| Signal::from_f32(v))
    }

    /// From an `f64`, rounding to nearest (ties to even) and saturating; NaN gives zero.
    ///
    /// The PC tools convert every sample of a recording through here, so it is written
    /// for speed, without a branch, so that a loop over a column runs several at once:
    /// scaling by 2¹⁶ is exact, the clamp to the `i32` range keeps NaN, adding and taking
    /// away 1.5 × 2⁵² rounds any value below 2⁵¹ to an integer in the float unit's own
    /// mode (nearest, ties to even), and `as` maps NaN to zero.
    #[inline]
    pub fn from_f64(v: f64) -> Signal {
        const ROUNDING: f64 = 6_755_399_441_055_744.0; // 1.5 × 2⁵²
        let x = (v * 65536.0).clamp(f64::from(i32::MIN), f64::from(i32::MAX));
        Signal(((x + ROUNDING) - ROUNDING) as i32)
    }

    /// As an `f32` (exact for |value| < 256, otherwise rounded).
    pub fn to_f32(self) -> f32 {
        I16F16::from_bits(self.0).to_num()
    }

    /// As an `f64` (always exact).
    pub fn to_f64(self) -> f64 {
        I16F16::from_bits(self.0).to_num()
    }

    /// As the `fixed` crate's type.
    pub const fn to_fixed(self) -> I16F16 {
        I16F16::from_bits(self.0)
    }

    /// From the `fixed` crate's type.
    pub const fn from_fixed(v: I16F16) -> Signal {
        Signal(v.to_bits())
    }

    /// Whether `v` lies inside the representable range (finite and within ±32768).
    pub fn representable(v: f32) -> bool {
        v.is_finite() && (-32768.0..32768.0).contains(&v)
    }
}

impl core::fmt::Display for Signal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        core::fmt::Display::fmt(&self.to_fixed(), f)
    }
}

/// A confidence in [0, 1]: how strongly a feature, or an event as a whole, supports the
/// hypothesis that the event could be occurring.
///
/// Q15 in a `u16`: `0` is 0, `32768` ([`Confidence::ONE`]) is 1, resolution 2⁻¹⁵ ≈ 3.1·10⁻⁵.
/// Values above one cannot be constructed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(transparent)]
pub struct Confidence(u16);

impl Confidence {
    /// No support at all.
    pub const ZERO: Confidence = Confidence(0);
    /// Full support.
    pub const ONE: Confidence = Confidence(1 << 15);
    /// Number of fraction bits.
    pub const FRAC_BITS: u32 = 15;

    /// From raw Q15 bits; `None` above [`Confidence::ONE`] (32768).
    pub const fn from_bits(bits: u16) -> Option<Confidence> {
        if bits <= Confidence::ONE.0 {
            Some(Confidence(bits))
        } else {
            None
        }
    }

    /// From raw Q15 bits its caller has bounded by one (checked in debug builds): for
    /// arithmetic whose result provably lies in [0, 1], where a clamp would cost the tick
    /// instructions for nothing.
    #[inline(always)]
    pub(crate) const fn from_bits_within_one(bits: u32) -> Confidence {
        debug_assert!(bits <= Confidence::ONE.0 as u32);
        Confidence(bits as u16)
    }

    /// From raw Q15 bits, clamping anything above one to one.
    pub const fn from_bits_clamped(bits: u32) -> Confidence {
        if bits >= Confidence::ONE.0 as u32 {
            Confidence::ONE
        } else {
            Confidence(bits as u16)
        }
    }

    /// The raw Q15 bits, 0..=32768.
    pub const fn to_bits(self) -> u16 {
        self.0
    }

    /// From an `f32`, rounding to nearest; `None` outside [0, 1] or for NaN.
    pub fn from_f32(v: f32) -> Option<Confidence> {
        if (0.0..=1.0).contains(&v) {
            // In range, so the product is in [0, 32768] and the cast is exact after rounding.
            Some(Confidence((v * 32768.0 + 0.5) as u16).min(Confidence::ONE))
        } else {
            None
        }
    }

    /// As an `f32` in [0, 1] (exact).
    pub fn to_f32(self) -> f32 {
        self.0 as f32 / 32768.0
    }

    /// As an `f64` in [0, 1] (exact).
    pub fn to_f64(self) -> f64 {
        self.0 as f64 / 32768.0
    }

    /// The product of two confidences, rounded to nearest. Never exceeds either factor
    /// by more than rounding, never exceeds one.
    #[inline]
    pub const fn mul(self, other: Confidence) -> Confidence {
        let p = (self.0 as u32 * other.0 as u32 + (1 << 14)) >> 15;
        Confidence::from_bits_clamped(p)
    }

    /// One minus this confidence.
    #[inline]
    pub const fn complement(self) -> Confidence {
        Confidence(Confidence::ONE.0 - self.0)
    }
}

impl core::fmt::Display for Confidence {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // Four decimals are enough to show every step of 2^-15 apart from its neighbours' digits.
        let scaled = (self.0 as u32 * 10_000 + (1 << 14)) >> 15;
        write!(f, "{}.{:04}", scaled / 10_000, scaled % 10_000)
    }
}

/// A detector tick: a free-running counter at the configured detector rate (5 kHz by
/// default, so it wraps after about 9.9 days). Durations between ticks use wrapping
/// subtraction. The caller supplies it; the core keeps no clock.
pub type Tick = u32;

/// A set of input channels, bit `i` for channel `i` (`i` < [`crate::MAX_CHANNELS`]).
pub type ChannelMask = u32;

/// A set of events, bit `i` for event `i` (`i` < [`crate::MAX_EVENTS`]).
pub type EventMask = u8;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signal_conversions_round_and_saturate() {
        assert_eq!(Signal::from_f32(1.0).to_bits(), 1 << 16);
        assert_eq!(Signal::from_f64(-0.5).to_bits(), -(1 << 15));
        assert_eq!(Signal::from_f32(1e9), Signal::MAX);
        assert_eq!(Signal::from_f32(-1e9), Signal::MIN);
        assert_eq!(Signal::from_f32(f32::NAN), Signal::ZERO);
        assert_eq!(Signal::from_f32(f32::INFINITY), Signal::MAX);
        assert_eq!(Signal::from_bits(12345).to_f64() * 65536.0, 12345.0);
    }

    /// The fast conversion against the `fixed` crate's, on ties, range ends and a million
    /// random bit patterns of every magnitude.
    #[test]
    fn from_f64_rounds_as_the_fixed_crate_does() {
        let oracle = |v: f64| {
            if v.is_nan() {
                0
            } else {
                I16F16::saturating_from_num(v).to_bits()
            }
        };
        let lsb = 1.0 / 65536.0;
        let mut values = vec![
            0.0,
            -0.0,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
            5e-324,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            32768.0,
            -32768.0,
            32768.0 - lsb / 2.0,
            -32768.0 - lsb / 2.0,
        ];
        for k in [0.5, 1.5, 2.5, -0.5, -1.5, -2.5, 1e9 + 0.5, -1e9 - 0.5] {
            values.push(k * lsb);
        }
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        for _ in 0..1_000_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            // Exponents concentrated around the 16.16 range, with random sign and mantissa.
            let exponent = 1023 - 40 + (seed >> 52) % 64;
            values.push(f64::from_bits(
                (seed & 0x800f_ffff_ffff_ffff) | (exponent << 52),
            ));
            values.push(f64::from_bits(seed));
        }
        for v in values {
            assert_eq!(Signal::from_f64(v).to_bits(), oracle(v), "{v:e}");
        }
    }

    #[test]
    fn confidence_range_is_enforced() {
        assert_eq!(Confidence::from_bits(32768), Some(Confidence::ONE));
        assert_eq!(Confidence::from_bits(32769), None);
        assert_eq!(Confidence::from_f32(1.5), None);
        assert_eq!(Confidence::from_f32(-0.1), None);
        assert_eq!(Confidence::from_f32(f32::NAN), None);
        assert_eq!(Confidence::from_f32(0.5), Confidence::from_bits(16384));
        assert_eq!(Confidence::from_bits_clamped(99_999), Confidence::ONE);
    }

    #[test]
    fn confidence_product_and_display() {
        let half = Confidence::from_bits(16384).unwrap_or_default();
        assert_eq!(half.mul(half).to_bits(), 8192);
        assert_eq!(Confidence::ONE.mul(Confidence::ONE), Confidence::ONE);
        assert_eq!(Confidence::ZERO.mul(Confidence::ONE), Confidence::ZERO);
        assert_eq!(half.complement(), half);
        assert_eq!(format!("{}", half), "0.5000");
        assert_eq!(format!("{}", Confidence::ONE), "1.0000");
    }
}
