//! A detector's state saved ([`State::save`]) and restored ([`Detector::restore`]): the
//! start of a flight recording. A restored state resumes bit for bit; saved bytes that are
//! not a state this detector can reach are refused, naming why; and no mutation of saved
//! bytes makes a tick panic (dev profile: integer overflow panics too).

#[path = "reference_support.rs"]
mod support;

use detector_build::Config;
use detector_core::feature::MAX_SLOTS;
use detector_core::{Detector, Inputs, Output, SAVED_MAGIC, Signal, State, StateError};
use proptest::prelude::*;
use support::{cases, proptest_config};

fn default_detector() -> Detector {
    let config = Config::from_toml(include_str!("../../configs/approach.toml")).expect("parses");
    detector_build::build(&config).expect("builds")
}

/// Inputs of tick `k` of a run that has everything a state holds: quiet motion, then a
/// ramp of force and stress rate, vibration on the force, a position error, commanded
/// accelerations, and now and then a withheld channel. The load is taken off from tick
/// 1400 to 1900 and put on again, so that levels are raised after every cut.
fn inputs_at(detector: &Detector, k: u32) -> Inputs {
    let t = f64::from(k) / 5000.0;
    let phase = f64::from(k % 97) / 97.0;
    let load_start = if k > 1900 { 1900 } else { 1200 };
    let loaded = k > 1200 && !(1400..=1900).contains(&k);
    let si = |name: &str| -> f64 {
        match name {
            "force_x" if loaded => -0.002 * f64::from(k - load_start) + 0.05 * (t * 700.0).sin(),
            "force_x" => 0.01 * (t * 300.0).sin(),
            "force_y" => 0.02 * (t * 90.0).cos(),
            "skin_accel" => 3.0 * (t * 2000.0).sin() * phase,
            "stress_rate" if loaded => 8.0 + phase,
            "stress_rate" => 0.1 * phase,
            "pos_err_x" => 1e-5 * phase,
            "vel_des_x" => 0.05,
            "acc_des_x" if k % 700 < 40 => 2.0,
            _ => 0.0,
        }
    };
    let mut inputs = Inputs::default();
    for (i, c) in detector.channels().iter().enumerate() {
        inputs.samples[i] = detector.sample_from_si(i, si(c.as_str()));
    }
    inputs.faults = if k % 911 == 5 { 1 << 3 } else { 0 };
    inputs
}

/// Runs `state` from tick `from` to `to` (exclusive), returning every output.
fn run(detector: &Detector, state: &mut State, from: u32, to: u32) -> Vec<Output> {
    (from..to)
        .map(|k| detector.tick(state, k, &inputs_at(detector, k)))
        .collect()
}

#[test]
fn a_restored_state_resumes_bit_for_bit() {
    let detector = default_detector();
    for cut in [0, 1, 37, 1199, 1250, 1600] {
        let mut state = detector.new_state();
        run(&detector, &mut state, 0, cut);
        let mut saved = [0u8; State::SAVED_BYTES];
        state.save(&mut saved);
        let mut restored = detector
            .restore(&saved)
            .expect("a state saved by the same detector");
        assert_eq!(restored, state, "restored after {cut} ticks");
        let original = run(&detector, &mut state, cut, 2400);
        let resumed = run(&detector, &mut restored, cut, 2400);
        assert_eq!(resumed, original, "outputs after a restore at tick {cut}");
        assert_eq!(
            restored, state,
            "states at the end after a restore at tick {cut}"
        );
        // The run confirms something, so the comparison covers decisions too.
        assert!(
            original.iter().any(|o| !o.decisions.is_empty()),
            "the run raises levels"
        );
    }
}

/// Offsets in the saved form (docs/trace-format.md).
const PHASE: usize = 4;
const STAGES: usize = PHASE + 1 + 4 * MAX_SLOTS;
const STAGE_BYTES: usize = 15;

fn saved_after(detector: &Detector, ticks: u32) -> Vec<u8> {
    let mut state = detector.new_state();
    run(detector, &mut state, 0, ticks);
    let mut saved = [0u8; State::SAVED_BYTES];
    state.save(&mut saved);
    saved.to_vec()
}

#[test]
fn saved_bytes_that_are_not_a_reachable_state_are_refused_naming_why() {
    let detector = default_detector();
    let good = saved_after(&detector, 1300);
    let feature = |name: &str| {
        detector
            .features()
            .iter()
            .position(|f| f.as_str() == name)
            .expect("a feature of the default")
    };
    let envelope = feature("motion_ring");
    let mean = feature("stress_mean");
    let ste = feature("ste_force");
    // A running sum one step off the window's entries, all of them within range.
    let sum_off_by_one = |k: usize| {
        let mut b = good.clone();
        let at = STAGES + STAGE_BYTES * k;
        let sum = i64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
        b[at..at + 8].copy_from_slice(&(sum + 1).to_le_bytes());
        (b, StateError::Feature(k))
    };
    let cases: Vec<(Vec<u8>, StateError)> = vec![
        (good[..100].to_vec(), StateError::Length(100)),
        (
            [good.as_slice(), &[0]].concat(),
            StateError::Length(State::SAVED_BYTES + 1),
        ),
        (
            {
                let mut b = good.clone();
                b[0] = b'X';
                b
            },
            StateError::Magic,
        ),
        (
            {
                let mut b = good.clone();
                b[STAGES + STAGE_BYTES * 2 + 14] = 2;
                b
            },
            StateError::Flag,
        ),
        (
            {
                let mut b = good.clone();
                b[PHASE] = 1;
                b
            },
            StateError::Phase(1, 1),
        ),
        (
            {
                let mut b = good.clone();
                let at = STAGES + STAGE_BYTES * envelope;
                b[at..at + 8].copy_from_slice(&i64::MAX.to_le_bytes());
                b
            },
            StateError::Feature(envelope),
        ),
        (
            {
                // A window position past the window's end.
                let mut b = good.clone();
                let at = STAGES + STAGE_BYTES * mean + 12;
                b[at..at + 2].copy_from_slice(&u16::MAX.to_le_bytes());
                b
            },
            StateError::Feature(mean),
        ),
        sum_off_by_one(mean),
        sum_off_by_one(ste),
    ];
    for (bytes, expected) in cases {
        assert_eq!(detector.restore(&bytes), Err(expected));
        assert!(!expected.to_string().is_empty());
    }
    assert_eq!(&good[..4], &SAVED_MAGIC);
    assert!(
        StateError::Feature(mean)
            .to_string()
            .contains("another detector"),
        "the message suggests the likely cause"
    );
}

proptest! {
    #![proptest_config(proptest_config(cases(512), file!()))]

    /// Any bytes changed anywhere in a saved state: refused, or a state every tick runs
    /// on without a panic, whatever the inputs.
    #[test]
    fn no_mutation_of_a_saved_state_makes_a_tick_panic(
        changes in prop::collection::vec((0..State::SAVED_BYTES, any::<u8>()), 1..24),
        samples in prop::collection::vec(any::<i32>(), 16),
        faults in any::<u32>(),
    ) {
        let detector = default_detector();
        let mut bytes = saved_after(&detector, 1300);
        for (at, b) in changes {
            bytes[at] = b;
        }
        if let Ok(mut state) = detector.restore(&bytes) {
            let mut inputs = Inputs::default();
            for (s, &v) in inputs.samples.iter_mut().zip(&samples) {
                *s = Signal::from_bits(v);
            }
            inputs.faults = faults;
            for k in 0..300 {
                let out = detector.tick(&mut state, 1300 + k, &inputs);
                for c in out.confidences {
                    prop_assert!(c.to_f64() <= 1.0);
                }
            }
        }
    }
}
