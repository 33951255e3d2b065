//! How soon after its onset a link collision can be told from a blow that pushes the arm,
//! by the arm's progress alone: `cargo run --release -p fingertip --example separation
//! [RUNS] [BASE_SEED]`.
//!
//! A link collision is defined by the arm being held back; a tap or a burst on the finger
//! pushes it too, for as long as it lasts (taps 0.5-3 ms) and until the controller brings
//! it back. For every run of the link collisions and of the disturbances and knocks, the
//! position error's displacement since the onset, in any direction, over the commanded
//! travel in that time (the share of the commanded motion lost or pushed), `t` ms after
//! the onset; then, for each `t`, the single threshold on it that puts the fewest runs on
//! the wrong side (collisions above it, the others below), and the share of runs it gets
//! wrong. The controller's position error arrives at 1 kHz, up to 0.8 ms late.

mod seeds;

use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;
use rayon::prelude::*;

/// Milliseconds after the onset at which the classes are compared.
const TIMES_MS: [f64; 9] = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0];

/// The share of the commanded travel the error moved by, `t` ms after the onset, for each
/// time of [`TIMES_MS`].
fn shares(tr: &Trace) -> Option<Vec<f64>> {
    let (on, _) = tr.truth_onset()?;
    let rate = tr.rate_hz();
    let (ex, ey) = (tr.column("pos_err_x")?, tr.column("pos_err_y")?);
    let (vx, vy) = (tr.column("vel_des_x")?, tr.column("vel_des_y")?);
    let speed = vx[on].hypot(vy[on]);
    TIMES_MS
        .iter()
        .map(|ms| {
            let k = on + (ms * 1e-3 * rate).round() as usize;
            let moved = (ex.get(k)? - ex[on]).hypot(ey.get(k)? - ey[on]);
            Some(moved / (speed * ms * 1e-3).max(1e-12))
        })
        .collect()
}

/// The fewest runs a single threshold puts on the wrong side, over all runs, with
/// `held` meant to lie above it and `pushed` below.
fn best_split(held: &[f64], pushed: &[f64]) -> (f64, usize) {
    let mut cuts: Vec<f64> = held.iter().chain(pushed).copied().collect();
    cuts.sort_by(f64::total_cmp);
    cuts.push(f64::INFINITY);
    cuts.iter()
        .map(|&cut| {
            let wrong = held.iter().filter(|&&v| v < cut).count()
                + pushed.iter().filter(|&&v| v >= cut).count();
            (cut, wrong)
        })
        .min_by_key(|&(_, wrong)| wrong)
        .unwrap_or((f64::INFINITY, held.len()))
}

fn runs_of(scenarios: &[Scenario], runs: u64, base: u64) -> Vec<Vec<f64>> {
    scenarios
        .iter()
        .flat_map(|&s| (base..base + runs).map(move |seed| (s, seed)))
        .collect::<Vec<_>>()
        .into_par_iter()
        .filter_map(|(s, seed)| {
            let opts = SimOptions {
                seed,
                randomize: true,
                ..SimOptions::default()
            };
            shares(&sim::simulate(&s, &opts).ok()?)
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (runs, base) = seeds::runs_and_base(500)?;
    let held = runs_of(
        &[Scenario::LinkCollision8, Scenario::LinkCollision2],
        runs,
        base,
    );
    let pushed = runs_of(
        &[
            Scenario::DisturbanceLarge5,
            Scenario::DisturbanceSlow2,
            Scenario::KnockLink1,
            Scenario::KnockLink2,
        ],
        runs,
        base,
    );
    println!(
        "{} link collisions against {} disturbances and knocks (seeds {base}..{} of each scenario):",
        held.len(),
        pushed.len(),
        base + runs - 1
    );
    println!("  after   best threshold   runs on the wrong side");
    for (i, ms) in TIMES_MS.iter().enumerate() {
        let h: Vec<f64> = held.iter().map(|r| r[i]).collect();
        let p: Vec<f64> = pushed.iter().map(|r| r[i]).collect();
        let (cut, wrong) = best_split(&h, &p);
        println!(
            "  {ms:>4} ms  {:>13.0} %   {wrong:>5} = {:.1} %",
            100.0 * cut,
            100.0 * wrong as f64 / (h.len() + p.len()).max(1) as f64
        );
    }
    Ok(())
}
