//! Runs the fixed-point detector — the same code as on the chip — over a trace.

use detector_core::{Detector, DetectorTick, Inputs, Level, Output, PhaseId, Signal, State, Tick};

use crate::trace::{ReadAhead, Trace, TraceError, TraceReader};

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
    /// A recording's saved state (its `state` metadata) is not one this detector runs on.
    #[error(
        "{trace}: metadata 'state': {reason} (replay a flight recording with the configuration the fingertip ran)"
    )]
    SavedState {
        /// The trace's name.
        trace: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A recording's `first_tick` metadata is not a tick.
    #[error("{trace}: metadata 'first_tick': `{value}` is not a tick (a whole number below 2^32)")]
    FirstTick {
        /// The trace's name.
        trace: String,
        /// The value found.
        value: String,
    },
    /// A `withheld` cell is not a set of the configuration's channels.
    #[error(
        "{trace}: line {line}, column 'withheld': `{value}` is not a set of the configuration's {channels} channels (a whole number below 2^{channels})"
    )]
    Withheld {
        /// The trace's name.
        trace: String,
        /// The row's file line.
        line: usize,
        /// The cell.
        value: f64,
        /// The configuration's channel count.
        channels: usize,
    },
}

/// A flight recording's metadata: the detector's state before its first row, hex
/// ([`State::save`]'s bytes).
pub const STATE_KEY: &str = "state";
/// A flight recording's metadata: the fingertip's tick at its first row.
pub const FIRST_TICK_KEY: &str = "first_tick";

/// The column of a flight recording that names the channels withheld at each tick (bit
/// `i` for the configuration's channel `i`): docs/trace-format.md.
pub const WITHHELD_COLUMN: &str = "withheld";

/// The channels a `withheld` cell names, checked against the detector's channel count.
fn withheld(detector: &Detector, trace: &str, line: usize, v: f64) -> Result<u32, ReplayError> {
    let channels = detector.channels().len();
    if v.fract() == 0.0 && v >= 0.0 && v < f64::from(1u32 << channels.min(31)) {
        Ok(v as u32)
    } else {
        Err(ReplayError::Withheld {
            trace: trace.to_string(),
            line,
            value: v,
            channels,
        })
    }
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

/// An event labelled in a trace's `truth` column: a maximal run of rows with the same
/// non-empty label (docs/trace-format.md).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Labelled {
    /// The event's name.
    pub event: String,
    /// Its onset: the time of the run's first row (s).
    pub onset_s: f64,
    /// Its end: the time of the run's last row (s).
    pub end_s: f64,
}

/// The rules every row of a replayed trace must follow, checked as it comes: its phase is
/// one of the configuration's, its truth label empty or one of the configuration's events.
/// Collects the labelled events.
struct RowRules<'d> {
    detector: &'d Detector,
    trace: String,
    /// The last phase label seen and its id (phases change seldom).
    phase: Option<(String, PhaseId)>,
    /// The events labelled so far; whether the last is still going on.
    labelled: Vec<Labelled>,
    open: bool,
}

impl<'d> RowRules<'d> {
    fn new(detector: &'d Detector, trace: &str) -> RowRules<'d> {
        RowRules {
            detector,
            trace: trace.to_string(),
            phase: None,
            labelled: Vec::new(),
            open: false,
        }
    }

    /// The phase named on the row at `line`.
    fn phase(&mut self, label: &str, line: usize) -> Result<PhaseId, ReplayError> {
        if let Some((last, id)) = &self.phase
            && last == label
        {
            return Ok(*id);
        }
        let id = self
            .detector
            .phase(label)
            .ok_or_else(|| ReplayError::UnknownPhase {
                trace: self.trace.clone(),
                line,
                phase: label.to_string(),
                have: listed(self.detector.phases()),
            })?;
        self.phase = Some((label.to_string(), id));
        Ok(id)
    }

    /// The truth label of the row at time `t` and `line`: an empty label ends the event
    /// going on, another label than its starts a new one.
    fn truth(&mut self, label: &str, t: f64, line: usize) -> Result<(), ReplayError> {
        if label.is_empty() {
            self.open = false;
            return Ok(());
        }
        match self.labelled.last_mut() {
            Some(last) if self.open && last.event == label => {
                last.end_s = t;
                return Ok(());
            }
            _ => {}
        }
        if self.detector.event(label).is_none() {
            return Err(ReplayError::UnknownTruth {
                trace: self.trace.clone(),
                line,
                event: label.to_string(),
                have: listed(self.detector.events()),
            });
        }
        self.labelled.push(Labelled {
            event: label.to_string(),
            onset_s: t,
            end_s: t,
        });
        self.open = true;
        Ok(())
    }
}

/// The detector's rate when `rate_hz` is within [`RATE_TOLERANCE`] of it.
fn check_rate(detector: &Detector, trace: &str, rate_hz: f64) -> Result<(), ReplayError> {
    let config_hz = detector.rate_hz();
    if (rate_hz - f64::from(config_hz)).abs() > RATE_TOLERANCE * f64::from(config_hz) {
        return Err(ReplayError::RateMismatch {
            trace: trace.to_string(),
            trace_hz: rate_hz,
            config_hz,
        });
    }
    Ok(())
}

/// The trace's column for each of the detector's channels, in sample order.
pub fn channel_columns<'t>(
    detector: &Detector,
    trace: &'t Trace,
) -> Result<Vec<&'t [f64]>, ReplayError> {
    let names = trace.channel_names();
    Ok(channel_positions(detector, trace.name(), names)?
        .into_iter()
        .filter_map(|i| names.get(i).and_then(|n| trace.column(n)))
        .collect())
}

/// Where each of `detector`'s channels is among a trace's channel `names`, in the
/// detector's order; a channel the trace lacks is named in the error, with what it has.
fn channel_positions(
    detector: &Detector,
    trace: &str,
    names: &[String],
) -> Result<Vec<usize>, ReplayError> {
    detector
        .channels()
        .iter()
        .map(|channel| {
            names
                .iter()
                .position(|n| n == channel.as_str())
                .ok_or_else(|| ReplayError::MissingChannel {
                    trace: trace.to_string(),
                    channel: channel.to_string(),
                    have: names.join(", "),
                })
        })
        .collect()
}

/// Replays `trace` through `detector`, calling `each_tick(row, &state, &output)` after every
/// tick, and returns every level raised. The channels and the rate are checked first,
/// each row's phase and truth as it comes.
pub fn replay(
    detector: &Detector,
    trace: &Trace,
    each_tick: impl FnMut(usize, &State, &Output),
) -> Result<Vec<DecisionRecord>, ReplayError> {
    replay_with(Ticker::new(detector), detector, trace, each_tick)
}

/// [`replay`] with the given ticker.
fn replay_with(
    mut ticker: Ticker,
    detector: &Detector,
    trace: &Trace,
    mut each_tick: impl FnMut(usize, &State, &Output),
) -> Result<Vec<DecisionRecord>, ReplayError> {
    // Each channel's samples converted at once: a loop over one column at a time runs
    // several conversions in parallel, where one row at a time waits for each.
    let samples: Vec<Vec<Signal>> = channel_columns(detector, trace)?
        .iter()
        .enumerate()
        .map(|(k, column)| {
            column
                .iter()
                .map(|&v| detector.sample_from_si(k, v))
                .collect()
        })
        .collect();
    check_rate(detector, trace.name(), trace.rate_hz())?;
    ticker.start_from(detector, trace.name(), trace.metadata())?;
    let withheld_column = trace.column(WITHHELD_COLUMN);
    let mut rules = RowRules::new(detector, trace.name());
    let t = trace.time();
    for row in 0..t.len() {
        let line = trace.line_of(row);
        if let Some(p) = trace.phase().and_then(|p| p.get(row)) {
            let id = rules.phase(p, line)?;
            detector.set_phase(&mut ticker.state, id);
        }
        if let Some(label) = trace.truth().and_then(|l| l.get(row)) {
            rules.truth(label, t[row], line)?;
        }
        let faults = match withheld_column.and_then(|c| c.get(row)) {
            Some(&v) => withheld(detector, trace.name(), line, v)?,
            None => 0,
        };
        ticker.tick(
            detector,
            row,
            faults,
            |k| samples.get(k).and_then(|c| c.get(row)).copied(),
            |r| match usize::try_from(r).ok().and_then(|r| t.get(r)) {
                Some(&at) => at,
                None => t[0] + r as f64 / trace.rate_hz(),
            },
        );
        each_tick(row, &ticker.state, &ticker.out);
    }
    Ok(ticker.records)
}

/// What a streamed replay found, beside what it handed out tick by tick.
#[derive(Debug)]
pub struct Streamed {
    /// Every level raised.
    pub decisions: Vec<DecisionRecord>,
    /// Rows replayed.
    pub rows: usize,
    /// The trace's rate over all its rows (Hz).
    pub rate_hz: f64,
    /// The times of its first and last rows (s).
    pub span_s: (f64, f64),
    /// The events labelled in the trace's `truth` column, in order.
    pub labelled: Vec<Labelled>,
    /// The trace's `scenario` metadata, from a comment before its header: what a simulated
    /// run records, and how a corpus may name what each recording shows.
    pub scenario: Option<String>,
}

impl Streamed {
    /// The first labelled event and its onset (s), if any.
    pub fn first_truth(&self) -> Option<(String, f64)> {
        self.labelled.first().map(|l| (l.event.clone(), l.onset_s))
    }
}

/// One tick of a streamed replay, as [`replay_stream`] and [`replay_stream_each`] hand it
/// out.
pub struct StreamTick<'a> {
    /// The row's time (s).
    pub t: f64,
    /// The row's index.
    pub row: usize,
    /// The detector's state after the tick.
    pub state: &'a State,
    /// The tick's output.
    pub output: &'a Output,
    /// The events labelled so far, this row's included.
    pub labelled: &'a [Labelled],
    /// Whether this row is labelled: then it belongs to the last of `labelled`.
    pub in_event: bool,
}

/// Replays a trace read row by row, for recordings of any length: nothing but the levels
/// raised is kept. `each_tick` runs after every tick. Each time
/// step must be within 1 % of the detector's period, and the rate over the whole trace
/// within [`RATE_TOLERANCE`] of the detector's (checked at the end: a caller writes its
/// outputs only once this returns).
pub fn replay_stream<R: std::io::BufRead + Send>(
    detector: &Detector,
    reader: TraceReader<R>,
    mut each_tick: impl FnMut(&StreamTick<'_>),
) -> Result<Streamed, StreamError> {
    std::thread::scope(|scope| {
        let reader = ReadAhead::spawn(scope, reader);
        let mut parts = [Part::new(detector, &reader)?];
        let read = replay_rows(&mut parts, reader, |_, tick| each_tick(tick))?;
        let [part] = parts;
        part.finish(&read)
    })
}

/// [`replay_stream`] for several detectors at once, the trace read once: `each_tick` is
/// given the detector's index with each of its ticks; the results are in the detectors'
/// order.
pub fn replay_stream_each<R: std::io::BufRead + Send>(
    detectors: &[&Detector],
    reader: TraceReader<R>,
    each_tick: impl FnMut(usize, &StreamTick<'_>),
) -> Result<Vec<Streamed>, StreamError> {
    std::thread::scope(|scope| {
        let reader = ReadAhead::spawn(scope, reader);
        let mut parts = detectors
            .iter()
            .map(|d| Part::new(d, &reader))
            .collect::<Result<Vec<_>, _>>()?;
        let read = replay_rows(&mut parts, reader, each_tick)?;
        parts.into_iter().map(|p| p.finish(&read)).collect()
    })
}

/// One detector's share of a streamed replay: where its channels are in the trace, the
/// rules its rows follow, its state.
struct Part<'d> {
    detector: &'d Detector,
    columns: Vec<usize>,
    /// The `withheld` column's place among the trace's channels, if it has one.
    withheld: Option<usize>,
    rules: RowRules<'d>,
    ticker: Ticker,
    period: f64,
}

/// What a streamed replay read: the trace's name, its rows, the times of its first and
/// last rows (s), its `scenario` metadata.
struct Read {
    name: String,
    rows: usize,
    span_s: (f64, f64),
    scenario: Option<String>,
}

impl<'d> Part<'d> {
    fn new(detector: &'d Detector, reader: &ReadAhead) -> Result<Part<'d>, StreamError> {
        let name = reader.name();
        let mut ticker = Ticker::new(detector);
        ticker.start_from(detector, name, reader.metadata())?;
        Ok(Part {
            detector,
            columns: channel_positions(detector, name, reader.channel_names())?,
            withheld: reader
                .channel_names()
                .iter()
                .position(|n| n == WITHHELD_COLUMN),
            rules: RowRules::new(detector, name),
            ticker,
            period: 1.0 / f64::from(detector.rate_hz()),
        })
    }

    /// The replay's results once every row is read, the rate checked.
    fn finish(self, read: &Read) -> Result<Streamed, StreamError> {
        let (first_t, last_t) = read.span_s;
        let rate_hz = (read.rows - 1) as f64 / (last_t - first_t);
        check_rate(self.detector, &read.name, rate_hz)?;
        Ok(Streamed {
            decisions: self.ticker.records,
            rows: read.rows,
            rate_hz,
            span_s: read.span_s,
            labelled: self.rules.labelled,
            scenario: read.scenario.clone(),
        })
    }
}

/// A streamed replay once the rows are parsed on their own thread: every row ticks each
/// detector of `parts`. Returns what was read; at least two rows.
fn replay_rows(
    parts: &mut [Part<'_>],
    mut reader: ReadAhead,
    mut each_tick: impl FnMut(usize, &StreamTick<'_>),
) -> Result<Read, StreamError> {
    let name = reader.name().to_string();
    let scenario = reader
        .metadata()
        .iter()
        .find(|(key, _)| key == crate::sim::META_SCENARIO)
        .map(|(_, value)| value.clone());
    // Times of the first and last rows, and of the levels' ticks, which the stream forgets:
    // a tick's time is the first row's plus the tick times the period, exact for a uniform
    // trace.
    let mut first_t = None;
    let mut last_t = 0.0;
    let mut rows = 0usize;
    let mut last_line = 0;
    while let Some(r) = reader.next_row()? {
        let row = rows;
        let t0 = *first_t.get_or_insert(r.t);
        for (d, part) in parts.iter_mut().enumerate() {
            let period = part.period;
            if row > 0 && ((r.t - last_t) - period).abs() > 0.01 * period {
                return Err(StreamError::Step {
                    trace: name,
                    line: r.line,
                    step: r.t - last_t,
                    period,
                });
            }
            if let Some(p) = r.phase {
                let id = part.rules.phase(p, r.line)?;
                part.detector.set_phase(&mut part.ticker.state, id);
            }
            if let Some(label) = r.truth {
                part.rules.truth(label, r.t, r.line)?;
            }
            let (values, columns, detector) = (r.values, &part.columns, part.detector);
            let faults = match part.withheld.and_then(|c| values.get(c)) {
                Some(&v) => withheld(detector, &name, r.line, v)?,
                None => 0,
            };
            part.ticker.tick(
                part.detector,
                row,
                faults,
                |k| {
                    let v = columns.get(k).and_then(|&c| values.get(c));
                    v.map(|&v| detector.sample_from_si(k, v))
                },
                |r| t0 + r as f64 * period,
            );
            each_tick(
                d,
                &StreamTick {
                    t: r.t,
                    row,
                    state: &part.ticker.state,
                    output: &part.ticker.out,
                    labelled: &part.rules.labelled,
                    in_event: part.rules.open,
                },
            );
        }
        last_t = r.t;
        last_line = r.line;
        rows += 1;
    }
    match rows {
        0 => Err(StreamError::Trace(TraceError::NoRows {
            file: name,
            line: reader.header_line(),
        })),
        1 => Err(StreamError::Trace(TraceError::SingleRow {
            file: name,
            line: last_line,
        })),
        _ => Ok(Read {
            name,
            rows,
            span_s: (first_t.unwrap_or(0.0), last_t),
            scenario,
        }),
    }
}

/// Why a streamed replay stopped.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// A row could not be read.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// The trace does not fit the configuration.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// A time step is not the detector's period.
    #[error(
        "{trace}: line {line}, column `t`: time step {} s is not the detector's period {} s (within 1 %)",
        crate::readable(*step),
        crate::readable(*period)
    )]
    Step {
        /// The trace's name.
        trace: String,
        /// The row's file line.
        line: usize,
        /// The step from the previous row.
        step: f64,
        /// The detector's period.
        period: f64,
    },
}

/// The detector's state and inputs across ticks, the last tick's output, and the levels
/// raised so far.
struct Ticker {
    state: State,
    inputs: Inputs,
    out: Output,
    records: Vec<DecisionRecord>,
    /// The detector is the default one: its generated tick runs, bit for bit the
    /// interpreter's.
    generated: bool,
    /// The tick of the first row (a flight recording's; 0 otherwise).
    first: Tick,
}

impl Ticker {
    fn new(detector: &Detector) -> Ticker {
        Ticker {
            state: detector.new_state(),
            inputs: Inputs::default(),
            out: Output::default(),
            records: Vec::new(),
            generated: crate::builtin::is_default(detector),
            first: 0,
        }
    }

    /// Starts where a flight recording started, when the trace is one: from its saved
    /// state (`state` metadata, hex) at its first tick (`first_tick`), as the fingertip
    /// did; otherwise from a fresh state at tick 0.
    fn start_from(
        &mut self,
        detector: &Detector,
        trace: &str,
        metadata: &[(String, String)],
    ) -> Result<(), ReplayError> {
        let meta = |key: &str| metadata.iter().find(|(k, _)| k == key).map(|(_, v)| v);
        if let Some(hex_state) = meta(STATE_KEY) {
            let saved_state = |reason: String| ReplayError::SavedState {
                trace: trace.to_string(),
                reason,
            };
            let bytes = hex::decode(hex_state)
                .map_err(|e| saved_state(format!("not hexadecimal bytes ({e})")))?;
            self.state = detector.restore(&bytes).map_err(|e| {
                saved_state(match e {
                    detector_core::StateError::Feature(k) => format!(
                        "{e}: feature `{}`",
                        detector.features().get(k).map_or("?", |n| n.as_str())
                    ),
                    e => e.to_string(),
                })
            })?;
        }
        if let Some(v) = meta(FIRST_TICK_KEY) {
            self.first = v.parse().map_err(|_| ReplayError::FirstTick {
                trace: trace.to_string(),
                value: v.clone(),
            })?;
        }
        Ok(())
    }

    /// One tick on row `row` with the channels `faults` withheld: channel `k`'s sample
    /// from `sample(k)` (0 when missing); levels raised are recorded with times from
    /// `time_of(row of the tick)` (negative before the first row).
    fn tick(
        &mut self,
        detector: &Detector,
        row: usize,
        faults: u32,
        sample: impl Fn(usize) -> Option<Signal>,
        time_of: impl Fn(i64) -> f64,
    ) {
        self.inputs.faults = faults;
        for (k, s) in self
            .inputs
            .samples
            .iter_mut()
            .enumerate()
            .take(detector.channels().len())
        {
            *s = sample(k).unwrap_or(Signal::ZERO);
        }
        let tick: &dyn DetectorTick = if self.generated {
            &crate::builtin::ApproachTick
        } else {
            detector
        };
        let now = self.first.wrapping_add(row as Tick);
        tick.tick_into(&mut self.state, now, &self.inputs, &mut self.out);
        // The row of a tick: an onset may come before a recording's first row.
        let first = self.first;
        let row_of = |tick: Tick| i64::from(tick.wrapping_sub(first) as i32);
        for d in &self.out.decisions {
            self.records.push(DecisionRecord {
                event: detector
                    .events()
                    .get(usize::from(d.event.0))
                    .map(|n| n.to_string())
                    .unwrap_or_default(),
                level: d.level.name(),
                confidence: d.confidence.to_f64(),
                onset_s: time_of(row_of(d.onset)),
                t_s: time_of(row_of(d.tick)),
            });
        }
    }
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
    /// naming the file line (comments counted): an unknown phase or truth label, a rate
    /// beyond 0.1 %, in either direction.
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
        for rate in [4950.0, 4990.0, 5010.0, 5050.0] {
            refused(&text(rate, 10, &[], &[]), &["Hz", "5000 Hz", "0.1 %"]);
        }
    }

    /// Each maximal run of rows with the same label is one labelled event, its onset the
    /// run's first row and its end the last: an event may follow another directly, and
    /// the same event may come back.
    #[test]
    fn every_run_of_a_label_is_one_event() {
        let truth = [
            "",
            "contact",
            "contact",
            "",
            "disturbance",
            "disturbance",
            "contact",
            "",
            "",
            "",
        ];
        let csv = text(5000.0, 10, &[], &truth);
        let reader = TraceReader::new(csv.as_bytes(), "run.csv").expect("header");
        let streamed = replay_stream(&approach(), reader, |_| {}).expect("runs");
        let got: Vec<(&str, f64, f64)> = streamed
            .labelled
            .iter()
            .map(|l| (l.event.as_str(), l.onset_s * 5000.0, l.end_s * 5000.0))
            .collect();
        let want = [
            ("contact", 1.0, 2.0),
            ("disturbance", 4.0, 5.0),
            ("contact", 6.0, 6.0),
        ];
        assert_eq!(got.len(), want.len());
        for ((e, on, end), (we, won, wend)) in got.iter().zip(want) {
            assert_eq!(*e, we);
            assert!(
                (on - won).abs() < 1e-9 && (end - wend).abs() < 1e-9,
                "{got:?}"
            );
        }
        assert_eq!(streamed.first_truth().map(|t| t.0), Some("contact".into()));
    }

    /// Within the tolerance, and with events labelled apart, the trace runs.
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

#[cfg(test)]
mod stream_tests {
    use super::*;
    use crate::sim::{self, Scenario, SimOptions};

    fn approach() -> Detector {
        let config = detector_build::Config::from_toml(crate::APPROACH_TOML).expect("parses");
        detector_build::build(&config).expect("builds")
    }

    /// A trace read row by row replays exactly as the same trace held in memory: the same
    /// levels at the same times, the same truth, every tick handed out.
    #[test]
    fn streamed_replay_equals_the_replay_in_memory() {
        let detector = approach();
        for scenario in [
            Scenario::ContactHard8,
            Scenario::LinkCollision2,
            Scenario::DisturbanceSmall5,
        ] {
            let trace = sim::simulate(
                &scenario,
                &SimOptions {
                    seed: 3,
                    randomize: true,
                    ..SimOptions::default()
                },
            )
            .expect("simulates");
            let whole = replay(&detector, &trace, |_, _, _| {}).expect("replays");
            let text = trace.to_csv();
            let reader = TraceReader::new(text.as_bytes(), "run.csv").expect("header");
            let mut ticks = 0;
            let streamed = replay_stream(&detector, reader, |_| ticks += 1).expect("streams");
            assert_eq!(ticks, trace.len());
            assert_eq!(streamed.rows, trace.len());
            assert_eq!(streamed.decisions.len(), whole.len(), "{scenario}");
            for (a, b) in streamed.decisions.iter().zip(&whole) {
                assert_eq!((&a.event, a.level), (&b.event, b.level), "{scenario}");
                assert!((a.t_s - b.t_s).abs() < 1e-9 && (a.onset_s - b.onset_s).abs() < 1e-9);
            }
            let truth = trace
                .truth_onset()
                .map(|(row, e)| (e.to_string(), trace.time()[row]));
            assert_eq!(streamed.first_truth(), truth);
        }
    }

    /// Several detectors replayed over one reading of a trace each give what their own
    /// replay gives, each tick handed out with its detector's index; a trace one of them
    /// refuses stops them all with that one's reason.
    #[test]
    fn detectors_replayed_together_each_replay_as_alone() {
        let approach = approach();
        let paper = detector_build::build(
            &detector_build::Config::from_toml(include_str!("../../configs/paper.toml"))
                .expect("parses"),
        )
        .expect("builds");
        let trace = sim::simulate(
            &Scenario::ContactSoft5,
            &SimOptions {
                seed: 9,
                randomize: true,
                ..SimOptions::default()
            },
        )
        .expect("simulates");
        let text = trace.to_csv();
        let reader = || TraceReader::new(text.as_bytes(), "run.csv").expect("header");
        // Each tick as a detector saw it: its row, phase, confidences and first feature.
        let digest = |tick: &StreamTick| {
            (
                tick.row,
                tick.state.phase().index(),
                tick.output.confidences.map(|c| c.to_bits()),
                tick.state.feature(0).map(|f| f.to_bits()),
            )
        };
        let detectors = [&approach, &paper, &approach];
        let mut seen = vec![Vec::new(); 3];
        let together = replay_stream_each(&detectors, reader(), |d, tick| {
            seen[d].push(digest(tick));
        })
        .expect("replays");
        assert!(seen.iter().all(|s| s.len() == trace.len()));
        assert_ne!(seen[0], seen[1], "two detectors, two digests");
        assert_eq!(together.len(), 3);
        for ((d, streamed), seen) in detectors.iter().zip(&together).zip(&seen) {
            let mut own = Vec::new();
            let alone = replay_stream(d, reader(), |tick| own.push(digest(tick))).expect("replays");
            assert_eq!(seen, &own);
            assert_eq!(streamed.decisions.len(), alone.decisions.len());
            for (a, b) in streamed.decisions.iter().zip(&alone.decisions) {
                assert_eq!((&a.event, a.level, a.t_s), (&b.event, b.level, b.t_s));
            }
            assert_eq!(
                (streamed.rows, streamed.span_s, &streamed.labelled),
                (alone.rows, alone.span_s, &alone.labelled)
            );
        }
        assert!(!together[0].decisions.is_empty());
        // A truth label one of the detectors does not know is refused, naming it and the file.
        let relabelled = text.replace(",contact\n", ",link_collision\n");
        assert_ne!(relabelled, text);
        let mut bus = detector_build::Config::from_toml(crate::APPROACH_TOML).expect("parses");
        bus.events.retain(|e| e.name != "link_collision");
        for phase in &mut bus.phases {
            phase.events.retain(|e| e != "link_collision");
        }
        for event in &mut bus.events {
            event.excludes.retain(|e| e != "link_collision");
        }
        let without = detector_build::build(&bus).expect("builds");
        let e = replay_stream_each(
            &[&approach, &without],
            TraceReader::new(relabelled.as_bytes(), "run.csv").expect("header"),
            |_, _| {},
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("link_collision") && e.contains("run.csv"), "{e}");
    }

    /// The default detector runs its generated tick, and that tick leaves the same state
    /// and output as the interpreter at every tick of a run of each kind; any other
    /// detector is interpreted.
    #[test]
    fn the_default_detector_runs_generated_and_bit_for_bit_interpreted() {
        let detector = approach();
        assert!(Ticker::new(&detector).generated);
        let paper = detector_build::Config::from_toml(include_str!("../../configs/paper.toml"))
            .expect("parses");
        assert!(!Ticker::new(&detector_build::build(&paper).expect("builds")).generated);
        for scenario in [
            Scenario::ContactSoft2,
            Scenario::LinkCollision2,
            Scenario::DisturbanceLarge5,
            Scenario::FreeMotion,
        ] {
            let opts = SimOptions {
                seed: 5,
                randomize: true,
                duration_s: (scenario == Scenario::FreeMotion).then_some(2.0),
                ..SimOptions::default()
            };
            let trace = sim::simulate(&scenario, &opts).expect("simulates");
            let mut ticks = Vec::new();
            let generated = replay(&detector, &trace, |_, state, out| {
                ticks.push((state.clone(), out.clone()));
            })
            .expect("replays");
            let mut interpreter = Ticker::new(&detector);
            interpreter.generated = false;
            let mut row = 0;
            let interpreted = replay_with(interpreter, &detector, &trace, |_, state, out| {
                assert_eq!(
                    ticks.get(row),
                    Some(&(state.clone(), out.clone())),
                    "{scenario} row {row}"
                );
                row += 1;
            })
            .expect("replays");
            assert_eq!(row, trace.len());
            assert_eq!(generated.len(), interpreted.len(), "{scenario}");
            assert!(
                !generated.is_empty() || scenario == Scenario::FreeMotion,
                "{scenario}"
            );
        }
    }

    /// A step off the detector's period, or a rate off by more than 0.1 % overall, stops a
    /// streamed replay with the line named.
    #[test]
    fn a_stream_off_the_period_is_refused() {
        let detector = approach();
        let header = "t,force_x,force_y,skin_accel,stress_rate,pos_err_x,pos_err_y,vel_des_x,vel_des_y,acc_des_x,acc_des_y\n";
        let row = |t: f64| format!("{t},0,0,0,0,0,0,0,0,0,0\n");
        let mut jump = String::from(header);
        for k in [0, 1, 2, 4, 5] {
            jump.push_str(&row(f64::from(k) * 0.0002));
        }
        let e = replay_stream(
            &detector,
            TraceReader::new(jump.as_bytes(), "j.csv").expect("header"),
            |_| {},
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("line 5") && e.contains("period"), "{e}");
        // 0.5 % slow, each step within 1 %: refused on the whole trace's rate.
        let mut slow = String::from(header);
        for k in 0..100 {
            slow.push_str(&row(f64::from(k) * 0.000201));
        }
        let e = replay_stream(
            &detector,
            TraceReader::new(slow.as_bytes(), "s.csv").expect("header"),
            |_| {},
        )
        .expect_err("refused")
        .to_string();
        assert!(e.contains("0.1 %"), "{e}");
    }
}
