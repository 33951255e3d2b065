//! Physical sanity of the simulator: the signatures the paper's features rely on (section
//! 3.2) must be there, in nominal runs and in randomized ones.

use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;

fn run(s: Scenario, seed: u64, randomize: bool) -> Trace {
    sim::simulate(
        &s,
        &SimOptions {
            seed,
            randomize,
            ..SimOptions::default()
        },
    )
    .expect("valid options")
}

fn col<'a>(tr: &'a Trace, name: &str) -> &'a [f64] {
    tr.column(name)
        .expect("simulated traces have every channel")
}

fn max_abs(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |m, v| m.max(v.abs()))
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Rows per millisecond at the default rate.
const MS: usize = 5;

/// The sensor's reading before the event: its offset, drift and noise averaged over the
/// 10 ms before `row`.
fn baseline(x: &[f64], row: usize) -> f64 {
    mean(&x[row.saturating_sub(10 * MS)..row])
}

fn onset_row(tr: &Trace) -> usize {
    tr.truth_onset().expect("the run has a truth onset").0
}

/// Randomized seeds checked per scenario (each run is ~0.15 s of simulated time).
const SEEDS: u64 = 40;

/// Stress rate that only noise, hum, offset, drift and crosstalk reach without contact:
/// noise at most 1 N/s RMS, offset 2 N/s, hum 3 LSB (1.5 N/s), crosstalk a few N/s in the
/// strongest disturbances.
const STRESS_QUIET: f64 = 15.0;

/// Without contact the stress-rate film stays at its noise floor all run long.
fn assert_stress_quiet(tr: &Trace, what: &str) {
    let sr = max_abs(col(tr, "stress_rate"));
    assert!(sr < STRESS_QUIET, "{what}: stress rate {sr}");
}

#[test]
fn contacts_force_rises_against_motion_and_stress_rate_fires() {
    let contacts = [
        Scenario::ContactHard8,
        Scenario::ContactHard5,
        Scenario::ContactHard2,
        Scenario::ContactSoft8,
        Scenario::ContactSoft5,
        Scenario::ContactSoft2,
        Scenario::ObjectMoves5,
        Scenario::ContactBraking,
    ];
    for s in contacts {
        for seed in 0..SEEDS {
            let randomize = seed > 0;
            let tr = run(s, seed, randomize);
            let on = onset_row(&tr);
            let f = col(&tr, "force_x");
            let v = col(&tr, "vel_des_x");
            let sr = col(&tr, "stress_rate");
            let what = format!("{s} seed {seed}");
            assert_eq!(tr.truth_onset().unwrap().1, "contact", "{what}");
            // Quiet before the onset, firing within 2 ms after it.
            assert!(
                max_abs(&sr[..on]) < STRESS_QUIET,
                "{what}: stress rate before onset"
            );
            let fired = mean(&sr[on..on + 2 * MS]) - baseline(sr, on);
            assert!(
                fired > 6.0,
                "{what}: stress rate must fire within 2 ms: {fired}"
            );
            // The force (less the sensor's offset) opposes the motion from 5 ms on, in
            // every 1 ms average, and keeps rising over 20 ms (an object that slides keeps
            // it at its friction level instead).
            let b = baseline(f, on);
            // A light object can slide ahead of the fingertip after it breaks away and
            // leave it for a while, and a braking finger soon stops pressing harder (its
            // inertial load, in the baseline, goes when the command stops): check their
            // first 10 ms only.
            let short = matches!(s, Scenario::ObjectMoves5 | Scenario::ContactBraking);
            let until = if short { 10 } else { 25 };
            for k in 5..until {
                let w = on + k * MS..on + (k + 1) * MS;
                let fv = (mean(&f[w.clone()]) - b) * mean(&v[w]);
                assert!(fv < 0.0, "{what}: force . velocity = {fv} at {k} ms");
            }
            let early = mean(&f[on + 4 * MS..on + 6 * MS]) - b;
            let later = mean(&f[on + 19 * MS..on + 21 * MS]) - b;
            if s == Scenario::ObjectMoves5 {
                assert!(later < -0.2, "{what}: pushing the object: {later}");
            } else if !short {
                assert!(
                    later < early - 0.05,
                    "{what}: force rises: {early} then {later}"
                );
            }
        }
    }
}

#[test]
fn hard_contact_rings_the_skin_at_impact() {
    for seed in 0..SEEDS {
        let tr = run(Scenario::ContactHard5, seed, true);
        let on = onset_row(&tr);
        let a = col(&tr, "skin_accel");
        let before = max_abs(&a[..on]);
        let after = max_abs(&a[on..on + 2 * MS]);
        assert!(
            after > 10.0 * before.max(1.0),
            "seed {seed}: {before} then {after}"
        );
    }
}

#[test]
fn collisions_and_disturbances_ring_about_zero_with_stress_rate_quiet() {
    for s in [
        Scenario::LinkCollision8,
        Scenario::LinkCollision2,
        Scenario::DisturbanceLarge5,
        Scenario::DisturbanceSmall5,
    ] {
        for seed in 0..SEEDS {
            let tr = run(s, seed, seed > 0);
            let on = onset_row(&tr);
            let what = format!("{s} seed {seed}");
            let b = baseline(col(&tr, "force_x"), on);
            let f: Vec<f64> = col(&tr, "force_x")[on..on + 40 * MS]
                .iter()
                .map(|x| x - b)
                .collect();
            assert_stress_quiet(&tr, &what);
            // The force oscillates: it takes both signs, well above noise, and its mean is
            // small against its swing.
            let hi = f.iter().cloned().fold(f64::MIN, f64::max);
            let lo = f.iter().cloned().fold(f64::MAX, f64::min);
            assert!(hi > 0.05 && lo < -0.05, "{what}: force swings {lo}..{hi}");
            assert!(
                mean(&f).abs() < 0.25 * (hi - lo),
                "{what}: mean {} vs swing {}",
                mean(&f),
                hi - lo
            );
        }
    }
}

#[test]
fn position_error_grows_for_contacts_and_collisions_not_disturbances() {
    // Growth of the position error 100 ms after the onset, over its value at the onset.
    let growth = |tr: &Trace| {
        let on = onset_row(tr);
        let e = col(tr, "pos_err_x");
        e[on + 100 * MS] - e[on]
    };
    for seed in 0..SEEDS {
        let r = seed > 0;
        for s in [
            Scenario::ContactHard2,
            Scenario::ContactSoft2,
            Scenario::ContactHard8,
        ] {
            let g = growth(&run(s, seed, r));
            assert!(g > 25e-6, "{s} seed {seed}: {g}");
        }
        for s in [Scenario::LinkCollision2, Scenario::LinkCollision8] {
            let g = growth(&run(s, seed, r));
            assert!(g > 700e-6, "{s} seed {seed}: {g}");
        }
        for s in [
            Scenario::DisturbanceLarge5,
            Scenario::DisturbanceSmall5,
            Scenario::DisturbanceSlow2,
            Scenario::KnockLink1,
            Scenario::KnockLink2,
        ] {
            let tr = run(s, seed, r);
            let on = onset_row(&tr);
            let e = col(&tr, "pos_err_x");
            // Disturbed, then brought back by the controller.
            let g = e[on + 100 * MS] - e[on];
            assert!(g.abs() < 15e-6, "{s} seed {seed}: {g}");
        }
    }
}

#[test]
fn knocks_push_the_finger_off_its_path_and_leave_the_skin_untouched() {
    for s in [Scenario::KnockLink1, Scenario::KnockLink2] {
        for seed in 0..SEEDS {
            let tr = run(s, seed, seed > 0);
            let on = onset_row(&tr);
            let what = format!("{s} seed {seed}");
            let e = col(&tr, "pos_err_x");
            let moved = e[on..on + 20 * MS]
                .iter()
                .fold(0.0f64, |m, x| m.max((x - e[on]).abs()));
            assert!(moved > 2e-6, "{what}: the error moved by {moved} m");
            assert_stress_quiet(&tr, &what);
        }
    }
}

/// A very soft object at 1 cm/s: the stress rate stays at its noise floor (the force builds
/// at 0.4 to 1.2 N/s), but the force against the motion grows steadily: by 24 to 72 mN
/// after 60 ms, more than the sensor's noise averaged over 10 ms.
#[test]
fn very_soft_contact_builds_force_without_stress_rate() {
    for seed in 0..SEEDS {
        let tr = run(Scenario::ContactVerySoft1, seed, seed > 0);
        let on = onset_row(&tr);
        let what = format!("seed {seed}");
        let f = col(&tr, "force_x");
        let b = baseline(f, on);
        let at_60 = mean(&f[on + 55 * MS..on + 65 * MS]) - b;
        assert!(at_60 < -0.015, "{what}: force {at_60} N after 60 ms");
        assert_stress_quiet(&tr, &what);
    }
}

/// In `contact_braking` the command decelerates before and through the contact.
#[test]
fn braking_contact_happens_while_the_command_decelerates() {
    for seed in 0..SEEDS {
        let tr = run(Scenario::ContactBraking, seed, seed > 0);
        let on = onset_row(&tr);
        let a = col(&tr, "acc_des_x");
        let v = col(&tr, "vel_des_x");
        let what = format!("seed {seed}");
        assert!(a[on] < -0.25 && a[on] > -1.05, "{what}: acc_des {}", a[on]);
        assert!(a[on.saturating_sub(5 * MS)] < 0.0, "{what}: braking before");
        assert!(v[on] > 0.005, "{what}: still moving: {}", v[on]);
    }
}

#[test]
fn collision_stops_the_finger_while_the_command_goes_on() {
    let tr = run(Scenario::LinkCollision8, 1, false);
    let on = onset_row(&tr);
    let e = col(&tr, "pos_err_x");
    // 100 ms after the onset the arm has stood still: the error has grown by nearly the
    // commanded travel (8 cm/s x 0.1 s = 8 mm), less the bounce.
    let g = e[on + 100 * MS] - e[on];
    assert!(g > 6e-3 && g < 8.5e-3, "{g}");
    // The first force swing is positive: the fingertip decelerates, force . velocity > 0.
    let f = &col(&tr, "force_x")[on..on + 10 * MS];
    let first_big = f.iter().find(|x| x.abs() > 0.2).unwrap();
    assert!(*first_big > 0.0);
}

#[test]
fn sudden_acceleration_loads_the_force_sensor_with_the_fingertip_mass() {
    for s in [
        Scenario::SuddenAccelStandstill,
        Scenario::SuddenAccelMoving5,
    ] {
        for seed in 0..SEEDS {
            let r = seed > 0;
            let tr = run(s, seed, r);
            let what = format!("{s} seed {seed}");
            assert!(tr.truth_onset().is_none(), "{what}: no event");
            assert!(tr.meta(sim::META_ONSET).is_none(), "{what}");
            let acc = col(&tr, "acc_des_x");
            let f = col(&tr, "force_x");
            let rows: Vec<usize> = (0..tr.len()).filter(|&k| acc[k] > 5.0).collect();
            let (first, last) = (rows[0], *rows.last().unwrap());
            assert!(
                rows.len() == last - first + 1,
                "{what}: one acceleration step"
            );
            let a = acc[first];
            let param = |k: &str| tr.meta(k).unwrap().parse::<f64>().unwrap();
            let m = param("param.plant.carrier_mass") + param("param.plant.skin_mass");
            // The tip follows the command within a few ms, through the structure's
            // compliance; over the step and 3 ms after, the force averages about -m a.
            let b = baseline(f, first);
            let window = &f[first..(last + 3 * MS).min(tr.len())];
            let avg = mean(window) - b;
            assert!(
                avg < -0.5 * m * a && avg > -1.5 * m * a,
                "{what}: mean force {avg} vs -m a = {}",
                -m * a
            );
            // Before the step the sensor reads only noise (and hum, and drift).
            let quiet = f[..first].iter().fold(0.0f64, |m, x| m.max((x - b).abs()));
            assert!(quiet < 0.12, "{what}: {quiet}");
            assert_stress_quiet(&tr, &what);
        }
    }
}

#[test]
fn free_motion_has_no_event_and_no_contact_stress() {
    for seed in 0..3 {
        let tr = sim::simulate(
            &Scenario::FreeMotion,
            &SimOptions {
                seed,
                randomize: true,
                duration_s: Some(3.0),
                ..SimOptions::default()
            },
        )
        .unwrap();
        assert!(tr.truth_onset().is_none());
        assert!(tr.truth().unwrap().iter().all(|s| s.is_empty()));
        assert_stress_quiet(&tr, &format!("free motion seed {seed}"));
        // It does move, in both axes.
        assert!(max_abs(col(&tr, "vel_des_x")) > 0.005);
        assert!(max_abs(col(&tr, "vel_des_y")) > 0.005);
        assert_eq!(tr.meta(sim::META_EXPECTED), Some("none"));
    }
}

#[test]
fn truth_onset_is_the_physical_onset() {
    for s in Scenario::table1().iter().filter(|s| s.expected().is_some()) {
        for seed in 0..SEEDS {
            let r = seed > 0;
            let tr = run(*s, seed, r);
            let what = format!("{s} seed {seed}");
            let onset: f64 = tr.meta(sim::META_ONSET).unwrap().parse().unwrap();
            let scheduled: f64 = tr.meta("scheduled_onset_s").unwrap().parse().unwrap();
            // The physical onset is where it was staged; the drive's ripple and friction
            // move the tip by a few micrometres, i.e. a fraction of a millisecond at
            // 2 cm/s. A nominal run is within an integration step or two.
            let tol = if r { 0.5e-3 } else { 50e-6 };
            assert!(
                (onset - scheduled).abs() < tol,
                "{what}: {onset} vs {scheduled}"
            );
            // The truth column starts on the first row at or after the onset.
            let (row, event) = tr.truth_onset().unwrap();
            assert_eq!(Some(event), s.expected(), "{what}");
            let t = tr.time();
            assert!(t[row] >= onset && t[row - 1] < onset, "{what}");
            // ... and holds the event on every row after it.
            let truth = tr.truth().unwrap();
            assert!(truth.iter().skip(row).all(|e| e == event), "{what}");
        }
        // The nominal runs reproduce Table 1: the event at 20 ms.
        let tr = run(*s, 7, false);
        let onset: f64 = tr.meta(sim::META_ONSET).unwrap().parse().unwrap();
        assert!((onset - 0.020).abs() < 50e-6, "{s}: {onset}");
        assert_eq!(tr.len(), 751, "{s}: 150 ms at 5 kHz");
    }
}

#[test]
fn onset_follows_the_randomized_schedule() {
    let mut onsets = Vec::new();
    for seed in 1..30 {
        let tr = run(Scenario::ContactHard8, seed, true);
        let onset: f64 = tr.meta(sim::META_ONSET).unwrap().parse().unwrap();
        assert!((0.015..=0.0405).contains(&onset), "{onset}");
        // Every run lasts onset + 130 ms.
        let end = *tr.time().last().unwrap();
        assert!((end - (onset + 0.130)).abs() < 0.5e-3, "{end} vs {onset}");
        onsets.push(onset);
    }
    let spread = onsets.iter().cloned().fold(f64::MIN, f64::max)
        - onsets.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread > 0.01, "onsets vary: {spread}");
}
