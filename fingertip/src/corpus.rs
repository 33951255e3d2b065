//! Recorded corpora: `fingertip evaluate --traces`, the detector scored on labelled
//! recordings from a real robot instead of simulated runs.
//!
//! A recording is a trace whose `truth` column may label many events, each a maximal run of
//! rows with the same label ([`crate::replay::Labelled`]). Every recording is replayed
//! (streamed, any length) and scored by [`score_recording`]: each labelled event gets an
//! [`Outcome`] as a simulated run does, and a confirmation outside every event's window is
//! a false confirmation. The report is tallied per event name, with the same fields as a
//! simulated evaluation's scenarios.

use std::path::{Path, PathBuf};

use crate::score::{Outcome, RecordingScore, ScenarioReport, score_recording};

pub use crate::replay::Labelled;

/// The default time after a labelled event's end during which a confirmation still
/// counts for it (ms): a label may end before the detector has confirmed a short event.
pub const DEFAULT_AFTER_MS: f64 = 100.0;

/// Failures listed per event name in a printed report.
const SHOWN_FAILURES: usize = 3;

/// Why a corpus could not be gathered.
#[derive(Debug, thiserror::Error)]
pub enum CorpusError {
    /// A path given does not exist or cannot be listed.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The path.
        path: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// No recording was found.
    #[error("{0}: no recording (`*.csv`) found")]
    Empty(String),
}

/// The recordings named by `paths`: files as given, and every `*.csv` file under each
/// directory (recursively, hidden entries skipped), each directory's in name order.
pub fn find_recordings(paths: &[PathBuf]) -> Result<Vec<PathBuf>, CorpusError> {
    let mut found = Vec::new();
    for p in paths {
        let meta = std::fs::metadata(p).map_err(|source| CorpusError::Read {
            path: p.display().to_string(),
            source,
        })?;
        if meta.is_dir() {
            let before = found.len();
            walk(p, &mut found)?;
            if found.len() == before {
                return Err(CorpusError::Empty(p.display().to_string()));
            }
        } else {
            found.push(p.clone());
        }
    }
    Ok(found)
}

fn walk(dir: &Path, found: &mut Vec<PathBuf>) -> Result<(), CorpusError> {
    let read = |source| CorpusError::Read {
        path: dir.display().to_string(),
        source,
    };
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(read)?
        .map(|e| e.map(|e| e.path()))
        .collect::<Result<_, _>>()
        .map_err(read)?;
    entries.sort();
    for path in entries {
        let hidden = path
            .file_name()
            .and_then(|n| n.to_str())
            .is_none_or(|n| n.starts_with('.'));
        if hidden {
            continue;
        }
        if path.is_dir() {
            walk(&path, found)?;
        } else if path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("csv"))
        {
            found.push(path);
        }
    }
    Ok(())
}

/// One recording replayed and scored.
#[derive(Clone, Debug)]
pub struct RecordingResult {
    /// The recording's name (its path).
    pub name: String,
    /// Its length (s).
    pub seconds: f64,
    /// Its `scenario` metadata, by which its events are binned.
    pub scenario: Option<String>,
    /// How it went.
    pub score: RecordingScore,
}

impl RecordingResult {
    /// Scores a replayed recording.
    pub fn new(name: &str, streamed: &crate::replay::Streamed, after_s: f64) -> RecordingResult {
        let (first, last) = streamed.span_s;
        RecordingResult {
            name: name.to_string(),
            seconds: last - first,
            scenario: streamed.scenario.clone(),
            score: score_recording(
                &streamed.labelled,
                &streamed.decisions,
                after_s,
                (first, last),
            ),
        }
    }
}

/// One event's outcomes tallied, and per bin of the scenarios of the recordings they are
/// from (in name order; outcomes from recordings without one are in no bin), where any
/// has one.
fn tally_by_scenario(event: &str, outcomes: &[(Outcome, Option<&str>)]) -> ScenarioReport {
    let (outcomes, scenarios): (Vec<Outcome>, Vec<Option<&str>>) = outcomes.iter().cloned().unzip();
    let mut labels: Vec<String> = scenarios.iter().flatten().map(|s| s.to_string()).collect();
    labels.sort_unstable();
    labels.dedup();
    if labels.is_empty() {
        return ScenarioReport::tally(event, Some(event), &outcomes);
    }
    let binned: Vec<Option<usize>> = scenarios
        .iter()
        .map(|s| s.and_then(|s| labels.iter().position(|l| l == s)))
        .collect();
    ScenarioReport::tally_binned(
        event,
        Some(event),
        &outcomes,
        ("the recordings' scenario", &labels, &binned),
    )
}

/// A corpus's results, tallied per event name.
#[derive(Clone, Debug)]
pub struct CorpusReport {
    /// One per event name labelled in the corpus, in the configuration's event order.
    pub events: Vec<ScenarioReport>,
    /// Recordings.
    pub recordings: usize,
    /// Their total length (h).
    pub hours: f64,
    /// Confirmations outside every event's window.
    pub false_confirmations: usize,
    /// ... of each of the configuration's events, in its order.
    pub false_by_event: Vec<usize>,
    /// Labelled events of another name in which each of the configuration's events was
    /// the (first) wrong confirmation, in its order.
    pub intrusions_by_event: Vec<usize>,
    /// The time outside every event's window (h).
    pub outside_hours: f64,
    /// Per scenario the recordings name, in name order: its false confirmations and its
    /// time outside every event's window (h). Empty where none names one.
    pub false_by_scenario: Vec<(String, usize, f64)>,
    /// How long after an event's end a confirmation counted for it (ms).
    pub after_ms: f64,
    /// What went wrong, every labelled event not right, then every false confirmation.
    pub failures: Vec<CorpusFailure>,
}

/// One thing that went wrong in a recording.
#[derive(Clone, Debug, PartialEq)]
pub struct CorpusFailure {
    /// The recording's name.
    pub recording: String,
    /// The labelled event, or the event confirmed outside every labelled one.
    pub event: String,
    /// The labelled event's onset, or the time of the confirmation outside (s).
    pub at_s: f64,
    /// The labelled event's outcome; `None` for a confirmation outside every labelled event.
    pub outcome: Option<Outcome>,
}

impl CorpusFailure {
    /// What the failure is grouped by when the first few of each are shown: its event, or
    /// the time outside events.
    fn kind(&self) -> &str {
        match self.outcome {
            Some(_) => &self.event,
            None => "outside events",
        }
    }

    /// What went wrong, in words.
    fn what(&self) -> String {
        match &self.outcome {
            Some(outcome) => outcome.to_string(),
            None => "confirmed outside every labelled event".to_string(),
        }
    }
}

impl std::fmt::Display for CorpusFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (recording, event, t) = (&self.recording, &self.event, self.at_s);
        match &self.outcome {
            Some(outcome) => write!(f, "{recording}: {event} at {t:.3} s: {outcome}"),
            None => write!(
                f,
                "{recording}: {event} confirmed at {t:.3} s, outside every labelled event"
            ),
        }
    }
}

impl CorpusReport {
    /// Tallies `results` for a detector with events `event_names`.
    pub fn tally(
        event_names: &[String],
        results: &[RecordingResult],
        after_ms: f64,
    ) -> CorpusReport {
        // Each event's outcomes, with the scenario of the recording each is from.
        let mut outcomes: Vec<Vec<(Outcome, Option<&str>)>> = vec![Vec::new(); event_names.len()];
        let mut failures = Vec::new();
        let mut false_alarms = Vec::new();
        let mut false_by_event = vec![0; event_names.len()];
        let mut intrusions_by_event = vec![0; event_names.len()];
        for r in results {
            for (event, onset, outcome) in &r.score.events {
                if let Outcome::Wrong {
                    event: intruder, ..
                } = outcome
                    && let Some(i) = event_names.iter().position(|n| n == intruder)
                {
                    intrusions_by_event[i] += 1;
                }
                if let Some(i) = event_names.iter().position(|n| n == event) {
                    outcomes[i].push((outcome.clone(), r.scenario.as_deref()));
                }
                if !outcome.is_right() {
                    failures.push(CorpusFailure {
                        recording: r.name.clone(),
                        event: event.clone(),
                        at_s: *onset,
                        outcome: Some(outcome.clone()),
                    });
                }
            }
            for (event, t) in &r.score.false_confirmations {
                if let Some(i) = event_names.iter().position(|n| n == event) {
                    false_by_event[i] += 1;
                }
                false_alarms.push(CorpusFailure {
                    recording: r.name.clone(),
                    event: event.clone(),
                    at_s: *t,
                    outcome: None,
                });
            }
        }
        let false_confirmations = false_alarms.len();
        failures.extend(false_alarms);
        let mut false_by_scenario = std::collections::BTreeMap::<&str, (usize, f64)>::new();
        for r in results {
            if let Some(scenario) = &r.scenario {
                let (n, hours) = false_by_scenario.entry(scenario).or_default();
                *n += r.score.false_confirmations.len();
                *hours += r.score.outside_s / 3600.0;
            }
        }
        CorpusReport {
            events: event_names
                .iter()
                .zip(&outcomes)
                .filter(|(_, o)| !o.is_empty())
                .map(|(name, o)| tally_by_scenario(name, o))
                .collect(),
            recordings: results.len(),
            hours: results.iter().map(|r| r.seconds).sum::<f64>() / 3600.0,
            false_confirmations,
            false_by_event,
            intrusions_by_event,
            outside_hours: results.iter().map(|r| r.score.outside_s).sum::<f64>() / 3600.0,
            false_by_scenario: false_by_scenario
                .into_iter()
                .map(|(scenario, (n, hours))| (scenario.to_string(), n, hours))
                .collect(),
            after_ms,
            failures,
        }
    }

    /// False confirmations per hour outside events (0 when there was no such time).
    pub fn false_per_hour(&self) -> f64 {
        if self.outside_hours > 0.0 {
            self.false_confirmations as f64 / self.outside_hours
        } else {
            0.0
        }
    }

    /// The report as text: a table per event name (right: confirmed once, nothing else in
    /// its window), the false confirmations, and the first failures of each kind.
    pub fn write(&self, out: &mut impl std::io::Write) -> std::io::Result<()> {
        writeln!(
            out,
            "{} recordings, {:.3} h; a confirmation counts for an event from its onset until {} ms after its labelled end",
            self.recordings, self.hours, self.after_ms
        )?;
        crate::score::write_table(out, ("event", "events"), false, &self.events)?;
        writeln!(
            out,
            "false confirmations: {} in {:.3} h outside labelled events = {:.2} per hour",
            self.false_confirmations,
            self.outside_hours,
            self.false_per_hour()
        )?;
        if !self.false_by_scenario.is_empty() {
            writeln!(out, "  by the recordings' scenario:")?;
            for (scenario, n, hours) in &self.false_by_scenario {
                writeln!(out, "  {scenario:<26} {n:>6} in {hours:.4} h")?;
            }
        }
        if !self.failures.is_empty() {
            writeln!(
                out,
                "what went wrong (at most {SHOWN_FAILURES} of each kind):"
            )?;
            let mut shown: std::collections::HashMap<&str, usize> = Default::default();
            for failure in &self.failures {
                let n = shown.entry(failure.kind()).or_default();
                *n += 1;
                if *n <= SHOWN_FAILURES {
                    writeln!(out, "  {failure}")?;
                }
            }
        }
        Ok(())
    }

    /// The report as JSON: the simulated evaluation's fields where they coincide (`config`,
    /// `false_alarms`, `false_alarms_per_hour`; `events` holds what `scenarios` holds
    /// there, one entry per event name, `runs` counting labelled events; `failures` every
    /// labelled event not right and every false confirmation, each with its recording, its
    /// event, its time and what went wrong).
    pub fn json(&self, config: &str) -> serde_json::Value {
        serde_json::json!({
            "config": config,
            "recordings": self.recordings,
            "hours": self.hours,
            "after_ms": self.after_ms,
            "events": self.events,
            "false_alarms": self.false_confirmations,
            "false_alarms_per_hour": self.false_per_hour(),
            "outside_event_hours": self.outside_hours,
            "false_alarms_by_scenario": self
                .false_by_scenario
                .iter()
                .map(|(scenario, n, hours)| serde_json::json!({
                    "scenario": scenario,
                    "false_alarms": n,
                    "outside_event_hours": hours,
                }))
                .collect::<Vec<_>>(),
            "failures": self
                .failures
                .iter()
                .map(|f| serde_json::json!({
                    "recording": f.recording,
                    "event": f.event,
                    "at_s": f.at_s,
                    "outcome": f.what(),
                }))
                .collect::<Vec<_>>(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn recording(scenario: Option<&str>, outcome: Outcome) -> RecordingResult {
        RecordingResult {
            name: format!("{scenario:?}.csv"),
            seconds: 1.0,
            scenario: scenario.map(str::to_string),
            score: RecordingScore {
                events: vec![("contact".to_string(), 0.02, outcome)],
                false_confirmations: Vec::new(),
                outside_s: 0.5,
            },
        }
    }

    /// An event's tally is binned by the scenarios its recordings name, in name order, and
    /// so are the false confirmations with the time outside events; a recording without
    /// one counts in the event's row but in no bin, and a corpus where none names one is
    /// not binned.
    #[test]
    fn events_are_binned_by_the_recordings_scenario() {
        let right = || Outcome::Correct { latency_s: 0.002 };
        let results = [
            recording(Some("soft"), right()),
            recording(Some("hard"), right()),
            recording(Some("soft"), Outcome::Missed),
            recording(None, right()),
        ];
        let events = ["contact".to_string()];
        let report = CorpusReport::tally(&events, &results, 100.0);
        let contact = &report.events[0];
        assert_eq!((contact.runs, contact.correct), (4, 3));
        assert_eq!(contact.binned_by, "the recordings' scenario");
        let bins: Vec<(&str, usize, usize, usize)> = contact
            .bins
            .iter()
            .map(|b| (b.name.as_str(), b.runs, b.correct, b.missed))
            .collect();
        assert_eq!(bins, [("hard", 1, 1, 0), ("soft", 2, 1, 1)]);
        // Each named scenario's time outside events and false confirmations, in name order.
        let mut quiet = recording(Some("free"), right());
        quiet.score.false_confirmations = vec![("contact".to_string(), 0.7)];
        let with_false: Vec<RecordingResult> = results.iter().cloned().chain([quiet]).collect();
        let report = CorpusReport::tally(&events, &with_false, 100.0);
        let by: Vec<(&str, usize)> = report
            .false_by_scenario
            .iter()
            .map(|(s, n, _)| (s.as_str(), *n))
            .collect();
        assert_eq!(by, [("free", 1), ("hard", 0), ("soft", 0)]);
        assert!((report.false_by_scenario[2].2 - 1.0 / 3600.0).abs() < 1e-12);

        let unnamed = [recording(None, right())];
        let report = CorpusReport::tally(&events, &unnamed, 100.0);
        assert!(report.events[0].bins.is_empty() && report.events[0].binned_by.is_empty());
        assert!(report.false_by_scenario.is_empty());
    }

    /// Every failure is in the JSON report, with its recording, event, time and outcome,
    /// the false confirmations after the events; the text shows the first few of each kind.
    #[test]
    fn every_failure_is_listed_with_its_recording_and_time() {
        let mut missed = recording(Some("soft"), Outcome::Missed);
        missed.score.false_confirmations = (0..5)
            .map(|k| ("contact".to_string(), 1.5 + f64::from(k)))
            .collect();
        let report = CorpusReport::tally(&["contact".to_string()], &[missed], 100.0);
        let json = report.json("c.toml");
        let listed = json["failures"].as_array().expect("a list");
        assert_eq!(listed.len(), 6);
        assert_eq!(listed[0]["recording"], "Some(\"soft\").csv");
        assert_eq!(listed[0]["event"], "contact");
        assert_eq!(listed[0]["at_s"], 0.02);
        assert_eq!(listed[0]["outcome"], Outcome::Missed.to_string());
        assert_eq!(listed[5]["at_s"], 5.5);
        assert_eq!(
            listed[5]["outcome"],
            "confirmed outside every labelled event"
        );
        let mut text = Vec::new();
        report.write(&mut text).expect("writes");
        let text = String::from_utf8(text).expect("UTF-8");
        assert!(text.contains("contact at 0.020 s: "));
        assert!(text.contains("contact confirmed at 3.500 s, outside every labelled event"));
        assert!(
            !text.contains("confirmed at 4.500 s"),
            "more than {SHOWN_FAILURES} shown"
        );
    }
}
