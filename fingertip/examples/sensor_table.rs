//! What the sensors see, over randomized runs: the table of `docs/simulator.md`.
//!
//! `cargo run --release -p fingertip --example sensor_table [RUNS]` prints, per event
//! scenario, the 1st percentile and median of the largest absolute `skin_accel` and
//! `force_x` readings in the first 2 and 5 ms after the true onset, then the largest
//! readings before the onsets and in sudden accelerations and free motion.

use fingertip::score::nearest_rank;
use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;

fn run(s: Scenario, seed: u64, duration_s: Option<f64>) -> Result<Trace, sim::SimError> {
    sim::simulate(
        &s,
        &SimOptions {
            seed,
            randomize: true,
            duration_s,
            ..SimOptions::default()
        },
    )
}

fn peak(x: &[f64]) -> f64 {
    x.iter().fold(0.0, |m, v| m.max(v.abs()))
}

fn column<'t>(tr: &'t Trace, name: &str) -> &'t [f64] {
    tr.column(name).unwrap_or(&[])
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(1000);
    let rows_per_ms = 5;
    println!("| scenario | skin_accel 2 ms | skin_accel 5 ms | force_x 2 ms | force_x 5 ms |");
    println!("|---|---|---|---|---|");
    let mut before = [0.0f64; 3];
    for s in Scenario::single_event() {
        if s.expected().is_none() {
            continue;
        }
        let mut cells: [Vec<f64>; 4] = Default::default();
        for seed in 0..runs {
            let tr = run(*s, seed, None)?;
            let Some((on, _)) = tr.truth_onset() else {
                continue;
            };
            let (a, f, sr) = (
                column(&tr, "skin_accel"),
                column(&tr, "force_x"),
                column(&tr, "stress_rate"),
            );
            for (k, (x, ms)) in [(a, 2), (a, 5), (f, 2), (f, 5)].into_iter().enumerate() {
                cells[k].push(peak(&x[on..(on + ms * rows_per_ms).min(x.len())]));
            }
            for (m, x) in before.iter_mut().zip([a, f, sr]) {
                *m = m.max(peak(&x[..on]));
            }
        }
        let cell = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            format!(
                "{} / {}",
                two_digits(nearest_rank(v, 0.01)),
                two_digits(nearest_rank(v, 0.5))
            )
        };
        let [a2, a5, f2, f5] = &mut cells;
        println!(
            "| {s} | {} | {} | {} | {} |",
            cell(a2),
            cell(a5),
            cell(f2),
            cell(f5)
        );
    }
    println!(
        "before the onsets: skin_accel {:.1} m/s^2, force_x {:.2} N, stress_rate {:.1} N/s",
        before[0], before[1], before[2]
    );
    let mut quiet = [0.0f64; 3];
    for s in [
        Scenario::SuddenAccelStandstill,
        Scenario::SuddenAccelMoving5,
    ] {
        for seed in 0..runs {
            let tr = run(s, seed, None)?;
            for (m, c) in quiet
                .iter_mut()
                .zip(["skin_accel", "force_x", "stress_rate"])
            {
                *m = m.max(peak(column(&tr, c)));
            }
        }
    }
    println!(
        "sudden accelerations: skin_accel {:.0} m/s^2, force_x {:.2} N, stress_rate {:.1} N/s",
        quiet[0], quiet[1], quiet[2]
    );
    let mut free = [0.0f64; 3];
    for seed in 0..(runs / 100).max(1) {
        let tr = run(Scenario::FreeMotion, seed, Some(60.0))?;
        for (m, c) in free
            .iter_mut()
            .zip(["skin_accel", "force_x", "stress_rate"])
        {
            *m = m.max(peak(column(&tr, c)));
        }
    }
    println!(
        "free motion ({} min): skin_accel {:.0} m/s^2, force_x {:.2} N, stress_rate {:.1} N/s",
        (runs / 100).max(1),
        free[0],
        free[1],
        free[2]
    );
    Ok(())
}

/// Two significant digits, as the doc's table has them.
fn two_digits(v: f64) -> String {
    if v >= 100.0 {
        format!("{v:.0}")
    } else if v >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}
