//! Decoding candump logs (and live traffic) into the fingertips' confidences, events and
//! status, reporting every problem by line number without stopping.
//!
//! Problems: lines that are not frames, frames of the protocol with a wrong length, a bad
//! CRC or a value out of range, gaps and repetitions in the rolling counters of protected
//! messages and in the confidence stream's sequence numbers, and CAN error frames.
//! Frames with identifiers outside the protocol are counted as foreign, not reported.

use std::collections::HashMap;
use std::fmt;
use std::io::{self, BufRead, Write};
use std::path::Path;

use detector_core::{Level, Tick};
use fingertip_can::{
    ConfidenceMsg, Counter, DecodeError, EventMsg, Message, MessageKind, NodeId, StatusPage,
};

use super::CanToolError;
use super::candump::{LogFrame, parse_line};

/// How to decode and print.
#[derive(Clone, Debug)]
pub struct DecodeOptions {
    /// The detector rate in Hz, to turn ticks into seconds until a status frame tells
    /// the fingertip's own rate.
    pub tick_rate_hz: f64,
    /// Event names by index (from the configuration); `event<i>` where missing.
    pub event_names: Vec<String>,
    /// Only this node's frames, if set.
    pub node: Option<NodeId>,
    /// Print every confidence page (otherwise only events, status and problems).
    pub print_confidences: bool,
}

impl Default for DecodeOptions {
    fn default() -> Self {
        DecodeOptions {
            tick_rate_hz: 5000.0,
            event_names: Vec::new(),
            node: None,
            print_confidences: true,
        }
    }
}

impl DecodeOptions {
    /// The name of event `index`.
    pub fn event_name(&self, index: usize) -> String {
        self.event_names
            .get(index)
            .cloned()
            .unwrap_or_else(|| format!("event{index}"))
    }
}

/// A decoded frame of the protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// 1-based line (or frame number, live).
    pub line: usize,
    /// Timestamp in seconds, when known.
    pub time: Option<f64>,
    /// The node.
    pub node: NodeId,
    /// The message.
    pub message: Message,
}

/// A problem found in a log.
#[derive(Clone, Debug, PartialEq)]
pub enum Problem {
    /// The line is not a frame.
    Malformed {
        /// What was wrong.
        reason: String,
    },
    /// A frame of the protocol that does not decode (wrong length, bad CRC, value out of
    /// range).
    Invalid {
        /// The node of its identifier.
        node: NodeId,
        /// What was wrong.
        error: DecodeError,
    },
    /// A protected message's counter skipped values: frames were lost.
    CounterGap {
        /// The node.
        node: NodeId,
        /// The message.
        kind: MessageKind,
        /// The counter expected.
        expected: u8,
        /// The counter found.
        got: u8,
    },
    /// A protected message's counter did not advance: a repeated frame.
    CounterRepeated {
        /// The node.
        node: NodeId,
        /// The message.
        kind: MessageKind,
        /// The counter found again.
        counter: u8,
    },
    /// The confidence stream's sequence number skipped samples.
    SequenceGap {
        /// The node.
        node: NodeId,
        /// The sequence number expected (or the current one).
        expected: u8,
        /// The sequence number found.
        got: u8,
    },
    /// A CAN error frame.
    ErrorFrame,
    /// A remote frame for an identifier of the protocol, which uses none.
    Remote {
        /// The node.
        node: NodeId,
        /// The message.
        kind: MessageKind,
    },
    /// A CAN FD frame on an identifier of the protocol, whose frames are classic CAN.
    FdFrame {
        /// The node.
        node: NodeId,
        /// The message of the identifier.
        kind: MessageKind,
        /// Its data length.
        len: usize,
    },
    /// An event frame for an event the configuration does not have.
    UnknownEvent {
        /// The node.
        node: NodeId,
        /// The event's index.
        event: u8,
        /// How many events the configuration has.
        known: usize,
    },
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Malformed { reason } => write!(f, "malformed line: {reason}"),
            Problem::Invalid { node, error } => write!(f, "node {}: {error}", node.get()),
            Problem::CounterGap {
                node,
                kind,
                expected,
                got,
            } => write!(
                f,
                "node {}: {} counter gap: expected {expected}, got {got} ({} lost)",
                node.get(),
                kind.name(),
                got.wrapping_sub(*expected) & 0x0F
            ),
            Problem::CounterRepeated {
                node,
                kind,
                counter,
            } => write!(
                f,
                "node {}: {} counter repeated ({counter})",
                node.get(),
                kind.name()
            ),
            Problem::SequenceGap {
                node,
                expected,
                got,
            } => write!(
                f,
                "node {}: confidence stream sequence gap: expected {expected}, got {got}",
                node.get()
            ),
            Problem::ErrorFrame => write!(f, "CAN error frame"),
            Problem::Remote { node, kind } => {
                write!(f, "node {}: remote frame for {}", node.get(), kind.name())
            }
            Problem::FdFrame { node, kind, len } => write!(
                f,
                "node {}: a CAN FD frame ({len} bytes) on the identifier of {}, whose frames are classic CAN",
                node.get(),
                kind.name()
            ),
            Problem::UnknownEvent { node, event, known } => write!(
                f,
                "node {}: event {event}, but the configuration has {known} events",
                node.get()
            ),
        }
    }
}

/// A problem and the line it was found on.
#[derive(Clone, Debug, PartialEq)]
pub struct LineProblem {
    /// 1-based line (or frame number, live).
    pub line: usize,
    /// The problem.
    pub problem: Problem,
}

/// One thing found on a line, in line order.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// A decoded frame.
    Record(Record),
    /// A problem.
    Problem(LineProblem),
}

/// Per-node stream tracking.
#[derive(Clone, Copy, Debug, Default)]
struct StreamSeq {
    seq: u8,
    pages: u8,
}

/// A streaming decoder: feed it frames in order, get records and problems back.
#[derive(Debug, Default)]
pub struct Decoder {
    counters: HashMap<(NodeId, MessageKind), Counter>,
    streams: HashMap<NodeId, StreamSeq>,
    rates: HashMap<NodeId, f64>,
    uptimes: HashMap<NodeId, Tick>,
    /// Frames decoded or rejected that belong to the protocol.
    pub protocol_frames: usize,
    /// Frames with identifiers outside the protocol.
    pub foreign_frames: usize,
}

impl Decoder {
    /// A decoder that has seen nothing.
    pub fn new() -> Decoder {
        Decoder::default()
    }

    /// The detector rate of `node` (from its status), or `default`.
    pub fn tick_rate(&self, node: NodeId, default: f64) -> f64 {
        self.rates.get(&node).copied().unwrap_or(default)
    }

    /// The last uptime (ticks) `node` reported.
    pub fn uptime(&self, node: NodeId) -> Option<Tick> {
        self.uptimes.get(&node).copied()
    }

    /// Decodes one line of a log.
    pub fn push_line(&mut self, line_no: usize, line: &str, opts: &DecodeOptions) -> Vec<Item> {
        match parse_line(line_no, line) {
            Ok(None) => Vec::new(),
            Ok(Some(frame)) => self.push_frame(&frame, opts),
            Err(e) => vec![Item::Problem(LineProblem {
                line: line_no,
                problem: Problem::Malformed { reason: e.reason },
            })],
        }
    }

    /// Decodes one frame.
    pub fn push_frame(&mut self, f: &LogFrame, opts: &DecodeOptions) -> Vec<Item> {
        let mut out = Vec::new();
        let problem = |p: Problem| {
            Item::Problem(LineProblem {
                line: f.line,
                problem: p,
            })
        };
        if f.error {
            out.push(problem(Problem::ErrorFrame));
            return out;
        }
        let Some((kind, node)) = MessageKind::from_id(f.id) else {
            self.foreign_frames += 1;
            return out;
        };
        if opts.node.is_some_and(|n| n != node) {
            return out;
        }
        self.protocol_frames += 1;
        if f.fd {
            out.push(problem(Problem::FdFrame {
                node,
                kind,
                len: f.data.len(),
            }));
            return out;
        }
        if f.remote {
            out.push(problem(Problem::Remote { node, kind }));
            return out;
        }
        let message = match Message::decode(f.id, &f.data) {
            Ok((_, m)) => m,
            Err(error) => {
                out.push(problem(Problem::Invalid { node, error }));
                return out;
            }
        };
        if let Some(c) = message.counter()
            && let Some(last) = self.counters.insert((node, kind), c)
        {
            match last.delta_to(c) {
                1 => {}
                0 => out.push(problem(Problem::CounterRepeated {
                    node,
                    kind,
                    counter: c.get(),
                })),
                _ => out.push(problem(Problem::CounterGap {
                    node,
                    kind,
                    expected: last.next().get(),
                    got: c.get(),
                })),
            }
        }
        match message {
            Message::Event(e)
                if !opts.event_names.is_empty()
                    && usize::from(e.event.0) >= opts.event_names.len() =>
            {
                out.push(problem(Problem::UnknownEvent {
                    node,
                    event: e.event.0,
                    known: opts.event_names.len(),
                }));
            }
            Message::Confidence(m) => {
                let bit = 1u8 << m.page;
                let entry = self.streams.get(&node).copied();
                let next = match entry {
                    Some(s) if s.seq == m.seq && s.pages & bit == 0 => StreamSeq {
                        seq: s.seq,
                        pages: s.pages | bit,
                    },
                    Some(s) => {
                        if m.seq != s.seq.wrapping_add(1) {
                            out.push(problem(Problem::SequenceGap {
                                node,
                                expected: s.seq.wrapping_add(1),
                                got: m.seq,
                            }));
                        }
                        StreamSeq {
                            seq: m.seq,
                            pages: bit,
                        }
                    }
                    None => StreamSeq {
                        seq: m.seq,
                        pages: bit,
                    },
                };
                self.streams.insert(node, next);
            }
            Message::Status(StatusPage::Timing { tick_rate_hz, .. }) if tick_rate_hz > 0 => {
                self.rates.insert(node, f64::from(tick_rate_hz));
            }
            Message::Status(StatusPage::Health { uptime, .. }) => {
                self.uptimes.insert(node, uptime);
            }
            _ => {}
        }
        out.push(Item::Record(Record {
            line: f.line,
            time: f.time,
            node,
            message,
        }));
        out
    }

    /// One line of text for an item, as `fingertip decode` prints it; `None` for
    /// confidence pages when `opts.print_confidences` is off.
    pub fn describe(&self, item: &Item, opts: &DecodeOptions) -> Option<String> {
        match item {
            Item::Problem(p) => Some(format!("line {}: {}", p.line, p.problem)),
            Item::Record(r) => {
                let time = r
                    .time
                    .map(|t| format!("{t:.6}"))
                    .unwrap_or_else(|| "-".into());
                let head = format!("{time} node {:>2}", r.node.get());
                let rate = self.tick_rate(r.node, opts.tick_rate_hz);
                let body = match &r.message {
                    Message::Event(m) => describe_event(m, rate, opts),
                    Message::Confidence(m) => {
                        if !opts.print_confidences {
                            return None;
                        }
                        describe_confidences(m, opts)
                    }
                    Message::Status(p) => describe_status(p),
                    Message::Phase(m) => {
                        format!("phase     {} (sequence {})", m.phase, m.sequence)
                    }
                    Message::Context(m) => {
                        let v = m.vel_des.map(|r| f64::from(r) * 1e-4);
                        let a = m.acc_des.map(|r| f64::from(r) * 2e-3);
                        format!(
                            "context   vel_des ({:+.4}, {:+.4}) m/s  acc_des ({:+.3}, {:+.3}) m/s²",
                            v[0], v[1], a[0], a[1]
                        )
                    }
                    Message::TipState(m) => {
                        let p = m.pos_err.map(|r| f64::from(r) * 1e-3);
                        format!("tip state pos_err ({:+.3}, {:+.3}) mm", p[0], p[1])
                    }
                };
                Some(format!("{head}  {body}"))
            }
        }
    }
}

fn describe_event(m: &EventMsg, rate: f64, opts: &DecodeOptions) -> String {
    let level = match m.level {
        Level::Alert => "ALERT",
        Level::Confirm => "CONFIRM",
    };
    format!(
        "EVENT     {} {level} confidence {} tick {} onset {:.1} ms earlier",
        opts.event_name(usize::from(m.event.0)),
        m.confidence,
        m.tick,
        f64::from(m.onset_age) * 1000.0 / rate
    )
}

fn describe_confidences(m: &ConfidenceMsg, opts: &DecodeOptions) -> String {
    let mut s = format!("stream    seq {:3}", m.seq);
    for (k, c) in m.confidences.iter().enumerate() {
        if m.evaluated & (1 << k) != 0 {
            let e = 3 * usize::from(m.page) + k;
            let flag = if m.unjudgeable & (1 << k) != 0 {
                " (unjudgeable)"
            } else {
                ""
            };
            s.push_str(&format!("  {}={c}{flag}", opts.event_name(e)));
        }
    }
    s
}

fn describe_status(p: &StatusPage) -> String {
    match *p {
        StatusPage::Health {
            reset,
            faults,
            uptime,
            phase,
            phase_seq,
        } => {
            let names: Vec<&str> = fingertip_can::FaultFlags::NAMES
                .iter()
                .enumerate()
                .filter(|(i, _)| faults.0 & (1 << i) != 0)
                .map(|(_, n)| *n)
                .collect();
            let phase = phase
                .map(|p| format!("{p} (sequence {phase_seq})"))
                .unwrap_or_else(|| "none".into());
            format!(
                "status    uptime {uptime} ticks, phase {phase}, faults [{}], reset {}",
                names.join(" "),
                reset.name()
            )
        }
        StatusPage::Timing {
            overruns,
            worst_tick,
            tick_rate_hz,
            protocol,
        } => format!(
            "status    {tick_rate_hz} Hz, worst tick {:.1} µs, {overruns} overruns, protocol {protocol}",
            f64::from(worst_tick) / 10.0
        ),
        StatusPage::Link {
            stale_episodes,
            lost_frames,
            bus_errors,
        } => format!(
            "status    {stale_episodes} stale episodes, {lost_frames} lost frames, {bus_errors} bus errors"
        ),
        StatusPage::FrameRejects {
            wrong_length,
            unknown_id,
            bad_crc,
        } => format!(
            "status    rejected: {wrong_length} wrong length, {unknown_id} unknown id, {bad_crc} bad CRC"
        ),
        StatusPage::ContentRejects {
            sequence,
            phase_not_configured,
            out_of_range,
        } => format!(
            "status    rejected: {sequence} counter, {phase_not_configured} phase not configured, {out_of_range} out of range"
        ),
        StatusPage::Config {
            checksum,
            tx_dropped,
        } => format!("status    configuration 0x{checksum:08X}, {tx_dropped} frames not sent"),
    }
}

/// A whole decoded log.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DecodedLog {
    /// Records and problems in line order.
    pub items: Vec<Item>,
    /// Lines read.
    pub lines: usize,
    /// Frames of the protocol.
    pub protocol_frames: usize,
    /// Frames outside the protocol.
    pub foreign_frames: usize,
}

impl DecodedLog {
    /// The problems.
    pub fn problems(&self) -> impl Iterator<Item = &LineProblem> {
        self.items.iter().filter_map(|i| match i {
            Item::Problem(p) => Some(p),
            Item::Record(_) => None,
        })
    }

    /// The records.
    pub fn records(&self) -> impl Iterator<Item = &Record> {
        self.items.iter().filter_map(|i| match i {
            Item::Record(r) => Some(r),
            Item::Problem(_) => None,
        })
    }

    /// The event frames.
    pub fn events(&self) -> impl Iterator<Item = (&Record, &EventMsg)> {
        self.records().filter_map(|r| match &r.message {
            Message::Event(m) => Some((r, m)),
            _ => None,
        })
    }
}

/// Decodes a whole log from a reader, printing each item to `out` as it goes (pass
/// `io::sink()` for none). Read errors stop it; problems in the log do not.
pub fn decode_reader(
    reader: impl BufRead,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> io::Result<DecodedLog> {
    let mut dec = Decoder::new();
    let mut log = DecodedLog::default();
    for (i, line) in reader.lines().enumerate() {
        let line = line?;
        log.lines = i + 1;
        for item in dec.push_line(i + 1, &line, opts) {
            if let Some(text) = dec.describe(&item, opts) {
                writeln!(out, "{text}")?;
            }
            log.items.push(item);
        }
    }
    log.protocol_frames = dec.protocol_frames;
    log.foreign_frames = dec.foreign_frames;
    Ok(log)
}

/// [`decode_reader`] on a file, followed by a one-line summary on `out`.
pub fn decode_file(
    path: &Path,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> Result<DecodedLog, CanToolError> {
    let file = std::fs::File::open(path).map_err(|e| CanToolError::io(path, e))?;
    let log = decode_reader(io::BufReader::new(file), opts, out)
        .map_err(|e| CanToolError::io(path, e))?;
    write_summary(&log, out).map_err(|e| CanToolError::io(path, e))?;
    Ok(log)
}

/// One line: lines, frames, events, problems.
pub fn write_summary(log: &DecodedLog, out: &mut dyn Write) -> io::Result<()> {
    writeln!(
        out,
        "{} lines, {} fingertip frames, {} other frames, {} events, {} problems",
        log.lines,
        log.protocol_frames,
        log.foreign_frames,
        log.events().count(),
        log.problems().count()
    )
}

/// The confidence stream as CSV for plotting: `time,node,seq,event,confidence,unjudgeable`,
/// one row per evaluated event per page. Rows without a timestamp are written with an
/// empty time.
pub fn write_confidences_csv(
    log: &DecodedLog,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> io::Result<()> {
    writeln!(out, "time,node,seq,event,confidence,unjudgeable")?;
    for r in log.records() {
        if let Message::Confidence(m) = &r.message {
            for (k, c) in m.confidences.iter().enumerate() {
                if m.evaluated & (1 << k) == 0 {
                    continue;
                }
                let time = r.time.map(|t| format!("{t:.6}")).unwrap_or_default();
                writeln!(
                    out,
                    "{time},{},{},{},{:.6},{}",
                    r.node.get(),
                    m.seq,
                    opts.event_name(3 * usize::from(m.page) + k),
                    c.to_f64(),
                    u8::from(m.unjudgeable & (1 << k) != 0)
                )?;
            }
        }
    }
    Ok(())
}

/// The event frames as CSV: `time,node,event,level,confidence,tick,onset_age_s`.
pub fn write_events_csv(
    log: &DecodedLog,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> io::Result<()> {
    writeln!(out, "time,node,event,level,confidence,tick,onset_age_s")?;
    for (r, m) in log.events() {
        let time = r.time.map(|t| format!("{t:.6}")).unwrap_or_default();
        writeln!(
            out,
            "{time},{},{},{},{:.6},{},{:.6}",
            r.node.get(),
            opts.event_name(usize::from(m.event.0)),
            m.level.name(),
            m.confidence.to_f64(),
            m.tick,
            f64::from(m.onset_age) / opts.tick_rate_hz
        )?;
    }
    Ok(())
}
