//! Decoding candump logs (and live traffic) into the fingertips' confidences, events and
//! status, reporting every problem by line number without stopping.
//!
//! Problems: lines that are not frames, frames of the protocol with a wrong length, a bad
//! CRC or a value out of range, gaps and repetitions in the counters (every frame of the
//! protocol has one, per identifier) and in the classic stream's sample numbers, remote
//! frames, and CAN error frames. Frames with identifiers outside the protocol are counted
//! as foreign, not reported. CAN FD and classic frames are read alike: a message is known
//! by its identifier and its length.

use std::collections::HashMap;
use std::fmt;
use std::io::{self, BufRead, Write};
use std::path::Path;

use detector_core::{Level, MAX_EVENTS, Tick};
use fingertip_can::{
    Address, ContextGroup, ContextPart, ContextSlot, Counter, DecodeError, EventMsg, LevelState,
    Message, MessageKind, NodeId, StatusPage,
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
    /// Only this node's frames (and the context frames of its group), if set.
    pub node: Option<NodeId>,
    /// Print every stream sample (otherwise only events, status and problems).
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

    fn wants(&self, address: Address) -> bool {
        match (self.node, address) {
            (None, _) => true,
            (Some(n), Address::Node(m)) => n == m,
            (Some(n), Address::Group(g)) => ContextGroup::of(n) == g,
        }
    }
}

/// A decoded frame of the protocol.
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// 1-based line (or frame number, live).
    pub line: usize,
    /// Timestamp in seconds, when known.
    pub time: Option<f64>,
    /// The node (or, for a broadcast context frame, the group) of its identifier.
    pub address: Address,
    /// The message.
    pub message: Message,
}

/// One event's value in a stream sample, whichever the bus format.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamValue {
    /// The sample's number (the CAN FD frame's counter, the classic page's `Sample`).
    pub sample: u8,
    /// The event.
    pub event: usize,
    /// Its confidence, 0..=1.
    pub confidence: f64,
    /// Its level since the last sample.
    pub level: LevelState,
    /// It cannot be judged.
    pub unjudgeable: bool,
}

impl Record {
    /// The node, for a frame a fingertip sent or one addressed to one fingertip.
    pub fn node(&self) -> Option<NodeId> {
        self.address.node()
    }

    /// The evaluated events' values of a stream frame (empty for other messages).
    pub fn stream_values(&self) -> Vec<StreamValue> {
        match &self.message {
            Message::Stream(m) => (0..MAX_EVENTS)
                .filter(|e| m.evaluated & (1 << e) != 0)
                .map(|e| StreamValue {
                    sample: m.counter.get(),
                    event: e,
                    confidence: m.confidences[e].to_f64(),
                    level: m.levels[e],
                    unjudgeable: m.unjudgeable & (1 << e) != 0,
                })
                .collect(),
            Message::StreamPage(p) => vec![StreamValue {
                sample: p.sample,
                event: usize::from(p.event.0),
                confidence: p.confidence.to_f64(),
                level: p.level,
                unjudgeable: p.unjudgeable,
            }],
            _ => Vec::new(),
        }
    }
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
        /// The address of its identifier.
        address: Address,
        /// What was wrong.
        error: DecodeError,
    },
    /// A counter skipped values: frames were lost.
    CounterGap {
        /// The address of the identifier.
        address: Address,
        /// The message.
        kind: MessageKind,
        /// The counter expected.
        expected: u8,
        /// The counter found.
        got: u8,
    },
    /// A counter did not advance: a repeated frame.
    CounterRepeated {
        /// The address of the identifier.
        address: Address,
        /// The message.
        kind: MessageKind,
        /// The counter found again.
        counter: u8,
    },
    /// The classic stream's sample number skipped samples.
    SequenceGap {
        /// The node.
        node: NodeId,
        /// The sample number expected (or the current one).
        expected: u8,
        /// The sample number found.
        got: u8,
    },
    /// A CAN error frame.
    ErrorFrame,
    /// A remote frame for an identifier of the protocol, which uses none.
    Remote {
        /// The address of the identifier.
        address: Address,
        /// The message.
        kind: MessageKind,
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

/// `node 3` or `group 1`, as problems and records print an address.
pub fn address_text(a: Address) -> String {
    match a {
        Address::Node(n) => format!("node {}", n.get()),
        Address::Group(g) => format!("group {}", g.get()),
    }
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Malformed { reason } => write!(f, "malformed line: {reason}"),
            Problem::Invalid { address, error } => write!(f, "{}: {error}", address_text(*address)),
            Problem::CounterGap {
                address,
                kind,
                expected,
                got,
            } => write!(
                f,
                "{}: {} counter gap: expected {expected}, got {got} ({} lost)",
                address_text(*address),
                kind.name(),
                got.wrapping_sub(*expected)
            ),
            Problem::CounterRepeated {
                address,
                kind,
                counter,
            } => write!(
                f,
                "{}: {} counter repeated ({counter})",
                address_text(*address),
                kind.name()
            ),
            Problem::SequenceGap {
                node,
                expected,
                got,
            } => write!(
                f,
                "node {}: stream sample gap: expected {expected}, got {got}",
                node.get()
            ),
            Problem::ErrorFrame => write!(f, "CAN error frame"),
            Problem::Remote { address, kind } => {
                write!(
                    f,
                    "{}: remote frame for {}",
                    address_text(*address),
                    kind.name()
                )
            }
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

/// A streaming decoder: feed it frames in order, get records and problems back.
#[derive(Debug, Default)]
pub struct Decoder {
    counters: HashMap<u16, Counter>,
    samples: HashMap<NodeId, u8>,
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
        let Some((kind, address)) = MessageKind::from_id(f.id) else {
            self.foreign_frames += 1;
            return out;
        };
        if !opts.wants(address) {
            return out;
        }
        self.protocol_frames += 1;
        if f.remote {
            out.push(problem(Problem::Remote { address, kind }));
            return out;
        }
        let message = match Message::decode(f.id, &f.data) {
            Ok((_, m)) => m,
            Err(error) => {
                out.push(problem(Problem::Invalid { address, error }));
                return out;
            }
        };
        let c = message.counter();
        if let Some(last) = self.counters.insert(kind.raw_id_of(address.index()), c) {
            match last.delta_to(c) {
                1 => {}
                0 => out.push(problem(Problem::CounterRepeated {
                    address,
                    kind,
                    counter: c.get(),
                })),
                _ => out.push(problem(Problem::CounterGap {
                    address,
                    kind,
                    expected: last.next().get(),
                    got: c.get(),
                })),
            }
        }
        let node = address.node();
        match (message, node) {
            (Message::Event(e), Some(node))
                if !opts.event_names.is_empty()
                    && usize::from(e.event.0) >= opts.event_names.len() =>
            {
                out.push(problem(Problem::UnknownEvent {
                    node,
                    event: e.event.0,
                    known: opts.event_names.len(),
                }));
            }
            (Message::StreamPage(p), Some(node)) => {
                // Pages of one sample share its number; a new number must be the next.
                if let Some(last) = self.samples.insert(node, p.sample)
                    && p.sample != last
                    && p.sample != last.wrapping_add(1)
                {
                    out.push(problem(Problem::SequenceGap {
                        node,
                        expected: last.wrapping_add(1),
                        got: p.sample,
                    }));
                }
            }
            (Message::Status(s), Some(node)) => match s.page {
                StatusPage::Identity { tick_rate_hz, .. } if tick_rate_hz > 0 => {
                    self.rates.insert(node, f64::from(tick_rate_hz));
                }
                StatusPage::Uptime { uptime } => {
                    self.uptimes.insert(node, uptime);
                }
                _ => {}
            },
            _ => {}
        }
        out.push(Item::Record(Record {
            line: f.line,
            time: f.time,
            address,
            message,
        }));
        out
    }

    /// One line of text for an item, as `fingertip decode` prints it; `None` for stream
    /// frames when `opts.print_confidences` is off.
    pub fn describe(&self, item: &Item, opts: &DecodeOptions) -> Option<String> {
        match item {
            Item::Problem(p) => Some(format!("line {}: {}", p.line, p.problem)),
            Item::Record(r) => {
                let time = r
                    .time
                    .map(|t| format!("{t:.6}"))
                    .unwrap_or_else(|| "-".into());
                let head = match r.address {
                    Address::Node(n) => format!("{time} node {:>2}", n.get()),
                    Address::Group(g) => format!("{time} group {}", g.get()),
                };
                let rate = r
                    .node()
                    .map_or(opts.tick_rate_hz, |n| self.tick_rate(n, opts.tick_rate_hz));
                let body = match &r.message {
                    Message::Event(m) => describe_event(m, rate, opts),
                    Message::Stream(_) | Message::StreamPage(_) => {
                        if !opts.print_confidences {
                            return None;
                        }
                        describe_stream(r, opts)
                    }
                    Message::Status(p) => describe_status(&p.page),
                    Message::Phase(m) => {
                        format!("phase     {} (sequence {})", m.phase, m.sequence)
                    }
                    Message::Context(m) => {
                        let Address::Group(g) = r.address else {
                            return None;
                        };
                        let mut s = format!("context   t {} us", m.time_us);
                        for (k, slot) in m.slots.iter().enumerate() {
                            let Some(n) = g.node(k) else { continue };
                            if opts.node.is_some_and(|o| o != n) {
                                continue;
                            }
                            match slot {
                                Some(slot) => {
                                    s.push_str(&format!(" | {}: {}", n.get(), describe_slot(slot)))
                                }
                                None => s.push_str(&format!(" | {}: empty", n.get())),
                            }
                        }
                        s
                    }
                    Message::ContextPart(m) => {
                        let [x, y] = m.value.map(|v| f64::from(v) * m.part.scale());
                        match m.part {
                            ContextPart::Velocity => {
                                format!("context   vel_des ({x:+.4}, {y:+.4}) m/s")
                            }
                            ContextPart::Acceleration => {
                                format!("context   acc_des ({x:+.3}, {y:+.3}) m/s²")
                            }
                            ContextPart::PositionError => {
                                format!("context   pos_err ({:+.3}, {:+.3}) mm", 1e3 * x, 1e3 * y)
                            }
                        }
                    }
                };
                Some(format!("{head}  {body}"))
            }
        }
    }
}

fn describe_slot(s: &ContextSlot) -> String {
    let v = s.vel_des.map(|r| f64::from(r) * ContextSlot::VEL_SCALE);
    let a = s.acc_des.map(|r| f64::from(r) * ContextSlot::ACC_SCALE);
    let p = s
        .pos_err
        .map(|r| f64::from(r) * ContextSlot::POS_SCALE * 1e3);
    format!(
        "vel_des ({:+.4}, {:+.4}) m/s acc_des ({:+.3}, {:+.3}) m/s² pos_err ({:+.3}, {:+.3}) mm",
        v[0], v[1], a[0], a[1], p[0], p[1]
    )
}

fn describe_event(m: &EventMsg, rate: f64, opts: &DecodeOptions) -> String {
    let level = match m.level {
        Level::Alert => "ALERT",
        Level::Confirm => "CONFIRM",
    };
    format!(
        "EVENT     {} {level} tick {} onset {:.1} ms earlier",
        opts.event_name(usize::from(m.event.0)),
        m.tick,
        f64::from(m.onset_age) * 1000.0 / rate
    )
}

fn describe_stream(r: &Record, opts: &DecodeOptions) -> String {
    let values = r.stream_values();
    let sample = values.first().map_or(0, |v| v.sample);
    let mut s = format!("stream    sample {sample:3}");
    for v in values {
        let flag = if v.unjudgeable { " unjudgeable" } else { "" };
        let level = match v.level {
            LevelState::None => String::new(),
            l => format!(" {}", l.name()),
        };
        s.push_str(&format!(
            "  {}={:.5}{level}{flag}",
            opts.event_name(v.event),
            v.confidence
        ));
    }
    s
}

fn describe_status(p: &StatusPage) -> String {
    match *p {
        StatusPage::Health {
            reset,
            phase,
            faults,
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
                "status    phase {phase}, faults [{}], reset {}",
                names.join(" "),
                reset.name()
            )
        }
        StatusPage::Uptime { uptime } => format!("status    uptime {uptime} ticks"),
        StatusPage::Identity {
            tick_rate_hz,
            protocol,
            format,
            node_source,
        } => format!(
            "status    {tick_rate_hz} Hz, protocol {protocol}, {}, node id from {}",
            format.name(),
            node_source.name()
        ),
        StatusPage::Lateness { worst, late_ticks } => format!(
            "status    worst lateness {:.1} µs, {late_ticks} late ticks",
            f64::from(worst) / 10.0
        ),
        StatusPage::Compute {
            worst_tick,
            lost_scans,
        } => format!(
            "status    worst tick {:.1} µs, {lost_scans} scans lost",
            f64::from(worst_tick) / 10.0
        ),
        StatusPage::Link {
            stale_episodes,
            lost_frames,
        } => format!("status    {stale_episodes} stale episodes, {lost_frames} lost frames"),
        StatusPage::Bus {
            bus_errors,
            tx_dropped,
        } => format!("status    {bus_errors} bus errors, {tx_dropped} frames not sent"),
        StatusPage::RejectsFrame {
            wrong_length,
            bad_crc,
        } => format!("status    rejected: {wrong_length} wrong length, {bad_crc} bad CRC"),
        StatusPage::RejectsContent {
            sequence,
            out_of_range,
        } => format!("status    rejected: {sequence} repeated or old, {out_of_range} out of range"),
        StatusPage::RejectsRoute {
            unknown_id,
            phase_not_configured,
        } => format!(
            "status    rejected: {unknown_id} unknown id, {phase_not_configured} phase not configured"
        ),
        StatusPage::Config { checksum } => format!("status    configuration 0x{checksum:08X}"),
        StatusPage::Firmware { version, mode } => format!(
            "status    firmware {}.{}.{}, detector {}",
            version[0],
            version[1],
            version[2],
            mode.name()
        ),
        StatusPage::Build { hash } => format!("status    build {hash:08x}"),
        StatusPage::DetectorName { part, bytes } => {
            let text: String = bytes
                .iter()
                .take_while(|&&b| b != 0)
                .map(|&b| char::from(b))
                .collect();
            format!("status    detector name, bytes {}..: {text:?}", 4 * part)
        }
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

/// The confidence stream as CSV for plotting:
/// `time,node,sample,event,confidence,level,unjudgeable`, one row per evaluated event per
/// sample. Rows without a timestamp are written with an empty time.
pub fn write_confidences_csv(
    log: &DecodedLog,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> io::Result<()> {
    writeln!(out, "time,node,sample,event,confidence,level,unjudgeable")?;
    for r in log.records() {
        let Some(node) = r.node() else { continue };
        for v in r.stream_values() {
            let time = r.time.map(|t| format!("{t:.6}")).unwrap_or_default();
            writeln!(
                out,
                "{time},{},{},{},{:.6},{},{}",
                node.get(),
                v.sample,
                opts.event_name(v.event),
                v.confidence,
                v.level.name(),
                u8::from(v.unjudgeable)
            )?;
        }
    }
    Ok(())
}

/// The event frames as CSV: `time,node,event,level,tick,onset_age_s`.
pub fn write_events_csv(
    log: &DecodedLog,
    opts: &DecodeOptions,
    out: &mut dyn Write,
) -> io::Result<()> {
    writeln!(out, "time,node,event,level,tick,onset_age_s")?;
    for (r, m) in log.events() {
        let time = r.time.map(|t| format!("{t:.6}")).unwrap_or_default();
        writeln!(
            out,
            "{time},{},{},{},{},{:.6}",
            r.address.index(),
            opts.event_name(usize::from(m.event.0)),
            m.level.name(),
            m.tick,
            f64::from(m.onset_age) / opts.tick_rate_hz
        )?;
    }
    Ok(())
}
