//! How soon after its onset any detector can tell a link collision from a blow on the link,
//! and a hard contact from a blow on the pad:
//! `cargo run --release -p fingertip --example twins [RUNS] [BASE_SEED]`.
//!
//! Each link collision (at 8 and at 2 cm/s) and each hard contact (at 8, 5 and 2 cm/s) is
//! run again with the same seed, so with the same arm, sensors, motion and noise, but with
//! an obstacle or an object that gives way `g` ms after the link or the skin first touches
//! it (`SimOptions::gives_way_s`): a blow of the event's own force, `g` ms long, on the link
//! or on the pad, after which the finger is free. Until it gives way the two runs' readings
//! are the same bit for bit, so every causal detector decides the same in both: one that
//! confirms the event by then confirms it on the blow too, and a blow is a disturbance.
//! For each `g`, over all runs:
//! - how long after the onset the ten channels stay identical (the first row where any
//!   differs): the shortest and the median;
//! - the blows' peak force, and how many of them are, in force and length, taps of the
//!   envelope (peaks of 1-15 N, 0.5-3 ms: `large_disturbance`, `small_disturbance` and
//!   `knock`), a half-sine there where the blow has the event's shape; for a link, how
//!   many are taps of the force a separately written model strikes a link with (5-15 N
//!   and 50-200 N; counted here as 5-200 N);
//! - for a link, how many blows are the first push of a vibration burst of the envelope's
//!   40-150 Hz (half a period: 3.3-12.5 ms) with the amplitude of that model's bursts on
//!   a link (small ones 1-5 N, large ones 10-40 N; counted here as 1-40 N), and how many
//!   of these have a large one's: the push of a burst whose waveform has the collision's
//!   shape, which until it turns to pull is the collision bit for bit;
//! - what the default detector confirms on the blow, and on how many of the events it
//!   confirmed the event before the readings part (it then confirms it on the blow).

mod seeds;

use detector_core::Detector;
use fingertip::APPROACH_TOML;
use fingertip::replay::{self, DecisionRecord};
use fingertip::score::{Latency, nearest_rank};
use fingertip::sim::{self, CHANNELS, Scenario, SimOptions};
use fingertip::trace::Trace;
use rayon::prelude::*;

/// How long after the first touch the obstacle or the object gives way (ms).
/// Besides the taps' lengths, the half periods of bursts at 150, 100, 50 and 40 Hz.
const GIVE_WAY_MS: [f64; 8] = [0.5, 1.0, 2.0, 3.0, 1000.0 / 300.0, 5.0, 10.0, 12.5];

/// The envelope's taps: peak force (N) and length (s), on any body.
const TAP_PEAK_N: (f64, f64) = (1.0, 15.0);
/// The peak force of the taps a separately written model strikes a link with (N): its
/// small ones 5-15 N and its large ones 50-200 N (docs/simulator.md, the third model).
const OTHER_TAP_PEAK_N: (f64, f64) = (5.0, 200.0);
const TAP_LENGTH_S: (f64, f64) = (0.0005, 0.003);
/// The first push of a burst of the envelope's 40-150 Hz lasts half a period (s), widened
/// by a microsecond so that the half periods of 150 and 40 Hz, as computed, count.
const BURST_PUSH_S: (f64, f64) = (1.0 / 300.0 - 1e-6, 1.0 / 80.0 + 1e-6);
/// The amplitude of the bursts the separately written model strikes a link with (N): its
/// small ones 1-5 N and its large ones 10-40 N (docs/simulator.md, the third model), and
/// the large ones alone.
const OTHER_BURST_PEAK_N: [(f64, f64); 2] = [(1.0, 40.0), (10.0, 40.0)];

/// The first confirmation and its time (s), if any.
fn first_confirmation(decisions: &[DecisionRecord]) -> Option<(&str, f64)> {
    decisions
        .iter()
        .find(|d| d.is_confirm())
        .map(|d| (d.event.as_str(), d.t_s))
}

/// One event and its twin for one give-way time.
struct Pair {
    /// How long after the onset the channels stay identical (s).
    identical_s: f64,
    /// The blow's peak force (N).
    peak_n: f64,
    /// The blow's peak force is a tap's, and its length too.
    tap_sized: bool,
    /// The same with the peak force of the other model's taps on a link.
    other_tap_sized: bool,
    /// On a link, the blow is the first push of a burst of the envelope's frequencies with
    /// the amplitude of the other model's bursts on a link, and of its large ones.
    other_burst_sized: [bool; 2],
    /// The event the detector confirms first on the blow.
    on_blow: Option<String>,
    /// The detector confirmed the event before the readings parted.
    event_before_parting: bool,
}

fn simulate(s: Scenario, seed: u64, gives_way_s: Option<f64>) -> Option<Trace> {
    let opts = SimOptions {
        seed,
        randomize: true,
        gives_way_s,
        ..SimOptions::default()
    };
    sim::simulate(&s, &opts).ok()
}

/// A link collision or a contact as its twins are compared with it: its trace, its onset
/// (the first row at or after it, and the time), and when the detector confirmed the
/// expected event.
struct Event {
    trace: Trace,
    onset_row: usize,
    onset_s: f64,
    confirmed_s: Option<f64>,
}

impl Event {
    fn new(detector: &Detector, s: Scenario, seed: u64) -> Option<Event> {
        let trace = simulate(s, seed, None)?;
        let (onset_row, _) = trace.truth_onset()?;
        let onset_s = trace.meta("onset_s")?.parse().ok()?;
        let decisions = replay::replay(detector, &trace, |_, _, _| {}).ok()?;
        let confirmed_s = first_confirmation(&decisions)
            .filter(|(e, _)| Some(*e) == s.expected())
            .map(|(_, t)| t);
        Some(Event {
            trace,
            onset_row,
            onset_s,
            confirmed_s,
        })
    }

    /// The same run with the obstacle or the object giving way `g_s` after the first touch.
    fn twin(&self, detector: &Detector, s: Scenario, seed: u64, g_s: f64) -> Option<Pair> {
        let blow = simulate(s, seed, Some(g_s))?;
        let held = &self.trace;
        let differs = |k: usize| {
            CHANNELS
                .iter()
                .any(|c| held.column(c.name).map(|x| x[k]) != blow.column(c.name).map(|y| y[k]))
        };
        let parted = (self.onset_row..held.len())
            .find(|&k| differs(k))
            .unwrap_or(held.len() - 1);
        let parted_s = held.time()[parted];
        let peak: f64 = blow.meta("gives_way_peak_force_n")?.parse().ok()?;
        let on_link = s.expected() == Some(sim::LINK_COLLISION);
        let freed = replay::replay(detector, &blow, |_, _, _| {}).ok()?;
        let tap_length = (TAP_LENGTH_S.0..=TAP_LENGTH_S.1).contains(&g_s);
        let burst_push = on_link && (BURST_PUSH_S.0..=BURST_PUSH_S.1).contains(&g_s);
        Some(Pair {
            identical_s: parted_s - self.onset_s,
            peak_n: peak,
            tap_sized: tap_length && (TAP_PEAK_N.0..=TAP_PEAK_N.1).contains(&peak),
            other_tap_sized: on_link
                && tap_length
                && (OTHER_TAP_PEAK_N.0..=OTHER_TAP_PEAK_N.1).contains(&peak),
            other_burst_sized: OTHER_BURST_PEAK_N
                .map(|(low, high)| burst_push && (low..=high).contains(&peak)),
            on_blow: first_confirmation(&freed).map(|(e, _)| e.to_string()),
            event_before_parting: self.confirmed_s.is_some_and(|t| t < parted_s),
        })
    }
}

/// The events whose twins are run: link collisions against blows on the link, hard
/// contacts against blows on the pad.
const SCENARIOS: [Scenario; 5] = [
    Scenario::LinkCollision8,
    Scenario::LinkCollision2,
    Scenario::ContactHard8,
    Scenario::ContactHard5,
    Scenario::ContactHard2,
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (runs, base) = seeds::runs_and_base(500)?;
    let detector = detector_build::build(&detector_build::Config::from_toml(APPROACH_TOML)?)?;
    let jobs: Vec<(Scenario, u64)> = SCENARIOS
        .into_iter()
        .flat_map(|s| (base..base + runs).map(move |seed| (s, seed)))
        .collect();
    let pairs: Vec<(Scenario, Vec<Pair>)> = jobs
        .into_par_iter()
        .filter_map(|(s, seed)| {
            let event = Event::new(&detector, s, seed)?;
            let at: Option<Vec<Pair>> = GIVE_WAY_MS
                .iter()
                .map(|g| event.twin(&detector, s, seed, g / 1000.0))
                .collect();
            Some((s, at?))
        })
        .collect();
    for s in SCENARIOS {
        let of: Vec<&Vec<Pair>> = pairs
            .iter()
            .filter(|(t, _)| *t == s)
            .map(|(_, p)| p)
            .collect();
        let (what, on_what) = if s.expected() == Some(sim::LINK_COLLISION) {
            ("an obstacle", "link")
        } else {
            ("an object", "pad")
        };
        println!(
            "{} ({} runs, seeds {base}..{}), each against the same run with {what} that gives way (a blow on the {on_what}):",
            s.name(),
            of.len(),
            base + runs - 1
        );
        println!(
            "  gives way | identical for [ms]: min / median | the blow's peak [N]: median / 99 % / max | tap-sized blows: the envelope's, the other model's | burst pushes of the other model's bursts on a link: all / large | the default on the blow: {} / disturbance / another / nothing | events it confirmed before the readings part",
            s.expected().unwrap_or("-")
        );
        for (i, g) in GIVE_WAY_MS.iter().enumerate() {
            let at: Vec<&Pair> = of.iter().map(|p| &p[i]).collect();
            let identical: Vec<f64> = at.iter().map(|p| p.identical_s).collect();
            let shortest = 1000.0 * identical.iter().copied().fold(f64::INFINITY, f64::min);
            let count = |f: &dyn Fn(&Pair) -> bool| at.iter().filter(|p| f(p)).count();
            let on = |e: Option<&str>| count(&|p: &Pair| p.on_blow.as_deref() == e);
            let tap_sized = count(&|p: &Pair| p.tap_sized);
            let other_tap_sized = count(&|p: &Pair| p.other_tap_sized);
            let [burst, large_burst] = [0, 1].map(|k| count(&|p: &Pair| p.other_burst_sized[k]));
            let (event, disturbance, nothing) =
                (on(s.expected()), on(Some(sim::DISTURBANCE)), on(None));
            let mut peaks: Vec<f64> = at.iter().map(|p| p.peak_n).collect();
            peaks.sort_by(f64::total_cmp);
            println!(
                "  {g:>6.2} ms | {shortest:>5.1} / {:>4.1} | {:>5.1} / {:>5.1} / {:>5.1} | {tap_sized:>4} ({:>4.1} %), {other_tap_sized:>4} | {burst:>4} / {large_burst:>4} | {event:>4} / {disturbance:>4} / {:>4} / {nothing:>4} | {:>4}",
                Latency::from_seconds(&identical).median,
                nearest_rank(&peaks, 0.5),
                nearest_rank(&peaks, 0.99),
                nearest_rank(&peaks, 1.0),
                100.0 * tap_sized as f64 / at.len().max(1) as f64,
                at.len() - event - disturbance - nothing,
                count(&|p: &Pair| p.event_before_parting),
            );
        }
    }
    Ok(())
}
