//! Shape properties of each confidence distribution function over random parameters and
//! inputs, as the `cdf` module documents them:
//!
//! - every value in [0, 1];
//! - sigmoid: 0 at or below `low`, 1 at or above `high`, non-decreasing (falling: the mirror,
//!   non-increasing);
//! - bell: 1 at the centre, ½ (within 2 LSB: the position is truncated) at half the half-width, 0 at or beyond the
//!   half-width, symmetric about the centre within 1 LSB of Q15, non-increasing away from it;
//! - flat bell: 1 on the plateau, 0 outside (low, high), non-decreasing on the rising
//!   shoulder and non-increasing on the falling one;
//! - binary: exactly 0 or 1, 1 at the threshold itself (inclusive);
//! - every shape within 2.5 LSB of Q15 (2.5 · 2⁻¹⁵) of the `f64` model for parameters and
//!   inputs exact in 16.16 (the S-function position is truncated to Q15, at most 2 LSB after
//!   the slope of 2, plus ½ LSB of rounding).
//!
//! Parameters are random 16.16 bit patterns converted to `f32` (so any magnitude, any
//! width down to one step); inputs lie around and beyond the parameters.
//! Case counts: [`CASES`] per property (override with `PROPTEST_CASES`).

#[path = "reference_support.rs"]
mod support;

use detector_core::{Cdf, CdfSpec, Confidence, Signal};
use host_tests::reference::cdf;
use proptest::prelude::*;
use support::proptest_config;

/// Cases per property.
const CASES: u32 = 1024;

fn f(bits: i64) -> f32 {
    Signal::from_bits(bits.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32).to_f32()
}

/// The engine's 16.16 bits for an `f32` parameter.
fn bits(v: f32) -> i64 {
    i64::from(Signal::from_f32(v).to_bits())
}

fn eval(c: &Cdf, x: i64) -> u16 {
    let x = x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
    c.eval(Signal::from_bits(x)).to_bits()
}

/// Sorted raw parameter bits `a < b` within ±16384 (so `f32` rounding stays in range), of
/// any width from one step.
fn ordered_pair() -> impl Strategy<Value = (i64, i64)> {
    (-(1i64 << 30)..(1i64 << 30), 0u32..=30).prop_flat_map(|(a, k)| {
        (Just(a), 1i64..=(1i64 << k).max(2)).prop_map(|(a, w)| {
            let a = a.min((1i64 << 30) - w);
            (a, a + w)
        })
    })
}

proptest! {
    #![proptest_config(proptest_config(CASES, "proptest-regressions/core_cdf_shapes.txt"))]

    /// Sigmoid: range, end values, monotone (rising non-decreasing, falling non-increasing).
    #[test]
    fn sigmoid_is_monotone((lo, hi) in ordered_pair(), falling: bool, d in 0i64..=1 << 20, raw in any::<u64>()) {
        let spec = CdfSpec::Sigmoid { low: f(lo), high: f(hi), falling };
        let Ok(c) = Cdf::new(&spec) else {
            // Only a pair that collapses to one 16.16 value after f32 rounding may be rejected.
            prop_assert!(bits(f(lo)) >= bits(f(hi)));
            return Ok(());
        };
        let (l, h) = (bits(f(lo)), bits(f(hi)));
        let span = h - l;
        let x1 = l - span + (raw % (3 * span as u64 + 1)) as i64;
        let x2 = x1 + d.min(span);
        let (y1, y2) = (eval(&c, x1), eval(&c, x2));
        prop_assert!(y1 <= 32768 && y2 <= 32768);
        if falling {
            prop_assert!(y1 >= y2, "falling: f({}) = {} < f({}) = {}", x1, y1, x2, y2);
        } else {
            prop_assert!(y1 <= y2, "rising: f({}) = {} > f({}) = {}", x1, y1, x2, y2);
        }
        let (at_low, at_high) = if falling { (32768, 0) } else { (0, 32768) };
        prop_assert_eq!(eval(&c, l), at_low);
        prop_assert_eq!(eval(&c, l - 1 - d), at_low);
        prop_assert_eq!(eval(&c, h), at_high);
        prop_assert_eq!(eval(&c, h + 1 + d), at_high);
    }

    /// Bell: 1 at the centre, ½ at half the half-width, 0 from the half-width on, symmetric
    /// within 1 LSB, non-increasing away from the centre.
    #[test]
    fn bell_is_symmetric_and_unimodal(
        center in -(1i32 << 30)..(1i32 << 30),
        hw in 1i64..=1 << 30,
        d1 in 0i64..=1 << 31,
        step in 0i64..=1 << 20,
    ) {
        let spec = CdfSpec::Bell { center: f(i64::from(center)), half_width: f(hw) };
        let c = Cdf::new(&spec);
        prop_assert!(c.is_ok(), "{:?}: {:?}", spec, c);
        let Ok(c) = c else { return Ok(()) };
        let (m, w) = (bits(f(i64::from(center))), bits(f(hw)));
        let d1 = d1 % (2 * w);
        let d2 = d1 + step.min(w);
        let inside = |x: i64| x >= i64::from(i32::MIN) && x <= i64::from(i32::MAX);
        prop_assert_eq!(eval(&c, m), 32768);
        if inside(m + d1) && inside(m - d1) {
            let (a, b) = (eval(&c, m + d1), eval(&c, m - d1));
            prop_assert!(a.abs_diff(b) <= 1, "asymmetric at ±{}: {} vs {}", d1, a, b);
        }
        for sign in [1i64, -1] {
            if inside(m + sign * d2) {
                let (near, far) = (eval(&c, m + sign * d1), eval(&c, m + sign * d2));
                prop_assert!(near >= far, "not unimodal: f(c{:+}) = {} < f(c{:+}) = {}", sign * d1, near, sign * d2, far);
            }
            if inside(m + sign * w) {
                prop_assert_eq!(eval(&c, m + sign * w), 0);
            }
            if w % 2 == 0 && inside(m + sign * w / 2) {
                prop_assert!(eval(&c, m + sign * w / 2).abs_diff(16384) <= 2);
            }
        }
    }

    /// Flat bell: 1 on the plateau, 0 outside [low, high], monotone on each shoulder.
    #[test]
    fn flat_bell_has_plateau_and_monotone_shoulders(
        (lo, pl) in ordered_pair(),
        plateau in 0i64..=1 << 24,
        shoulder in 1i64..=1 << 24,
        raw in any::<[u32; 2]>(),
        step in 0i64..=1 << 16,
    ) {
        let (ph, hi) = (pl + plateau, pl + plateau + shoulder);
        prop_assume!(hi <= i64::from(i32::MAX));
        let spec = CdfSpec::FlatBell {
            low: f(lo), plateau_low: f(pl), plateau_high: f(ph), high: f(hi),
        };
        let [l, pl, ph, h] = [lo, pl, ph, hi].map(|b| bits(f(b)));
        let Ok(c) = Cdf::new(&spec) else {
            // Only rounding to f32 may merge parameters that were distinct.
            prop_assert!(l >= pl || pl > ph || ph >= h, "{:?} rejected", spec);
            return Ok(());
        };
        // Plateau.
        let x = pl + i64::from(raw[0]) % (ph - pl + 1);
        prop_assert_eq!(eval(&c, x), 32768);
        // Outside.
        prop_assert_eq!(eval(&c, l), 0);
        prop_assert_eq!(eval(&c, h), 0);
        prop_assert_eq!(eval(&c, l - 1 - step), 0);
        prop_assert_eq!(eval(&c, h + 1 + step), 0);
        // Shoulders.
        let x1 = l + i64::from(raw[1]) % (pl - l + 1);
        let x2 = (x1 + step).min(pl);
        prop_assert!(eval(&c, x1) <= eval(&c, x2), "rising shoulder at {}..{}", x1, x2);
        let y1 = ph + i64::from(raw[1]) % (h - ph + 1);
        let y2 = (y1 + step).min(h);
        prop_assert!(eval(&c, y1) >= eval(&c, y2), "falling shoulder at {}..{}", y1, y2);
    }

    /// Binary: exactly 0 or 1, inclusive at the threshold.
    #[test]
    fn binary_is_zero_or_one_and_inclusive(threshold in any::<i32>(), above: bool, x in any::<i32>()) {
        let t = f(i64::from(threshold));
        let c = Cdf::new(&CdfSpec::Binary { threshold: t, above });
        prop_assert!(c.is_ok());
        let Ok(c) = c else { return Ok(()) };
        let tb = bits(t);
        let y = eval(&c, i64::from(x));
        let on = if above { i64::from(x) >= tb } else { i64::from(x) <= tb };
        prop_assert_eq!(y, if on { 32768 } else { 0 });
        prop_assert_eq!(eval(&c, tb), 32768);
    }

    /// Every shape within 2.5 LSB of Q15 of the `f64` model for exact parameters and inputs.
    #[test]
    fn every_shape_matches_the_model(
        (lo, hi) in ordered_pair(),
        plateau in 0i64..=1 << 20,
        shoulder in 1i64..=1 << 28,
        falling: bool,
        raw in any::<u64>(),
    ) {
        // Parameters exact in both f32 and 16.16.
        let e = |b: i64| f(bits(f(b)));
        let (ph, h2) = (hi + plateau, hi + plateau + shoulder);
        prop_assume!(h2 <= i64::from(i32::MAX));
        let specs = [
            CdfSpec::Sigmoid { low: e(lo), high: e(hi), falling },
            CdfSpec::Bell { center: e(lo), half_width: e(hi - lo) },
            CdfSpec::FlatBell { low: e(lo), plateau_low: e(hi), plateau_high: e(ph), high: e(h2) },
            CdfSpec::Binary { threshold: e(hi), above: falling },
        ];
        let span = (h2 - lo).max(1);
        let x = lo - span + (raw % (3 * span as u64 + 1)) as i64;
        let x = x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32;
        for spec in specs {
            let Ok(c) = Cdf::new(&spec) else { continue };
            let got = c.eval(Signal::from_bits(x)).to_f64();
            let want = cdf(&spec, Signal::from_bits(x).to_f64());
            prop_assert!((got - want).abs() < 2.5 / 32768.0,
                "{:?} at {}: engine {} model {}", spec, Signal::from_bits(x).to_f64(), got, want);
        }
    }
}

/// Hand-worked values of the S-function shapes: sigmoid 0..4 at 1 (t = ¼) is 2·(¼)² = ⅛, at
/// 3 (t = ¾) 1 − 2·(¼)² = ⅞, at 2 exactly ½; a bell of half-width 4 at distance 1 is
/// 1 − ⅛ = ⅞.
#[test]
fn hand_worked_values() {
    let sig = Cdf::new(&CdfSpec::Sigmoid {
        low: 0.0,
        high: 4.0,
        falling: false,
    })
    .expect("valid");
    let bell = Cdf::new(&CdfSpec::Bell {
        center: 10.0,
        half_width: 4.0,
    })
    .expect("valid");
    let at = |c: &Cdf, x: f32| c.eval(Signal::from_f32(x));
    let q = |v: f32| Confidence::from_f32(v).expect("in range");
    assert_eq!(at(&sig, 1.0), q(0.125));
    assert_eq!(at(&sig, 2.0), q(0.5));
    assert_eq!(at(&sig, 3.0), q(0.875));
    assert_eq!(at(&bell, 9.0), q(0.875));
    assert_eq!(at(&bell, 11.0), q(0.875));
    assert_eq!(at(&bell, 12.0), q(0.5));
    assert_eq!(at(&bell, 14.0), q(0.0));
}
