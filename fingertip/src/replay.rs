//! Runs the fixed-point detector — the same code as on the chip — over a trace.

use detector_core::{Detector, Inputs, Level, Output, State, Tick};

use crate::trace::Trace;

/// A level raised during a replay, with times in seconds of the trace's `t` column.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DecisionRecord {
    /// The event's name.
    pub event: String,
    /// `alert` or `confirm`.
    pub level: &'static str,
    /// The event's confidence when the level was raised, in [0, 1].
    pub confidence: f64,
    /// Back-dated onset (s).
    pub onset_s: f64,
    /// When the level was raised (s).
    pub t_s: f64,
}

impl DecisionRecord {
    /// Whether this is a confirmation.
    pub fn is_confirm(&self) -> bool {
        self.level == Level::Confirm.name()
    }
}

/// Why a trace cannot be replayed with a configuration.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ReplayError {
    /// The configuration reads a channel the trace has no column for.
    #[error(
        "{trace}: the configuration reads channel '{channel}', but the trace has no such column (it has: {have})"
    )]
    MissingChannel {
        /// The trace's name (its path).
        trace: String,
        /// The channel.
        channel: String,
        /// The trace's columns, comma-separated.
        have: String,
    },
    /// The trace was sampled at another rate than the detector runs at (beyond
    /// [`RATE_TOLERANCE`]).
    #[error(
        "{trace}: sampled at {trace_hz:.3} Hz, but the configuration runs the detector at {config_hz} Hz (at most 0.1 % apart)"
    )]
    RateMismatch {
        /// The trace's name.
        trace: String,
        /// The trace's sample rate.
        trace_hz: f64,
        /// The configured detector rate.
        config_hz: f32,
    },
    /// A row names a phase the configuration does not define.
    #[error(
        "{trace}: line {line}, column 'phase': phase '{phase}' is not in the configuration (it has: {have})"
    )]
    UnknownPhase {
        /// The trace's name.
        trace: String,
        /// The row's file line.
        line: usize,
        /// The phase named.
        phase: String,
        /// The configured phases, comma-separated.
        have: String,
    },
    /// The `truth` column names an event the configuration does not monitor: latencies
    /// would be measured against nothing it can confirm.
    #[error(
        "{trace}: line {line}, column 'truth': event '{event}' is not in the configuration (it has: {have})"
    )]
    UnknownTruth {
        /// The trace's name.
        trace: String,
        /// The file line of its first row.
        line: usize,
        /// The event named.
        event: String,
        /// The configured events, comma-separated.
        have: String,
    },
    /// The `truth` column labels more than one event; scoring takes one per trace.
    #[error(
        "{trace}: line {line}, column 'truth': a second event '{second}' after '{first}': one labelled event per trace is scored"
    )]
    SeveralTruths {
        /// The trace's name.
        trace: String,
        /// The file line where the second event starts.
        line: usize,
        /// The first event.
        first: String,
        /// The second.
        second: String,
    },
}

/// How far a trace's rate may be from the detector's, as a fraction of the detector's: a
/// recording's clock is off by far less (crystals by 10⁻⁴ at most), while 1 % would shift
/// every filter and window by as much.
pub const RATE_TOLERANCE: f64 = 0.001;

/// Names as a message lists them: comma-separated.
fn listed(names: &[detector_core::Name]) -> String {
    names
        .iter()
        .map(|n| n.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Checks a trace's `truth` column against the detector's events: every label names one
/// of them, and at most one event is labelled.
fn check_truth(detector: &Detector, trace: &Trace) -> Result<(), ReplayError> {
    let Some(truth) = trace.truth() else {
        return Ok(());
    };
    let mut first: Option<&str> = None;
    for (row, label) in truth.iter().enumerate() {
        if label.is_empty() || first == Some(label.as_str()) {
            continue;
        }
        if detector.event(label).is_none() {
            return Err(ReplayError::UnknownTruth {
                trace: trace.name().to_string(),
                line: trace.line_of(row),
                event: label.clone(),
                have: listed(detector.events()),
            });
        }
        match first {
            None => first = Some(label),
            Some(f) => {
                return Err(ReplayError::SeveralTruths {
                    trace: trace.name().to_string(),
                    line: trace.line_of(row),
                    first: f.to_string(),
                    second: label.clone(),
                });
            }
        }
    }
    Ok(())
}

/// The trace's column for each of the detector's channels, in sample order.
pub fn channel_columns<'t>(
    detector: &Detector,
    trace: &'t Trace,
) -> Result<Vec<&'t [f64]>, ReplayError> {
    detector
        .channels()
        .iter()
        .map(|channel| {
            trace
                .column(channel)
                .ok_or_else(|| ReplayError::MissingChannel {
                    trace: trace.name().to_string(),
                    channel: channel.to_string(),
                    have: trace.channel_names().join(", "),
                })
        })
        .collect()
}

/// Replays `trace` through `detector`, calling `each_tick(row, &state, &output)` after every
/// tick,
/// and returns every level raised. The trace is checked first (channels, rate, phases);
/// on error nothing has run.
pub fn replay(
    detector: &Detector,
    trace: &Trace,
    mut each_tick: impl FnMut(usize, &State, &Output),
) -> Result<Vec<DecisionRecord>, ReplayError> {
    let name = trace.name().to_string();
    let columns = channel_columns(detector, trace)?;
    let config_hz = detector.rate_hz();
    if (trace.rate_hz() - f64::from(config_hz)).abs() > RATE_TOLERANCE * f64::from(config_hz) {
        return Err(ReplayError::RateMismatch {
            trace: name,
            trace_hz: trace.rate_hz(),
            config_hz,
        });
    }
    let phases = match trace.phase() {
        Some(names) => {
            let mut ids = Vec::with_capacity(names.len());
            for (row, p) in names.iter().enumerate() {
                match detector.phase(p) {
                    Some(id) => ids.push(id),
                    None => {
                        return Err(ReplayError::UnknownPhase {
                            trace: name,
                            line: trace.line_of(row),
                            phase: p.clone(),
                            have: listed(detector.phases()),
                        });
                    }
                }
            }
            Some(ids)
        }
        None => None,
    };
    check_truth(detector, trace)?;

    let t = trace.time();
    let time_of = |tick: Tick| t.get(tick as usize).copied().unwrap_or(f64::NAN);
    let mut state = detector.new_state();
    let mut inputs = Inputs::default();
    let mut records = Vec::new();
    for row in 0..t.len() {
        if let Some(p) = phases.as_ref().and_then(|p| p.get(row)) {
            detector.set_phase(&mut state, *p);
        }
        for (k, (sample, column)) in inputs.samples.iter_mut().zip(&columns).enumerate() {
            *sample = detector.sample_from_si(k, column.get(row).copied().unwrap_or(0.0));
        }
        let out = detector.tick(&mut state, row as Tick, &inputs);
        for d in &out.decisions {
            records.push(DecisionRecord {
                event: detector
                    .events()
                    .get(usize::from(d.event.0))
                    .map(|n| n.to_string())
                    .unwrap_or_default(),
                level: d.level.name(),
                confidence: d.confidence.to_f64(),
                onset_s: time_of(d.onset),
                t_s: time_of(d.tick),
            });
        }
        each_tick(row, &state, &out);
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Labels;

    fn approach() -> Detector {
        let config = detector_build::Config::from_toml(crate::APPROACH_TOML).expect("parses");
        detector_build::build(&config).expect("builds")
    }

    /// A quiet trace of the approach detector's channels at `rate_hz`, `rows` long, with
    /// comment lines interleaved so that file lines and rows differ.
    fn text(rate_hz: f64, rows: usize, phase: &[&str], truth: &[&str]) -> String {
        let channels = "force_x,force_y,skin_accel,stress_rate,pos_err_x,pos_err_y,vel_des_x,vel_des_y,acc_des_x,acc_des_y";
        let mut s = format!("# a comment\nt,{channels},phase,truth\n");
        for k in 0..rows {
            if k == 3 {
                s.push_str("# another comment\n");
            }
            let p = phase.get(k).copied().unwrap_or("approach");
            let e = truth.get(k).copied().unwrap_or("");
            s.push_str(&format!(
                "{},0,0,0,0,0,0,0,0,0,0,{p},{e}\n",
                k as f64 / rate_hz
            ));
        }
        s
    }

    fn refused(text: &str, words: &[&str]) {
        let trace = Trace::parse(text, "run.csv").expect("parses");
        let e = replay(&approach(), &trace, |_, _, _| {})
            .expect_err("refused")
            .to_string();
        for w in words {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    }

    /// Each way a trace can disagree with the configuration is refused before any tick,
    /// naming the file line (comments counted): an unknown phase or truth label, a second
    /// labelled event, a rate beyond 0.1 %, in either direction.
    #[test]
    fn traces_that_disagree_with_the_configuration_are_refused() {
        let mut phase = vec!["approach"; 10];
        phase[5] = "grasp";
        // Row 5 is on line 9: a comment, the header, rows 0-2, a comment, rows 3-5.
        refused(
            &text(5000.0, 10, &phase, &[]),
            &["line 9", "'grasp'", "approach"],
        );
        let mut truth = vec![""; 10];
        truth[4] = "slip";
        refused(
            &text(5000.0, 10, &[], &truth),
            &["line 8", "'slip'", "contact"],
        );
        let truth = ["", "contact", "contact", "", "disturbance"];
        refused(
            &text(5000.0, 10, &[], &truth),
            &["line 8", "'disturbance' after 'contact'"],
        );
        for rate in [4950.0, 4990.0, 5010.0, 5050.0] {
            refused(&text(rate, 10, &[], &[]), &["Hz", "5000 Hz", "0.1 %"]);
        }
    }

    /// Within the tolerance, and with one event labelled twice apart, the trace runs.
    #[test]
    fn traces_within_the_rules_run() {
        let truth = ["", "contact", "", "contact"];
        for rate in [4996.0, 5000.0, 5004.0] {
            let trace = Trace::parse(&text(rate, 10, &[], &truth), "run.csv").expect("parses");
            assert!(
                replay(&approach(), &trace, |_, _, _| {}).is_ok(),
                "{rate} Hz"
            );
        }
        let built = Trace::from_columns("mem", vec![0.0, 0.0002], vec![])
            .expect("built")
            .with_truth(Labels::switch_at("", "slip", 1, 2))
            .expect("labels");
        // A trace built in memory counts lines as written without metadata.
        assert_eq!(built.line_of(1), 3);
    }
}
