//! Ticks per second of `fingertip replay` on a long event-free recording at 5 kHz
//! ([`fingertip::sim::long`], written once to a temporary file): the whole command as a
//! user runs it, without outputs and writing the per-tick CSV (`--out`), and the library's
//! streamed replay alone.
//!
//! `cargo bench -p fingertip --bench replay [-- MINUTES]` (default 5 minutes of recording,
//! 1.5 M ticks). Prints the fastest of five passes of each. Peak memory is not measured
//! here: `/usr/bin/time -v` on the command gives it (docs/performance.md).

use std::io::{BufWriter, Write};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use fingertip::replay::replay_stream;
use fingertip::sim::long::{RATE_HZ, write_long_recording};
use fingertip::trace::TraceReader;

const PASSES: usize = 5;

fn fastest(mut pass: impl FnMut() -> Result<(), String>) -> Result<Duration, String> {
    let mut best = Duration::MAX;
    for _ in 0..PASSES {
        let start = Instant::now();
        pass()?;
        best = best.min(start.elapsed());
    }
    Ok(best)
}

fn command(args: &[&str]) -> Result<(), String> {
    let status = Command::new(env!("CARGO_BIN_EXE_fingertip"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .status()
        .map_err(|e| e.to_string())?;
    status
        .success()
        .then_some(())
        .ok_or_else(|| format!("fingertip {args:?}: {status}"))
}

fn run(trace: &Path, out: &Path, rows: u64) -> Result<(), String> {
    let trace_arg = trace.to_str().ok_or("temporary path is not UTF-8")?;
    let out_arg = out.to_str().ok_or("temporary path is not UTF-8")?;
    let detector = detector_build::build(
        &detector_build::Config::from_toml(fingertip::APPROACH_TOML).map_err(|e| e.to_string())?,
    )
    .map_err(|e| e.to_string())?;
    let report = |what: &str, time: Duration| {
        let per_s = rows as f64 / time.as_secs_f64();
        println!(
            "{what:<44} {:>7.3} s  {:>5.2} M ticks/s  {:>6.0}x real time",
            time.as_secs_f64(),
            per_s / 1e6,
            per_s / RATE_HZ
        );
    };
    report(
        "fingertip replay TRACE",
        fastest(|| command(&["replay", trace_arg]))?,
    );
    report(
        "fingertip replay TRACE --out CSV",
        fastest(|| command(&["replay", trace_arg, "--out", out_arg]))?,
    );
    report(
        "replay_stream (library, no output)",
        fastest(|| {
            let reader = TraceReader::open(trace).map_err(|e| e.to_string())?;
            let mut ticks = 0u64;
            replay_stream(&detector, reader, |_| ticks += 1).map_err(|e| e.to_string())?;
            (ticks == rows)
                .then_some(())
                .ok_or_else(|| format!("{ticks} ticks for {rows} rows"))
        })?,
    );
    Ok(())
}

fn main() -> Result<(), String> {
    let minutes: f64 = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .filter(|m: &f64| m.is_finite() && *m > 0.0)
        .unwrap_or(5.0);
    let rows = (minutes * 60.0 * RATE_HZ) as u64;
    let dir = std::env::temp_dir();
    let trace = dir.join(format!("fingertip-bench-{}.csv", std::process::id()));
    let out = dir.join(format!("fingertip-bench-{}-out.csv", std::process::id()));
    let written = std::fs::File::create(&trace).and_then(|f| {
        let mut w = BufWriter::with_capacity(1 << 20, f);
        write_long_recording(&mut w, rows)?;
        w.flush()
    });
    println!(
        "{minutes} min of recording at 5 kHz, {rows} ticks, {} MB; fastest of {PASSES} passes",
        std::fs::metadata(&trace).map_or(0, |m| m.len()) / 1_000_000
    );
    let result = written
        .map_err(|e| format!("{}: {e}", trace.display()))
        .and_then(|()| run(&trace, &out, rows));
    let _ = std::fs::remove_file(&trace);
    let _ = std::fs::remove_file(&out);
    result
}
