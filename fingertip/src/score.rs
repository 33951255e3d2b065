//! Scoring replays against the truth: what a run detected, how fast, and the statistics
//! over many runs that `fingertip evaluate` reports.

use crate::replay::{DecisionRecord, Labelled};

/// What a run's confirmations amount to, given the event expected.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The expected event was confirmed at or after its onset, and nothing else was
    /// confirmed in the whole run.
    Correct {
        /// From the true onset to the (first) confirmation (s).
        latency_s: f64,
    },
    /// Something else was confirmed at some point of the run: another event (even after
    /// the right one), the right one before its true onset, or any event in a run where
    /// none is expected.
    Wrong {
        /// The first event wrongly confirmed.
        event: String,
        /// When (s).
        t_s: f64,
    },
    /// The expected event was confirmed more than once and nothing else was confirmed: a
    /// controller would see one physical event as several.
    Repeated {
        /// How many times.
        confirmations: usize,
        /// From the true onset to the first confirmation (s).
        latency_s: f64,
    },
    /// An event was expected and nothing was confirmed.
    Missed,
    /// No event expected and none confirmed.
    QuietAsExpected,
}

impl Outcome {
    /// Whether the run went as it should.
    pub fn is_right(&self) -> bool {
        matches!(self, Outcome::Correct { .. } | Outcome::QuietAsExpected)
    }
}

/// Scores one run: `expected` is the true event and its onset (s), or `None` for a run in
/// which nothing should be confirmed.
pub fn classify(expected: Option<(&str, f64)>, decisions: &[DecisionRecord]) -> Outcome {
    let mut confirmations = decisions.iter().filter(|d| d.is_confirm());
    let is_wrong = |d: &&DecisionRecord| match expected {
        Some((event, onset)) => d.event != event || d.t_s < onset,
        None => true,
    };
    if let Some(d) = confirmations.clone().find(is_wrong) {
        return Outcome::Wrong {
            event: d.event.clone(),
            t_s: d.t_s,
        };
    }
    let count = confirmations.clone().count();
    match (expected, confirmations.next()) {
        (None, _) => Outcome::QuietAsExpected,
        (Some(_), None) => Outcome::Missed,
        (Some((_, onset)), Some(d)) if count == 1 => Outcome::Correct {
            latency_s: d.t_s - onset,
        },
        (Some((_, onset)), Some(d)) => Outcome::Repeated {
            confirmations: count,
            latency_s: d.t_s - onset,
        },
    }
}

impl core::fmt::Display for Outcome {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Outcome::Correct { latency_s } => {
                write!(f, "confirmed {:.2} ms after onset", latency_s * 1e3)
            }
            Outcome::Repeated {
                confirmations,
                latency_s,
            } => write!(
                f,
                "REPEATED: confirmed {confirmations} times, first {:.2} ms after onset",
                latency_s * 1e3
            ),
            Outcome::Wrong { event, t_s } => {
                write!(f, "WRONG: {event} confirmed at {:.2} ms", t_s * 1e3)
            }
            Outcome::Missed => f.write_str("MISSED"),
            Outcome::QuietAsExpected => f.write_str("nothing confirmed, as expected"),
        }
    }
}

/// Latency statistics (ms).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct Latency {
    /// Median.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

/// The value at quantile `q` of `sorted` (ascending) by nearest rank: the smallest value
/// that at least a share `q` of the values are at or below; 0 when there is none.
pub fn nearest_rank(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let k = ((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[k - 1]
}

impl Latency {
    /// From latencies in seconds (nearest-rank percentiles); all zero when empty.
    pub fn from_seconds(latencies: &[f64]) -> Latency {
        let mut ms: Vec<f64> = latencies.iter().map(|s| s * 1e3).collect();
        ms.sort_by(f64::total_cmp);
        Latency {
            median: nearest_rank(&ms, 0.5),
            p95: nearest_rank(&ms, 0.95),
            p99: nearest_rank(&ms, 0.99),
            max: ms.last().copied().unwrap_or(0.0),
        }
    }
}

/// One scenario's results over many runs.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ScenarioReport {
    /// The scenario's name.
    pub name: String,
    /// The event expected, or `none`.
    pub expected: String,
    /// Runs made.
    pub runs: usize,
    /// Runs that went as they should.
    pub correct: usize,
    /// Runs that confirmed a wrong event (or anything, where nothing was expected).
    pub wrong: usize,
    /// Runs that confirmed nothing although an event happened.
    pub missed: usize,
    /// Runs that confirmed the right event, and nothing else, more than once.
    pub repeated: usize,
    /// Latency from true onset to confirmation over the correct runs (ms).
    pub latency_ms: Latency,
    /// The parameter the runs are binned by, with its unit (empty when not binned).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub binned_by: String,
    /// The same tally per bin of that parameter, each named by its range or kind.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub bins: Vec<ScenarioReport>,
}

impl ScenarioReport {
    /// Tallies outcomes.
    pub fn tally(name: &str, expected: Option<&str>, outcomes: &[Outcome]) -> ScenarioReport {
        let latencies: Vec<f64> = outcomes
            .iter()
            .filter_map(|o| match o {
                Outcome::Correct { latency_s } => Some(*latency_s),
                _ => None,
            })
            .collect();
        ScenarioReport {
            name: name.to_string(),
            expected: expected.unwrap_or("none").to_string(),
            runs: outcomes.len(),
            correct: outcomes.iter().filter(|o| o.is_right()).count(),
            wrong: outcomes
                .iter()
                .filter(|o| matches!(o, Outcome::Wrong { .. }))
                .count(),
            missed: outcomes
                .iter()
                .filter(|o| matches!(o, Outcome::Missed))
                .count(),
            repeated: outcomes
                .iter()
                .filter(|o| matches!(o, Outcome::Repeated { .. }))
                .count(),
            latency_ms: Latency::from_seconds(&latencies),
            binned_by: String::new(),
            bins: Vec::new(),
        }
    }

    /// Tallies outcomes per bin too: `binned` holds each outcome's bin (an index into
    /// `labels`, `None` for a run that fits no bin), `parameter` names what they bin.
    pub fn tally_binned(
        name: &str,
        expected: Option<&str>,
        outcomes: &[Outcome],
        (parameter, labels, binned): (&str, &[String], &[Option<usize>]),
    ) -> ScenarioReport {
        let mut report = ScenarioReport::tally(name, expected, outcomes);
        report.binned_by = parameter.to_string();
        report.bins = labels
            .iter()
            .enumerate()
            .map(|(b, label)| {
                let mine: Vec<Outcome> = outcomes
                    .iter()
                    .zip(binned)
                    .filter(|(_, bin)| **bin == Some(b))
                    .map(|(o, _)| o.clone())
                    .collect();
                ScenarioReport::tally(label, expected, &mine)
            })
            .collect();
        report
    }
}

/// The table of an evaluation, a row per report: right, wrong, missed, repeated and the
/// latency percentiles; the first column named `first` (scenario or event), with the
/// expected event beside it when `expected`, the count named `count` (runs or events).
/// A report's bins follow it, indented, after a line naming the parameter they bin.
pub fn write_table(
    out: &mut impl std::io::Write,
    (first, count): (&str, &str),
    expected: bool,
    reports: &[ScenarioReport],
) -> std::io::Result<()> {
    let lead = |name: &str, event: &str| {
        if expected {
            format!("{name:<26} {event:<15}")
        } else {
            format!("{name:<26}")
        }
    };
    writeln!(
        out,
        "{} {:>6} {:>6} {:>6} {:>6} {:>6}   {:>7} {:>7} {:>7} {:>7}",
        lead(first, "expected"),
        count,
        "right",
        "wrong",
        "missed",
        "repeat",
        "med ms",
        "p95 ms",
        "p99 ms",
        "max ms"
    )?;
    let row = |out: &mut dyn std::io::Write, lead: String, r: &ScenarioReport| {
        writeln!(
            out,
            "{} {:>6} {:>6} {:>6} {:>6} {:>6}   {:>7.2} {:>7.2} {:>7.2} {:>7.2}",
            lead,
            r.runs,
            r.correct,
            r.wrong,
            r.missed,
            r.repeated,
            r.latency_ms.median,
            r.latency_ms.p95,
            r.latency_ms.p99,
            r.latency_ms.max
        )
    };
    for r in reports {
        row(out, lead(&r.name, &r.expected), r)?;
        // Each bin under its scenario, indented, after a line naming what they bin.
        if !r.bins.is_empty() {
            writeln!(out, "  by {}:", r.binned_by)?;
        }
        for b in &r.bins {
            row(out, lead(&format!("  {}", b.name), ""), b)?;
        }
    }
    Ok(())
}

/// How one recording went: each labelled event's outcome, and the confirmations outside
/// every event.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordingScore {
    /// Per labelled event, in order: its name, onset (s) and outcome.
    pub events: Vec<(String, f64, Outcome)>,
    /// Confirmations outside every event's window: the event confirmed and when (s).
    pub false_confirmations: Vec<(String, f64)>,
    /// The recording's time outside every event's window (s).
    pub outside_s: f64,
}

/// Scores a recording with several labelled events. A confirmation belongs to the latest
/// labelled event whose window holds it; an event's window runs from its onset to `after_s`
/// past its end. Each event is then classified as a simulated run is ([`classify`], on the
/// confirmations of its window: the right event once, something else, several times, or
/// nothing); a confirmation in no window is a false confirmation. `span` is the recording's
/// first and last time (s).
pub fn score_recording(
    labelled: &[Labelled],
    decisions: &[DecisionRecord],
    after_s: f64,
    span: (f64, f64),
) -> RecordingScore {
    let mut mine: Vec<Vec<DecisionRecord>> = vec![Vec::new(); labelled.len()];
    let mut false_confirmations = Vec::new();
    for d in decisions.iter().filter(|d| d.is_confirm()) {
        let owner = labelled
            .iter()
            .rposition(|l| l.onset_s <= d.t_s && d.t_s <= l.end_s + after_s);
        match owner {
            Some(k) => mine[k].push(d.clone()),
            None => false_confirmations.push((d.event.clone(), d.t_s)),
        }
    }
    let events = labelled
        .iter()
        .zip(&mine)
        .map(|(l, ds)| {
            let outcome = classify(Some((&l.event, l.onset_s)), ds);
            (l.event.clone(), l.onset_s, outcome)
        })
        .collect();
    // The windows' union within the span, from the windows in onset order.
    let (start, end) = span;
    let mut covered = 0.0;
    let mut reach = start;
    for l in labelled {
        let (a, b) = (l.onset_s.max(reach), (l.end_s + after_s).min(end));
        if b > a {
            covered += b - a;
            reach = b;
        }
    }
    RecordingScore {
        events,
        false_confirmations,
        outside_s: (end - start - covered).max(0.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn confirm(event: &str, t_s: f64) -> DecisionRecord {
        DecisionRecord {
            event: event.into(),
            level: "confirm",
            confidence: 0.9,
            onset_s: t_s - 0.001,
            t_s,
        }
    }

    #[test]
    fn classification() {
        let alert = DecisionRecord {
            level: "alert",
            ..confirm("link_collision", 0.0205)
        };
        let runs = [confirm("contact", 0.0215)];
        assert_eq!(
            classify(Some(("contact", 0.020)), &runs),
            Outcome::Correct {
                latency_s: 0.0215 - 0.020
            }
        );
        // An alert for another event does not count; the first confirmation does.
        assert_eq!(
            classify(
                Some(("contact", 0.020)),
                &[alert.clone(), confirm("contact", 0.022)]
            ),
            Outcome::Correct {
                latency_s: 0.022 - 0.020
            }
        );
        assert!(matches!(
            classify(Some(("contact", 0.020)), &[confirm("disturbance", 0.021)]),
            Outcome::Wrong { .. }
        ));
        // Another event confirmed after the right one is still a wrong confirmation.
        assert_eq!(
            classify(
                Some(("disturbance", 0.020)),
                &[
                    confirm("disturbance", 0.021),
                    confirm("link_collision", 0.024)
                ]
            ),
            Outcome::Wrong {
                event: "link_collision".into(),
                t_s: 0.024
            }
        );
        // Confirming the right event before it happened is a false alarm.
        assert!(matches!(
            classify(Some(("contact", 0.020)), &[confirm("contact", 0.010)]),
            Outcome::Wrong { .. }
        ));
        assert_eq!(
            classify(Some(("contact", 0.020)), &[alert]),
            Outcome::Missed
        );
        // The right event confirmed twice is one physical event reported as two.
        assert_eq!(
            classify(
                Some(("contact", 0.020)),
                &[confirm("contact", 0.021), confirm("contact", 0.025)]
            ),
            Outcome::Repeated {
                confirmations: 2,
                latency_s: 0.021 - 0.020
            }
        );
        assert!(
            !Outcome::Repeated {
                confirmations: 2,
                latency_s: 0.0
            }
            .is_right()
        );
        assert_eq!(classify(None, &[]), Outcome::QuietAsExpected);
        assert!(matches!(
            classify(None, &[confirm("contact", 0.05)]),
            Outcome::Wrong { .. }
        ));
    }

    fn labelled(event: &str, onset_s: f64, end_s: f64) -> Labelled {
        Labelled {
            event: event.into(),
            onset_s,
            end_s,
        }
    }

    /// Confirmations go to the latest event whose window holds them: found, repeated,
    /// wrong, missed, and outside every window a false confirmation; the time outside
    /// counts overlapping windows once.
    #[test]
    fn recordings_are_scored_event_by_event() {
        let events = [
            labelled("contact", 1.0, 1.5),
            labelled("link_collision", 3.0, 3.02),
            labelled("contact", 3.05, 3.5),
            labelled("disturbance", 6.0, 6.1),
            labelled("contact", 8.0, 8.2),
        ];
        let decisions = [
            confirm("contact", 0.5),
            confirm("contact", 1.002),
            DecisionRecord {
                level: "alert",
                ..confirm("disturbance", 2.0)
            },
            // 50 ms after the collision's end, within its 100 ms: but the contact labelled
            // at 3.05 s is later and holds it too.
            confirm("link_collision", 3.07),
            confirm("contact", 3.06),
            confirm("disturbance", 6.05),
            confirm("disturbance", 6.15),
            confirm("link_collision", 7.0),
        ];
        let s = score_recording(&events, &decisions, 0.1, (0.0, 10.0));
        let outcomes: Vec<&Outcome> = s.events.iter().map(|e| &e.2).collect();
        assert_eq!(
            outcomes,
            [
                &Outcome::Correct {
                    latency_s: 1.002 - 1.0
                },
                &Outcome::Missed,
                &Outcome::Wrong {
                    event: "link_collision".into(),
                    t_s: 3.07
                },
                &Outcome::Repeated {
                    confirmations: 2,
                    latency_s: 6.05 - 6.0
                },
                &Outcome::Missed,
            ]
        );
        assert_eq!(
            s.false_confirmations,
            [
                ("contact".to_string(), 0.5),
                ("link_collision".to_string(), 7.0)
            ]
        );
        // Windows: 1.0-1.6, 3.0-3.12 and 3.05-3.6 (overlapping: 3.0-3.6), 6.0-6.2, 8.0-8.3.
        assert!(
            (s.outside_s - (10.0 - 0.6 - 0.6 - 0.2 - 0.3)).abs() < 1e-9,
            "{}",
            s.outside_s
        );
    }

    /// Bins tally their own runs; a run in no bin counts for the scenario only.
    #[test]
    fn tally_binned_splits_the_runs() {
        let outcomes = [
            Outcome::Correct { latency_s: 0.001 },
            Outcome::Missed,
            Outcome::Correct { latency_s: 0.004 },
            Outcome::Missed,
        ];
        let labels = ["soft".to_string(), "hard".to_string()];
        let r = ScenarioReport::tally_binned(
            "s",
            Some("contact"),
            &outcomes,
            (
                "stiffness [N/m]",
                &labels,
                &[Some(1), Some(0), Some(1), None],
            ),
        );
        assert_eq!((r.runs, r.correct, r.missed), (4, 2, 2));
        assert_eq!(r.binned_by, "stiffness [N/m]");
        let counts: Vec<(&str, usize, usize, usize)> = r
            .bins
            .iter()
            .map(|b| (b.name.as_str(), b.runs, b.correct, b.missed))
            .collect();
        assert_eq!(counts, [("soft", 1, 0, 1), ("hard", 2, 2, 0)]);
        assert_eq!(r.bins[1].latency_ms.max, 4.0);
        let mut table = Vec::new();
        write_table(&mut table, ("scenario", "runs"), true, &[r]).unwrap();
        let table = String::from_utf8(table).unwrap();
        assert!(table.contains("  by stiffness [N/m]:\n  soft "), "{table}");
    }

    #[test]
    fn nearest_rank_percentiles() {
        let s: Vec<f64> = (1..=100).map(|k| k as f64 * 1e-3).collect();
        let l = Latency::from_seconds(&s);
        assert_eq!((l.median, l.p95, l.p99, l.max), (50.0, 95.0, 99.0, 100.0));
        assert_eq!(Latency::from_seconds(&[]), Latency::default());
        let one = Latency::from_seconds(&[0.002]);
        assert_eq!((one.median, one.p99, one.max), (2.0, 2.0, 2.0));
    }

    #[test]
    fn tally_counts_each_outcome() {
        let outcomes = [
            Outcome::Correct { latency_s: 0.001 },
            Outcome::Correct { latency_s: 0.003 },
            Outcome::Missed,
            Outcome::Wrong {
                event: "x".into(),
                t_s: 0.0,
            },
            Outcome::Repeated {
                confirmations: 3,
                latency_s: 0.002,
            },
        ];
        let r = ScenarioReport::tally("contact_hard_8", Some("contact"), &outcomes);
        assert_eq!(
            (r.runs, r.correct, r.wrong, r.missed, r.repeated),
            (5, 2, 1, 1, 1)
        );
        assert_eq!(r.latency_ms.max, 3.0);
        assert_eq!(
            ScenarioReport::tally("s", None, &[Outcome::QuietAsExpected]).correct,
            1
        );
    }
}
