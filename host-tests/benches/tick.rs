//! Host nanoseconds per detector tick for the approach configuration: the fixed-point core's
//! tick generated for it at build time (the firmware's, `fingertip_tick::ApproachTick`) and its
//! interpreter `Detector::tick_into`, over the simulator's golden runs that the QEMU test replays too (the 13
//! Table 1 runs and one second of event-free motion, nominal parameters, seed 0, a fresh
//! state per run).
//!
//! `cargo bench -p host-tests --bench tick`. Prints the fastest and the median of several
//! timed passes over all runs for the two fixed-point ticks and for the f64 reference model's
//! tick (`host_tests::reference::Model::tick`, fed the same samples unquantized), and their
//! ratios to the generated tick.
//!
//! Note the profiles: `cargo bench` builds detector-core and the tick crate with the
//! workspace's release settings (opt-level "s"; the chip's build compiles the tick at 3 and
//! the core at "z"), host-tests itself at opt-level 3.

use std::hint::black_box;
use std::time::{Duration, Instant};

use detector_build::Config;
use detector_core::{Detector, DetectorTick, Inputs, Output, Tick};
use fingertip::replay::channel_columns;
use fingertip::sim::golden_runs;
use fingertip_qemu::ApproachTick;
use host_tests::reference::Model;

/// Timed passes over the trace per model, after one warm-up pass.
const PASSES: usize = 21;
/// Each pass repeats the trace until it has run at least this long.
const MIN_PASS: Duration = Duration::from_millis(50);

/// One run, converted once so the timing covers the tick alone: the fixed-point inputs and
/// the same samples as `f64` in each channel's working unit, for the reference model.
struct Segment {
    ticks: Vec<(Tick, Inputs)>,
    samples: Vec<Vec<f64>>,
}

fn load() -> Result<(Config, Detector, Vec<Segment>), String> {
    let config = Config::from_toml(fingertip::APPROACH_TOML).map_err(|e| e.to_string())?;
    let detector = detector_build::build(&config).map_err(|e| e.to_string())?;
    if fingertip_qemu::detector().map_err(|e| e.to_string())? != detector {
        return Err("the generated tick was made from another configuration".into());
    }
    let model = Model::new(&config).map_err(|e| e.to_string())?;
    let mut segments = Vec::new();
    let runs = golden_runs(f64::from(config.rate_hz)).map_err(|e| e.to_string())?;
    for (_, t) in &runs {
        let columns = channel_columns(&detector, t).map_err(|e| e.to_string())?;
        let si = |k: usize, row: usize| columns.get(k).and_then(|c| c.get(row)).copied();
        let ticks = (0..t.len())
            .map(|row| {
                let mut inputs = Inputs::default();
                for (k, x) in inputs.samples.iter_mut().enumerate().take(columns.len()) {
                    *x = detector.sample_from_si(k, si(k, row).unwrap_or(0.0));
                }
                (row as Tick, inputs)
            })
            .collect();
        let samples = (0..t.len())
            .map(|row| {
                (0..columns.len())
                    .map(|k| model.working_unit(k, si(k, row).unwrap_or(0.0)))
                    .collect()
            })
            .collect();
        segments.push(Segment { ticks, samples });
    }
    Ok((config, detector, segments))
}

/// A tick model to time: runs one whole segment from a fresh state.
type Timed<'a> = (&'static str, Box<dyn Fn(&Segment) + 'a>);

/// A fixed-point tick to time: the same loop for the generated tick and the interpreter,
/// so that only the tick differs.
fn fixed<'a>(
    name: &'static str,
    detector: &'a Detector,
    tick: &'a (impl DetectorTick + 'a),
) -> Timed<'a> {
    (
        name,
        Box::new(move |seg: &Segment| {
            let mut state = detector.new_state();
            let mut out = Output::default();
            for (now, inputs) in &seg.ticks {
                tick.tick_into(&mut state, *now, black_box(inputs), &mut out);
                black_box(&out);
            }
        }),
    )
}

fn models<'a>(detector: &'a Detector, model: &'a Model) -> Vec<Timed<'a>> {
    let compiled = fixed(
        "fixed point, generated (the firmware's)",
        detector,
        &ApproachTick,
    );
    let interpreted = fixed("fixed point, interpreted (Detector)", detector, detector);
    let reference: Timed = (
        "f64 reference (host_tests::reference)",
        Box::new(move |seg: &Segment| {
            let mut state = model.new_state();
            for ((now, _), samples) in seg.ticks.iter().zip(&seg.samples) {
                black_box(model.tick(&mut state, *now, black_box(samples), 0));
            }
        }),
    );
    vec![compiled, interpreted, reference]
}

/// ns per tick of one pass: the whole trace, repeated for at least `MIN_PASS`.
fn pass(run: &dyn Fn(&Segment), segments: &[Segment]) -> f64 {
    let ticks_per_trace: usize = segments.iter().map(|s| s.ticks.len()).sum();
    let start = Instant::now();
    let mut ticks = 0usize;
    while start.elapsed() < MIN_PASS {
        for s in segments {
            run(s);
        }
        ticks += ticks_per_trace;
    }
    start.elapsed().as_nanos() as f64 / ticks.max(1) as f64
}

fn main() {
    let (config, detector, segments) = match load() {
        Ok(x) => x,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    };
    let ticks: usize = segments.iter().map(|s| s.ticks.len()).sum();
    println!(
        "approach configuration, simulator's golden runs ({} runs, {ticks} ticks), {PASSES} passes per model",
        segments.len()
    );
    let model = match Model::new(&config) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("error: reference model: {e}");
            std::process::exit(1);
        }
    };
    let models = models(&detector, &model);
    // Passes alternate between the models so that a busy machine slows them alike; the
    // fastest pass is the least disturbed, the median shows the spread.
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); models.len()];
    for p in 0..=PASSES {
        for ((_, run), t) in models.iter().zip(times.iter_mut()) {
            let ns = pass(run.as_ref(), &segments);
            if p > 0 {
                t.push(ns); // pass 0 warms up
            }
        }
    }
    let mut best = Vec::new();
    for ((name, _), t) in models.iter().zip(times.iter_mut()) {
        t.sort_by(f64::total_cmp);
        let (min, median) = (t[0], t[t.len() / 2]);
        println!("{name}: {min:.1} ns per tick (fastest pass; median {median:.1})");
        best.push(min);
    }
    if let [fixed, rest @ ..] = best.as_slice() {
        for ((name, _), ns) in models.iter().skip(1).zip(rest) {
            println!("{name} / generated: {:.2}x", ns / fixed);
        }
    }
}
