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
    /// The trace was sampled at another rate than the detector runs at.
    #[error(
        "{trace}: sampled at {trace_hz:.1} Hz, but the configuration runs the detector at {config_hz} Hz"
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
        "{trace}, data row {row}, column 'phase': phase '{phase}' is not in the configuration (it has: {have})"
    )]
    UnknownPhase {
        /// The trace's name.
        trace: String,
        /// 1-based data row.
        row: usize,
        /// The phase named.
        phase: String,
        /// The configured phases, comma-separated.
        have: String,
    },
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
    if (trace.rate_hz() - f64::from(config_hz)).abs() > 0.01 * f64::from(config_hz) {
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
                            row: row + 1,
                            phase: p.clone(),
                            have: detector
                                .phases()
                                .iter()
                                .map(|n| n.as_str())
                                .collect::<Vec<_>>()
                                .join(", "),
                        });
                    }
                }
            }
            Some(ids)
        }
        None => None,
    };

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
