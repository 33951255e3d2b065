//! How far the events the default detector misses reach the fingertip's sensors:
//! `cargo run --release -p fingertip --example reach [RUNS] [BASE_SEED]`.
//!
//! For every run of the scenarios where the detector falls short of its targets, the
//! signal the event leaves on each sensor, over what the same sensor read just before it,
//! binned, with the share of the runs the default detector gets right in each bin:
//! - disturbances and knocks: the vibration above 25 Hz in the 50 ms after the onset, as an
//!   RMS over the RMS of the 30 ms before it, on the force sensor (both axes), the skin
//!   accelerometer and the position error (both axes); binned by the best of the three;
//! - very soft contacts: how fast the stress-rate film's reading rises over the 60 ms after
//!   the onset (N/s, the mean of its last 40 ms over the mean before the onset), the signal
//!   the contact's slow path judges (docs/simulator.md gives the film's event-free level).
//!
//! A detector can only find an event whose signal stands out of the sensors' own reading;
//! where the right share falls with the signal, the misses are at the sensors' reach.

mod seeds;

use detector_core::Detector;
use fingertip::score::classify;
use fingertip::sim::filters::HighPass1;
use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;
use fingertip::{APPROACH_TOML, replay};
use rayon::prelude::*;

/// Rows per millisecond at the simulator's default rate.
const MS: usize = 5;

/// `x` high-passed at `hz` (the simulator's first-order RC coupling) at `rate` samples
/// per second, from the steady state of its first sample.
fn high_pass(x: &[f64], hz: f64, rate: f64) -> Vec<f64> {
    let mut f = HighPass1::new(hz, rate);
    f.settle(x.first().copied().unwrap_or(0.0));
    x.iter().map(|&v| f.process(v)).collect()
}

/// RMS over `rows` of the vector whose components are `axes`.
fn rms(axes: &[&[f64]], rows: std::ops::Range<usize>) -> f64 {
    let n = rows.len().max(1) as f64;
    let sum: f64 = rows
        .map(|k| axes.iter().map(|a| a[k] * a[k]).sum::<f64>())
        .sum();
    (sum / n).sqrt()
}

/// The vibration a disturbance leaves on each sensor over the 30 ms before it: force,
/// skin acceleration, position error (RMS ratios).
fn vibration_ratios(tr: &Trace, on: usize) -> Option<[f64; 3]> {
    let rate = tr.rate_hz();
    let hp = |name: &str| tr.column(name).map(|c| high_pass(c, 25.0, rate));
    let (fx, fy, acc, ex, ey) = (
        hp("force_x")?,
        hp("force_y")?,
        hp("skin_accel")?,
        hp("pos_err_x")?,
        hp("pos_err_y")?,
    );
    // The filters settle in the run's first 10 ms; the onset is later.
    let before = on.saturating_sub(30 * MS).max(10 * MS)..on;
    let after = on..(on + 50 * MS).min(tr.len());
    if before.is_empty() || after.is_empty() {
        return None;
    }
    let ratio = |axes: &[&[f64]]| rms(axes, after.clone()) / rms(axes, before.clone()).max(1e-12);
    Some([ratio(&[&fx, &fy]), ratio(&[&acc]), ratio(&[&ex, &ey])])
}

/// How fast the film's reading rose after a contact's onset (N/s).
fn film_rise(tr: &Trace, on: usize) -> Option<f64> {
    let film = tr.column("stress_rate")?;
    let mean = |r: std::ops::Range<usize>| film[r.clone()].iter().sum::<f64>() / r.len() as f64;
    let before = on.saturating_sub(20 * MS)..on;
    let after = on + 20 * MS..(on + 60 * MS).min(tr.len());
    (!before.is_empty() && !after.is_empty()).then(|| mean(after) - mean(before))
}

/// One run: its signal measure and whether the default detector got it right.
fn run(detector: &Detector, s: Scenario, seed: u64) -> Option<(f64, [f64; 3], bool)> {
    let opts = SimOptions {
        seed,
        randomize: true,
        ..SimOptions::default()
    };
    let tr = sim::simulate(&s, &opts).ok()?;
    let (on, _) = tr.truth_onset()?;
    let onset_s = tr.time().get(on).copied()?;
    let decisions = replay::replay(detector, &tr, |_, _, _| {}).ok()?;
    let right = classify(s.expected().map(|e| (e, onset_s)), &decisions).is_right();
    if s == Scenario::ContactVerySoft1 {
        return Some((film_rise(&tr, on)?, [0.0; 3], right));
    }
    let r = vibration_ratios(&tr, on)?;
    Some((r.iter().copied().fold(0.0, f64::max), r, right))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (runs, base) = seeds::runs_and_base(500)?;
    let config = detector_build::Config::from_toml(APPROACH_TOML)?;
    let detector = detector_build::build(&config)?;
    println!(
        "{runs} randomized runs per scenario (seeds {base}..{}), configs/approach.toml",
        base + runs - 1
    );
    for s in Scenario::disturbances().chain([Scenario::ContactVerySoft1]) {
        let results: Vec<(f64, [f64; 3], bool)> = (base..base + runs)
            .into_par_iter()
            .filter_map(|seed| run(&detector, s, seed))
            .collect();
        let (edges, what): (&[f64], &str) = if s == Scenario::ContactVerySoft1 {
            (&[0.3, 0.5, 0.8, 1.2], "the film's rise over 60 ms [N/s]")
        } else {
            (
                &[1.5, 2.0, 3.0, 5.0],
                "vibration RMS after / before, the best of force, skin acceleration and position error",
            )
        };
        println!("\n{} ({} runs), by {what}:", s.name(), results.len());
        println!(
            "  {:<12} {:>5} {:>6} {:>7}   median ratio: force / accel / error",
            "bin", "runs", "right", "share"
        );
        for b in 0..=edges.len() {
            let lo = if b == 0 {
                f64::NEG_INFINITY
            } else {
                edges[b - 1]
            };
            let hi = edges.get(b).copied().unwrap_or(f64::INFINITY);
            let mut inside: Vec<&(f64, [f64; 3], bool)> =
                results.iter().filter(|r| (lo..hi).contains(&r.0)).collect();
            if inside.is_empty() {
                continue;
            }
            let right = inside.iter().filter(|r| r.2).count();
            let label = match (b, edges.get(b)) {
                (0, Some(h)) => format!("< {h}"),
                (_, Some(h)) => format!("{lo}-{h}"),
                (_, None) => format!(">= {lo}"),
            };
            let medians = if s == Scenario::ContactVerySoft1 {
                String::new()
            } else {
                let median = |k: usize, v: &mut Vec<&(f64, [f64; 3], bool)>| {
                    v.sort_by(|a, b| a.1[k].total_cmp(&b.1[k]));
                    v[v.len() / 2].1[k]
                };
                format!(
                    "{:.1} / {:.1} / {:.1}",
                    median(0, &mut inside),
                    median(1, &mut inside),
                    median(2, &mut inside)
                )
            };
            println!(
                "  {label:<12} {:>5} {right:>6} {:>6.1} %   {medians}",
                inside.len(),
                100.0 * right as f64 / inside.len() as f64
            );
        }
    }
    Ok(())
}
