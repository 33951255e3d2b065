//! Worst-case bus load and event-frame latency of the fingertip protocol on classic CAN.
//!
//! Frame length: a classic data frame with a standard identifier and `n` data bytes is
//! `47 + 8n` bits including the 3-bit interframe space, of which `34 + 8n` (start of frame
//! to CRC) are subject to bit stuffing, worst case one stuff bit per 4 bits after the
//! first: `47 + 8n + ⌊(34 + 8n − 1)/4⌋` bits (135 for 8 bytes). Extended identifiers: `67 +
//! 8n + ⌊(54 + 8n − 1)/4⌋`.
//!
//! Load: every message's worst-case bits times its rate, over the bit rate. Event frames
//! are sporadic: the load counts an assumed worst-case rate per fingertip.
//!
//! Latency: response-time analysis for non-preemptive fixed-priority CAN (the analysis of
//! Tindell, as revised by Davis, Burns, Bril and Lukkien, 2007). An event frame is queued
//! when its tick ends; it waits for at most one lower-priority frame already on the bus
//! (blocking `B`, a maximum-length frame), then for every higher-priority frame queued
//! meanwhile: the event frames of fingertips with lower node ids and the earlier frames of
//! its own burst (one tick can raise several levels). The worst case is the last frame of
//! a full burst of the highest node id while every other fingertip sends a full burst too.
//! Error frames and retransmissions are not modelled, nor is traffic with identifiers
//! below 0x080.

use std::fmt;
use std::io::{self, Write};

use fingertip_can::{ConfidenceMsg, Direction, MessageKind};

/// Worst-case length in bits of a classic CAN data frame with a standard identifier and
/// `n` data bytes (at most 8), with bit stuffing and the interframe space.
pub const fn frame_bits(n: usize) -> u32 {
    let n = if n > 8 { 8 } else { n } as u32;
    47 + 8 * n + (34 + 8 * n - 1) / 4
}

/// As [`frame_bits`] for an extended identifier.
pub const fn frame_bits_extended(n: usize) -> u32 {
    let n = if n > 8 { 8 } else { n } as u32;
    67 + 8 * n + (54 + 8 * n - 1) / 4
}

/// The traffic to analyse. Rates are per fingertip.
#[derive(Clone, Debug, PartialEq)]
pub struct BusConfig {
    /// Bit rate in bit/s.
    pub bitrate: u32,
    /// Fingertips on the bus, 1..=16.
    pub fingertips: u32,
    /// Detector rate in Hz.
    pub tick_rate_hz: f64,
    /// Ticks per confidence-stream sample.
    pub stream_decimation: u32,
    /// Most events in one phase (sets the stream pages per sample and the burst), 1..=8.
    pub events_per_phase: u32,
    /// Heartbeat period in ms (two status frames per period).
    pub heartbeat_ms: f64,
    /// Assumed worst-case event frames per second per fingertip (sporadic).
    pub event_frames_per_s: f64,
    /// Most event frames one fingertip queues at once; the core raises at most two levels
    /// per event per tick, so `2 · events_per_phase` is the worst case.
    pub event_burst: u32,
    /// Context frames per second the controller sends each fingertip.
    pub context_hz: f64,
    /// Tip state frames per second the controller sends each fingertip.
    pub tip_state_hz: f64,
    /// Phase frames per second the controller sends each fingertip.
    pub phase_hz: f64,
}

impl Default for BusConfig {
    /// The defaults: 1 Mbit/s, one fingertip at 5 kHz, the default stream decimation
    /// (20: 250 samples/s) and heartbeat (50 ms), the paper's three events per phase,
    /// 50 event frames/s assumed, context and tip state at 1 kHz, phase at 50 Hz.
    fn default() -> Self {
        BusConfig {
            bitrate: 1_000_000,
            fingertips: 1,
            tick_rate_hz: 5000.0,
            stream_decimation: u32::from(fingertip_can::DEFAULT_STREAM_DECIMATION),
            events_per_phase: 3,
            heartbeat_ms: f64::from(fingertip_can::DEFAULT_HEARTBEAT_MS),
            event_frames_per_s: 50.0,
            event_burst: 6,
            context_hz: 1000.0,
            tip_state_hz: 1000.0,
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

    /// Stream pages per sample: one per group of three events.
    pub fn stream_pages(&self) -> u32 {
        self.events_per_phase
            .div_ceil(3)
            .min(u32::from(ConfidenceMsg::PAGES))
    }
}

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
    /// Worst-case bits per frame.
    pub frame_bits: u32,
    /// Frames per second, all fingertips together.
    pub frames_per_s: f64,
    /// Bits per second.
    pub bits_per_s: f64,
    /// Share of the bit rate, 0..
    pub load: f64,
}

/// The worst-case event-frame latency on the bus, from queueing to the end of
/// transmission.
#[derive(Clone, Debug, PartialEq)]
pub struct EventLatency {
    /// Time of one maximum-length frame (the blocking), µs.
    pub blocking_us: f64,
    /// Worst case: the last frame of a full burst of the highest node id while every
    /// other fingertip sends a full burst, µs.
    pub worst_us: f64,
    /// The same with one event frame per fingertip at a time, µs.
    pub single_us: f64,
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
    /// The highest context (and tip state) rate per fingertip that keeps the total load at
    /// or under `limit` with everything else unchanged; 0 if nothing is left.
    pub fn max_context_hz(&self, cfg: &BusConfig, limit: f64) -> f64 {
        let other: f64 = self
            .messages
            .iter()
            .filter(|m| !matches!(m.kind, MessageKind::Context | MessageKind::TipState))
            .map(|m| m.bits_per_s)
            .sum();
        let per_hz = f64::from(cfg.fingertips)
            * f64::from(
                frame_bits(MessageKind::Context.dlc()) + frame_bits(MessageKind::TipState.dlc()),
            );
        ((limit * f64::from(cfg.bitrate) - other) / per_hz).max(0.0)
    }
}

/// The most frames per second one kind of message can have on any classic CAN bus: at
/// 1 Mbit/s a frame takes at least 47 bits, so about 21,000 frames fill the bus.
const MAX_FRAME_RATE: f64 = 25_000.0;

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
        "10 kbit/s to 1 Mbit/s, classic CAN",
    )?;
    check(
        "fingertips",
        f(cfg.fingertips),
        (1..=16).contains(&cfg.fingertips),
        "1..=16",
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
        "above 0, at most 25,000 frames/s (more than a classic CAN bus carries)",
    )?;
    for (name, v) in [
        ("context_hz", cfg.context_hz),
        ("tip_state_hz", cfg.tip_state_hz),
        ("phase_hz", cfg.phase_hz),
    ] {
        check(
            name,
            v,
            (0.0..=MAX_FRAME_RATE).contains(&v),
            "0 to 25,000 frames/s (more than a classic CAN bus carries)",
        )?;
    }

    let n = f(cfg.fingertips);
    let bitrate = f(cfg.bitrate);
    let per_fingertip = |kind: MessageKind| -> f64 {
        match kind {
            MessageKind::Event => cfg.event_frames_per_s,
            MessageKind::Phase => cfg.phase_hz,
            MessageKind::Context => cfg.context_hz,
            MessageKind::TipState => cfg.tip_state_hz,
            MessageKind::Confidence => {
                cfg.tick_rate_hz / f(cfg.stream_decimation) * f(cfg.stream_pages())
            }
            MessageKind::Status => 2.0 * 1000.0 / cfg.heartbeat_ms,
        }
    };
    let messages: Vec<MessageLoad> = MessageKind::ALL
        .iter()
        .map(|&kind| {
            let bits = frame_bits(kind.dlc());
            let frames_per_s = per_fingertip(kind) * n;
            let bits_per_s = frames_per_s * f(bits);
            MessageLoad {
                kind,
                frame_bits: bits,
                frames_per_s,
                bits_per_s,
                load: bits_per_s / bitrate,
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
    let fingertip_frames_per_s = sum(Direction::FromFingertip, |m| m.frames_per_s);
    let fingertip_load = sum(Direction::FromFingertip, |m| m.load);
    let controller_frames_per_s = sum(Direction::ToFingertip, |m| m.frames_per_s);
    let controller_load = sum(Direction::ToFingertip, |m| m.load);
    let latency = event_latency(cfg)?;
    Ok(BusReport {
        messages,
        fingertip_frames_per_s,
        fingertip_load,
        controller_frames_per_s,
        controller_load,
        total_load: fingertip_load + controller_load,
        latency,
    })
}

/// Response time of the last frame of a burst of `burst` event frames from the
/// lowest-priority fingertip, every fingertip bursting `burst` frames at most every
/// `interval_s`.
fn response_time_us(cfg: &BusConfig, burst: u32, interval_s: f64) -> Result<f64, BusError> {
    let bit_us = 1e6 / f64::from(cfg.bitrate);
    let c = f64::from(frame_bits(MessageKind::Event.dlc())) * bit_us;
    // Any frame of lower priority may be on the bus: the longest is a full 8-byte frame.
    let b = f64::from(frame_bits(8)) * bit_us;
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

fn event_latency(cfg: &BusConfig) -> Result<EventLatency, BusError> {
    let bit_us = 1e6 / f64::from(cfg.bitrate);
    let worst = response_time_us(
        cfg,
        cfg.event_burst,
        f64::from(cfg.event_burst) / cfg.event_frames_per_s,
    )?;
    let single = response_time_us(cfg, 1, 1.0 / cfg.event_frames_per_s)?;
    Ok(EventLatency {
        blocking_us: f64::from(frame_bits(8)) * bit_us,
        worst_us: worst,
        single_us: single,
    })
}

/// The fingertip-side load limit the default stream settings keep for five fingertips.
pub const FINGERTIP_LOAD_TARGET: f64 = 0.35;

/// Prints the analysis as a table.
pub fn write_report(cfg: &BusConfig, r: &BusReport, out: &mut dyn Write) -> io::Result<()> {
    writeln!(
        out,
        "{} fingertip(s) on {} kbit/s classic CAN, detector {} Hz, stream every {} ticks ({:.1} samples/s, {} page(s)), heartbeat {} ms",
        cfg.fingertips,
        cfg.bitrate / 1000,
        cfg.tick_rate_hz,
        cfg.stream_decimation,
        cfg.tick_rate_hz / f64::from(cfg.stream_decimation),
        cfg.stream_pages(),
        cfg.heartbeat_ms
    )?;
    writeln!(
        out,
        "{:<11} {:<11} {:>5} {:>9} {:>11} {:>7}",
        "message", "sender", "bits", "frames/s", "bit/s", "load"
    )?;
    for m in &r.messages {
        let sender = match m.kind.direction() {
            Direction::FromFingertip => "fingertip",
            Direction::ToFingertip => "controller",
        };
        writeln!(
            out,
            "{:<11} {:<11} {:>5} {:>9.1} {:>11.0} {:>6.2}%",
            m.kind.name(),
            sender,
            m.frame_bits,
            m.frames_per_s,
            m.bits_per_s,
            100.0 * m.load
        )?;
    }
    writeln!(
        out,
        "fingertips: {:.1} frames/s, {:.2}% worst case{}",
        r.fingertip_frames_per_s,
        100.0 * r.fingertip_load,
        if r.fingertip_load <= FINGERTIP_LOAD_TARGET {
            " (within the 35% target)"
        } else {
            " (ABOVE the 35% target: raise the stream decimation)"
        }
    )?;
    writeln!(
        out,
        "controller: {:.1} frames/s, {:.2}% worst case",
        r.controller_frames_per_s,
        100.0 * r.controller_load
    )?;
    writeln!(out, "total:      {:.2}% worst case", 100.0 * r.total_load)?;
    if r.total_load > 1.0 {
        writeln!(
            out,
            "OVERLOADED: the bus cannot carry this; the controller's context and tip state must drop to {:.0} Hz per fingertip for 70% total",
            r.max_context_hz(cfg, 0.7)
        )?;
    } else if r.total_load > 0.7 {
        writeln!(
            out,
            "warning: above 70% total; context and tip state at {:.0} Hz per fingertip would give 70%",
            r.max_context_hz(cfg, 0.7)
        )?;
    }
    writeln!(
        out,
        "event frame latency on the bus: {:.0} µs worst case (bursts of {} frames from every fingertip), {:.0} µs with one event frame per fingertip; blocking {:.0} µs",
        r.latency.worst_us, cfg.event_burst, r.latency.single_us, r.latency.blocking_us
    )
}

impl fmt::Display for MessageLoad {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} bits, {:.1} frames/s, {:.2}%",
            self.kind.name(),
            self.frame_bits,
            self.frames_per_s,
            100.0 * self.load
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lengths_match_hand_worked_values() {
        // 47 + 8n + floor((33 + 8n)/4): 0 bytes 47 + 8 = 55; 8 bytes 47 + 64 + 24 = 135.
        let want = [55, 65, 75, 85, 95, 105, 115, 125, 135];
        for (n, &w) in want.iter().enumerate() {
            assert_eq!(frame_bits(n), w, "{n} bytes");
        }
        assert_eq!(frame_bits(12), 135);
        // Extended, 8 bytes: 67 + 64 + floor(117/4) = 160.
        assert_eq!(frame_bits_extended(8), 160);
        assert_eq!(frame_bits_extended(0), 80);
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-6 * b.abs().max(1.0)
    }

    #[test]
    fn default_load_for_one_and_five_fingertips() {
        // Per fingertip: stream 5000/20 = 250 frames/s, status 2 per 50 ms = 40 frames/s,
        // events 50 frames/s, all 135 bits: 340 · 135 = 45 900 bit/s = 4.59%.
        let one = analyse(&BusConfig::with_fingertips(1)).unwrap();
        assert!(close(one.fingertip_frames_per_s, 340.0));
        assert!(close(one.fingertip_load, 0.0459));
        // Controller: context 1000 · 135 + tip state 1000 · 115 + phase 50 · 95
        // = 254 750 bit/s.
        assert!(close(one.controller_load, 0.25475));
        let five = analyse(&BusConfig::with_fingertips(5)).unwrap();
        assert!(close(five.fingertip_frames_per_s, 1700.0));
        assert!(close(five.fingertip_load, 0.2295));
        assert!(five.fingertip_load <= FINGERTIP_LOAD_TARGET);
        assert!(close(five.total_load, 0.2295 + 5.0 * 0.25475));
        // Context at x Hz for 70% total: (700 000 - 229 500 - 5 · 4750) / (5 · 250).
        assert!(close(
            five.max_context_hz(&BusConfig::with_fingertips(5), 0.7),
            (700_000.0 - 229_500.0 - 23_750.0) / 1250.0
        ));
    }

    #[test]
    fn event_latency_matches_hand_worked_values() {
        // Five fingertips, one frame each: blocking 135 + four higher 4 · 135 + own 135
        // = 810 µs. Bursts of 6: 135 + own 5 · 135 + four others 4 · 6 · 135 + 135
        // = 31 · 135 = 4185 µs.
        let r = analyse(&BusConfig::with_fingertips(5)).unwrap();
        assert!(close(r.latency.blocking_us, 135.0));
        assert!(close(r.latency.single_us, 810.0));
        assert!(close(r.latency.worst_us, 4185.0));
        // Alone on the bus: 135 + 135 = 270 µs for a single frame.
        let one = analyse(&BusConfig::with_fingertips(1)).unwrap();
        assert!(close(one.latency.single_us, 270.0));
        assert!(close(one.latency.worst_us, 6.0 * 135.0 + 135.0));
    }

    #[test]
    fn stream_pages_follow_events_per_phase() {
        let mut c = BusConfig::with_fingertips(5);
        c.events_per_phase = 4;
        assert_eq!(c.stream_pages(), 2);
        let r = analyse(&c).unwrap();
        // Stream 500 frames/s per fingertip now.
        assert!(close(r.messages[4].frames_per_s, 2500.0));
        c.events_per_phase = 8;
        assert_eq!(c.stream_pages(), 3);
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
        c = BusConfig::with_fingertips(2);
        c.stream_decimation = 0;
        assert!(analyse(&c).is_err());
        // Rates no bus carries are refused, and printed readably.
        for huge in [1e300, f64::INFINITY, 30_000.0] {
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
        assert!(analyse(&c).is_err(), "classic CAN stops at 1 Mbit/s");
        // Event frames so frequent their bursts overlap: unschedulable.
        c = BusConfig::with_fingertips(16);
        c.event_frames_per_s = 20_000.0;
        assert!(matches!(analyse(&c), Err(BusError::Unschedulable { .. })));
    }

    #[test]
    fn report_prints() {
        let c = BusConfig::with_fingertips(5);
        let r = analyse(&c).unwrap();
        let mut out = Vec::new();
        write_report(&c, &r, &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert!(
            text.contains("22.95% worst case (within the 35% target)"),
            "{text}"
        );
        assert!(text.contains("OVERLOADED"));
        assert!(text.contains("4185 µs worst case"));
    }
}
