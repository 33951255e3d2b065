//! `fingertip fit`: a configuration's numbers fitted to labelled recordings, its structure
//! kept.
//!
//! The user's configuration says which channels, features, events and phases there are
//! and which feature judges which event, as context or as sensor. The fit keeps all of
//! that and sets the numbers from the corpus ([`crate::features`] sorts each feature's
//! values into the first `window` of each labelled event and the time outside events):
//!
//! - **Sensor terms** (evidence for the event): a rising sigmoid from where the time
//!   outside events ends (its 99.999 % quantile, over the ticks the event's base context
//!   lets through) to what nine in ten of the event's occurrences reach in the window (the
//!   10 % quantile of their peaks); falling, mirrored, when the base's is. A term whose feature does not
//!   separate the event (balanced accuracy of the best single threshold below
//!   [`MIN_SEPARATION`]) keeps the base's numbers when another of the event's terms
//!   separates (a corpus of hard contacts never exercises a slow path), and stops the fit
//!   with the figures when none does.
//! - **Weights**: in proportion to each fitted sensor term's separation above chance from
//!   the time outside events and from every other labelled event, the weakest of these,
//!   summing to what the kept terms leave of the base's total.
//! - **Context terms** (permission, placed by the user for physical reasons a corpus may
//!   not show, such as a veto on sudden commanded motion): kept, and widened only where
//!   the event's own central 95 % lies beyond the confidence they give.
//! - **Levels**: every event's confirm level and dwell from a grid, the combination that
//!   gets the most events right while its false confirmations stay within the budget per
//!   hour; the alert and the `off` levels keep their ratios to `on`, the holds are kept.
//!
//! Fitted numbers are rounded to four significant digits, so that the file written is
//! exactly the configuration that was scored.

use std::path::PathBuf;

use detector_build::{Config, EarlySpec, EventSpec, LevelSpec};
use detector_core::Detector;
use detector_core::{CdfSpec, EventId, LevelParams, LevelState};
use rayon::prelude::*;

use crate::corpus::{CorpusReport, RecordingResult};
use crate::features::{FeatureSamples, best_threshold};
use crate::replay::{DecisionRecord, StreamError, replay_stream_each};
use crate::score::nearest_rank;
use crate::trace::TraceReader;

/// The least balanced accuracy of a sensor term's feature against its event for the fit
/// to use it: 0.6, a little better than chance.
pub const MIN_SEPARATION: f64 = 0.6;

/// The fewest outside ticks an event's context must let through for its sensor terms to
/// be fitted against those alone.
const MIN_LET_THROUGH: usize = 1000;

/// The confirm levels tried: low ones too, for events whose weakest occurrences reach only
/// the foot of their terms' sigmoids.
const CONFIRM_ON: [f32; 17] = [
    0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9,
];
/// The confirm dwells tried, in ticks of the detector's rate (at 5 kHz: 0, 0.4, 1, 2 and
/// 5 ms; at 10 Hz: 0, 0.2, 0.5, 1 and 2.5 s).
const DWELL_TICKS: [f32; 5] = [0.0, 2.0, 5.0, 10.0, 25.0];

/// How to fit.
#[derive(Clone, Copy, Debug)]
pub struct FitOptions {
    /// How long after each labelled onset the event's feature values are taken (s).
    pub window_s: f64,
    /// How long after a labelled event's end a confirmation still counts for it (s).
    pub after_s: f64,
    /// The false confirmations per hour outside events that the levels may cost.
    pub budget_per_hour: f64,
}

/// Why a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// A recording could not be replayed.
    #[error(transparent)]
    Stream(#[from] StreamError),
    /// A configuration could not be built.
    #[error("{0}")]
    Config(String),
    /// A fold of the cross-validation failed.
    #[error("fold {fold}: {source}")]
    Fold {
        /// The fold, from 1.
        fold: usize,
        /// What failed.
        source: Box<FitError>,
    },
    /// No recording labels an event of the configuration.
    #[error(
        "none of the {0} recordings labels an event of the configuration in its `truth` column: there is nothing to fit"
    )]
    NothingLabelled(usize),
    /// A sensor term's feature does not separate its event from the time outside events.
    #[error(
        "feature `{feature}` does not separate event `{event}` from the time outside events: the best single threshold ({threshold}) tells them apart in {:.1} % (balanced accuracy; {:.0} % at least is needed). In the event's first window its median is {event_median}, outside {outside_median}. Choose another feature for this term, or label more events",
        accuracy * 100.0,
        MIN_SEPARATION * 100.0
    )]
    NoSeparation {
        /// The feature.
        feature: String,
        /// The event.
        event: String,
        /// The best threshold.
        threshold: f32,
        /// Its balanced accuracy.
        accuracy: f64,
        /// The medians.
        event_median: f32,
        /// ... outside events.
        outside_median: f32,
    },
}

/// A fitted number's explanation, for the comment beside it in the file written.
#[derive(Clone, Debug, PartialEq)]
pub struct Note {
    /// The event.
    pub event: String,
    /// What it explains: `context`, `sensor`, `confirm` or `skipped`.
    pub item: &'static str,
    /// The explanation, one line.
    pub text: String,
}

/// Rounds to four significant digits, as written to the file.
fn round4(v: f64) -> f32 {
    if v == 0.0 || !v.is_finite() {
        return 0.0;
    }
    let digits = 3 - v.abs().log10().floor() as i32;
    let scale = 10f64.powi(digits);
    ((v * scale).round() / scale) as f32
}

/// A sigmoid's bounds as written: within the range a feature can take (it saturates at
/// ±32768), rounded, `low` below `high`.
fn sigmoid_bounds(low: f64, high: f64) -> (f32, f32) {
    const TOP: f32 = 32767.0;
    let high = round4(high).clamp(-TOP, TOP);
    let below = round4(f64::from(high) - gap(f64::from(high), 0.0)).max(-TOP - 1.0);
    (round4(low).clamp(-TOP - 1.0, TOP).min(below), high)
}

fn sorted(v: &[f64]) -> Vec<f64> {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s
}

/// A distance that keeps two bounds apart when the data would put them together: a
/// thousandth of their size, or the fixed-point resolution.
fn gap(a: f64, b: f64) -> f64 {
    (a.abs().max(b.abs()) * 1e-3).max(1e-4)
}

/// Fits every term of every labelled event from `samples`; events without labelled
/// examples keep the base's numbers.
pub fn fit_terms(base: &Config, samples: &FeatureSamples) -> Result<(Config, Vec<Note>), FitError> {
    let mut config = base.clone();
    let mut notes = Vec::new();
    let feature_index = |name: &str| samples.features.iter().position(|f| f == name);
    for event in &mut config.events {
        let Some(e) = samples.events.iter().position(|n| *n == event.name) else {
            continue;
        };
        if samples.inside[e].iter().all(Vec::is_empty) {
            notes.push(Note {
                event: event.name.clone(),
                item: "skipped",
                text: "not labelled in the corpus: its numbers are the base's".into(),
            });
            continue;
        }
        let inside = |f: usize| sorted(&samples.inside[e][f]);
        // The outside ticks this event's base context lets through (at least half its
        // confidence): those its sensor terms must tell it from.
        let rows = samples.outside.first().map_or(0, Vec::len);
        let mut allowed = vec![true; rows];
        for term in &event.context {
            let (Some(f), Ok(cdf)) = (
                feature_index(&term.feature),
                detector_core::Cdf::new(&term.cdf),
            ) else {
                continue;
            };
            for (a, v) in allowed.iter_mut().zip(&samples.outside[f]) {
                *a &= cdf.eval(detector_core::Signal::from_f64(*v)).to_f64() >= 0.5;
            }
        }
        // When the context lets almost nothing through, the sensor terms are fitted against
        // all the time outside events.
        let gated = allowed.iter().filter(|a| **a).count() >= MIN_LET_THROUGH;
        let let_through = |f: usize| -> Vec<f64> {
            sorted(
                &samples.outside[f]
                    .iter()
                    .zip(&allowed)
                    .filter(|(_, a)| **a || !gated)
                    .map(|(v, _)| *v)
                    .collect::<Vec<f64>>(),
            )
        };
        for term in &mut event.context {
            let Some(f) = feature_index(&term.feature) else {
                continue;
            };
            let values = inside(f);
            let (cdf, text) = fit_context(&term.cdf, &values);
            term.cdf = cdf;
            notes.push(Note {
                event: event.name.clone(),
                item: "context",
                text: format!("{}: {text}", term.feature),
            });
        }
        let total: f32 = event.sensor.iter().map(|t| t.weight).sum();
        // Each term's separation above chance, `None` for a term kept as the base has it.
        let mut strengths = Vec::new();
        let mut unseparated = None;
        for term in &mut event.sensor {
            let Some(f) = feature_index(&term.feature) else {
                continue;
            };
            let values = inside(f);
            let others = let_through(f);
            let (threshold, above, accuracy) = best_threshold(&values, &others);
            if accuracy < MIN_SEPARATION {
                // Another path to the same evidence may be all the corpus shows (hard
                // contacts never exercise a slow path): this term keeps the base's numbers
                // as long as another term of the event separates.
                notes.push(Note {
                    event: event.name.clone(),
                    item: "sensor",
                    text: format!(
                        "{}: kept the base's (weight {}): one threshold separates only {:.1} % of this corpus from outside",
                        term.feature,
                        term.weight,
                        accuracy * 100.0
                    ),
                });
                strengths.push(None);
                unseparated.get_or_insert_with(|| FitError::NoSeparation {
                    feature: term.feature.clone(),
                    event: event.name.clone(),
                    threshold: round4(threshold),
                    accuracy,
                    event_median: round4(nearest_rank(&values, 0.5)),
                    outside_median: round4(nearest_rank(&others, 0.5)),
                });
                continue;
            }
            let falling = matches!(term.cdf, CdfSpec::Sigmoid { falling: true, .. });
            // What each occurrence reaches: its greatest value (its least, falling).
            let reached = sorted(
                &samples.peaks[e][f]
                    .iter()
                    .map(|&(low, high)| if falling { low } else { high })
                    .collect::<Vec<f64>>(),
            );
            let (cdf, text) = fit_sensor(falling, &values, &reached, &others, (threshold, above));
            term.cdf = cdf;
            // How well it tells the event from each other labelled event, on its side.
            let mut weakest = (accuracy, "the time outside events".to_string());
            for (o, other) in samples.events.iter().enumerate() {
                let theirs = sorted(&samples.inside[o][f]);
                if o == e || theirs.is_empty() {
                    continue;
                }
                let (_, side, acc) = best_threshold(&values, &theirs);
                let acc = if side != falling { acc } else { 0.5 };
                if acc < weakest.0 {
                    weakest = (acc, format!("`{other}`"));
                }
            }
            strengths.push(Some(weakest.0 - 0.5));
            notes.push(Note {
                event: event.name.clone(),
                item: "sensor",
                text: format!(
                    "{}: {text}; one threshold separates {:.1} % from outside, at worst {:.1} % from {}",
                    term.feature,
                    accuracy * 100.0,
                    weakest.0 * 100.0,
                    weakest.1
                ),
            });
        }
        if let Some(err) = unseparated
            && strengths.iter().all(Option::is_none)
        {
            return Err(err);
        }
        let fitted: Vec<f64> = strengths.iter().flatten().copied().collect();
        if fitted.iter().sum::<f64>() > 0.0 && strengths.len() == event.sensor.len() {
            // The fitted terms share what the kept ones leave of the base's total.
            let kept: f32 = event
                .sensor
                .iter()
                .zip(&strengths)
                .filter(|(_, s)| s.is_none())
                .map(|(t, _)| t.weight)
                .sum();
            let mut weights = shares(f64::from(total - kept), &fitted).into_iter();
            let mut fitted_terms: Vec<&mut detector_build::SensorTerm> = event
                .sensor
                .iter_mut()
                .zip(&strengths)
                .filter(|(_, s)| s.is_some())
                .map(|(t, _)| t)
                .collect();
            for term in &mut fitted_terms {
                term.weight = round4(weights.next().unwrap_or(0.0));
            }
            // Rounding may push the sum past the base's: take it off the largest.
            let excess: f32 = fitted_terms.iter().map(|t| t.weight).sum::<f32>() + kept - total;
            if excess > 0.0
                && let Some(t) = fitted_terms
                    .iter_mut()
                    .max_by(|a, b| a.weight.total_cmp(&b.weight))
            {
                t.weight = round4(f64::from(t.weight - excess) - 1e-4);
            }
        }
    }
    Ok((config, notes))
}

/// `total` shared in proportion to `strengths`, no share above 1 (a weight's most): what a
/// capped share would have had beyond 1 goes to the others, in proportion again.
fn shares(total: f64, strengths: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; strengths.len()];
    let mut capped = vec![false; strengths.len()];
    let mut left = total;
    // Each round caps at least one more share or ends: at most one round per term.
    for _ in 0..strengths.len() {
        let open: f64 = strengths
            .iter()
            .zip(&capped)
            .filter(|(_, c)| !**c)
            .map(|(s, _)| *s)
            .sum();
        if open <= 0.0 {
            break;
        }
        let mut capped_now = false;
        for ((o, s), c) in out.iter_mut().zip(strengths).zip(capped.iter_mut()) {
            if !*c {
                *o = left * s / open;
                if *o > 1.0 {
                    *o = 1.0;
                    *c = true;
                    capped_now = true;
                }
            }
        }
        if !capped_now {
            break;
        }
        left = total - capped.iter().filter(|c| **c).count() as f64;
    }
    out
}

/// A sensor term: from the end of the outside distribution to what nine in ten of the
/// event's occurrences reach (`reached`: each occurrence's greatest value in its window, its
/// least when falling, sorted), so that the term is sure of most events at their peak.
fn fit_sensor(
    falling: bool,
    event: &[f64],
    reached: &[f64],
    outside: &[f64],
    (threshold, above): (f64, bool),
) -> (CdfSpec, String) {
    if !falling {
        let mut low = nearest_rank(outside, 0.99999);
        let mut high = nearest_rank(reached, 0.1);
        let mut how = "from the 99.999 % quantile outside events to what 90 % of the events reach";
        if high <= low + gap(low, high) {
            // Most events peak inside the outside tail: start where one threshold
            // separates best and end where most of the event is.
            low = if above { threshold } else { low };
            high = nearest_rank(event, 0.9).max(low + gap(low, high));
            how = "from the best single threshold to the event's 90 % quantile (most events peak within the outside tail)";
        }
        let (low, high) = sigmoid_bounds(low, high);
        (
            CdfSpec::Sigmoid {
                low,
                high,
                falling: false,
            },
            format!("rising {low}..{high}, {how}"),
        )
    } else {
        let mut high = nearest_rank(outside, 0.00001);
        let mut low = nearest_rank(reached, 0.9);
        let mut how =
            "falling from what 90 % of the events reach to the 0.1 % quantile outside events";
        if low >= high - gap(low, high) {
            high = if above { high } else { threshold };
            low = nearest_rank(event, 0.1).min(high - gap(low, high));
            how = "falling from the event's 10 % quantile to the best single threshold (most events peak within the outside tail)";
        }
        let (low, high) = sigmoid_bounds(low, high);
        (
            CdfSpec::Sigmoid {
                low,
                high,
                falling: true,
            },
            format!("falling {low}..{high}, {how}"),
        )
    }
}

/// A context term: the base's, widened where the event's central 95 % lies beyond it.
fn fit_context(base: &CdfSpec, event: &[f64]) -> (CdfSpec, String) {
    let (q025, q975) = (nearest_rank(event, 0.025), nearest_rank(event, 0.975));
    let central = format!(
        "the event's central 95 % is {}..{}",
        round4(q025),
        round4(q975)
    );
    let kept = |cdf: CdfSpec| (cdf, format!("kept: {central}, within it"));
    let widened = |cdf: CdfSpec| (cdf, format!("widened: {central}"));
    match *base {
        CdfSpec::Sigmoid {
            low,
            high,
            falling: true,
        } if q975 > f64::from(low) => widened(CdfSpec::Sigmoid {
            low: round4(q975),
            high: round4(q975 + f64::from(high - low)),
            falling: true,
        }),
        CdfSpec::Sigmoid {
            low,
            high,
            falling: false,
        } if q025 < f64::from(high) => widened(CdfSpec::Sigmoid {
            low: round4(q025 - f64::from(high - low)),
            high: round4(q025),
            falling: false,
        }),
        CdfSpec::Bell { center, half_width } => {
            // At a third of the half-width the bell still gives 0.78.
            let reach = 3.0 * (q975 - f64::from(center)).max(f64::from(center) - q025);
            if reach > f64::from(half_width) {
                widened(CdfSpec::Bell {
                    center,
                    half_width: round4(reach),
                })
            } else {
                kept(*base)
            }
        }
        CdfSpec::FlatBell {
            low,
            plateau_low,
            plateau_high,
            high,
        } if q025 < f64::from(plateau_low) || q975 > f64::from(plateau_high) => {
            let pl = round4(q025.min(f64::from(plateau_low)));
            let ph = round4(q975.max(f64::from(plateau_high)));
            widened(CdfSpec::FlatBell {
                low: pl - (plateau_low - low),
                plateau_low: pl,
                plateau_high: ph,
                high: ph + (high - plateau_high),
            })
        }
        CdfSpec::Binary { threshold, above }
            if (above && q025 < f64::from(threshold))
                || (!above && q975 > f64::from(threshold)) =>
        {
            widened(CdfSpec::Binary {
                threshold: round4(if above { q025 } else { q975 }),
                above,
            })
        }
        _ => kept(*base),
    }
}

/// `level` with `on` moved to `on`, `off` keeping its ratio.
fn scaled(level: &LevelSpec, on: f32) -> LevelSpec {
    let ratio = if level.on > 0.0 { on / level.on } else { 1.0 };
    LevelSpec {
        on: round4(f64::from(on)),
        off: round4(f64::from((level.off * ratio).min(on))),
        ..level.clone()
    }
}

/// `event` with its confirm level at `on` and `dwell_ms`, its alert moved with it.
fn with_levels(event: &EventSpec, on: f32, dwell_ms: f32) -> EventSpec {
    let mut e = event.clone();
    let alert_ratio = if event.confirm.on > 0.0 {
        event.alert.on / event.confirm.on
    } else {
        1.0
    };
    // An early dwell keeps its feature and level, and is at most the new dwell.
    let early = event.confirm.early.clone().map(|early| EarlySpec {
        dwell_ms: early.dwell_ms.min(dwell_ms),
        ..early
    });
    e.confirm = LevelSpec {
        dwell_ms,
        early,
        ..scaled(&event.confirm, on)
    };
    e.alert = scaled(&event.alert, (on * alert_ratio).min(on));
    e.onset_level = e.onset_level.min(e.alert.on * 0.99);
    e
}

fn build(config: &Config) -> Result<Detector, FitError> {
    detector_build::build(config).map_err(|e| FitError::Config(e.to_string()))
}

/// One tick of a recording as the fitted terms judged it.
#[derive(Clone, Copy)]
struct Judged {
    t: f64,
    phase: u8,
    /// The events evaluated in the phase, and of those the ones that could be judged.
    evaluated: u8,
    judged: u8,
    confidences: [u16; detector_core::MAX_EVENTS],
    /// The events whose confirm level's early dwell has its feature showing.
    shown: u8,
}

/// A recording replayed once: its ticks that can move a decision level (an event with a
/// confidence above 0, or the phase or the events evaluated or judged changing), each
/// after the count of ticks since the one before, ticks at confidence 0 with the same
/// phase and events as it.
struct Recorded {
    name: String,
    span: (f64, f64),
    labelled: Vec<crate::replay::Labelled>,
    scenario: Option<String>,
    ticks: Vec<(u32, Judged)>,
}

impl Recorded {
    /// Replays `file` with each of `detectors` (terms fitted), the file read once, and
    /// keeps what the levels need: one per detector, in their order.
    fn replay_each(detectors: &[&Detector], file: &PathBuf) -> Result<Vec<Recorded>, FitError> {
        let mut kept: Vec<(Vec<(u32, Judged)>, u32)> = vec![(Vec::new(), 0); detectors.len()];
        let reader = TraceReader::open(file).map_err(StreamError::from)?;
        let name = reader.name().to_string();
        // Each detector's confirm levels, whose early dwells the ticks record as shown.
        let confirms: Vec<Vec<LevelParams>> = detectors
            .iter()
            .map(|d| {
                (0..d.events().len())
                    .filter_map(|e| d.event_levels(EventId(e as u8)).map(|l| l[1]))
                    .collect()
            })
            .collect();
        let streamed = replay_stream_each(detectors, reader, |d, tick| {
            let (Some(confirm), Some((ticks, gap))) = (confirms.get(d), kept.get_mut(d)) else {
                return;
            };
            let out = tick.output;
            let mut judged = Judged {
                t: tick.t,
                phase: tick.state.phase().index(),
                evaluated: out.evaluated,
                judged: out.evaluated & !out.unjudgeable,
                confidences: [0; detector_core::MAX_EVENTS],
                shown: 0,
            };
            for (e, (q, level)) in judged.confidences.iter_mut().zip(confirm).enumerate() {
                let bit = 1 << e;
                if judged.judged & bit != 0 {
                    *q = out.confidences[e].to_bits();
                    if level.shown(tick.state, out.degraded & bit != 0) {
                        judged.shown |= bit;
                    }
                }
            }
            let same = ticks.last().is_some_and(|(_, last): &(u32, Judged)| {
                (last.phase, last.evaluated, last.judged)
                    == (judged.phase, judged.evaluated, judged.judged)
            });
            if same && judged.confidences.iter().all(|&q| q == 0) {
                *gap += 1;
            } else {
                ticks.push((*gap, judged));
                *gap = 0;
            }
        })?;
        Ok(streamed
            .into_iter()
            .zip(kept)
            .map(|(streamed, (ticks, _))| Recorded {
                name: name.clone(),
                span: streamed.span_s,
                labelled: streamed.labelled,
                scenario: streamed.scenario,
                ticks,
            })
            .collect())
    }

    /// The confirmations each set of confirm levels (`sets[set][event]`) raises on these
    /// confidences, stepped as the detector steps its own: only while the event is
    /// evaluated, reset when it cannot be judged or the phase changes, held down while an
    /// event of `excluded_by[event]` has its confirm level up (events in order, as the
    /// detector decides them).
    fn confirmations(
        &self,
        sets: &[Vec<LevelParams>],
        excluded_by: &[u8],
        names: &[String],
    ) -> Vec<Vec<DecisionRecord>> {
        let events = names.len();
        let mut states = vec![vec![LevelState::default(); events]; sets.len()];
        let mut raised = vec![Vec::new(); sets.len()];
        // Per event: every set's level down and counting nothing, so that a tick at
        // confidence 0 changes none of them.
        let mut idle = vec![true; events];
        let mut last: Option<Judged> = None;
        let mut step = |tick: &Judged, states: &mut Vec<Vec<LevelState>>, idle: &mut Vec<bool>| {
            for e in 0..events {
                let bit = 1u8 << e;
                let q = tick.confidences[e];
                if tick.evaluated & bit == 0 || (idle[e] && q == 0) {
                    continue;
                }
                let judged = tick.judged & bit != 0;
                let mask = excluded_by.get(e).copied().unwrap_or(0);
                idle[e] = true;
                for (c, set) in sets.iter().enumerate() {
                    let excluded =
                        (0..events).any(|j| mask & (1 << j) != 0 && states[c][j].is_up());
                    let state = &mut states[c][e];
                    if !judged || excluded {
                        *state = LevelState::default();
                    } else if state.step(&set[e], q, tick.shown & bit != 0) {
                        raised[c].push(DecisionRecord {
                            event: names[e].clone(),
                            level: detector_core::Level::Confirm.name(),
                            confidence: f64::from(q) / 32768.0,
                            onset_s: tick.t,
                            t_s: tick.t,
                        });
                    }
                    idle[e] &= *state == LevelState::default();
                }
            }
        };
        for (gap, tick) in &self.ticks {
            if let Some(before) = last {
                // The ticks at confidence 0 since: they move a level only until it is idle.
                let quiet = Judged {
                    confidences: [0; detector_core::MAX_EVENTS],
                    shown: 0,
                    ..before
                };
                for _ in 0..*gap {
                    if idle.iter().all(|i| *i) {
                        break;
                    }
                    step(&quiet, &mut states, &mut idle);
                }
                if before.phase != tick.phase {
                    states
                        .iter_mut()
                        .flatten()
                        .for_each(|s| *s = LevelState::default());
                    idle.iter_mut().for_each(|i| *i = true);
                }
            }
            step(tick, &mut states, &mut idle);
            last = Some(*tick);
        }
        raised
    }
}

/// Every set of levels' confirmations on one recording, with the recording's labels.
struct Tried {
    name: String,
    span: (f64, f64),
    labelled: Vec<crate::replay::Labelled>,
    scenario: Option<String>,
    /// `[set]`: the confirmations that set of levels raises.
    confirmations: Vec<Vec<DecisionRecord>>,
}

/// A level candidate's figures for one event: events right less the other events' windows
/// it confirmed in, its false confirmations, its median latency (ms), and its index in the
/// grid of confirm levels and dwells.
type Candidate = (i64, usize, f64, usize);

/// What a fit gives: the configuration, a note per fitted number, and the fitted
/// configuration's figures on the recordings it was fitted on and on those held out.
#[derive(Debug)]
pub struct Fitted {
    /// The fitted configuration.
    pub config: Config,
    /// What data set each fitted number.
    pub notes: Vec<Note>,
    /// Its figures on the recordings it was fitted on.
    pub trained: CorpusReport,
    /// Each recording held out, scored (none held out: empty); tallied over several
    /// folds' together, they give the cross-validated figures.
    pub held: Vec<RecordingResult>,
    /// The labelled events for which no candidate level kept the false confirmations
    /// within the event's share of the budget: each got the candidate with the fewest.
    pub over_budget: Vec<String>,
}

/// The confirmations of one candidate per event (`choice[event]`), in time order.
fn chosen(tried: &Tried, choice: &[usize], events: &[String]) -> Vec<DecisionRecord> {
    let mut all: Vec<DecisionRecord> = events
        .iter()
        .zip(choice)
        .flat_map(|(name, &c)| {
            tried.confirmations[c]
                .iter()
                .filter(move |d| d.event == *name)
        })
        .cloned()
        .collect();
    all.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    all
}

/// Tallies `tried` with each event's confirmations from `choice`.
fn tally(tried: &[Tried], choice: &[usize], events: &[String], after_s: f64) -> CorpusReport {
    CorpusReport::tally(
        events,
        &scores(tried, choice, events, after_s),
        after_s * 1e3,
    )
}

/// Each recording of `tried` scored with each event's confirmations from `choice`.
fn scores(
    tried: &[Tried],
    choice: &[usize],
    events: &[String],
    after_s: f64,
) -> Vec<RecordingResult> {
    tried
        .iter()
        .map(|t| RecordingResult {
            name: t.name.clone(),
            seconds: t.span.1 - t.span.0,
            scenario: t.scenario.clone(),
            score: crate::score::score_recording(
                &t.labelled,
                &chosen(t, choice, events),
                after_s,
                t.span,
            ),
        })
        .collect()
}

/// The confirm levels and dwells (ms) tried at `rate_hz`: every level with every dwell of
/// [`DWELL_TICKS`].
fn level_grid(rate_hz: f32) -> Vec<(f32, f32)> {
    let tick_ms = 1e3 / f64::from(rate_hz);
    CONFIRM_ON
        .iter()
        .flat_map(|&on| {
            DWELL_TICKS
                .iter()
                .map(move |&ticks| (on, round4(f64::from(ticks) * tick_ms)))
        })
        .collect()
}

/// Every set of levels' confirmations on each recording.
fn try_sets(
    recorded: &[&Recorded],
    sets: &[Vec<LevelParams>],
    excluded_by: &[u8],
    names: &[String],
) -> Vec<Tried> {
    recorded
        .par_iter()
        .map(|r| Tried {
            name: r.name.clone(),
            span: r.span,
            labelled: r.labelled.clone(),
            scenario: r.scenario.clone(),
            confirmations: r.confirmations(sets, excluded_by, names),
        })
        .collect()
}

/// Chooses every labelled event's confirm level and dwell on `train`: the most events
/// right less the other events' windows it confirms in, its false confirmations within its
/// share of the budget, then the shortest median latency; when no candidate keeps within
/// the share, the fewest false confirmations, then the most right (the event is named in
/// [`Fitted::over_budget`]). Every candidate runs on the confidences kept by the
/// replays of `train` and `held` with `config`'s detector: first the grid's
/// candidates for all labelled events at once, each event choosing its own; then, when
/// events hold each other down (`excludes`), so that one event's levels change how the
/// others fare, each event's candidates again beside the others' first choices. The levels
/// chosen are scored on `train` and on `held` (recordings replayed with `config`'s
/// detector).
fn fit_levels(
    config: &Config,
    train: &[&Recorded],
    held: &[&Recorded],
    options: &FitOptions,
    labelled: &[String],
) -> Result<Fitted, FitError> {
    let names: Vec<String> = config.events.iter().map(|e| e.name.clone()).collect();
    let share = options.budget_per_hour / labelled.len().max(1) as f64;
    let grid = level_grid(config.rate_hz);
    let compiled = detector_build::compile(config).map_err(|e| FitError::Config(e.to_string()))?;
    // The exclusions and the base's levels, the same in every candidate.
    let excluded_by: Vec<u8> = compiled.events.iter().map(|e| e.excluded_by).collect();
    let base_levels: Vec<LevelParams> = compiled.events.iter().map(|e| e.levels[1]).collect();
    // Each candidate's confirm levels, compiled exactly as the detector would have them.
    let candidates: Vec<Vec<LevelParams>> = grid
        .iter()
        .map(|&(on, dwell)| {
            let mut c = config.clone();
            for e in &mut c.events {
                *e = with_levels(e, on, dwell);
            }
            detector_build::compile(&c)
                .map(|compiled| compiled.events.iter().map(|e| e.levels[1]).collect())
                .map_err(|e| FitError::Config(e.to_string()))
        })
        .collect::<Result<_, _>>()?;
    let labelled_index: Vec<usize> = (0..names.len())
        .filter(|&k| labelled.contains(&names[k]))
        .collect();
    // A set of levels: the chosen candidate for each labelled event, the base's for the rest.
    let set_of = |choice: &[usize]| -> Vec<LevelParams> {
        (0..names.len())
            .map(|e| {
                if labelled_index.contains(&e) {
                    candidates[choice[e]][e]
                } else {
                    base_levels[e]
                }
            })
            .collect()
    };
    let mut outside_hours = 0.0;
    // For each labelled event, the best of the sets `set_for(event, candidate)` names.
    let mut choose = |tried: &[Tried], set_for: &dyn Fn(usize, usize) -> usize| {
        let mut best: Vec<Option<Candidate>> = vec![None; names.len()];
        let mut reports = std::collections::HashMap::new();
        for &k in &labelled_index {
            for c in 0..grid.len() {
                let set = set_for(k, c);
                let report = reports.entry(set).or_insert_with(|| {
                    tally(tried, &vec![set; names.len()], &names, options.after_s)
                });
                outside_hours = report.outside_hours;
                let within = |false_count: usize| {
                    outside_hours <= 0.0 || (false_count as f64 / outside_hours) <= share
                };
                let tally = report.events.iter().find(|r| r.name == names[k]);
                // Confirming this event in another's window costs what one right gains.
                let right = tally.map_or(0, |r| r.correct) as i64
                    - report.intrusions_by_event.get(k).copied().unwrap_or(0) as i64;
                let latency = tally.map_or(f64::MAX, |r| r.latency_ms.median);
                let false_count = report.false_by_event.get(k).copied().unwrap_or(0);
                // Within the share: the most right, then the fewest false. Beyond it: the
                // fewest false, then the most right.
                let rank = |right: i64, false_count: usize| {
                    let fewer = -(false_count as i64);
                    if within(false_count) {
                        (true, right, fewer)
                    } else {
                        (false, fewer, right)
                    }
                };
                let better = match best[k] {
                    None => true,
                    Some((r, f, l, _)) => {
                        let (now, was) = (rank(right, false_count), rank(r, f));
                        now > was || (now == was && latency < l)
                    }
                };
                if better {
                    best[k] = Some((right, false_count, latency, c));
                }
            }
        }
        best
    };
    // Round one: the grid's candidates, all labelled events at once.
    let uniform: Vec<Vec<LevelParams>> = (0..grid.len())
        .map(|c| set_of(&vec![c; names.len()]))
        .collect();
    let tried = try_sets(train, &uniform, &excluded_by, &names);
    let mut best = choose(&tried, &|_, c| c);
    let first: Vec<usize> = best.iter().map(|b| b.map_or(0, |b| b.3)).collect();
    if excluded_by.iter().any(|m| *m != 0) && labelled_index.len() > 1 {
        // Round two: each event's candidates beside the others' first choices.
        let mut sets = Vec::new();
        for &k in &labelled_index {
            for c in 0..grid.len() {
                let mut choice = first.clone();
                choice[k] = c;
                sets.push(set_of(&choice));
            }
        }
        let tried = try_sets(train, &sets, &excluded_by, &names);
        let slot = |k: usize| labelled_index.iter().position(|&e| e == k).unwrap_or(0);
        best = choose(&tried, &|k, c| slot(k) * grid.len() + c);
    }
    let choice: Vec<usize> = best.iter().map(|b| b.map_or(0, |b| b.3)).collect();
    let mut fitted = config.clone();
    let mut notes = Vec::new();
    let mut over_budget = Vec::new();
    for (event, b) in fitted.events.iter_mut().zip(&best) {
        if let Some((right, false_count, latency, c)) = *b {
            let (on, dwell) = grid[c];
            *event = with_levels(event, on, dwell);
            let per_hour = if outside_hours > 0.0 {
                false_count as f64 / outside_hours
            } else {
                0.0
            };
            let over = per_hour > share;
            if over {
                over_budget.push(event.name.clone());
            }
            notes.push(Note {
                event: event.name.clone(),
                item: "confirm",
                text: format!(
                    "on {on} for {dwell} ms: {right} events right less those of others it confirmed in, {false_count} false confirmations in {outside_hours:.3} h outside events ({per_hour:.2} per hour; {}budget {share:.2} per hour for this event), median latency {latency:.2} ms; the alert and the `off` levels keep the base's ratios",
                    if over {
                        "OVER the "
                    } else {
                        ""
                    }
                ),
            });
        }
    }
    // The levels chosen, as they are, on the recordings fitted and held out.
    let chosen = [set_of(&choice)];
    let scored = try_sets(train, &chosen, &excluded_by, &names);
    let held_scored = try_sets(held, &chosen, &excluded_by, &names);
    let only = vec![0; names.len()];
    Ok(Fitted {
        trained: tally(&scored, &only, &names, options.after_s),
        held: scores(&held_scored, &only, &names, options.after_s),
        config: fitted,
        notes,
        over_budget,
    })
}

/// The events labelled in `samples`.
pub fn labelled_events(samples: &FeatureSamples) -> Vec<String> {
    samples
        .events
        .iter()
        .zip(&samples.inside)
        .filter(|(_, inside)| inside.iter().any(|v| !v.is_empty()))
        .map(|(e, _)| e.clone())
        .collect()
}

/// A fit cross-validated by recording.
#[derive(Debug)]
pub struct CrossValidated {
    /// Each fold's fit, on the others' recordings, scored on its own (`held`); none when
    /// fewer than two folds were asked for, or there are fewer than two recordings.
    pub folds: Vec<Fitted>,
    /// The fit on every recording (nothing held out).
    pub whole: Fitted,
    /// The base detector's figures on each recording, in file order.
    pub base: Vec<RecordingResult>,
}

impl CrossValidated {
    /// Whether fold `fold` (from 0) held out recording `i` (in file order): recording i
    /// is in fold i mod k.
    pub fn holds_out(&self, fold: usize, i: usize) -> bool {
        held_out(self.folds.len(), fold, i)
    }
}

/// Whether fit `fit` of a `k`-fold cross-validation holds out recording `i`: the folds'
/// fits (`fit < k`) hold out recording i when i mod k is theirs; the last holds out none.
fn held_out(k: usize, fit: usize, i: usize) -> bool {
    fit < k && i % k == fit
}

/// Fits `base` (built as `detector`) on `files` and, with `folds` of at least 2,
/// cross-validates by recording: recording i is in fold i mod k (k at most the
/// recordings), each fold fitted on the others and scored on itself. Each recording is
/// read twice: once with `detector`, for the feature samples (the recordings each fit is
/// fitted on, merged in file order) and the base's figures, from which every fit's terms
/// come; then once replayed with every fit's terms together, and each fit's levels run on
/// what its replays kept. Memory grows with the number of fits (k + 1): each keeps its
/// replays' ticks.
pub fn fit_folds(
    base: &Config,
    detector: &Detector,
    files: &[PathBuf],
    folds: usize,
    options: &FitOptions,
) -> Result<CrossValidated, FitError> {
    let k = folds.min(files.len());
    let k = if k >= 2 { k } else { 0 };
    // Which recordings each fit holds out: the folds', then none.
    let held = |fit: usize, i: usize| held_out(k, fit, i);
    // The samples each fit is fitted on, and the base's figures per file.
    let (samples, base_results) = crate::features::sample_sets(
        detector,
        files,
        options.window_s,
        options.after_s,
        k + 1,
        |fit, i| !held(fit, i),
        |f, streamed| RecordingResult::new(&f.display().to_string(), streamed, options.after_s),
    )?;
    let in_fold = |fit: usize, e: FitError| {
        if fit < k {
            FitError::Fold {
                fold: fit + 1,
                source: Box::new(e),
            }
        } else {
            e
        }
    };
    // Each fit's terms, from the samples of the recordings it is fitted on.
    let terms = samples
        .iter()
        .enumerate()
        .map(|(fit, trained_on)| {
            let labelled = labelled_events(trained_on);
            if labelled.is_empty() {
                let training = (0..files.len()).filter(|&i| !held(fit, i)).count();
                return Err(in_fold(fit, FitError::NothingLabelled(training)));
            }
            let (config, notes) = fit_terms(base, trained_on).map_err(|e| in_fold(fit, e))?;
            Ok((config, notes, labelled))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let detectors = terms
        .iter()
        .enumerate()
        .map(|(fit, (config, _, _))| build(config).map_err(|e| in_fold(fit, e)))
        .collect::<Result<Vec<_>, _>>()?;
    let refs: Vec<&Detector> = detectors.iter().collect();
    // `recorded[i][fit]`: recording i replayed with that fit's terms.
    let recorded: Vec<Vec<Recorded>> = files
        .par_iter()
        .map(|f| Recorded::replay_each(&refs, f))
        // In file order, so that the error reported is the first file's.
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Result<_, _>>()?;
    let mut fits = terms
        .into_iter()
        .enumerate()
        .map(|(fit, (config, notes, labelled))| {
            let side = |held_out: bool| -> Vec<&Recorded> {
                recorded
                    .iter()
                    .enumerate()
                    .filter(|&(i, _)| held(fit, i) == held_out)
                    .filter_map(|(_, r)| r.get(fit))
                    .collect()
            };
            let mut fitted = fit_levels(&config, &side(false), &side(true), options, &labelled)
                .map_err(|e| in_fold(fit, e))?;
            fitted.notes.splice(0..0, notes);
            Ok(fitted)
        })
        .collect::<Result<Vec<_>, FitError>>()?;
    // The last fit holds nothing out: the whole corpus's (k + 1 fits, so there is one).
    let Some(whole) = fits.pop() else {
        return Err(FitError::NothingLabelled(files.len()));
    };
    Ok(CrossValidated {
        folds: fits,
        whole,
        base: base_results,
    })
}

/// A TOML number for an `f32`, written as its shortest decimal (0.1, not 0.100000001).
fn number(x: f32) -> toml_edit::Value {
    toml_edit::Value::from(format!("{x}").parse::<f64>().unwrap_or(0.0))
}

fn cdf_table(cdf: &CdfSpec) -> toml_edit::InlineTable {
    let mut params = toml_edit::InlineTable::new();
    let shape = match *cdf {
        CdfSpec::Sigmoid { low, high, falling } => {
            params.insert("low", number(low));
            params.insert("high", number(high));
            if falling {
                params.insert("falling", true.into());
            }
            "sigmoid"
        }
        CdfSpec::Bell { center, half_width } => {
            params.insert("center", number(center));
            params.insert("half_width", number(half_width));
            "bell"
        }
        CdfSpec::FlatBell {
            low,
            plateau_low,
            plateau_high,
            high,
        } => {
            params.insert("low", number(low));
            params.insert("plateau_low", number(plateau_low));
            params.insert("plateau_high", number(plateau_high));
            params.insert("high", number(high));
            "flat_bell"
        }
        CdfSpec::Binary { threshold, above } => {
            params.insert("threshold", number(threshold));
            params.insert("above", above.into());
            "binary"
        }
    };
    let mut t = toml_edit::InlineTable::new();
    t.insert(shape, params.into());
    t
}

fn level_table(level: &LevelSpec) -> toml_edit::InlineTable {
    let mut t = toml_edit::InlineTable::new();
    t.insert("on", number(level.on));
    t.insert("off", number(level.off));
    t.insert("dwell_ms", number(level.dwell_ms));
    t.insert("hold_ms", number(level.hold_ms));
    if let Some(early) = &level.early {
        let mut e = toml_edit::InlineTable::new();
        e.insert("feature", early.feature.as_str().into());
        e.insert("above", number(early.above));
        e.insert("dwell_ms", number(early.dwell_ms));
        t.insert("early", e.into());
    }
    t
}

/// One term per line.
fn term_array(terms: impl Iterator<Item = toml_edit::InlineTable>) -> toml_edit::Array {
    let mut a: toml_edit::Array = terms.collect();
    for v in a.iter_mut() {
        v.decor_mut().set_prefix("\n    ");
    }
    a.set_trailing(",\n");
    a
}

/// `# ` before every line of `lines`, for a key's decor.
fn comment(lines: &[String]) -> String {
    lines.iter().map(|l| format!("# {l}\n")).collect()
}

/// How the header a fit writes begins.
const HEADER_START: &str = "Fitted by `fingertip fit`";

/// The header of a fitted file: the base and the corpus it was fitted from, and how.
pub fn header(base_name: &str, recordings: usize, options: &FitOptions) -> Vec<String> {
    vec![
        format!("{HEADER_START} from {base_name} on {recordings} labelled recordings: each"),
        format!(
            "event's first {} ms against the time outside events, confirmations counted until {} ms",
            options.window_s * 1e3,
            options.after_s * 1e3
        ),
        format!(
            "after a labelled end, false confirmations within {} per hour. Structure as the base.",
            options.budget_per_hour
        ),
        String::new(),
    ]
}

/// A key's comment lines without those of an earlier fit (`# fitted sensor:` and the
/// indented lines under it): what the user wrote stays.
fn user_comments(prefix: &str) -> String {
    let mut kept = String::new();
    let mut in_fitted = false;
    for line in prefix.split_inclusive('\n') {
        let t = line.trim_start();
        if ["context", "sensor", "confirm"]
            .iter()
            .any(|item| t.starts_with(&format!("# fitted {item}:")))
        {
            in_fitted = true;
            continue;
        }
        if in_fitted && t.starts_with("#   ") {
            continue;
        }
        in_fitted = false;
        kept.push_str(line);
    }
    kept
}

/// `text` without the header an earlier fit wrote at its top.
fn without_fit_header(text: &str) -> &str {
    if !text.starts_with(&format!("# {HEADER_START}")) {
        return text;
    }
    let mut rest = text;
    while let Some((line, after)) = rest.split_once('\n') {
        rest = after;
        if line.trim_end() == "#" {
            break;
        }
    }
    rest
}

/// The base's TOML with the fitted numbers in place: every fitted event's terms and
/// levels rewritten, each with a comment saying what data set it below the user's own
/// comments; everything else (the channels, features, phases and their comments) as the
/// user wrote it. Refitting a fitted file replaces the earlier fit's header and comments.
/// The text is read back and must give exactly `fitted`.
pub fn write_toml(
    base_text: &str,
    fitted: &Config,
    notes: &[Note],
    header: &[String],
) -> Result<String, FitError> {
    let mut doc: toml_edit::DocumentMut = without_fit_header(base_text)
        .parse()
        .map_err(|e: toml_edit::TomlError| FitError::Config(e.to_string()))?;
    if let Some(events) = doc
        .get_mut("event")
        .and_then(toml_edit::Item::as_array_of_tables_mut)
    {
        for table in events.iter_mut() {
            let name = table
                .get("name")
                .and_then(|n| n.as_str())
                .unwrap_or_default()
                .to_string();
            let Some(spec) = fitted.events.iter().find(|e| e.name == name) else {
                continue;
            };
            let of = |item: &str| -> Vec<String> {
                notes
                    .iter()
                    .filter(|n| n.event == name && n.item == item)
                    .map(|n| n.text.clone())
                    .collect()
            };
            if !of("skipped").is_empty() {
                continue;
            }
            // The user's comments above each key rewritten, kept.
            let users: Vec<(&str, String)> = ["context", "sensor", "confirm"]
                .into_iter()
                .map(|key| {
                    let prefix = table
                        .key(key)
                        .and_then(|k| k.leaf_decor().prefix())
                        .and_then(|p| p.as_str())
                        .unwrap_or_default();
                    (key, user_comments(prefix))
                })
                .collect();
            if !spec.context.is_empty() {
                let terms = spec.context.iter().map(|t| {
                    let mut i = toml_edit::InlineTable::new();
                    i.insert("feature", t.feature.as_str().into());
                    i.insert("cdf", cdf_table(&t.cdf).into());
                    i
                });
                table.insert("context", toml_edit::value(term_array(terms)));
            }
            let terms = spec.sensor.iter().map(|t| {
                let mut i = toml_edit::InlineTable::new();
                i.insert("feature", t.feature.as_str().into());
                i.insert("weight", number(t.weight));
                i.insert("cdf", cdf_table(&t.cdf).into());
                i
            });
            table.insert("sensor", toml_edit::value(term_array(terms)));
            table.insert("alert", toml_edit::value(level_table(&spec.alert)));
            table.insert("confirm", toml_edit::value(level_table(&spec.confirm)));
            for (key, user) in users {
                let lines = of(key);
                if let Some(mut k) = table.key_mut(key) {
                    let mut prefix = user;
                    if !lines.is_empty() {
                        let mut all = vec![format!("fitted {key}:")];
                        all.extend(lines.iter().map(|l| format!("  {l}")));
                        prefix.push_str(&comment(&all));
                    }
                    k.leaf_decor_mut().set_prefix(prefix);
                }
            }
        }
    }
    let text = format!("{}{doc}", comment(header));
    let back = Config::from_toml(&text).map_err(|e| FitError::Config(e.to_string()))?;
    if back != *fitted {
        return Err(FitError::Config(
            "the fitted configuration does not read back as fitted (a number lost in writing)"
                .into(),
        ));
    }
    Ok(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_four_significant_digits() {
        assert_eq!(round4(1234.567), 1235.0);
        assert_eq!(round4(0.000123456), 0.0001235);
        assert_eq!(round4(-98.7654), -98.77);
        assert_eq!(round4(0.0), 0.0);
    }

    /// Levels run on a recording's kept ticks as on every tick: the quiet ticks between two
    /// kept ones let a raised level fall (its hold of 3 ticks passes in a gap of 5), so the
    /// second rise confirms again; a gap shorter than the hold does not; an event that
    /// excludes another holds it down.
    #[test]
    fn kept_ticks_with_their_gaps_step_levels_as_every_tick_would() {
        let tick = |t: f64, q: [u16; 2]| {
            let mut confidences = [0; detector_core::MAX_EVENTS];
            confidences[..2].copy_from_slice(&q);
            Judged {
                t,
                phase: 0,
                evaluated: 0b11,
                judged: 0b11,
                confidences,
                shown: 0,
            }
        };
        let high = 30_000;
        let recorded = |gap: u32| Recorded {
            name: "r".into(),
            span: (0.0, 1.0),
            labelled: Vec::new(),
            scenario: None,
            ticks: vec![
                (0, tick(0.0, [high, 0])),
                (0, tick(0.001, [0, 0])),
                (gap, tick(0.1, [high, high])),
            ],
        };
        let level = LevelParams::checked(16_384, 8_192, 1, 3, None);
        let names = vec!["a".to_string(), "b".to_string()];
        let raised = |r: &Recorded, excluded_by: &[u8]| -> Vec<(String, f64)> {
            r.confirmations(&[vec![level, level]], excluded_by, &names)[0]
                .iter()
                .map(|d| (d.event.clone(), d.t_s))
                .collect()
        };
        let a = |t: f64| ("a".to_string(), t);
        let b = |t: f64| ("b".to_string(), t);
        assert_eq!(raised(&recorded(5), &[0, 0]), [a(0.0), a(0.1), b(0.1)]);
        assert_eq!(raised(&recorded(1), &[0, 0]), [a(0.0), b(0.1)]);
        // `a` excludes `b`: while `a` is up, `b` is held down.
        assert_eq!(raised(&recorded(1), &[0, 0b01]), [a(0.0)]);
    }

    /// Shares follow the strengths, none above 1, what a capped one loses going to the rest.
    /// Dwells are tried in ticks of the detector's rate: a slow log gets dwells it can
    /// tell apart, a fast sensor sub-millisecond ones.
    #[test]
    fn dwells_follow_the_rate() {
        let dwells = |rate: f32| -> Vec<f32> {
            let mut d: Vec<f32> = level_grid(rate).iter().map(|&(_, d)| d).collect();
            d.sort_by(f32::total_cmp);
            d.dedup();
            d
        };
        assert_eq!(dwells(10.0), [0.0, 200.0, 500.0, 1000.0, 2500.0]);
        assert_eq!(dwells(5000.0), [0.0, 0.4, 1.0, 2.0, 5.0]);
        assert_eq!(
            level_grid(1000.0).len(),
            CONFIRM_ON.len() * DWELL_TICKS.len()
        );
    }

    /// The user's comments above a fitted key stay; an earlier fit's comments and header
    /// go.
    #[test]
    fn refits_keep_the_users_comments_and_replace_the_fits() {
        let prefix = "# mine, above\n# fitted sensor:\n#   old note\n#   another\n# mine, below\n";
        assert_eq!(user_comments(prefix), "# mine, above\n# mine, below\n");
        assert_eq!(user_comments("# plain\n"), "# plain\n");
        let options = FitOptions {
            window_s: 0.02,
            after_s: 0.1,
            budget_per_hour: 1.0,
        };
        let text = format!(
            "{}rate_hz = 10.0\n",
            comment(&header("b.toml", 3, &options))
        );
        assert_eq!(without_fit_header(&text), "rate_hz = 10.0\n");
        assert_eq!(
            without_fit_header("# mine\nrate_hz = 10.0\n"),
            "# mine\nrate_hz = 10.0\n"
        );
    }

    /// A confirm level's early dwell keeps its feature and level on every candidate, its
    /// dwell capped at the candidate's, and is written back with the level.
    #[test]
    fn an_early_dwell_is_kept_capped_and_written() {
        let config = Config::from_toml(crate::APPROACH_TOML).expect("the default is valid");
        let disturbance = config
            .events
            .iter()
            .find(|e| e.name == "disturbance")
            .expect("the default's disturbance");
        let early = disturbance.confirm.early.clone().expect("an early dwell");
        for (dwell_ms, want) in [(3.0, 3.0), (10.0, early.dwell_ms)] {
            let fitted = with_levels(disturbance, 0.8, dwell_ms);
            let kept = fitted.confirm.early.expect("kept");
            assert_eq!(kept.feature, early.feature);
            assert_eq!(
                (kept.above, kept.dwell_ms),
                (early.above, want),
                "dwell {dwell_ms}"
            );
        }
        let line = crate::APPROACH_TOML
            .lines()
            .find(|l| l.starts_with("confirm = ") && l.contains("early"))
            .expect("the disturbance's confirm level on one line");
        let written = format!("confirm = {}", level_table(&disturbance.confirm));
        let reread = Config::from_toml(&crate::APPROACH_TOML.replacen(line, &written, 1))
            .expect("the written level reads back");
        let reread = reread.events.iter().find(|e| e.name == "disturbance");
        assert_eq!(reread.map(|e| &e.confirm), Some(&disturbance.confirm));
    }

    #[test]
    fn weights_are_shared_and_capped_at_one() {
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(&shares(1.0, &[1.0, 3.0]), &[0.25, 0.75]));
        // Two sufficient terms of a base summing to 2, one much stronger: 1 and 1.
        assert!(close(&shares(2.0, &[0.1, 0.4]), &[1.0, 1.0]));
        // Capped at 1, the rest shared 1 : 2.
        assert!(close(
            &shares(2.0, &[4.0, 1.0, 2.0]),
            &[1.0, 1.0 / 3.0, 2.0 / 3.0]
        ));
        assert!(close(&shares(1.5, &[0.0, 1.0]), &[0.0, 1.0]));
    }

    /// Two paths to one event, each sufficient: a corpus that shows only one of them fits
    /// that one and keeps the other as the base has it; a corpus that shows neither stops.
    #[test]
    fn a_path_the_corpus_does_not_show_keeps_the_bases_numbers() {
        let base = Config::from_toml(
            r#"
rate_hz = 1000.0
[[channel]]
name = "x"
unit = "N"
[[channel]]
name = "y"
unit = "N"
[[feature]]
name = "fast"
stage = { raw = { input = "x" } }
[[feature]]
name = "slow"
stage = { raw = { input = "y" } }
[[event]]
name = "e"
sensor = [
    { feature = "fast", weight = 1.0, cdf = { sigmoid = { low = 1.0, high = 2.0 } } },
    { feature = "slow", weight = 0.75, cdf = { sigmoid = { low = 3.0, high = 4.0 } } },
]
alert = { on = 0.55, off = 0.35, hold_ms = 50.0 }
confirm = { on = 0.75, off = 0.5, hold_ms = 50.0 }
[[phase]]
name = "p"
events = ["e"]
"#,
        )
        .expect("base");
        let detector = detector_build::build(&base).expect("builds");
        let mut samples = FeatureSamples::new(&detector);
        let ramp = |from: f64, n: u32| (0..n).map(move |k| from + f64::from(k) / 10.0);
        // `fast` rises well above its outside values in every event; `slow` does not move.
        samples.outside = vec![
            ramp(0.0, 1000).map(|v| v / 100.0).collect(),
            vec![0.5; 1000],
        ];
        samples.inside[0] = vec![ramp(5.0, 100).collect(), vec![0.5; 100]];
        samples.peaks[0] = vec![vec![(5.0, 15.0); 10], vec![(0.5, 0.5); 10]];
        let (fitted, notes) = fit_terms(&base, &samples).expect("one path separates");
        let [fast, slow] = &fitted.events[0].sensor[..] else {
            panic!("two terms");
        };
        assert_eq!(
            (slow.weight, slow.cdf),
            (0.75, base.events[0].sensor[1].cdf)
        );
        assert_ne!(fast.cdf, base.events[0].sensor[0].cdf);
        // The fitted term takes what the kept one leaves of the base's 1.75, capped at 1.
        assert_eq!(fast.weight, 1.0);
        assert!(
            notes
                .iter()
                .any(|n| n.text.starts_with("slow: kept the base's (weight 0.75)")),
            "{notes:?}"
        );
        // Neither path shows: the fit stops, naming the first.
        samples.outside[0] = vec![0.5; 1000];
        samples.inside[0][0] = vec![0.5; 100];
        samples.peaks[0][0] = vec![(0.5, 0.5); 10];
        assert!(matches!(
            fit_terms(&base, &samples),
            Err(FitError::NoSeparation { feature, .. }) if feature == "fast"
        ));
    }

    /// A feature saturated in the corpus (±32768) still gives bounds a sigmoid takes.
    #[test]
    fn bounds_stay_within_the_feature_range() {
        for (low, high) in [(32767.99, 32767.99), (100.0, 40000.0), (-40000.0, -32768.0)] {
            let (l, h) = sigmoid_bounds(low, high);
            assert!(
                l < h && h <= 32767.0 && l >= -32768.0,
                "{low}..{high} gave {l}..{h}"
            );
            assert!(
                detector_core::Cdf::new(&CdfSpec::Sigmoid {
                    low: l,
                    high: h,
                    falling: false
                })
                .is_ok(),
                "{l}..{h}"
            );
        }
    }

    /// A sensor term rises from the outside tail to the event's median, or falls when the
    /// base's does; a context term passes the event's own values.
    #[test]
    fn terms_sit_between_the_distributions() {
        let outside: Vec<f64> = (0..1000).map(|k| f64::from(k) / 100.0).collect();
        let event: Vec<f64> = (0..100).map(|k| 50.0 + f64::from(k)).collect();
        let (threshold, above, _) = best_threshold(&event, &outside);
        // Ten events reaching 60, 65, .. 105.
        let reached: Vec<f64> = (0..10).map(|k| 60.0 + 5.0 * f64::from(k)).collect();
        let (cdf, _) = fit_sensor(false, &event, &reached, &outside, (threshold, above));
        assert_eq!(
            cdf,
            CdfSpec::Sigmoid {
                low: 9.99,
                high: 60.0,
                falling: false
            }
        );
        // A veto the event stays within is kept; one it crosses moves out to take it in,
        // its width kept.
        let veto = CdfSpec::Sigmoid {
            low: 200.0,
            high: 300.0,
            falling: true,
        };
        assert_eq!(fit_context(&veto, &event).0, veto);
        let (cdf, text) = fit_context(
            &CdfSpec::Sigmoid {
                low: 100.0,
                high: 120.0,
                falling: true,
            },
            &event,
        );
        assert_eq!(
            cdf,
            CdfSpec::Sigmoid {
                low: 147.0,
                high: 167.0,
                falling: true
            },
            "{text}"
        );
        let (cdf, _) = fit_context(
            &CdfSpec::Bell {
                center: 100.0,
                half_width: 10.0,
            },
            &event,
        );
        assert_eq!(
            cdf,
            CdfSpec::Bell {
                center: 100.0,
                half_width: 144.0
            }
        );
    }
}
