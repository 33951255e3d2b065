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
//! where the right share falls with the signal, the misses are at the sensors' reach. For
//! each scenario, the same measure is also taken where nothing happens: in each run started
//! 100 ms sooner (the same plant, motion and sensors), over the same windows, which now end
//! 40-50 ms before its event. Where an event's measure is below the largest of those, no
//! threshold on it finds the event without reading steady motion as that event about as
//! often; the threshold that would find 99.5 % of the events is printed with the share of
//! event-free windows that reach it.

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

/// How fast the film's reading rose after a contact's onset (N/s).
fn film_rise(tr: &Trace, on: usize) -> Option<f64> {
    let film = tr.column("stress_rate")?;
    let mean = |r: std::ops::Range<usize>| film[r.clone()].iter().sum::<f64>() / r.len() as f64;
    let before = on.saturating_sub(20 * MS)..on;
    let after = on + 20 * MS..(on + 60 * MS).min(tr.len());
    (!before.is_empty() && !after.is_empty()).then(|| mean(after) - mean(before))
}

/// The lead-in of a run's event-free twin (ms).
const TWIN_LEAD_IN_MS: usize = 100;

/// One run: its measure (for a disturbance the best of its three ratios), whether the
/// default detector got it right, and the same measure on its event-free twin.
struct Run {
    best: f64,
    ratios: [f64; 3],
    right: bool,
    event_free: f64,
}

fn run(detector: &Detector, s: Scenario, seed: u64) -> Option<Run> {
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
    // The event-free twin: the same run started 100 ms sooner, so that its event comes
    // 100 ms after this run's onset.
    let twin = sim::simulate(
        &s,
        &SimOptions {
            lead_in_s: TWIN_LEAD_IN_MS as f64 * 1e-3,
            ..opts
        },
    )
    .ok()?;
    if s == Scenario::ContactVerySoft1 {
        // The film's rise is judged up to 60 ms after `on`: the twin's event is later.
        return Some(Run {
            best: film_rise(&tr, on)?,
            ratios: [0.0; 3],
            right,
            event_free: film_rise(&twin, on)?,
        });
    }
    // The filters settle in the run's first 10 ms; the onset is later.
    let before = on.saturating_sub(30 * MS).max(10 * MS)..on;
    let after = on..on + 50 * MS;
    let ratios = vibration_ratios(&tr, before.clone(), after.clone())?;
    // The same windows in the twin end 50 ms before its event.
    let event_free = vibration_ratios(&twin, before, after)?;
    Some(Run {
        best: best_of(&ratios),
        ratios,
        right,
        event_free: best_of(&event_free),
    })
}

fn best_of(ratios: &[f64; 3]) -> f64 {
    ratios.iter().copied().fold(0.0, f64::max)
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
        let results: Vec<Run> = (base..base + runs)
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
            let mut inside: Vec<&Run> = results
                .iter()
                .filter(|r| (lo..hi).contains(&r.best))
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
            let medians = if s == Scenario::ContactVerySoft1 {
                String::new()
            } else {
                let median = |k: usize, v: &mut Vec<&Run>| {
                    v.sort_by(|a, b| a.ratios[k].total_cmp(&b.ratios[k]));
                    v[v.len() / 2].ratios[k]
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
        print_event_free(&results);
    }
    Ok(())
}

/// How high the measure reads where nothing happens, and how many events read below that.
fn print_event_free(results: &[Run]) {
    let mut free: Vec<f64> = results.iter().map(|r| r.event_free).collect();
    if free.is_empty() {
        return;
    }
    free.sort_by(f64::total_cmp);
    let quantile = |q: f64| free[((free.len() - 1) as f64 * q).round() as usize];
    let largest = quantile(1.0);
    let below: Vec<&Run> = results.iter().filter(|r| r.best < largest).collect();
    let right = below.iter().filter(|r| r.right).count();
    println!(
        "  where nothing happens (each run's twin, {TWIN_LEAD_IN_MS} ms sooner): median {:.2}, \
         99 % below {:.2}, largest {largest:.2}; {} of the events ({:.1} %) read below that \
         largest, {right} of them right",
        quantile(0.5),
        quantile(0.99),
        below.len(),
        100.0 * below.len() as f64 / results.len() as f64
    );
    // The threshold that would pass 99.5 % of the events, and how much steady motion it
    // would pass too.
    let mut events: Vec<f64> = results.iter().map(|r| r.best).collect();
    events.sort_by(f64::total_cmp);
    let threshold = events[((events.len() - 1) as f64 * 0.005).round() as usize];
    let passed = free.iter().filter(|&&f| f >= threshold).count();
    println!(
        "  a threshold passing 99.5 % of the events is at most {threshold:.2}, which {:.1} % of \
         the event-free windows reach",
        100.0 * passed as f64 / free.len() as f64
    );
}
