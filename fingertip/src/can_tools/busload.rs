//! Worst-case bus load and event-frame latency of the fingertip protocol, on CAN FD (the
//! default) or classic CAN.
//!
//! Classic frame length: a data frame with a standard identifier and `n` data bytes is
//! `47 + 8n` bits including the 3-bit interframe space, of which `34 + 8n` (start of frame
//! to CRC) are subject to bit stuffing, worst case one stuff bit per 4 bits after the
//! first: `47 + 8n + ⌊(34 + 8n − 1)/4⌋` bits (135 for 8 bytes).
//!
//! CAN FD frame length (ISO 11898-1:2015, standard identifier, bit-rate switching), in two
//! phases:
//! - at the arbitration rate: start of frame, identifier, RRS, IDE, FDF, res and BRS (17
//!   bits, up to 4 stuff bits), then the CRC delimiter, ACK, ACK delimiter, end of frame and
//!   interframe space (13 bits): 34 bits;
//! - at the data rate: ESI, DLC and data (`5 + 8n` bits, up to `⌊(5 + 8n)/4⌋` stuff bits:
//!   the dynamic stuffing runs from the start of frame to the end of the data, at most
//!   `⌊(21 + 8n)/4⌋` bits in all, 4 of them in the arbitration phase), the stuff count (4),
//!   the CRC (17 bits up to 16 data bytes, 21 above) and its fixed stuff bits (6 or 7).
//!
//! Both delimiters where the rate switches are counted at the slower rate. 64 bytes at
//! 1 and 5 Mbit/s: 34 µs + 678 bits / 5 Mbit/s = 169.6 µs; 8 bytes: 56.6 µs.
//!
//! Load: every message's worst-case frame time times its rate, over one second. Event
//! frames are sporadic: the load counts an assumed worst-case rate per fingertip.
//!
//! Latency: response-time analysis for non-preemptive fixed-priority CAN (the analysis of
//! Tindell, as revised by Davis, Burns, Bril and Lukkien, 2007). An event frame is queued
//! when its tick ends; it waits for at most one lower-priority frame already on the bus
//! (blocking `B`, the longest frame of the protocol), then for every higher-priority frame
//! queued meanwhile: the event frames of fingertips with lower node ids and the earlier
//! frames of its own burst (one tick can raise several levels). Two cases: every fingertip
//! with one event frame at a time, and every fingertip queueing a full burst at once.
//! Error frames and retransmissions are not modelled, nor is traffic with identifiers
//! below the protocol's.

use std::fmt;
use std::io::{self, Write};

use fingertip_can::{BusFormat, ContextGroup, ContextPart, Direction, MessageKind};

/// The worst-case length of a frame: bits at the arbitration rate and at the data rate
/// (0 for a classic frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameBits {
    /// Bits at the nominal (arbitration) rate, stuff bits and interframe space included.
    pub nominal: u32,
    /// Bits at the data rate (CAN FD with bit-rate switching), stuff bits included.
    pub data: u32,
}

impl FrameBits {
    /// Its time on the bus, µs.
    pub fn micros(&self, bitrate: u32, data_bitrate: u32) -> f64 {
        1e6 * (f64::from(self.nominal) / f64::from(bitrate)
            + f64::from(self.data) / f64::from(data_bitrate.max(1)))
    }
}

/// Worst-case length of a classic CAN data frame with a standard identifier and `n` data
/// bytes (at most 8), with bit stuffing and the interframe space.
pub const fn classic_frame_bits(n: usize) -> FrameBits {
    let n = if n > 8 { 8 } else { n } as u32;
    FrameBits {
        nominal: 47 + 8 * n + (34 + 8 * n - 1) / 4,
        data: 0,
    }
}

/// Worst-case length of a CAN FD data frame with a standard identifier, bit-rate
/// switching and `n` data bytes (at most 64).
pub const fn fd_frame_bits(n: usize) -> FrameBits {
    let n = if n > 64 { 64 } else { n } as u32;
    let (crc, fixed_stuff) = if n > 16 { (21, 7) } else { (17, 6) };
    FrameBits {
        nominal: 17 + 4 + 13,
        data: 5 + 8 * n + (5 + 8 * n) / 4 + 4 + crc + fixed_stuff,
    }
}

/// The traffic to analyse. Rates are per fingertip.
#[derive(Clone, Debug, PartialEq)]
pub struct BusConfig {
    /// The bus format.
    pub format: BusFormat,
    /// Nominal (arbitration) bit rate in bit/s.
    pub bitrate: u32,
    /// Data-phase bit rate in bit/s (CAN FD; ignored on classic CAN).
    pub data_bitrate: u32,
    /// Fingertips on the bus, 1..=15.
    pub fingertips: u32,
    /// Detector rate in Hz.
    pub tick_rate_hz: f64,
    /// Ticks per confidence-stream sample.
    pub stream_decimation: u32,
    /// Most events in one phase (the classic stream's pages per sample), 1..=8.
    pub events_per_phase: u32,
    /// Heartbeat period in ms (two status frames per period).
    pub heartbeat_ms: f64,
    /// Assumed worst-case event frames per second per fingertip (sporadic).
    pub event_frames_per_s: f64,
    /// Most event frames one fingertip queues at once; the core raises at most two levels
    /// per event per tick, so `2 · events_per_phase` is the worst case.
    pub event_burst: u32,
    /// Control cycles per second: the context the controller sends each fingertip (one
    /// broadcast frame per group of five on CAN FD, three frames per fingertip on classic
    /// CAN).
    pub context_hz: f64,
    /// Phase frames per second the controller sends each fingertip.
    pub phase_hz: f64,
}

impl Default for BusConfig {
    /// The defaults: CAN FD at 1 and 5 Mbit/s, one fingertip at 5 kHz, the default stream
    /// decimation (20: 250 samples/s) and heartbeat (50 ms), the paper's three events per
    /// phase, 50 event frames/s assumed, context at 1 kHz, phase at 50 Hz.
    fn default() -> Self {
        BusConfig {
            format: BusFormat::Fd,
            bitrate: 1_000_000,
            data_bitrate: 5_000_000,
            fingertips: 1,
            tick_rate_hz: 5000.0,
            stream_decimation: u32::from(fingertip_can::DEFAULT_STREAM_DECIMATION),
            events_per_phase: 3,
            heartbeat_ms: f64::from(fingertip_can::DEFAULT_HEARTBEAT_MS),
            event_frames_per_s: 50.0,
            event_burst: 6,
            context_hz: 1000.0,
            phase_hz: 50.0,
        }
    }
}

impl BusConfig {
    /// The defaults for `fingertips` fingertips.
    pub fn with_fingertips(fingertips: u32) -> BusConfig {
        BusConfig {
            fingertips,
            ..BusConfig::default()
        }
    }

    /// The same traffic on classic CAN at the same nominal rate.
    pub fn classic(&self) -> BusConfig {
        BusConfig {
            format: BusFormat::Classic,
            ..self.clone()
        }
    }

    /// The worst-case frame of `kind` on this bus.
    pub fn frame_bits(&self, kind: MessageKind) -> FrameBits {
        match self.format {
            BusFormat::Fd => fd_frame_bits(kind.data_len()),
            BusFormat::Classic => classic_frame_bits(kind.data_len()),
        }
    }

    /// Its time on the bus, µs.
    pub fn frame_us(&self, kind: MessageKind) -> f64 {
        self.frame_bits(kind)
            .micros(self.bitrate, self.data_bitrate)
    }

    /// Context groups on the bus (CAN FD: one broadcast frame per group per cycle).
    pub fn groups(&self) -> u32 {
        self.fingertips.div_ceil(ContextGroup::SLOTS as u32)
    }

    /// Frames of `kind` per second, all fingertips together.
    pub fn frames_per_s(&self, kind: MessageKind) -> f64 {
        let n = f64::from(self.fingertips);
        let samples = self.tick_rate_hz / f64::from(self.stream_decimation);
        match kind {
            MessageKind::Event => n * self.event_frames_per_s,
            MessageKind::Context => f64::from(self.groups()) * self.context_hz,
            MessageKind::ContextPart => n * ContextPart::ALL.len() as f64 * self.context_hz,
            MessageKind::Phase => n * self.phase_hz,
            MessageKind::Stream => n * samples,
            MessageKind::StreamPage => n * samples * f64::from(self.events_per_phase),
            MessageKind::Status => n * 2.0 * 1000.0 / self.heartbeat_ms,
        }
    }

    /// The messages this bus carries, in priority order.
    pub fn kinds(&self) -> impl Iterator<Item = MessageKind> + '_ {
        MessageKind::ALL
            .into_iter()
            .filter(|k| k.carried_by(self.format))
    }
}

/// The load the whole bus may have, both directions, worst case, for `fingertips`: 35 %
/// up to five fingertips (one hand), 70 % up to ten; `None` above.
pub fn load_target(fingertips: u32) -> Option<f64> {
    match fingertips {
        0..=5 => Some(0.35),
        6..=10 => Some(0.70),
        _ => None,
    }
}

/// The worst-case event-frame latency the protocol aims at, µs.
pub const LATENCY_TARGET_US: f64 = 500.0;

/// A parameter is out of its range.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BusError {
    /// A parameter is out of its range.
    #[error("{name} = {} is out of range ({rule})", crate::readable(*value))]
    Parameter {
        /// The parameter.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The rule.
        rule: &'static str,
    },
    /// The event frames' response time does not converge within their burst interval:
    /// the bus is overloaded at their priority.
    #[error("event frames are not schedulable: their response time exceeds {interval_us:.0} µs")]
    Unschedulable {
        /// The burst interval the response time exceeded.
        interval_us: f64,
    },
}

/// One message's share of the bus.
#[derive(Clone, Debug, PartialEq)]
pub struct MessageLoad {
    /// The message.
    pub kind: MessageKind,
    /// Worst-case frame length.
    pub frame_bits: FrameBits,
    /// Worst-case time of one frame on the bus, µs.
    pub frame_us: f64,
    /// Frames per second, all fingertips together.
    pub frames_per_s: f64,
    /// Share of the bus time, 0..
    pub load: f64,
}

/// The worst-case event-frame latency on the bus, from queueing to the end of
/// transmission.
#[derive(Clone, Debug, PartialEq)]
pub struct EventLatency {
    /// Time of the longest frame of the protocol (the blocking), µs.
    pub blocking_us: f64,
    /// Every fingertip with one event frame at a time: the lowest-priority node's frame,
    /// µs.
    pub single_us: f64,
    /// Every fingertip queueing a full burst at once: the last frame of the
    /// lowest-priority node's burst, µs.
    pub burst_us: f64,
}

/// The analysis.
#[derive(Clone, Debug, PartialEq)]
pub struct BusReport {
    /// Per message, in priority order.
    pub messages: Vec<MessageLoad>,
    /// Frames per second sent by the fingertips.
    pub fingertip_frames_per_s: f64,
    /// Load of the fingertips' frames.
    pub fingertip_load: f64,
    /// Frames per second sent by the controller.
    pub controller_frames_per_s: f64,
    /// Load of the controller's frames.
    pub controller_load: f64,
    /// Load of everything.
    pub total_load: f64,
    /// Event-frame latency.
    pub latency: EventLatency,
}

impl BusReport {
    /// The highest control-cycle rate that keeps the total load at or under `limit` with
    /// everything else unchanged; 0 if nothing is left.
    pub fn max_context_hz(&self, cfg: &BusConfig, limit: f64) -> f64 {
        let context =
            |k: &MessageKind| matches!(k, MessageKind::Context | MessageKind::ContextPart);
        let other: f64 = self
            .messages
            .iter()
            .filter(|m| !context(&m.kind))
            .map(|m| m.load)
            .sum();
        // Bus time per second of one cycle per second.
        let per_hz: f64 = self
            .messages
            .iter()
            .filter(|m| context(&m.kind))
            .map(|m| m.frame_us * 1e-6 * m.frames_per_s / cfg.context_hz.max(f64::MIN_POSITIVE))
            .sum();
        if per_hz <= 0.0 {
            return 0.0;
        }
        ((limit - other) / per_hz).max(0.0)
    }
}

/// The most frames per second one kind of message can have on any bus: a CAN FD frame
/// takes at least 34 µs at 1 Mbit/s arbitration, so about 30,000 frames fill the bus.
const MAX_FRAME_RATE: f64 = 30_000.0;

fn check(name: &'static str, value: f64, ok: bool, rule: &'static str) -> Result<(), BusError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(BusError::Parameter { name, value, rule })
    }
}

/// Analyses the traffic of `cfg`.
pub fn analyse(cfg: &BusConfig) -> Result<BusReport, BusError> {
    let f = |v: u32| f64::from(v);
    check(
        "bitrate",
        f(cfg.bitrate),
        (10_000..=1_000_000).contains(&cfg.bitrate),
        "10 kbit/s to 1 Mbit/s",
    )?;
    if cfg.format == BusFormat::Fd {
        check(
            "data_bitrate",
            f(cfg.data_bitrate),
            cfg.data_bitrate >= cfg.bitrate && cfg.data_bitrate <= 8_000_000,
            "the arbitration rate to 8 Mbit/s",
        )?;
    }
    check(
        "fingertips",
        f(cfg.fingertips),
        (1..=15).contains(&cfg.fingertips),
        "1..=15",
    )?;
    check(
        "tick_rate_hz",
        cfg.tick_rate_hz,
        cfg.tick_rate_hz > 0.0 && cfg.tick_rate_hz <= 50_000.0,
        "above 0, at most the detector's 50 kHz",
    )?;
    check(
        "stream_decimation",
        f(cfg.stream_decimation),
        cfg.stream_decimation >= 1,
        "at least 1",
    )?;
    check(
        "events_per_phase",
        f(cfg.events_per_phase),
        (1..=8).contains(&cfg.events_per_phase),
        "1..=8",
    )?;
    check(
        "heartbeat_ms",
        cfg.heartbeat_ms,
        cfg.heartbeat_ms >= 1.0 && cfg.heartbeat_ms <= 3.6e6,
        "1 ms to 1 hour",
    )?;
    check(
        "event_burst",
        f(cfg.event_burst),
        (1..=16).contains(&cfg.event_burst),
        "1..=16",
    )?;
    check(
        "event_frames_per_s",
        cfg.event_frames_per_s,
        cfg.event_frames_per_s > 0.0 && cfg.event_frames_per_s <= MAX_FRAME_RATE,
        "above 0, at most 30,000 frames/s (more than a CAN bus carries)",
    )?;
    for (name, v) in [("context_hz", cfg.context_hz), ("phase_hz", cfg.phase_hz)] {
        check(
            name,
            v,
            (0.0..=MAX_FRAME_RATE).contains(&v),
            "0 to 30,000 frames/s (more than a CAN bus carries)",
        )?;
    }

    let messages: Vec<MessageLoad> = cfg
        .kinds()
        .map(|kind| {
            let frame_us = cfg.frame_us(kind);
            let frames_per_s = cfg.frames_per_s(kind);
            MessageLoad {
                kind,
                frame_bits: cfg.frame_bits(kind),
                frame_us,
                frames_per_s,
                load: frames_per_s * frame_us * 1e-6,
            }
        })
        .collect();
    let sum = |dir: Direction, field: fn(&MessageLoad) -> f64| -> f64 {
        messages
            .iter()
            .filter(|m| m.kind.direction() == dir)
            .map(field)
            .sum()
    };
    let fingertip_load = sum(Direction::FromFingertip, |m| m.load);
    let controller_load = sum(Direction::ToFingertip, |m| m.load);
    Ok(BusReport {
        fingertip_frames_per_s: sum(Direction::FromFingertip, |m| m.frames_per_s),
        fingertip_load,
        controller_frames_per_s: sum(Direction::ToFingertip, |m| m.frames_per_s),
        controller_load,
        total_load: fingertip_load + controller_load,
        latency: event_latency(cfg)?,
        messages,
    })
}

/// Response time of the last frame of a burst of `burst` event frames from the
/// lowest-priority fingertip, every fingertip bursting `burst` frames at most every
/// `interval_s`.
fn response_time_us(cfg: &BusConfig, burst: u32, interval_s: f64) -> Result<f64, BusError> {
    let c = cfg.frame_us(MessageKind::Event);
    let b = blocking_us(cfg);
    let bit_us = 1e6 / f64::from(cfg.bitrate);
    let interval_us = interval_s * 1e6;
    let higher = f64::from(cfg.fingertips - 1);
    let own = f64::from(burst - 1) * c;
    let mut w = b + own;
    for _ in 0..1000 {
        let bursts = ((w + bit_us) / interval_us).ceil();
        let next = b + own + higher * bursts * f64::from(burst) * c;
        if next + c > interval_us {
            return Err(BusError::Unschedulable { interval_us });
        }
        if (next - w).abs() < 1e-9 {
            return Ok(next + c);
        }
        w = next;
    }
    Err(BusError::Unschedulable { interval_us })
}

/// The longest frame of the protocol on this bus, µs: any may be on the bus when an event
/// frame is queued.
fn blocking_us(cfg: &BusConfig) -> f64 {
    cfg.kinds().map(|k| cfg.frame_us(k)).fold(0.0, f64::max)
}

fn event_latency(cfg: &BusConfig) -> Result<EventLatency, BusError> {
    Ok(EventLatency {
        blocking_us: blocking_us(cfg),
        single_us: response_time_us(cfg, 1, 1.0 / cfg.event_frames_per_s)?,
        burst_us: response_time_us(
            cfg,
            cfg.event_burst,
            f64::from(cfg.event_burst) / cfg.event_frames_per_s,
        )?,
    })
}

fn rates(cfg: &BusConfig) -> String {
    match cfg.format {
        BusFormat::Fd => format!(
            "CAN FD, {} kbit/s arbitration, {} kbit/s data with bit-rate switching",
            cfg.bitrate / 1000,
            cfg.data_bitrate / 1000
        ),
        BusFormat::Classic => format!("classic CAN, {} kbit/s", cfg.bitrate / 1000),
    }
}

/// Prints the analysis as a table, and on CAN FD what classic CAN would carry instead.
pub fn write_report(cfg: &BusConfig, r: &BusReport, out: &mut dyn Write) -> io::Result<()> {
    writeln!(
        out,
        "{} fingertip(s) on {}; detector {} Hz, stream every {} ticks ({:.1} samples/s), heartbeat {} ms, context {} Hz",
        cfg.fingertips,
        rates(cfg),
        cfg.tick_rate_hz,
        cfg.stream_decimation,
        cfg.tick_rate_hz / f64::from(cfg.stream_decimation),
        cfg.heartbeat_ms,
        cfg.context_hz
    )?;
    writeln!(
        out,
        "{:<11} {:<11} {:>5} {:>9} {:>9} {:>7}",
        "message", "sender", "bytes", "µs/frame", "frames/s", "load"
    )?;
    for m in &r.messages {
        let sender = match m.kind.direction() {
            Direction::FromFingertip => "fingertips",
            Direction::ToFingertip => "controller",
        };
        writeln!(
            out,
            "{:<11} {:<11} {:>5} {:>9.1} {:>9.1} {:>6.2}%",
            m.kind.name(),
            sender,
            m.kind.data_len(),
            m.frame_us,
            m.frames_per_s,
            100.0 * m.load
        )?;
    }
    writeln!(
        out,
        "fingertips: {:.1} frames/s, {:.2}% worst case",
        r.fingertip_frames_per_s,
        100.0 * r.fingertip_load
    )?;
    writeln!(
        out,
        "controller: {:.1} frames/s, {:.2}% worst case",
        r.controller_frames_per_s,
        100.0 * r.controller_load
    )?;
    let verdict = match load_target(cfg.fingertips) {
        Some(t) if r.total_load <= t => format!(
            ": within the {:.0}% target for {} fingertips",
            100.0 * t,
            cfg.fingertips
        ),
        Some(t) => format!(
            ": ABOVE the {:.0}% target for {} fingertips",
            100.0 * t,
            cfg.fingertips
        ),
        None => String::new(),
    };
    writeln!(
        out,
        "total:      {:.2}% worst case, both directions, bit stuffing {}{verdict}",
        100.0 * r.total_load,
        match cfg.format {
            BusFormat::Fd => "in both phases",
            BusFormat::Classic => "included",
        }
    )?;
    if r.total_load > 1.0 {
        writeln!(
            out,
            "OVERLOADED: the bus cannot carry this; context at {:.0} Hz would give 70% total",
            r.max_context_hz(cfg, 0.7)
        )?;
    }
    writeln!(
        out,
        "event frame latency on the bus: {:.0} µs worst case with one event frame per fingertip at a time ({}), {:.0} µs when every fingertip queues a burst of {}; blocking {:.0} µs",
        r.latency.single_us,
        if r.latency.single_us <= LATENCY_TARGET_US {
            "within the 500 µs target"
        } else {
            "ABOVE the 500 µs target"
        },
        r.latency.burst_us,
        cfg.event_burst,
        r.latency.blocking_us
    )?;
    if cfg.format == BusFormat::Fd {
        let classic = cfg.classic();
        if let Ok(c) = analyse(&classic) {
            writeln!(out, "{}", classic_summary(&classic, &c))?;
        }
    } else {
        writeln!(out, "{}", classic_summary(cfg, r))?;
    }
    Ok(())
}

/// The stream rate classic CAN's figures are also given at, samples per second.
pub const CLASSIC_STREAM_HZ: f64 = 50.0;

/// One line: what classic CAN at the same arbitration rate would need for `cfg`'s traffic,
/// and the context rates it can carry for 70 % total, with this stream and with a stream of
/// [`CLASSIC_STREAM_HZ`].
pub fn classic_summary(cfg: &BusConfig, r: &BusReport) -> String {
    let slow = BusConfig {
        stream_decimation: cfg
            .stream_decimation
            .max((cfg.tick_rate_hz / CLASSIC_STREAM_HZ).round() as u32),
        ..cfg.clone()
    };
    let head = format!(
        "{} would need {:.1}% for this traffic; for 70% total it carries context at up to {:.0} Hz per fingertip",
        rates(cfg),
        100.0 * r.total_load,
        r.max_context_hz(cfg, 0.7),
    );
    if slow.stream_decimation == cfg.stream_decimation {
        return head;
    }
    let slow_hz = analyse(&slow).map_or(0.0, |s| s.max_context_hz(&slow, 0.7));
    format!(
        "{head}, {:.0} Hz with the stream at {:.0} samples/s (--decimation {})",
        slow_hz,
        slow.tick_rate_hz / f64::from(slow.stream_decimation),
        slow.stream_decimation
    )
}

impl fmt::Display for MessageLoad {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {:.1} µs, {:.1} frames/s, {:.2}%",
            self.kind.name(),
            self.frame_us,
            self.frames_per_s,
            100.0 * self.load
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-6 * b.abs().max(1.0)
    }

    #[test]
    fn classic_frame_lengths_match_hand_worked_values() {
        // 47 + 8n + floor((33 + 8n)/4): 0 bytes 47 + 8 = 55; 8 bytes 47 + 64 + 24 = 135.
        let want = [55, 65, 75, 85, 95, 105, 115, 125, 135];
        for (n, &w) in want.iter().enumerate() {
            assert_eq!(classic_frame_bits(n).nominal, w, "{n} bytes");
        }
        assert_eq!(classic_frame_bits(12).nominal, 135);
    }

    #[test]
    fn fd_frame_lengths_match_hand_worked_values() {
        // 8 bytes: data 5 + 64 + 17 stuff + 4 + 17 + 6 = 113 bits; 64 bytes: 5 + 512 + 129
        // stuff + 4 + 21 + 7 = 678 bits; nominal 34 bits either way.
        assert_eq!(
            fd_frame_bits(8),
            FrameBits {
                nominal: 34,
                data: 113
            }
        );
        assert_eq!(
            fd_frame_bits(64),
            FrameBits {
                nominal: 34,
                data: 678
            }
        );
        assert_eq!(fd_frame_bits(24).data, 5 + 192 + 49 + 4 + 21 + 7);
        assert_eq!(fd_frame_bits(16).data, 5 + 128 + 33 + 4 + 17 + 6);
        assert!(close(fd_frame_bits(64).micros(1_000_000, 5_000_000), 169.6));
        assert!(close(fd_frame_bits(8).micros(1_000_000, 5_000_000), 56.6));
        // Without bit-rate switching the data bits run at 1 Mbit/s too.
        assert!(close(fd_frame_bits(8).micros(1_000_000, 1_000_000), 147.0));
    }

    #[test]
    fn default_load_for_five_and_ten_fingertips() {
        // Five: context 1 frame × 1000 × 169.6 µs; stream 1250 × 89.6; events 250 × 56.6;
        // status 200 × 56.6; phase 250 × 50.6.
        let five = analyse(&BusConfig::with_fingertips(5)).unwrap();
        let want = (169_600.0 + 1250.0 * 89.6 + 250.0 * 56.6 + 200.0 * 56.6 + 250.0 * 50.6) * 1e-6;
        assert!(close(five.total_load, want), "{}", five.total_load);
        assert!(five.total_load <= 0.35);
        let ten = analyse(&BusConfig::with_fingertips(10)).unwrap();
        assert!(
            close(ten.total_load, want * 2.0),
            "two groups, twice everything"
        );
        assert!(ten.total_load <= 0.70);
        // Eleven fingertips open a third group.
        assert_eq!(BusConfig::with_fingertips(11).groups(), 3);
    }

    #[test]
    fn classic_can_cannot_carry_a_hand_at_1_khz() {
        let c = BusConfig::with_fingertips(5).classic();
        let r = analyse(&c).unwrap();
        // Context: 5 × 3 frames × 1000 × 135 µs = 202.5 %.
        let ctx = r
            .messages
            .iter()
            .find(|m| m.kind == MessageKind::ContextPart)
            .unwrap();
        assert!(close(ctx.load, 2.025));
        assert!(r.total_load > 1.0);
        // Everything else: stream 5 × 250 × 3 pages, events 250, status 200 (135 µs each),
        // phase 250 × 105 µs (5 bytes).
        let other = (3750.0 + 250.0 + 200.0) * 135.0 * 1e-6 + 250.0 * 105.0 * 1e-6;
        let max = r.max_context_hz(&c, 0.7);
        assert!(
            close(max, (0.7 - other) / (5.0 * 3.0 * 135.0 * 1e-6)),
            "{max}"
        );
    }

    #[test]
    fn event_latency_matches_hand_worked_values() {
        // Five fingertips, one frame each: blocking 169.6 (the context frame) + four
        // higher-priority event frames + its own, 56.6 µs each.
        let r = analyse(&BusConfig::with_fingertips(5)).unwrap();
        assert!(close(r.latency.blocking_us, 169.6));
        assert!(close(r.latency.single_us, 169.6 + 5.0 * 56.6));
        assert!(r.latency.single_us <= LATENCY_TARGET_US);
        // Bursts of 6: its own 5 earlier, 4 × 6 from the others, its last.
        assert!(close(r.latency.burst_us, 169.6 + 30.0 * 56.6));
        // Classic: blocking by an 8-byte frame.
        let c = analyse(&BusConfig::with_fingertips(5).classic()).unwrap();
        assert!(close(c.latency.single_us, 135.0 + 5.0 * 135.0));
    }

    #[test]
    fn rejects_bad_parameters_and_overload() {
        let mut c = BusConfig::with_fingertips(0);
        assert!(matches!(
            analyse(&c),
            Err(BusError::Parameter {
                name: "fingertips",
                ..
            })
        ));
        c = BusConfig::with_fingertips(16);
        assert!(analyse(&c).is_err(), "15 node ids");
        c = BusConfig::with_fingertips(2);
        c.stream_decimation = 0;
        assert!(analyse(&c).is_err());
        for huge in [1e300, f64::INFINITY, 40_000.0] {
            c = BusConfig::with_fingertips(5);
            c.context_hz = huge;
            let e = analyse(&c).expect_err("refused");
            assert!(
                matches!(
                    e,
                    BusError::Parameter {
                        name: "context_hz",
                        ..
                    }
                ),
                "{e}"
            );
            assert!(e.to_string().len() < 120, "{e}");
        }
        c.context_hz = 1e300;
        assert!(
            analyse(&c)
                .unwrap_err()
                .to_string()
                .starts_with("context_hz = 1e300 ")
        );
        c = BusConfig::with_fingertips(5);
        c.bitrate = 2_000_000;
        assert!(analyse(&c).is_err(), "arbitration stops at 1 Mbit/s");
        c = BusConfig::with_fingertips(5);
        c.data_bitrate = 10_000_000;
        assert!(analyse(&c).is_err());
        c.format = BusFormat::Classic;
        assert!(
            analyse(&c).is_ok(),
            "the data rate does not matter on classic CAN"
        );
        // Event frames so frequent their bursts overlap: unschedulable.
        c = BusConfig::with_fingertips(15);
        c.event_frames_per_s = 29_000.0;
        assert!(matches!(analyse(&c), Err(BusError::Unschedulable { .. })));
    }

    #[test]
    fn report_prints_the_targets_and_classic_cans_rates() {
        let c = BusConfig::with_fingertips(5);
        let r = analyse(&c).unwrap();
        let mut out = Vec::new();
        write_report(&c, &r, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.contains("within the 35% target for 5 fingertips"),
            "{text}"
        );
        assert!(text.contains("within the 500 µs target"), "{text}");
        assert!(
            text.contains("classic CAN, 1000 kbit/s would need"),
            "{text}"
        );
        assert!(!text.contains("OVERLOADED"), "{text}");
        let classic = c.classic();
        let mut out = Vec::new();
        write_report(&classic, &analyse(&classic).unwrap(), &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(text.contains("OVERLOADED"), "{text}");
        assert!(text.contains("ABOVE the 35% target"), "{text}");
    }
}
