//! Confidence distribution functions (the paper's ψ): a feature value in, a confidence out.
//!
//! Four shapes, as in the paper's figure 2, built from the fuzzy-logic S-function (two
//! quadratic pieces meeting at the midpoint) so no exponential is needed:
//!
//! | shape | parameters | value |
//! |---|---|---|
//! | sigmoid (Σ) | `low < high`, `falling` | 0 below `low`, 1 above `high`, S-shaped between (mirrored when `falling`) |
//! | bell (Π) | `center`, `half_width > 0` | 1 at `center`, ½ at `center ± half_width/2`, 0 beyond `± half_width` |
//! | flat bell (Λ) | `low < plateau_low ≤ plateau_high < high` | 0 outside `[low, high]`, 1 on the plateau, S-shaped shoulders |
//! | binary (Γ) | `threshold`, `above` | 1 when the value is ≥ `threshold` (`above`) or ≤ it (not `above`), else 0 |
//!
//! Parameters are in the feature's own unit. [`CdfSpec`] is what a user writes;
//! [`Cdf::new`] validates it and precomputes the reciprocals so that evaluating costs one
//! 32×32→64 multiplication per shoulder and no division.

use crate::image::{ImageError, Reader, Sink};
use crate::num::{Confidence, Signal};

/// A confidence distribution function as a user describes it, parameters in the feature's
/// unit.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(
    feature = "serde",
    serde(rename_all = "snake_case", deny_unknown_fields)
)]
pub enum CdfSpec {
    /// Σ: rises from 0 at `low` to 1 at `high` (or falls, when `falling`).
    Sigmoid {
        /// Where the rise starts (confidence 0, or 1 when falling).
        low: f32,
        /// Where the rise ends (confidence 1, or 0 when falling).
        high: f32,
        /// Mirror the curve: 1 below `low`, 0 above `high`.
        #[cfg_attr(feature = "serde", serde(default))]
        falling: bool,
    },
    /// Π: 1 at `center`, falling symmetrically to 0 at `center ± half_width`.
    Bell {
        /// Where the confidence is 1.
        center: f32,
        /// Distance from the centre at which the confidence reaches 0; positive.
        half_width: f32,
    },
    /// Λ: 1 on `[plateau_low, plateau_high]`, 0 outside `[low, high]`, S-shaped shoulders.
    FlatBell {
        /// Where the rising shoulder starts.
        low: f32,
        /// Where the plateau starts.
        plateau_low: f32,
        /// Where the plateau ends.
        plateau_high: f32,
        /// Where the falling shoulder ends.
        high: f32,
    },
    /// Γ: 1 on one side of `threshold` (inclusive), 0 on the other.
    Binary {
        /// The switching value.
        threshold: f32,
        /// 1 for values ≥ `threshold` when true, for values ≤ `threshold` when false.
        above: bool,
    },
}

/// Why a [`CdfSpec`] was rejected.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum CdfError {
    /// A parameter is NaN, infinite or outside the feature range of ±32768.
    NotRepresentable {
        /// The parameter's name.
        param: &'static str,
        /// Its value.
        value: f32,
    },
    /// Two parameters are out of order (`first` must be below `second`, or at most
    /// equal where the shape allows it).
    OutOfOrder {
        /// The parameter that must be smaller.
        first: &'static str,
        /// Its value.
        first_value: f32,
        /// The parameter that must be larger.
        second: &'static str,
        /// Its value.
        second_value: f32,
    },
    /// A width is zero or negative, or shorter than the feature resolution (2⁻¹⁶).
    TooNarrow {
        /// The parameter's name.
        param: &'static str,
        /// Its value.
        value: f32,
    },
}

impl core::fmt::Display for CdfError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            CdfError::NotRepresentable { param, value } => {
                write!(f, "{param} = {value} is not a finite value within ±32768")
            }
            CdfError::OutOfOrder {
                first,
                first_value,
                second,
                second_value,
            } => write!(
                f,
                "{first} = {first_value} must be below {second} = {second_value}"
            ),
            CdfError::TooNarrow { param, value } => write!(
                f,
                "{param} = {value} must be positive and at least 2^-16 wide"
            ),
        }
    }
}

/// A linear map from `[start, start + span]` onto `[0, 1]` in Q15, clamped at both ends.
///
/// `t = (d << pre) · mul >> 32` for a distance `d = x − start` below `span`, rounded to
/// nearest: one 32×32→64 multiplication whose high word is the answer. A narrow ramp
/// (`span` < 2¹⁷ raw) shifts the distance up by `pre` = 15, which keeps it below 2³², and
/// uses `mul = 2³² / span`; a wide one takes the distance as it is with `mul = 2⁴⁷ / span`
/// (at most 2³⁰). Rounding `mul` moves `t` by less than half a Q15 step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ramp {
    start: i32,
    span: u32,
    mul: u32,
    pre: u8,
}

/// Spans below this are narrow (see [`Ramp`]).
const NARROW: u64 = 1 << 17;

impl Ramp {
    /// `start < end` in raw 16.16 bits; `None` if they are equal or reversed.
    fn new(start: i32, end: i32) -> Option<Ramp> {
        let span = end as i64 - start as i64;
        if span <= 0 {
            return None;
        }
        let span = span as u32; // 1..=2^32-1
        let (pre, mul) = Ramp::scaling(span);
        Some(Ramp {
            start,
            span,
            mul,
            pre,
        })
    }

    /// The pre-shift and the multiplier of a ramp `span` long (at least 1): `2³² / span`
    /// after a shift by 15 for a narrow one, `2⁴⁷ / span` for a wide one, rounded. Only a
    /// one-unit span would reach 2³²; its only distance below the span is 0.
    const fn scaling(span: u32) -> (u8, u32) {
        let span = span as u64;
        let (pre, scale) = if span < NARROW { (15, 32) } else { (0, 47) };
        let mul = ((1u64 << scale) + span / 2) / span;
        (
            pre,
            if mul > u32::MAX as u64 {
                u32::MAX
            } else {
                mul as u32
            },
        )
    }

    /// Position of a distance `d = x - start` (already known non-negative) along the ramp,
    /// at most 2¹⁵: for `d` ≤ `span` − 1 and the rounded multiplier of
    /// [`Ramp::scaling`], `d · mul` + 2³¹ stays below (2¹⁵ + 1) · 2³² (a narrow ramp's
    /// `mul` errs by at most ½, which `d` < 2¹⁷ turns into less than 2³¹ after the shift; a
    /// wide one's by at most ½ over `d` < 2³²). Every ramp is checked to carry that
    /// multiplier ([`Ramp::valid`]), so no clamp is needed; a test checks the last distance
    /// of every narrow span and of wide ones.
    #[inline(always)]
    fn along(&self, d: u32) -> u32 {
        if d >= self.span {
            return 1 << 15;
        }
        let d = d << self.pre;
        ((d as u64 * self.mul as u64 + (1 << 31)) >> 32) as u32
    }

    /// Position of `x` along the ramp, Q15 in [0, 32768].
    #[inline(always)]
    fn at(&self, x: i32) -> u32 {
        if x <= self.start {
            0
        } else {
            // x > start, so the wrapped difference is the exact distance (< 2^32).
            self.along((x as u32).wrapping_sub(self.start as u32))
        }
    }
}

/// The S-function of a position `t` ∈ [0, 1] (Q15): 2t² below ½, 1 − 2(1−t)² above.
#[inline(always)]
fn smooth(t: u32) -> u32 {
    if t <= 1 << 14 {
        (t * t + (1 << 13)) >> 14
    } else {
        let u = (1 << 15) - t;
        (1 << 15) - ((u * u + (1 << 13)) >> 14)
    }
}

/// A validated confidence distribution function, ready to evaluate: made by [`Cdf::new`]
/// or read from an image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cdf(Shape);

/// A compiled CDF's shape, for generated code (`detector_core::__private`), which builds a
/// [`Cdf`] from it with [`Shape::cdf`] and its ramps with [`Ramp::checked`].
#[doc(hidden)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    Rising(Ramp),
    Falling(Ramp),
    Bell { center: i32, ramp: Ramp },
    FlatBell { rise: Ramp, fall: Ramp },
    Above(i32),
    Below(i32),
}

fn param(name: &'static str, value: f32) -> Result<i32, CdfError> {
    if Signal::representable(value) {
        Ok(Signal::from_f32(value).to_bits())
    } else {
        Err(CdfError::NotRepresentable { param: name, value })
    }
}

fn ordered(
    first: (&'static str, f32, i32),
    second: (&'static str, f32, i32),
) -> Result<Ramp, CdfError> {
    let out_of_order = CdfError::OutOfOrder {
        first: first.0,
        first_value: first.1,
        second: second.0,
        second_value: second.1,
    };
    if first.1 >= second.1 {
        return Err(out_of_order);
    }
    // Distinct as floats but equal once quantized: narrower than the feature resolution.
    Ramp::new(first.2, second.2).ok_or(CdfError::TooNarrow {
        param: second.0,
        value: second.1 - first.1,
    })
}

impl Cdf {
    /// Validates a specification: every parameter finite and within ±32768, parameters in
    /// order, widths at least the feature resolution.
    pub fn new(spec: &CdfSpec) -> Result<Cdf, CdfError> {
        let shape = match *spec {
            CdfSpec::Sigmoid { low, high, falling } => {
                let ramp = ordered(
                    ("low", low, param("low", low)?),
                    ("high", high, param("high", high)?),
                )?;
                if falling {
                    Shape::Falling(ramp)
                } else {
                    Shape::Rising(ramp)
                }
            }
            CdfSpec::Bell { center, half_width } => {
                let c = param("center", center)?;
                let w = param("half_width", half_width)?;
                if half_width <= 0.0 || w <= 0 {
                    return Err(CdfError::TooNarrow {
                        param: "half_width",
                        value: half_width,
                    });
                }
                let ramp = Ramp::new(0, w).ok_or(CdfError::TooNarrow {
                    param: "half_width",
                    value: half_width,
                })?;
                Shape::Bell { center: c, ramp }
            }
            CdfSpec::FlatBell {
                low,
                plateau_low,
                plateau_high,
                high,
            } => {
                let a = ("low", low, param("low", low)?);
                let b = (
                    "plateau_low",
                    plateau_low,
                    param("plateau_low", plateau_low)?,
                );
                let c = (
                    "plateau_high",
                    plateau_high,
                    param("plateau_high", plateau_high)?,
                );
                let d = ("high", high, param("high", high)?);
                if plateau_low > plateau_high {
                    return Err(CdfError::OutOfOrder {
                        first: b.0,
                        first_value: b.1,
                        second: c.0,
                        second_value: c.1,
                    });
                }
                Shape::FlatBell {
                    rise: ordered(a, b)?,
                    fall: ordered(c, d)?,
                }
            }
            CdfSpec::Binary { threshold, above } => {
                let t = param("threshold", threshold)?;
                if above {
                    Shape::Above(t)
                } else {
                    Shape::Below(t)
                }
            }
        };
        Ok(Cdf(shape))
    }

    /// Whether `other` gives every value one minus this function's confidence, bit for bit:
    /// a rising and a falling sigmoid over the same range. Generated code evaluates such a
    /// pair on one feature once (see `mirror_psi`).
    pub fn mirrors(&self, other: &Cdf) -> bool {
        match (self.0, other.0) {
            (Shape::Rising(a), Shape::Falling(b)) | (Shape::Falling(a), Shape::Rising(b)) => a == b,
            _ => false,
        }
    }

    /// The confidence this function gives a feature value.
    #[inline(always)]
    pub fn eval(&self, x: Signal) -> Confidence {
        let x = x.to_bits();
        let q = match self.0 {
            Shape::Rising(r) => smooth(r.at(x)),
            Shape::Falling(r) => (1 << 15) - smooth(r.at(x)),
            Shape::Bell { center, ramp } => {
                // |x - center| < 2^32, exact in wrapping u32 arithmetic.
                let d = if x >= center {
                    (x as u32).wrapping_sub(center as u32)
                } else {
                    (center as u32).wrapping_sub(x as u32)
                };
                (1 << 15) - smooth(ramp.along(d))
            }
            Shape::FlatBell { rise, fall } => {
                if x < fall.start {
                    smooth(rise.at(x))
                } else {
                    (1 << 15) - smooth(fall.at(x))
                }
            }
            Shape::Above(t) => u32::from(x >= t) << 15,
            Shape::Below(t) => u32::from(x <= t) << 15,
        };
        // A position along a ramp is at most 2^15 (`Ramp::along`), and so is the S-function
        // of one: every shape stays within [0, 1] without a clamp.
        Confidence::from_bits_within_one(q)
    }
}

impl Ramp {
    /// Whether a ramp is one [`Ramp::new`] can make: a shifted distance stays below 2³²
    /// and the multiplier is the span's own, so that a position along it never passes 1.
    const fn valid(&self) -> bool {
        if self.span == 0 {
            return false;
        }
        let (pre, mul) = Ramp::scaling(self.span);
        self.pre == pre && self.mul == mul
    }

    /// A ramp from its raw values, for generated code's constants: values [`Ramp::new`]
    /// cannot make fail the build of the generated code.
    #[doc(hidden)]
    pub const fn checked(start: i32, span: u32, mul: u32, pre: u8) -> Ramp {
        let ramp = Ramp {
            start,
            span,
            mul,
            pre,
        };
        assert!(ramp.valid(), "CDF ramp");
        ramp
    }

    /// Appends this ramp to a detector image.
    pub fn write_image(&self, w: &mut impl Sink) {
        w.i32(self.start);
        w.u32(self.span);
        w.u32(self.mul);
        w.u8(self.pre);
    }

    fn read_image(r: &mut Reader<'_>) -> Result<Ramp, ImageError> {
        let ramp = Ramp {
            start: r.i32()?,
            span: r.u32()?,
            mul: r.u32()?,
            pre: r.u8()?,
        };
        if !ramp.valid() {
            return Err(ImageError::Invalid("CDF ramp"));
        }
        Ok(ramp)
    }
}

impl core::fmt::Display for crate::expr::Rust<'_, Ramp> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let r = self.0;
        write!(
            f,
            "Ramp::checked({}, {}, {}, {})",
            r.start, r.span, r.mul, r.pre
        )
    }
}

impl Shape {
    /// The CDF of this shape (every ramp is checked when it is made).
    #[doc(hidden)]
    pub const fn cdf(self) -> Cdf {
        Cdf(self)
    }
}

/// The tag that starts each CDF in an image.
#[derive(Clone, Copy)]
enum CdfTag {
    Rising = 0,
    Falling = 1,
    Bell = 2,
    FlatBell = 3,
    Above = 4,
    Below = 5,
}

impl CdfTag {
    const ALL: [CdfTag; 6] = [
        CdfTag::Rising,
        CdfTag::Falling,
        CdfTag::Bell,
        CdfTag::FlatBell,
        CdfTag::Above,
        CdfTag::Below,
    ];

    fn from_byte(b: u8) -> Option<CdfTag> {
        CdfTag::ALL.into_iter().find(|&t| t as u8 == b)
    }
}

impl core::fmt::Display for crate::expr::Rust<'_, Cdf> {
    /// The CDF as a Rust expression in generated code's scope (`detector_core::__private`).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::expr::Rust;
        match self.0.0 {
            Shape::Rising(r) => write!(f, "Shape::Rising({})", Rust(&r)),
            Shape::Falling(r) => write!(f, "Shape::Falling({})", Rust(&r)),
            Shape::Bell { center, ramp } => write!(
                f,
                "Shape::Bell {{ center: {center}, ramp: {} }}",
                Rust(&ramp)
            ),
            Shape::FlatBell { rise, fall } => write!(
                f,
                "Shape::FlatBell {{ rise: {}, fall: {} }}",
                Rust(&rise),
                Rust(&fall)
            ),
            Shape::Above(t) => write!(f, "Shape::Above({t})"),
            Shape::Below(t) => write!(f, "Shape::Below({t})"),
        }?;
        write!(f, ".cdf()")
    }
}

impl Cdf {
    /// This CDF as a Rust expression for generated code (see
    /// `detector_build::Compiled::to_rust`).
    pub fn rust(&self) -> crate::expr::Rust<'_, Cdf> {
        crate::expr::Rust(self)
    }

    /// Appends this CDF to a detector image.
    pub fn write_image(&self, w: &mut impl Sink) {
        match self.0 {
            Shape::Rising(r) => {
                w.u8(CdfTag::Rising as u8);
                r.write_image(w);
            }
            Shape::Falling(r) => {
                w.u8(CdfTag::Falling as u8);
                r.write_image(w);
            }
            Shape::Bell { center, ramp } => {
                w.u8(CdfTag::Bell as u8);
                w.i32(center);
                ramp.write_image(w);
            }
            Shape::FlatBell { rise, fall } => {
                w.u8(CdfTag::FlatBell as u8);
                rise.write_image(w);
                fall.write_image(w);
            }
            Shape::Above(t) => {
                w.u8(CdfTag::Above as u8);
                w.i32(t);
            }
            Shape::Below(t) => {
                w.u8(CdfTag::Below as u8);
                w.i32(t);
            }
        }
    }

    /// Reads a CDF from a detector image.
    pub(crate) fn read_image(r: &mut Reader<'_>) -> Result<Cdf, ImageError> {
        Ok(Cdf(match CdfTag::from_byte(r.u8()?) {
            Some(CdfTag::Rising) => Shape::Rising(Ramp::read_image(r)?),
            Some(CdfTag::Falling) => Shape::Falling(Ramp::read_image(r)?),
            Some(CdfTag::Bell) => Shape::Bell {
                center: r.i32()?,
                ramp: Ramp::read_image(r)?,
            },
            Some(CdfTag::FlatBell) => Shape::FlatBell {
                rise: Ramp::read_image(r)?,
                fall: Ramp::read_image(r)?,
            },
            Some(CdfTag::Above) => Shape::Above(r.i32()?),
            Some(CdfTag::Below) => Shape::Below(r.i32()?),
            None => return Err(ImageError::Invalid("CDF shape")),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Bytes;

    fn eval(spec: CdfSpec, x: f32) -> f32 {
        Cdf::new(&spec)
            .expect("valid")
            .eval(Signal::from_f32(x))
            .to_f32()
    }

    #[test]
    fn sigmoid_hits_its_anchor_points() {
        let s = CdfSpec::Sigmoid {
            low: 1.0,
            high: 3.0,
            falling: false,
        };
        assert_eq!(eval(s, 0.0), 0.0);
        assert_eq!(eval(s, 1.0), 0.0);
        assert_eq!(eval(s, 2.0), 0.5);
        assert_eq!(eval(s, 3.0), 1.0);
        assert_eq!(eval(s, 100.0), 1.0);
        // 2t² at t = 1/4.
        assert!((eval(s, 1.5) - 0.125).abs() < 1e-4);
        let f = CdfSpec::Sigmoid {
            low: 1.0,
            high: 3.0,
            falling: true,
        };
        assert_eq!(eval(f, 0.0), 1.0);
        assert!((eval(f, 1.5) - 0.875).abs() < 1e-4);
    }

    #[test]
    fn a_falling_sigmoid_mirrors_the_rising_one_over_the_same_range_only() {
        let sigmoid =
            |low, high, falling| Cdf::new(&CdfSpec::Sigmoid { low, high, falling }).expect("valid");
        let (up, down) = (sigmoid(-0.3, 2.7, false), sigmoid(-0.3, 2.7, true));
        assert!(up.mirrors(&down) && down.mirrors(&up));
        for k in -400..400 {
            let x = Signal::from_f32(k as f32 * 0.01);
            let sum = u32::from(up.eval(x).to_bits()) + u32::from(down.eval(x).to_bits());
            assert_eq!(sum, 1 << 15, "at {x:?}");
        }
        assert!(!up.mirrors(&up));
        assert!(!up.mirrors(&sigmoid(-0.3, 2.8, true)));
        let binary = |above| {
            Cdf::new(&CdfSpec::Binary {
                threshold: 1.0,
                above,
            })
            .expect("valid")
        };
        // At the threshold both read 1: not a mirror image.
        assert!(!binary(true).mirrors(&binary(false)));
    }

    #[test]
    fn bell_and_flat_bell_are_symmetric_where_they_should_be() {
        let b = CdfSpec::Bell {
            center: -2.0,
            half_width: 4.0,
        };
        assert_eq!(eval(b, -2.0), 1.0);
        assert_eq!(eval(b, 0.0), 0.5);
        assert_eq!(eval(b, -4.0), 0.5);
        assert_eq!(eval(b, 2.0), 0.0);
        assert_eq!(eval(b, -1000.0), 0.0);
        let l = CdfSpec::FlatBell {
            low: 0.0,
            plateau_low: 1.0,
            plateau_high: 2.0,
            high: 4.0,
        };
        assert_eq!(eval(l, -1.0), 0.0);
        assert_eq!(eval(l, 0.5), 0.5);
        assert_eq!(eval(l, 1.5), 1.0);
        assert_eq!(eval(l, 3.0), 0.5);
        assert_eq!(eval(l, 5.0), 0.0);
    }

    #[test]
    fn binary_is_inclusive_at_the_threshold() {
        let a = CdfSpec::Binary {
            threshold: 0.0,
            above: true,
        };
        let b = CdfSpec::Binary {
            threshold: 0.0,
            above: false,
        };
        assert_eq!(
            (eval(a, 0.0), eval(a, -1e-4), eval(a, 5.0)),
            (1.0, 0.0, 1.0)
        );
        assert_eq!(
            (eval(b, 0.0), eval(b, 1e-4), eval(b, -5.0)),
            (1.0, 0.0, 1.0)
        );
    }

    #[test]
    fn a_position_along_a_ramp_never_passes_one() {
        // The position grows with the distance, so the last distance below each span is
        // the one to check: every narrow span, and wide ones from the narrowest to the
        // widest in steps that also land next to powers of two.
        let wide = (17..32).flat_map(|b| {
            let p = 1u64 << b;
            [p - 1, p, p + 1, p + p / 3, 2 * p - 3]
        });
        let spans = (1..NARROW).chain(wide).chain([u64::from(u32::MAX)]);
        for span in spans {
            let end = i64::from(i32::MIN) + span as i64;
            let ramp = Ramp::new(i32::MIN, end as i32).expect("ordered");
            let span = span as u32;
            assert_eq!(ramp.span, span);
            assert!(ramp.along(span - 1) <= 1 << 15, "span {span}");
            assert_eq!(ramp.along(span), 1 << 15, "span {span}");
        }
    }

    #[test]
    fn a_ramp_whose_multiplier_is_not_its_spans_own_is_refused() {
        let good = Ramp::new(-5 << 16, 7 << 16).expect("ordered");
        assert!(good.valid());
        for mul in [good.mul + 1, good.mul - 1, 0, u32::MAX] {
            let bad = Ramp { mul, ..good };
            assert!(!bad.valid(), "mul {mul}");
            let mut image = Bytes(std::vec::Vec::new());
            bad.write_image(&mut image);
            assert_eq!(
                Ramp::read_image(&mut Reader::new(&image.0)),
                Err(ImageError::Invalid("CDF ramp"))
            );
        }
        assert!(
            !Ramp {
                pre: 15 - good.pre,
                ..good
            }
            .valid()
        );
        assert!(!Ramp { span: 0, ..good }.valid());
    }

    #[test]
    fn extreme_spans_stay_in_range() {
        let wide = CdfSpec::Sigmoid {
            low: -32768.0,
            high: 32767.0,
            falling: false,
        };
        assert!((eval(wide, 0.0) - 0.5).abs() < 1e-4);
        assert_eq!(eval(wide, 40000.0), 1.0);
        let narrow = Cdf::new(&CdfSpec::Sigmoid {
            low: 0.0,
            high: 2.0 / 65536.0,
            falling: false,
        })
        .expect("two steps wide");
        assert_eq!(narrow.eval(Signal::from_bits(1)).to_f32(), 0.5);
        assert_eq!(narrow.eval(Signal::MAX), Confidence::ONE);
        assert_eq!(narrow.eval(Signal::MIN), Confidence::ZERO);
    }

    #[test]
    fn bad_parameters_are_named() {
        assert_eq!(
            Cdf::new(&CdfSpec::Sigmoid {
                low: 2.0,
                high: 1.0,
                falling: false
            }),
            Err(CdfError::OutOfOrder {
                first: "low",
                first_value: 2.0,
                second: "high",
                second_value: 1.0
            })
        );
        assert_eq!(
            Cdf::new(&CdfSpec::Bell {
                center: f32::NAN,
                half_width: 1.0
            })
            .map_err(|e| matches!(
                e,
                CdfError::NotRepresentable {
                    param: "center",
                    ..
                }
            )),
            Err(true)
        );
        assert_eq!(
            Cdf::new(&CdfSpec::Bell {
                center: 0.0,
                half_width: 0.0
            }),
            Err(CdfError::TooNarrow {
                param: "half_width",
                value: 0.0
            })
        );
        assert_eq!(
            Cdf::new(&CdfSpec::Binary {
                threshold: f32::INFINITY,
                above: true
            }),
            Err(CdfError::NotRepresentable {
                param: "threshold",
                value: f32::INFINITY
            })
        );
        assert!(matches!(
            Cdf::new(&CdfSpec::FlatBell {
                low: 0.0,
                plateau_low: 2.0,
                plateau_high: 1.0,
                high: 3.0
            }),
            Err(CdfError::OutOfOrder {
                first: "plateau_low",
                second: "plateau_high",
                ..
            })
        ));
        assert!(matches!(
            Cdf::new(&CdfSpec::Sigmoid {
                low: 0.0,
                high: 1e-7,
                falling: false
            }),
            Err(CdfError::TooNarrow { .. })
        ));
    }
}
