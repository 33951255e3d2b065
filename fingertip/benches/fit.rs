//! Wall time of `fingertip fit` on a one-hour labelled corpus at 5 kHz: randomized runs of
//! the Table 1 scenarios (the events) and one-minute stretches of event-free motion, written
//! once to a temporary directory, fitted from `configs/approach.toml`'s structure without
//! and with a 5-fold cross-validation.
//!
//! `cargo bench -p fingertip --bench fit [-- HOURS]` (default 1). Prints each wall time.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use fingertip::sim::{self, Scenario, SimOptions};

fn corpus(dir: &Path, hours: f64) -> Result<f64, String> {
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    let mut seconds = 0.0;
    let mut seed = 0;
    // Events: a tenth of the time, every Table 1 scenario in turn; the rest free motion.
    while seconds < 0.1 * hours * 3600.0 {
        for scenario in Scenario::table1() {
            seed += 1;
            let opts = SimOptions {
                seed,
                randomize: true,
                ..SimOptions::default()
            };
            let trace = sim::simulate(scenario, &opts).map_err(|e| e.to_string())?;
            seconds += trace.len() as f64 / trace.rate_hz();
            trace
                .write(dir.join(format!("{}_{seed}.csv", scenario.name())))
                .map_err(|e| e.to_string())?;
        }
    }
    while seconds < hours * 3600.0 {
        seed += 1;
        let opts = SimOptions {
            seed,
            randomize: true,
            duration_s: Some(60.0),
            ..SimOptions::default()
        };
        let trace = sim::simulate(&Scenario::FreeMotion, &opts).map_err(|e| e.to_string())?;
        seconds += trace.len() as f64 / trace.rate_hz();
        trace
            .write(dir.join(format!("free_motion_{seed}.csv")))
            .map_err(|e| e.to_string())?;
    }
    Ok(seconds)
}

fn main() -> Result<(), String> {
    let hours: f64 = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .filter(|h: &f64| h.is_finite() && *h > 0.0)
        .unwrap_or(1.0);
    let dir = std::env::temp_dir().join(format!("fingertip-fit-bench-{}", std::process::id()));
    let seconds = corpus(&dir, hours);
    let result = seconds.and_then(|seconds| {
        println!(
            "corpus: {:.2} h at 5 kHz ({} recordings)",
            seconds / 3600.0,
            std::fs::read_dir(&dir).map_or(0, |d| d.count())
        );
        let out = dir.join("fitted.toml.out");
        for folds in ["0", "5"] {
            let start = Instant::now();
            let status = Command::new(env!("CARGO_BIN_EXE_fingertip"))
                .args(["fit", "--traces"])
                .arg(&dir)
                .arg("--out")
                .arg(&out)
                .args(["--folds", folds])
                .stdout(std::process::Stdio::null())
                .status()
                .map_err(|e| e.to_string())?;
            if !status.success() {
                return Err(format!("fingertip fit: {status}"));
            }
            println!(
                "fingertip fit --folds {folds:<2} {:>7.1} s",
                start.elapsed().as_secs_f64()
            );
        }
        Ok(())
    });
    let _ = std::fs::remove_dir_all(&dir);
    result
}
