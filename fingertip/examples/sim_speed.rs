//! Simulated seconds per CPU second of the simulator alone, per scenario:
//! `cargo run --release -p fingertip --example sim_speed [RUNS]`.

use fingertip::sim::{self, Scenario, SimOptions};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: u64 = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(200);
    let mut total = (0.0, 0.0);
    for s in Scenario::all() {
        let duration = (*s == Scenario::FreeMotion).then_some(60.0);
        let n = if duration.is_some() { runs / 20 } else { runs }.max(1);
        let started = Instant::now();
        let mut simulated = 0.0;
        for seed in 0..n {
            let opts = SimOptions {
                seed,
                randomize: true,
                duration_s: duration,
                ..SimOptions::default()
            };
            let tr = sim::simulate(s, &opts)?;
            simulated += tr.len() as f64 / tr.rate_hz();
        }
        let cpu = started.elapsed().as_secs_f64();
        total = (total.0 + simulated, total.1 + cpu);
        println!("{s:<26} {:>8.0} simulated s per s", simulated / cpu);
    }
    println!("{:<26} {:>8.0} simulated s per s", "all", total.0 / total.1);
    Ok(())
}
