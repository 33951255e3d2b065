//! What the detector-path tests share: detectors from TOML, randomized runs and what a
//! detector makes of them, and synthetic traces (the simulator's channels from the few a
//! test drives, and the force sensor's noise). Each test crate that includes it uses a part.
#![allow(dead_code)]

use detector_build::Config;
use detector_core::Detector;
use fingertip::APPROACH_TOML;
use fingertip::replay::replay;
use fingertip::score::{Outcome, classify};
use fingertip::sim::{self, CHANNELS, Scenario, SimOptions};
use fingertip::trace::Trace;
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

/// `n` sample times at 5 kHz from zero [s].
pub fn times(n: u32) -> Vec<f64> {
    (0..n).map(|k| f64::from(k) / 5000.0).collect()
}

/// A trace named `name` at times `t`: the channels in `given` as given (in the trace's
/// units), every other channel of the simulator's at zero.
pub fn trace_of(name: &str, t: Vec<f64>, given: Vec<(&str, Vec<f64>)>) -> Trace {
    let zeros = vec![0.0; t.len()];
    let mut channels: Vec<(String, Vec<f64>)> = CHANNELS
        .iter()
        .filter(|c| given.iter().all(|(g, _)| *g != c.name))
        .map(|c| (c.name.to_string(), zeros.clone()))
        .collect();
    channels.extend(given.into_iter().map(|(c, v)| (c.to_string(), v)));
    Trace::from_columns(name, t, channels).expect("a trace")
}

/// The force sensor's white noise, 1.5 cN RMS [N], the same sequence for the same `seed`.
pub fn force_noise(seed: u64) -> impl FnMut() -> f64 {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    move || 0.015 * rng.sample::<f64, _>(StandardNormal)
}

/// The detector a configuration's TOML builds.
pub fn detector(toml: &str) -> Detector {
    detector_build::build(&Config::from_toml(toml).expect("parses")).expect("builds")
}

/// The default detector with `written`, which `configs/approach.toml` must hold as written,
/// replaced by `instead`: the default without one of its parts, or with it changed.
pub fn default_with(written: &str, instead: &str) -> Detector {
    default_with_each(&[(written, instead)])
}

/// The default detector with each `(written, instead)` change of [`default_with`] made, in
/// order: a part changed while another that would mask it is taken away.
pub fn default_with_each(changes: &[(&str, &str)]) -> Detector {
    let toml = changes
        .iter()
        .fold(APPROACH_TOML.to_owned(), |toml, &(written, instead)| {
            assert!(
                toml.contains(written),
                "the default configuration no longer holds `{written}`: the test no longer tests it"
            );
            toml.replacen(written, instead, 1)
        });
    detector(&toml)
}

/// Of the randomized runs `picked` (each a scenario and a run seed, as `fingertip evaluate`
/// names them; the other options as in `base`), how many a `changed` default detector (see
/// [`default_with`]) confirms `event` on, the default itself checked to get every one of
/// them right.
pub fn confirming_where_right(
    changed: &Detector,
    picked: &[(Scenario, u64)],
    base: &SimOptions,
    event: &str,
) -> usize {
    let default = detector(APPROACH_TOML);
    picked
        .iter()
        .filter(|&&(s, seed)| {
            let run = runs(s, [seed], base);
            assert_eq!(right(&default, s, &run), [true], "{s:?} seed {seed}");
            confirmed(changed, &run[0]).iter().any(|e| e == event)
        })
        .count()
}

/// Obstacles stiff against the joint loops: the envelope's when the link collisions some
/// tests pick were picked (it now reaches down to padded ones), which those tests draw
/// from so that their runs stay the ones picked.
pub const STIFF_OBSTACLES: &str = "obstacle.stiffness=3e5..2e6";

/// Randomized runs against posts that yield (a padded fixture, a person's arm: 2·10^3 to
/// 1.5·10^4 N/m), the other options as the envelope's.
pub fn padded_posts() -> SimOptions {
    SimOptions {
        ranges: vec!["obstacle.stiffness=2e3..1.5e4".parse().expect("a range")],
        ..SimOptions::default()
    }
}

/// The randomized runs of scenario `s` on seeds `seeds`, the other options as in `base`.
pub fn runs(s: Scenario, seeds: impl IntoIterator<Item = u64>, base: &SimOptions) -> Vec<Trace> {
    seeds
        .into_iter()
        .map(|seed| {
            let opts = SimOptions {
                seed,
                randomize: true,
                ..base.clone()
            };
            sim::simulate(&s, &opts).expect("simulates")
        })
        .collect()
}

/// What `detector` makes of each of `traces` (runs of `s`).
pub fn outcomes(detector: &Detector, s: Scenario, traces: &[Trace]) -> Vec<Outcome> {
    traces
        .iter()
        .map(|tr| {
            let (on, _) = tr.truth_onset().expect("an event");
            let decisions = replay(detector, tr, |_, _, _| {}).expect("replays");
            classify(s.expected().map(|e| (e, tr.time()[on])), &decisions)
        })
        .collect()
}

/// How many of `traces` (runs of `s`) `detector` gets right within `within_s` of the onset.
pub fn right_within(detector: &Detector, s: Scenario, traces: &[Trace], within_s: f64) -> usize {
    outcomes(detector, s, traces)
        .iter()
        .filter(|o| matches!(o, Outcome::Correct { latency_s } if *latency_s <= within_s))
        .count()
}

/// The events `detector` confirms on `trace`, in order.
pub fn confirmed(detector: &Detector, trace: &Trace) -> Vec<String> {
    replay(detector, trace, |_, _, _| {})
        .expect("replays")
        .iter()
        .filter(|d| d.is_confirm())
        .map(|d| d.event.to_string())
        .collect()
}

/// When `detector` first confirms `event` on `trace` [s].
pub fn confirmed_at(detector: &Detector, trace: &Trace, event: &str) -> Option<f64> {
    replay(detector, trace, |_, _, _| {})
        .expect("replays")
        .iter()
        .find(|d| d.is_confirm() && d.event == event)
        .map(|d| d.t_s)
}

/// Minutes of free motion, the runs `seeds` with `range` drawn: the default confirms
/// nothing in any, and `changed` (`what` it is) confirms `event` in each.
pub fn minutes_read_only_by(
    seeds: &[u64],
    range: &str,
    changed: &Detector,
    what: &str,
    event: &str,
) {
    let options = SimOptions {
        duration_s: Some(60.0),
        ranges: vec![range.parse().expect("a range")],
        ..SimOptions::default()
    };
    let minutes = runs(Scenario::FreeMotion, seeds.iter().copied(), &options);
    let default = detector(APPROACH_TOML);
    for (seed, minute) in seeds.iter().zip(&minutes) {
        assert_eq!(
            confirmed(&default, minute),
            Vec::<String>::new(),
            "free motion {seed} with {range}"
        );
        assert!(
            confirmed_at(changed, minute, event).is_some(),
            "{what}, free motion {seed} with {range} confirms no {event} either: the test no longer shows what the change does"
        );
    }
}

/// Whether `detector` gets each of `traces` (runs of `s`) right.
pub fn right(detector: &Detector, s: Scenario, traces: &[Trace]) -> Vec<bool> {
    outcomes(detector, s, traces)
        .iter()
        .map(Outcome::is_right)
        .collect()
}

/// 500 ms at a steady commanded `speed` [m/s] along the approach (below zero, away from
/// the pad), the position error along it `err_um(t)` (t in s from the start): nothing on
/// the fingertip's sensors.
pub fn steady_motion(speed: f64, err_um: impl Fn(f64) -> f64) -> Trace {
    let t = times(2500);
    let err = t.iter().map(|&s| err_um(s) * 1e-6).collect();
    let speed = vec![speed; t.len()];
    trace_of(
        "steady motion",
        t,
        vec![("pos_err_x", err), ("vel_des_x", speed)],
    )
}
