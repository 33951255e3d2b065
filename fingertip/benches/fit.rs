//! Wall time of `fingertip fit` on a one-hour labelled corpus at 5 kHz: randomized runs of
//! the Table 1 scenarios (the events) and one-minute stretches of event-free motion, written
//! once to a temporary directory, fitted from `configs/approach.toml`'s structure without
//! and with a 5-fold cross-validation.
//!
//! `cargo bench -p fingertip --bench fit [-- HOURS]` (default 1). Prints each wall time and
//! peak resident memory.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;

/// Writes `trace` to `path` and waits until it is on disk, so that the fits timed do not
/// share the machine with the corpus's write-back.
fn write(trace: &Trace, path: &Path) -> Result<(), String> {
    trace.write(path).map_err(|e| e.to_string())?;
    std::fs::File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(|e| e.to_string())
}

/// A running process's peak resident memory so far, from `/proc` (`VmHWM`, KiB).
fn high_water_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

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
            write(&trace, &dir.join(format!("{}_{seed}.csv", scenario.name())))?;
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
        write(&trace, &dir.join(format!("free_motion_{seed}.csv")))?;
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
            let mut child = Command::new(env!("CARGO_BIN_EXE_fingertip"))
                .args(["fit", "--traces"])
                .arg(&dir)
                .arg("--out")
                .arg(&out)
                .args(["--folds", folds])
                .stdout(std::process::Stdio::null())
                .spawn()
                .map_err(|e| e.to_string())?;
            // The fit's peak resident memory, read while it runs (Linux).
            let mut peak_kib = None;
            let status = loop {
                if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
                    break status;
                }
                peak_kib = high_water_kib(child.id()).or(peak_kib);
                std::thread::sleep(std::time::Duration::from_millis(20));
            };
            if !status.success() {
                return Err(format!("fingertip fit: {status}"));
            }
            println!(
                "fingertip fit --folds {folds:<2} {:>7.1} s, peak resident memory {}",
                start.elapsed().as_secs_f64(),
                peak_kib.map_or("unknown".to_string(), |k| format!(
                    "{:.0} MiB",
                    k as f64 / 1024.0
                ))
            );
        }
        Ok(())
    });
    let _ = std::fs::remove_dir_all(&dir);
    result
}
