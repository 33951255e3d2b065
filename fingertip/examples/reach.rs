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
//!   the contact's slow path judges (docs/simulator.md gives the film's event-free level);
//!   and how far the force sensor is pushed back by then (N, the mean of its last 30 ms
//!   below the mean before the onset), the signal of its force path. A detector that
//!   confirms a contact within 60 ms has no more than these 60 ms to judge by;
//! - link collisions at 2 cm/s: how far the tip moves off its path (µm, the position
//!   error's largest distance from its mean over the 10 ms before the onset) in the 130 ms
//!   after it, the window a run is scored in: a padded obstacle that the loops press into
//!   takes a small share of a slow approach, and the arm's offset is the signal a detector
//!   has of a collision below the force sensor.
//!
//! A detector can only find an event whose signal stands out of the sensors' own reading;
//! where the right share falls with the signal, the misses are at the sensors' reach. For
//! each scenario, the same measure is also taken where nothing happens: in each run started
//! 100 ms sooner (200 ms for a link collision; the same plant, motion and sensors), over
//! the same windows, which now end 40-70 ms before its event. Where an event's measure is
//! below the largest of those, no threshold on it finds the event without reading steady
//! motion as that event about as often; the threshold that would find 99.5 % of the events
//! is printed with the share of event-free windows that reach it.
//!
//! The latency targets ask for 99 % of the disturbances within 20 ms (10 ms for large ones):
//! the same vibration ratio over only that window after the onset, against the same window
//! of each event-free twin, gives the threshold that passes 99 % of the events within it,
//! and the share of event-free windows that reach it too.
//!
//! `cargo run --release -p fingertip --example reach -- --traces PATH...` takes the same
//! measures on labelled recordings instead (trace files, or directories searched for
//! `*.csv`), such as those of another simulator: each disturbance, grouped by the
//! recording's `scenario` metadata, and each very soft contact (`contact_very_soft_1`);
//! the event-free windows are taken every 20 ms of the recordings labelled
//! `free_motion` where the finger cruises at a steady commanded speed of at least 1 cm/s,
//! as it does before an event.

mod seeds;

use detector_core::Detector;
use fingertip::corpus::find_recordings;
use fingertip::score::classify;
use fingertip::sim::filters::HighPass1;
use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;
use fingertip::{APPROACH_TOML, replay};
use rayon::prelude::*;
use std::path::PathBuf;

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

/// The vibration above 25 Hz on each sensor over `after` (a disturbance's first 50 ms) as
/// an RMS over that of `before` (what it read just before): force, skin acceleration,
/// position error.
fn vibration_ratios(
    tr: &Trace,
    before: std::ops::Range<usize>,
    after: std::ops::Range<usize>,
) -> Option<[f64; 3]> {
    let rate = tr.rate_hz();
    let hp = |name: &str| tr.column(name).map(|c| high_pass(c, 25.0, rate));
    let (fx, fy, acc, ex, ey) = (
        hp("force_x")?,
        hp("force_y")?,
        hp("skin_accel")?,
        hp("pos_err_x")?,
        hp("pos_err_y")?,
    );
    if before.is_empty() || after.is_empty() || after.end > tr.len() {
        return None;
    }
    let ratio = |axes: &[&[f64]]| rms(axes, after.clone()) / rms(axes, before.clone()).max(1e-12);
    Some([ratio(&[&fx, &fy]), ratio(&[&acc]), ratio(&[&ex, &ey])])
}

/// How far channel `name` moved from the 20 ms before a contact's onset row `on` to its
/// mean from `from_ms` to 60 ms after it.
fn moved(tr: &Trace, name: &str, on: usize, from_ms: usize) -> Option<f64> {
    let x = tr.column(name)?;
    let mean = |r: std::ops::Range<usize>| x[r.clone()].iter().sum::<f64>() / r.len() as f64;
    let before = on.saturating_sub(20 * MS)..on;
    let after = on + from_ms * MS..(on + 60 * MS).min(tr.len());
    (!before.is_empty() && !after.is_empty()).then(|| mean(after) - mean(before))
}

/// How fast the film's reading rose after a contact's onset (N/s).
fn film_rise(tr: &Trace, on: usize) -> Option<f64> {
    moved(tr, "stress_rate", on, 20)
}

/// How far the force sensor was pushed back 60 ms after a contact's onset (N): a contact
/// makes force_x fall.
fn force_push(tr: &Trace, on: usize) -> Option<f64> {
    moved(tr, "force_x", on, 30).map(|m| -m)
}

/// A very soft contact's measures: the film's rise and the force sensor's push.
fn contact_measure(tr: &Trace, on: usize) -> Option<Measure> {
    Some(Measure::contact(film_rise(tr, on)?, force_push(tr, on)?))
}

/// The lead-in of a run's event-free twin (ms): long enough that the twin's windows end
/// before its event.
fn twin_lead_in_ms(reads: Reads) -> usize {
    match reads {
        Reads::Offset => 200,
        Reads::Vibration { .. } | Reads::Film => 100,
    }
}

/// The window a link collision is scored in after its onset (ms).
const COLLISION_WINDOW_MS: usize = 130;

/// How far the tip moved off its path within `after_ms` of row `on` (µm; up to the
/// trace's end, which a run's scoring window reaches to within a row): the position
/// error's largest distance from its mean over the 10 ms before.
fn offset_measure(tr: &Trace, on: usize, after_ms: usize) -> Option<Measure> {
    let (x, y) = (tr.column("pos_err_x")?, tr.column("pos_err_y")?);
    let before = on.saturating_sub(10 * MS)..on;
    let end = (on + after_ms * MS).min(tr.len());
    if before.is_empty() || end < on + (after_ms - 1) * MS {
        return None;
    }
    let mean = |c: &[f64]| c[before.clone()].iter().sum::<f64>() / before.len() as f64;
    let (mx, my) = (mean(x), mean(y));
    let off = (on..end)
        .map(|k| (x[k] - mx).hypot(y[k] - my))
        .fold(0.0, f64::max);
    let um = off * 1e6;
    Some(Measure {
        best: um,
        ratios: [um, 0.0, 0.0],
    })
}

/// A link collision's measure: its offset over the window it is scored in.
fn collision_measures(tr: &Trace, on: usize) -> Option<Measures> {
    Some(Measures {
        whole: offset_measure(tr, on, COLLISION_WINDOW_MS)?,
        early: None,
    })
}

/// A window's measure: a very soft contact's film rise (`best`) and, in `ratios`, the
/// same and the force sensor's push; a disturbance's three vibration ratios and the
/// best of them; or a link collision's offset.
#[derive(Clone, Copy)]
struct Measure {
    best: f64,
    ratios: [f64; 3],
}

impl Measure {
    fn contact(rise: f64, push: f64) -> Measure {
        Measure {
            best: rise,
            ratios: [rise, push, 0.0],
        }
    }

    fn vibration(ratios: [f64; 3]) -> Measure {
        Measure {
            best: ratios.iter().copied().fold(0.0, f64::max),
            ratios,
        }
    }
}

/// The window a disturbance's p99 latency target leaves (ms): 10 ms for large ones, as
/// for hard contacts and link collisions, 20 ms (the paper's bound) for the others.
fn target_ms(scenario: &str) -> usize {
    if scenario == Scenario::DisturbanceLarge5.name() {
        10
    } else {
        20
    }
}

/// A window's measures: over the whole window, and for a disturbance over the first
/// [`target_ms`] of it too.
#[derive(Clone, Copy)]
struct Measures {
    whole: Measure,
    early: Option<Measure>,
}

/// A disturbance's measures in `tr` from the onset row `on`.
fn disturbance_measures(tr: &Trace, on: usize, target_ms: usize) -> Option<Measures> {
    let (before, after) = windows(on, 50);
    let (_, early) = windows(on, target_ms);
    Some(Measures {
        whole: Measure::vibration(vibration_ratios(tr, before.clone(), after)?),
        early: Some(Measure::vibration(vibration_ratios(tr, before, early)?)),
    })
}

/// A very soft contact's measures: its 60 ms window is the one its latency target leaves.
fn contact_measures(tr: &Trace, on: usize) -> Option<Measures> {
    Some(Measures {
        whole: contact_measure(tr, on)?,
        early: None,
    })
}

/// One run: its measures and whether the default detector got it right.
struct Run {
    measures: Measures,
    right: bool,
}

/// What a scenario's measure reads.
#[derive(Clone, Copy, PartialEq)]
enum Reads {
    /// A disturbance's vibration ratios, and the window its latency target leaves (ms).
    Vibration { target_ms: usize },
    /// A very soft contact's film rise and force sensor's push.
    Film,
    /// A link collision's offset off the tip's path.
    Offset,
}

impl Reads {
    /// What scenario `s`'s runs are measured by.
    fn of(s: Scenario) -> Reads {
        match s {
            Scenario::ContactVerySoft1 => Reads::Film,
            Scenario::LinkCollision2 => Reads::Offset,
            _ => Reads::Vibration {
                target_ms: target_ms(s.name()),
            },
        }
    }
}

/// The measures of one scenario's runs, and the same measures where nothing happens.
struct Measured {
    runs: Vec<Run>,
    event_free: Vec<Measures>,
    reads: Reads,
}

/// One simulated run and the measures on its event-free twin.
fn run(detector: &Detector, s: Scenario, seed: u64) -> Option<(Run, Measures)> {
    let reads = Reads::of(s);
    let opts = SimOptions {
        seed,
        randomize: true,
        ..SimOptions::default()
    };
    let tr = sim::simulate(&s, &opts).ok()?;
    let (on, _) = tr.truth_onset()?;
    let onset_s = tr.time().get(on).copied()?;
    let right = is_right(detector, &tr, s.expected().map(|e| (e, onset_s)))?;
    // The event-free twin: the same run started sooner, so that its event comes that
    // long after this run's onset.
    let twin = sim::simulate(
        &s,
        &SimOptions {
            lead_in_s: twin_lead_in_ms(reads) as f64 * 1e-3,
            ..opts
        },
    )
    .ok()?;
    // The contact is judged up to 60 ms after `on`, the twin's event is later; a
    // disturbance's windows in the twin end 50 ms before its event, a collision's 70 ms.
    let measures = |tr: &Trace| match reads {
        Reads::Film => contact_measures(tr, on),
        Reads::Offset => collision_measures(tr, on),
        Reads::Vibration { target_ms } => disturbance_measures(tr, on, target_ms),
    };
    let run = Run {
        measures: measures(&tr)?,
        right,
    };
    Some((run, measures(&twin)?))
}

/// The windows before and after a disturbance's onset row `on`: the 30 ms before (not the
/// first 10 ms of the trace, where the filters settle) and the `after_ms` after.
fn windows(on: usize, after_ms: usize) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
    (
        on.saturating_sub(30 * MS).max(10 * MS)..on,
        on..on + after_ms * MS,
    )
}

/// Whether the commanded motion holds a steady speed of at least 1 cm/s over `rows`.
fn cruising(tr: &Trace, rows: std::ops::Range<usize>) -> bool {
    let column = |name: &str| tr.column(name).and_then(|c| c.get(rows.clone()));
    let (Some(vx), Some(vy), Some(ax), Some(ay)) = (
        column("vel_des_x"),
        column("vel_des_y"),
        column("acc_des_x"),
        column("acc_des_y"),
    ) else {
        return false;
    };
    ax.iter().chain(ay).all(|&a| a == 0.0) && vx.iter().zip(vy).all(|(x, y)| x.hypot(*y) >= 0.01)
}

/// Whether the detector is right on `tr`, which should show `expected` (event, onset s).
fn is_right(detector: &Detector, tr: &Trace, expected: Option<(&str, f64)>) -> Option<bool> {
    let decisions = replay::replay(detector, tr, |_, _, _| {}).ok()?;
    Some(classify(expected, &decisions).is_right())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let config = detector_build::Config::from_toml(APPROACH_TOML)?;
    let detector = detector_build::build(&config)?;
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--traces") {
        let paths: Vec<PathBuf> = args[1..].iter().map(PathBuf::from).collect();
        return recordings(&detector, &paths);
    }
    let (runs, base) = seeds::runs_and_base(500)?;
    println!(
        "{runs} randomized runs per scenario (seeds {base}..{}), configs/approach.toml",
        base + runs - 1
    );
    for s in Scenario::disturbances().chain([Scenario::ContactVerySoft1, Scenario::LinkCollision2])
    {
        let (runs, event_free) = (base..base + runs)
            .into_par_iter()
            .filter_map(|seed| run(&detector, s, seed))
            .unzip();
        let reads = Reads::of(s);
        let measured = Measured {
            runs,
            event_free,
            reads,
        };
        print_scenario(
            s.name(),
            &measured,
            &format!("each run's twin, {} ms sooner", twin_lead_in_ms(reads)),
        );
    }
    Ok(())
}

/// The measures on labelled recordings: the disturbances and very soft contacts, by
/// scenario, against windows of the free-motion recordings.
fn recordings(detector: &Detector, paths: &[PathBuf]) -> Result<(), Box<dyn std::error::Error>> {
    if paths.is_empty() {
        return Err("--traces needs at least one trace file or directory".into());
    }
    let files = find_recordings(paths)?;
    let traces: Vec<Trace> = files
        .par_iter()
        .map(Trace::read)
        .collect::<Result<_, _>>()?;
    let scenario = |tr: &Trace| tr.meta(sim::META_SCENARIO).unwrap_or("").to_string();
    // Event-free windows every 20 ms of free motion, where the finger cruises as it does
    // before an event: at a steady commanded speed of at least 1 cm/s from 50 ms before
    // to 60 ms after.
    let free: Vec<&Trace> = traces
        .iter()
        .filter(|tr| scenario(tr) == "free_motion")
        .collect();
    let free_windows = |measures: &(dyn Fn(&Trace, usize) -> Option<Measures> + Sync)| {
        free.par_iter()
            .flat_map_iter(|tr| {
                (50 * MS..tr.len().saturating_sub(60 * MS))
                    .step_by(20 * MS)
                    .filter(|&on| cruising(tr, on - 50 * MS..on + 60 * MS))
                    .filter_map(|on| measures(tr, on))
            })
            .collect::<Vec<Measures>>()
    };
    let free_film = free_windows(&contact_measures);
    println!(
        "{} recordings ({} of free motion, {} event-free windows), configs/approach.toml",
        traces.len(),
        free.len(),
        free_film.len()
    );
    let mut scenarios: Vec<String> = traces.iter().map(scenario).collect();
    scenarios.sort();
    scenarios.dedup();
    for name in scenarios {
        let very_soft = name == Scenario::ContactVerySoft1.name();
        let runs: Vec<Run> = traces
            .par_iter()
            .filter(|tr| scenario(tr) == name)
            .filter_map(|tr| {
                let (on, event) = tr.truth_onset()?;
                if !(very_soft || event == "disturbance") {
                    return None;
                }
                let onset_s = tr.time().get(on).copied()?;
                let right = is_right(detector, tr, Some((event, onset_s)))?;
                let measures = if very_soft {
                    contact_measures(tr, on)?
                } else {
                    disturbance_measures(tr, on, target_ms(&name))?
                };
                Some(Run { measures, right })
            })
            .collect();
        if runs.is_empty() {
            continue;
        }
        let measured = if very_soft {
            Measured {
                runs,
                event_free: free_film.clone(),
                reads: Reads::Film,
            }
        } else {
            let target = target_ms(&name);
            Measured {
                runs,
                event_free: free_windows(&|tr, on| disturbance_measures(tr, on, target)),
                reads: Reads::Vibration { target_ms: target },
            }
        };
        print_scenario(&name, &measured, "windows of the free-motion recordings");
    }
    Ok(())
}

/// One scenario's table: the runs binned by their measure (the film's rise for very soft
/// contacts, the offset for link collisions), with the right share, and the event-free comparison (its windows taken at
/// `place`), within a disturbance's latency target too.
fn print_scenario(name: &str, measured: &Measured, place: &str) {
    let results = &measured.runs;
    let (edges, what): (&[f64], &str) = match measured.reads {
        Reads::Film => (&[0.3, 0.5, 0.8, 1.2], "the film's rise over 60 ms [N/s]"),
        Reads::Offset => (
            &[10.0, 20.0, 40.0, 80.0],
            "how far the tip moved off its path within 130 ms [um]",
        ),
        Reads::Vibration { .. } => (
            &[1.5, 2.0, 3.0, 5.0],
            "vibration RMS after / before, the best of force, skin acceleration and position error",
        ),
    };
    println!("\n{name} ({} runs), by {what}:", results.len());
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
        let mut inside: Vec<&Run> = results
            .iter()
            .filter(|r| (lo..hi).contains(&r.measures.whole.best))
            .collect();
        if inside.is_empty() {
            continue;
        }
        let right = inside.iter().filter(|r| r.right).count();
        let label = match (b, edges.get(b)) {
            (0, Some(h)) => format!("< {h}"),
            (_, Some(h)) => format!("{lo}-{h}"),
            (_, None) => format!(">= {lo}"),
        };
        let medians = if let Reads::Film | Reads::Offset = measured.reads {
            String::new()
        } else {
            let median = |k: usize, v: &mut Vec<&Run>| {
                v.sort_by(|a, b| a.measures.whole.ratios[k].total_cmp(&b.measures.whole.ratios[k]));
                v[v.len() / 2].measures.whole.ratios[k]
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
    print_event_free(measured, place);
    if let Reads::Vibration { target_ms } = measured.reads {
        print_within_target(measured, target_ms);
    }
}

/// Within the window a disturbance's latency target leaves: the threshold on the ratio
/// over that window that passes 99 % of the events, and how many event-free windows of
/// the same length reach it. Where that share is not zero, a detector judging these
/// measures confirms 99 % of the events within the target only by reading steady motion
/// as a disturbance as well, about once every `target_ms / share` of it.
fn print_within_target(measured: &Measured, target_ms: usize) {
    let early = |m: &Measures| m.early.map(|e| e.best);
    let mut events: Vec<f64> = measured
        .runs
        .iter()
        .filter_map(|r| early(&r.measures))
        .collect();
    let mut free: Vec<f64> = measured.event_free.iter().filter_map(early).collect();
    if events.is_empty() || free.is_empty() {
        return;
    }
    let largest = quantile(&mut free, 1.0);
    let below = events.iter().filter(|&&e| e < largest).count();
    let threshold = quantile(&mut events, 0.01);
    let passed = free.iter().filter(|&&f| f >= threshold).count();
    println!(
        "  within {target_ms} ms, the p99 latency target: the same ratio over those {target_ms} \
         ms reads up to {largest:.2} where nothing happens, and {below} of the events ({:.1} %) \
         read below that; a threshold passing 99 % of the events is at most {threshold:.2}, \
         which {:.1} % of the event-free {target_ms} ms windows reach",
        100.0 * below as f64 / events.len() as f64,
        100.0 * passed as f64 / free.len() as f64
    );
}

/// The `q` quantile of `values` (sorted here).
fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// How high the measure reads where nothing happens (`place`), on each sensor too for a
/// disturbance's, and how many events read below that.
fn print_event_free(measured: &Measured, place: &str) {
    let results = &measured.runs;
    let mut free: Vec<f64> = measured.event_free.iter().map(|m| m.whole.best).collect();
    if free.is_empty() || results.is_empty() {
        return;
    }
    let (median, p99, largest) = (
        quantile(&mut free, 0.5),
        quantile(&mut free, 0.99),
        quantile(&mut free, 1.0),
    );
    let below: Vec<&Run> = results
        .iter()
        .filter(|r| r.measures.whole.best < largest)
        .collect();
    let right = below.iter().filter(|r| r.right).count();
    println!(
        "  where nothing happens ({place}): median {median:.2}, 99 % below {p99:.2}, largest \
         {largest:.2}; {} of the events ({:.1} %) read below that largest, {right} of them right",
        below.len(),
        100.0 * below.len() as f64 / results.len() as f64
    );
    let p99_of = |k: usize| {
        let mut sensor: Vec<f64> = measured
            .event_free
            .iter()
            .map(|m| m.whole.ratios[k])
            .collect();
        quantile(&mut sensor, 0.99)
    };
    // The events that read below each sensor's 99 % event-free level.
    let below_all = |p99s: &[f64]| -> Vec<&Run> {
        results
            .iter()
            .filter(|r| r.measures.whole.ratios.iter().zip(p99s).all(|(v, p)| v < p))
            .collect()
    };
    // Sensor by sensor: a collision's offset is one measure.
    match measured.reads {
        Reads::Film => {
            let p99s = [p99_of(0), p99_of(1)];
            let within = below_all(&p99s);
            println!(
                "  there, 99 % below {:.2} N/s on the film and {:.2} cN on the force sensor; {} of \
                 the events ({:.1} %) read below both, {} of them right",
                p99s[0],
                100.0 * p99s[1],
                within.len(),
                100.0 * within.len() as f64 / results.len() as f64,
                within.iter().filter(|r| r.right).count()
            );
            let mut pushes: Vec<f64> = results.iter().map(|r| r.measures.whole.ratios[1]).collect();
            let threshold = quantile(&mut pushes, 0.005);
            let free_pushes: Vec<f64> = measured
                .event_free
                .iter()
                .map(|m| m.whole.ratios[1])
                .collect();
            let passed = free_pushes.iter().filter(|&&f| f >= threshold).count();
            println!(
                "  on the force sensor alone, a threshold passing 99.5 % of the events is at most \
                 {:.2} cN, which {:.1} % of the event-free windows reach (the largest: {:.2} cN)",
                100.0 * threshold,
                100.0 * passed as f64 / free_pushes.len() as f64,
                100.0
                    * free_pushes
                        .iter()
                        .copied()
                        .fold(f64::NEG_INFINITY, f64::max)
            );
        }
        Reads::Vibration { .. } => {
            let p99s = [p99_of(0), p99_of(1), p99_of(2)];
            let within = below_all(&p99s);
            println!(
                "  there, 99 % below {:.2} / {:.2} / {:.2} on the force / accel / error alone; {} of \
                 the events read below all three, {} of them right",
                p99s[0],
                p99s[1],
                p99s[2],
                within.len(),
                within.iter().filter(|r| r.right).count()
            );
        }
        Reads::Offset => {}
    }
    // The threshold that would pass 99.5 % of the events, and how much steady motion it
    // would pass too.
    let mut events: Vec<f64> = results.iter().map(|r| r.measures.whole.best).collect();
    let threshold = quantile(&mut events, 0.005);
    let passed = free.iter().filter(|&&f| f >= threshold).count();
    println!(
        "  a threshold passing 99.5 % of the events is at most {threshold:.2}, which {:.1} % of \
         the event-free windows reach",
        100.0 * passed as f64 / free.len() as f64
    );
}
