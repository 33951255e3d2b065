//! The combiner against eq. 14, Ψ = Π context ψ × min(1, Σ w ψ), on cases worked out by
//! hand. Every feature is a raw channel and every CDF a sigmoid or bell of the S-function
//! S(t) = 2t² (t ≤ ½), 1 − 2(1 − t)² (t ≥ ½), whose values at quarter points are exact:
//! a sigmoid from 0 to 4 gives S(¼) = ⅛ at 1, S(½) = ½ at 2, S(¾) = ⅞ at 3, 1 from 4.
//!
//! Each case checks the engine (event and term confidences, within the stated LSBs of Q15:
//! weights are rounded to Q15, so a weight like 0.3 costs up to ½ LSB), the model's
//! `combine` and the model's whole tick (to 1e-7, the `f32` weights' own rounding).

#[path = "reference_support.rs"]
mod support;

use detector_build::Config;
use detector_core::{CdfSpec, EventId};
use host_tests::reference::{Model, combine};
use support::*;

/// A sigmoid from 0 to 4: ⅛ at 1, ½ at 2, ⅞ at 3.
fn s04() -> CdfSpec {
    sigmoid(0.0, 4.0)
}

/// Channels `a b c d`, raw features `fa fb fc fd` of them, and the given event.
fn raw_config(e: detector_build::EventSpec) -> Config {
    config(
        1000.0,
        &["a", "b", "c", "d"],
        vec![
            ("fa", raw("a")),
            ("fb", raw("b")),
            ("fc", raw("c")),
            ("fd", raw("d")),
        ],
        vec![e],
        vec![phase("p", &["e"])],
    )
}

/// Runs one tick with samples `a b c d`; checks the engine's event confidence against `want`
/// within `lsb` steps of Q15, its term confidences against `terms` (context then sensor)
/// within 1 LSB, and the model's against `want` to 1e-7 (the model uses the `f32` weights
/// exactly: 0.3f32 is 0.30000001…).
fn check(config: &Config, samples: [f64; 4], want: f64, terms: &[f64], lsb: f64) {
    let det = detector_build::build(config).expect("valid");
    let mut st = det.new_state();
    let out = det.tick(&mut st, 0, &inputs_f64(&samples, 0));
    let got = out.confidences[0].to_f64();
    assert!(
        (got - want).abs() <= lsb / 32768.0,
        "engine Ψ = {got}, hand-worked {want}"
    );
    let (c, s) = st.terms(&det, EventId(0)).expect("event");
    let engine_terms: Vec<f64> = c.iter().chain(s.iter()).map(|x| x.to_f64()).collect();
    assert_eq!(engine_terms.len(), terms.len());
    for (g, w) in engine_terms.iter().zip(terms) {
        assert!((g - w).abs() <= 1.0 / 32768.0, "term {g} vs {w}");
    }
    let model = Model::new(config).expect("resolves");
    let mut ms = model.new_state();
    let m = model.tick(&mut ms, 0, &samples, 0);
    assert!(
        (m.judgement.confidences[0] - want).abs() <= 1e-7,
        "model Ψ = {}, hand-worked {want}",
        m.judgement.confidences[0]
    );
}

/// One context term at ½, sensors ⅛ (w 0.5) and ⅞ (w 0.3):
/// Ψ = ½ × (0.5·⅛ + 0.3·⅞) = ½ × (0.0625 + 0.2625) = ½ × 0.325 = 0.1625.
/// In Q15, 0.3 is 9830/32768 (½ LSB low), so the engine may be 1 LSB off.
#[test]
fn one_context_two_weighted_sensors() {
    let e = event(
        "e",
        vec![context("fc", s04())],
        vec![sensor("fa", 0.5, s04()), sensor("fb", 0.3, s04())],
    );
    check(
        &raw_config(e),
        [1.0, 3.0, 2.0, 0.0],
        0.1625,
        &[0.5, 0.125, 0.875],
        1.0,
    );
}

/// Two context terms ½ and ⅞ and one sensor of weight 1 at ⅞:
/// Ψ = ½ × ⅞ × ⅞ = 49/128 = 0.3828125, exactly 12544/32768.
#[test]
fn context_terms_multiply() {
    let e = event(
        "e",
        vec![context("fc", s04()), context("fd", s04())],
        vec![sensor("fa", 1.0, s04())],
    );
    check(
        &raw_config(e),
        [3.0, 0.0, 2.0, 3.0],
        0.3828125,
        &[0.5, 0.875, 0.875],
        0.0,
    );
}

/// A context term at 0 vetoes everything: sensors at 1 with weights 0.6 + 0.4 give Σ = 1,
/// but Ψ = 0 × 1 = 0.
#[test]
fn a_zero_context_vetoes() {
    let e = event(
        "e",
        vec![context("fc", s04())],
        vec![sensor("fa", 0.6, s04()), sensor("fb", 0.4, s04())],
    );
    check(
        &raw_config(e),
        [5.0, 4.0, 0.0, 0.0],
        0.0,
        &[0.0, 1.0, 1.0],
        0.0,
    );
}

/// Weights summing above 1 make either term sufficient: weights 1 and 1 on ψ = 1 and 0
/// give Ψ = 1; on ψ = 1 and 1 the sum saturates at 1.
#[test]
fn weights_above_one_saturate() {
    let e = event(
        "e",
        vec![],
        vec![sensor("fa", 1.0, s04()), sensor("fb", 1.0, s04())],
    );
    check(
        &raw_config(e.clone()),
        [5.0, 0.0, 0.0, 0.0],
        1.0,
        &[1.0, 0.0],
        0.0,
    );
    check(&raw_config(e), [5.0, 4.0, 0.0, 0.0], 1.0, &[1.0, 1.0], 0.0);
}

/// No context terms: Ψ is the weighted sum. Weights ¼, ¼, ½ on ψ = 1, ½, ⅛:
/// ¼ + ⅛ + 1/16 = 7/16 = 0.4375 exactly. A bell centred at 0 of half-width 4 gives ⅞ at
/// distance 1 (1 − S(¼)) and is the fourth term here with weight 0, contributing nothing.
#[test]
fn no_context_is_the_weighted_sum() {
    let e = event(
        "e",
        vec![],
        vec![
            sensor("fa", 0.25, s04()),
            sensor("fb", 0.25, s04()),
            sensor("fc", 0.5, s04()),
            sensor(
                "fd",
                0.0,
                CdfSpec::Bell {
                    center: 0.0,
                    half_width: 4.0,
                },
            ),
        ],
    );
    check(
        &raw_config(e),
        [4.0, 2.0, 1.0, -1.0],
        0.4375,
        &[1.0, 0.5, 0.125, 0.875],
        0.0,
    );
}

/// Weights 0.1 + 0.2 + 0.7 with every sensor at 1: their Q15 roundings 3277 + 6554 + 22938
/// sum to 32769, a step above 1 (validation allows 2 steps), and the cap keeps Ψ = 1
/// exactly. With a context term at ⅞ on top, Ψ = ⅞.
#[test]
fn the_sum_is_capped_at_one() {
    let sensors = || {
        vec![
            sensor("fa", 0.1, s04()),
            sensor("fb", 0.2, s04()),
            sensor("fc", 0.7, s04()),
        ]
    };
    check(
        &raw_config(event("e", vec![], sensors())),
        [9.0, 9.0, 9.0, 3.0],
        1.0,
        &[1.0, 1.0, 1.0],
        0.0,
    );
    let with_context = event("e", vec![context("fd", s04())], sensors());
    check(
        &raw_config(with_context),
        [9.0, 9.0, 9.0, 3.0],
        0.875,
        &[0.875, 1.0, 1.0, 1.0],
        0.0,
    );
}

/// The paper's example in the brief: context ½, weights 0.5 / 0.3 on ψ = ½ / ½:
/// Ψ = ½ × (0.25 + 0.15) = 0.2.
#[test]
fn half_context_half_sensors() {
    let e = event(
        "e",
        vec![context("fc", s04())],
        vec![sensor("fa", 0.5, s04()), sensor("fb", 0.3, s04())],
    );
    check(
        &raw_config(e),
        [2.0, 2.0, 2.0, 0.0],
        0.2,
        &[0.5, 0.5, 0.5],
        1.0,
    );
}

/// The model's `combine` on the same hand-worked numbers.
#[test]
fn model_combine_is_eq_14() {
    assert!((combine(&[0.5], &[(0.5, 0.125), (0.3, 0.875)]) - 0.1625).abs() < 1e-15);
    assert_eq!(combine(&[0.5, 0.875], &[(1.0, 0.875)]), 0.3828125);
    assert_eq!(combine(&[0.0], &[(0.6, 1.0), (0.4, 1.0)]), 0.0);
    assert_eq!(
        combine(&[], &[(0.25, 1.0), (0.25, 0.5), (0.5, 0.125)]),
        0.4375
    );
    assert_eq!(combine(&[0.875], &[(0.7, 1.0), (0.7, 1.0)]), 0.875);
}
