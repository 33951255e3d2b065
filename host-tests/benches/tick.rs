//! Host nanoseconds per detector tick for the approach configuration: the fixed-point core's
//! `Detector::tick`, over the same trace the QEMU program replays (`fingertip-qemu`'s
//! embedded trace, a fresh state per segment).
//!
//! `cargo bench -p host-tests --bench tick`. Prints the median of several timed passes over
//! the whole trace. When the f64 reference model (`host_tests::reference`) exists, add it
//! to `models()` below and the ratio is printed too.
//!
//! Note the profiles: `cargo bench` builds detector-core with the workspace's release
//! settings (opt-level "s", the firmware's), host-tests itself at opt-level 3.

use std::hint::black_box;
use std::time::{Duration, Instant};

use detector_core::{Config, Detector, Inputs, Signal, Tick};
use fingertip_qemu::trace::Trace;

/// Timed passes over the trace; the median is reported.
const PASSES: usize = 21;
/// Each pass repeats the trace until it has run at least this long.
const MIN_PASS: Duration = Duration::from_millis(50);

/// One segment of the trace, decoded once so the timing covers the tick alone.
struct Segment {
    ticks: Vec<(Tick, Inputs)>,
}

fn load() -> Result<(Detector, Vec<Segment>), String> {
    let config = Config::from_toml(host_tests::APPROACH_TOML).map_err(|e| e.to_string())?;
    let detector = Detector::build(&config).map_err(|e| e.to_string())?;
    let trace = Trace::parse(fingertip_qemu::TRACE).map_err(|e| e.to_string())?;
    let channels = trace.channels().min(detector.channels().len());
    let segments = trace
        .segments()
        .map(|s| Segment {
            ticks: (0u32..)
                .zip(s.records())
                .map(|(k, r)| {
                    let mut inputs = Inputs {
                        faults: r.faults,
                        ..Inputs::default()
                    };
                    for (x, &raw) in inputs.samples.iter_mut().zip(&r.samples).take(channels) {
                        *x = Signal::from_bits(raw);
                    }
                    (s.start_tick().wrapping_add(k), inputs)
                })
                .collect(),
        })
        .collect();
    Ok((detector, segments))
}

/// A tick model to time: runs one whole segment from a fresh state.
type Model<'a> = (&'static str, Box<dyn Fn(&Segment) + 'a>);

fn models(detector: &Detector) -> Vec<Model<'_>> {
    let fixed: Model = (
        "fixed point (detector-core)",
        Box::new(move |seg: &Segment| {
            let mut state = detector.new_state();
            for (now, inputs) in &seg.ticks {
                black_box(detector.tick(&mut state, *now, black_box(inputs)));
            }
        }),
    );
    // The f64 reference model goes here once host-tests/src/reference.rs exists, as a
    // second entry that runs the same segment through its own tick.
    vec![fixed]
}

/// Median ns per tick over `PASSES` passes.
fn time(run: &dyn Fn(&Segment), segments: &[Segment]) -> f64 {
    let ticks_per_trace: usize = segments.iter().map(|s| s.ticks.len()).sum();
    let mut per_tick: Vec<f64> = (0..PASSES + 1)
        .map(|_| {
            let start = Instant::now();
            let mut ticks = 0usize;
            while start.elapsed() < MIN_PASS {
                for s in segments {
                    run(s);
                }
                ticks += ticks_per_trace;
            }
            start.elapsed().as_nanos() as f64 / ticks as f64
        })
        .skip(1) // warm-up
        .collect();
    per_tick.sort_by(f64::total_cmp);
    per_tick[per_tick.len() / 2]
}

fn main() {
    let (detector, segments) = match load() {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let ticks: usize = segments.iter().map(|s| s.ticks.len()).sum();
    println!(
        "approach configuration, trace {} ({} segments, {ticks} ticks), median of {PASSES} passes",
        fingertip_qemu::TRACE_SOURCE,
        segments.len()
    );
    let models = models(&detector);
    let results: Vec<(&str, f64)> = models
        .iter()
        .map(|(name, run)| (*name, time(run.as_ref(), &segments)))
        .collect();
    for (name, ns) in &results {
        println!("{name}: {ns:.1} ns per tick");
    }
    if let [(_, fixed), rest @ ..] = results.as_slice() {
        for (name, ns) in rest {
            println!("{name} / fixed point: {:.2}x", ns / fixed);
        }
    }
}
