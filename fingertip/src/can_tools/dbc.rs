//! The published CAN database, `fingertip-can/fingertip.dbc`: its specification as a table, the
//! text rendered from it, and the signal values of a decoded message by DBC name.
//!
//! The table states bit positions, scaling and ranges as literals, independently of the
//! codec's packing code; the host tests hold the two to each other through cantools, and
//! hold the committed file to [`render`].

use std::fmt::Write as _;

use detector_core::{Confidence, Level};
use fingertip_can::{
    ContextMsg, FaultFlags, Message, MessageKind, NodeId, ResetReason, StatusPage, TipStateMsg,
};

/// Where a signal sits in a multiplexed message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mux {
    /// In every frame.
    Always,
    /// The multiplexer (`M`).
    Selector,
    /// Only in frames whose multiplexer has this value (`m<v>`).
    Page(u8),
}

/// One signal of the database.
#[derive(Clone, Debug, PartialEq)]
pub struct SignalDef {
    /// The name.
    pub name: String,
    /// Start bit (least significant bit, little-endian).
    pub start: u32,
    /// Length in bits.
    pub len: u32,
    /// Two's complement.
    pub signed: bool,
    /// Physical value per raw unit, as written in the file.
    pub factor: &'static str,
    /// Smallest physical value, as written.
    pub min: String,
    /// Largest physical value, as written.
    pub max: String,
    /// Unit.
    pub unit: &'static str,
    /// Multiplexing.
    pub mux: Mux,
    /// Description.
    pub comment: String,
    /// Named raw values.
    pub values: Vec<(i64, &'static str)>,
}

impl SignalDef {
    /// The factor as a number.
    pub fn factor_value(&self) -> f64 {
        self.factor.parse().unwrap_or(f64::NAN)
    }
}

/// One message of the database (for one node).
#[derive(Clone, Debug, PartialEq)]
pub struct MessageDef {
    /// The message.
    pub kind: MessageKind,
    /// Its description.
    pub comment: &'static str,
    /// Cycle time in ms at the defaults, for periodic messages.
    pub cycle_ms: Option<u32>,
    /// Its signals.
    pub signals: Vec<SignalDef>,
}

/// The factor of a Q15 confidence: 2⁻¹⁵, written out exactly.
pub const CONFIDENCE_FACTOR: &str = "0.000030517578125";

fn sig(name: &str, start: u32, len: u32, comment: &str) -> SignalDef {
    SignalDef {
        name: name.to_string(),
        start,
        len,
        signed: false,
        factor: "1",
        min: "0".into(),
        max: ((1u64 << len) - 1).to_string(),
        unit: "",
        mux: Mux::Always,
        comment: comment.to_string(),
        values: Vec::new(),
    }
}

fn scaled(
    name: &str,
    start: u32,
    len: u32,
    factor: &'static str,
    range: (&str, &str),
    unit: &'static str,
    comment: &str,
) -> SignalDef {
    SignalDef {
        signed: range.0.starts_with('-'),
        factor,
        min: range.0.into(),
        max: range.1.into(),
        unit,
        ..sig(name, start, len, comment)
    }
}

fn ranged(name: &str, start: u32, len: u32, max: u64, comment: &str) -> SignalDef {
    SignalDef {
        max: max.to_string(),
        ..sig(name, start, len, comment)
    }
}

fn on_page(mut s: SignalDef, page: u8) -> SignalDef {
    s.mux = Mux::Page(page);
    s
}

fn e2e_header() -> Vec<SignalDef> {
    vec![
        sig(
            "Crc",
            0,
            8,
            "CRC-8/AUTOSAR (poly 0x2F, init 0xFF, xorout 0xFF) over bytes 1..DLC then the data id ((CAN id & 0xFF) XOR 0x11*Counter): AUTOSAR E2E profile 2",
        ),
        sig(
            "Counter",
            8,
            4,
            "Rolling counter, +1 per frame sent, wraps 15 -> 0",
        ),
    ]
}

/// The database's messages, in priority order.
pub fn messages() -> Vec<MessageDef> {
    let conf = |name: &str, start: u32, comment: &str| {
        scaled(name, start, 16, CONFIDENCE_FACTOR, ("0", "1"), "", comment)
    };
    let mut event = e2e_header();
    event.extend([
        ranged(
            "EventId",
            12,
            3,
            7,
            "Index of the event in the fingertip's configuration",
        ),
        SignalDef {
            values: vec![(0, "alert"), (1, "confirm")],
            ..sig("Level", 15, 1, "Decision level raised")
        },
        conf("Confidence", 16, "Event confidence at the decision, Q15"),
        SignalDef {
            unit: "tick",
            ..sig(
                "Tick",
                32,
                16,
                "Low 16 bits of the detector tick of the decision (200 us per tick at 5 kHz; rate in Status TickRate)",
            )
        },
        SignalDef {
            unit: "tick",
            ..sig(
                "OnsetAge",
                48,
                16,
                "Ticks from the back-dated onset to the decision, saturating at 65535",
            )
        },
    ]);

    let mut phase = e2e_header();
    phase.extend([
        ranged(
            "PhaseId",
            16,
            8,
            7,
            "Phase to run: index in the fingertip's configuration (must be configured)",
        ),
        sig(
            "PhaseSeq",
            24,
            8,
            "Phase sequence, advanced by the controller at every phase entry",
        ),
    ]);

    let mut context = e2e_header();
    context.extend([
        scaled(
            "VelDesX",
            12,
            13,
            "0.0001",
            ("-0.4095", "0.4095"),
            "m/s",
            "Desired tip velocity along the pad normal (fingertip frame); raw -4096 invalid",
        ),
        scaled(
            "VelDesY",
            25,
            13,
            "0.0001",
            ("-0.4095", "0.4095"),
            "m/s",
            "Desired tip velocity, tangential; raw -4096 invalid",
        ),
        scaled(
            "AccDesX",
            38,
            13,
            "0.002",
            ("-8.19", "8.19"),
            "m/s^2",
            "Desired tip acceleration along the pad normal; raw -4096 invalid",
        ),
        scaled(
            "AccDesY",
            51,
            13,
            "0.002",
            ("-8.19", "8.19"),
            "m/s^2",
            "Desired tip acceleration, tangential; raw -4096 invalid",
        ),
    ]);

    let mut tip = e2e_header();
    tip.extend([
        scaled(
            "PosErrX",
            16,
            16,
            "0.000001",
            ("-0.032767", "0.032767"),
            "m",
            "Tip position error (commanded - actual) along the pad normal; raw -32768 invalid",
        ),
        scaled(
            "PosErrY",
            32,
            16,
            "0.000001",
            ("-0.032767", "0.032767"),
            "m",
            "Tip position error, tangential; raw -32768 invalid",
        ),
    ]);

    let mut stream = vec![
        sig(
            "Seq",
            0,
            8,
            "Sample sequence number; all pages of a sample share it",
        ),
        SignalDef {
            mux: Mux::Selector,
            ..ranged("Page", 8, 2, 2, "Page p carries events 3p, 3p+1, 3p+2")
        },
    ];
    for page in 0..3u8 {
        let slots = if page == 2 { 2 } else { 3 };
        for k in 0..slots {
            let e = 3 * u32::from(page) + k;
            stream.push(on_page(
                sig(
                    &format!("Evaluated{e}"),
                    10 + k,
                    1,
                    &format!("Event {e} belongs to the current phase"),
                ),
                page,
            ));
        }
        for k in 0..slots {
            let e = 3 * u32::from(page) + k;
            stream.push(on_page(
                sig(
                    &format!("Unjudgeable{e}"),
                    13 + k,
                    1,
                    &format!("Event {e} cannot be judged (faulty context or sensors)"),
                ),
                page,
            ));
        }
        for k in 0..slots {
            let e = 3 * u32::from(page) + k;
            stream.push(on_page(
                conf(
                    &format!("Conf{e}"),
                    16 + 16 * k,
                    &format!("Confidence of event {e}, Q15; 0 when not evaluated"),
                ),
                page,
            ));
        }
    }

    let mut status = vec![SignalDef {
        mux: Mux::Selector,
        ..ranged(
            "Page",
            0,
            4,
            5,
            "Status page; page 0 every heartbeat, pages 1..5 in turn",
        )
    }];
    status.push(on_page(
        SignalDef {
            values: ResetReason::ALL
                .iter()
                .map(|&r| (r as i64, r.name()))
                .collect(),
            ..ranged("ResetReason", 4, 4, 8, "Why the fingertip last reset")
        },
        0,
    ));
    let flag_comments = [
        "No valid context frame within the context timeout: context-dependent events not confirmed",
        "No valid tip state frame within the context timeout",
        "No valid phase frame within the phase timeout",
        "A tick overran its period since the last heartbeat",
        "CAN controller error-passive or bus-off since the last heartbeat",
        "A frame could not be queued since the last heartbeat",
        "Detector image rejected: detector out of service, status heartbeats only",
        "A sensor channel is flagged faulty",
    ];
    for (i, (name, comment)) in FaultFlags::NAMES.iter().zip(flag_comments).enumerate() {
        status.push(on_page(sig(name, 8 + i as u32, 1, comment), 0));
    }
    status.extend([
        on_page(
            SignalDef {
                unit: "tick",
                ..sig("Uptime", 16, 32, "Detector ticks since boot, wrapping")
            },
            0,
        ),
        on_page(
            SignalDef {
                values: vec![(255, "none")],
                ..sig(
                    "Phase",
                    48,
                    8,
                    "Phase the detector runs, 0..7; 255 before the first phase frame",
                )
            },
            0,
        ),
        on_page(sig("PhaseSeq", 56, 8, "Sequence number of that phase"), 0),
        on_page(
            sig(
                "Overruns",
                8,
                16,
                "Ticks that overran their period, saturating",
            ),
            1,
        ),
        on_page(
            scaled(
                "WorstTick",
                24,
                16,
                "0.1",
                ("0", "6553.5"),
                "us",
                "Longest tick computation since boot, saturating",
            ),
            1,
        ),
        on_page(
            SignalDef {
                unit: "Hz",
                ..sig(
                    "TickRate",
                    40,
                    16,
                    "Detector rate: the unit of every tick signal",
                )
            },
            1,
        ),
        on_page(sig("ProtocolVersion", 56, 8, "Protocol version"), 1),
        on_page(
            sig(
                "StaleEpisodes",
                8,
                16,
                "Times context or tip state went stale, saturating",
            ),
            2,
        ),
        on_page(
            sig(
                "LostFrames",
                24,
                16,
                "Controller frames lost (counter gaps), saturating",
            ),
            2,
        ),
        on_page(sig("BusErrors", 40, 16, "CAN error events, saturating"), 2),
        on_page(
            sig(
                "RejWrongLength",
                8,
                16,
                "Received frames rejected: wrong length",
            ),
            3,
        ),
        on_page(
            sig(
                "RejUnknownId",
                24,
                16,
                "Received frames rejected: unknown identifier",
            ),
            3,
        ),
        on_page(
            sig("RejBadCrc", 40, 16, "Received frames rejected: bad CRC"),
            3,
        ),
        on_page(
            sig(
                "RejSequence",
                8,
                16,
                "Received frames rejected: counter repeated, out of order or jumped",
            ),
            4,
        ),
        on_page(
            sig(
                "RejPhaseNotConfigured",
                24,
                16,
                "Received frames rejected: phase not configured",
            ),
            4,
        ),
        on_page(
            sig(
                "RejOutOfRange",
                40,
                16,
                "Received frames rejected: value out of range",
            ),
            4,
        ),
        on_page(
            sig(
                "ConfigChecksum",
                8,
                32,
                "Checksum of the active configuration",
            ),
            5,
        ),
        on_page(
            sig(
                "TxDropped",
                40,
                16,
                "Frames the fingertip could not queue, saturating",
            ),
            5,
        ),
    ]);

    vec![
        MessageDef {
            kind: MessageKind::Event,
            comment: "A decision level was raised; sent at once, highest priority of the protocol. E2E protected.",
            cycle_ms: None,
            signals: event,
        },
        MessageDef {
            kind: MessageKind::Phase,
            comment: "Phase to run; sent on every change and periodically. E2E protected.",
            cycle_ms: None,
            signals: phase,
        },
        MessageDef {
            kind: MessageKind::Context,
            comment: "Controller's commanded tip motion; stale after the context timeout. E2E protected.",
            cycle_ms: None,
            signals: context,
        },
        MessageDef {
            kind: MessageKind::TipState,
            comment: "Tip position error; stale after the context timeout. E2E protected.",
            cycle_ms: None,
            signals: tip,
        },
        MessageDef {
            kind: MessageKind::Confidence,
            comment: "Decimated confidence stream of the current phase's events (every 20 ticks = 4 ms by default)",
            cycle_ms: Some(4),
            signals: stream,
        },
        MessageDef {
            kind: MessageKind::Status,
            comment: "Status heartbeat: page 0 and one of pages 1..5 every 50 ms by default",
            cycle_ms: Some(50),
            signals: status,
        },
    ]
}

/// The DBC message name of `kind` for `node`: `Event_3`.
pub fn message_name(kind: MessageKind, node: NodeId) -> String {
    format!("{}_{}", kind.name(), node.get())
}

fn node_name(node: NodeId) -> String {
    format!("Fingertip{}", node.get())
}

fn nodes() -> impl Iterator<Item = NodeId> {
    (0..=NodeId::MAX).filter_map(NodeId::new)
}

fn escape(s: &str) -> String {
    s.replace('"', "'")
}

/// The database text.
pub fn render() -> String {
    let defs = messages();
    let mut s = String::new();
    let _ = writeln!(
        s,
        "VERSION \"fingertip-can {}\"",
        fingertip_can::PROTOCOL_VERSION
    );
    s.push_str("\n\nNS_ :\n");
    for ns in [
        "NS_DESC_",
        "CM_",
        "BA_DEF_",
        "BA_",
        "VAL_",
        "CAT_DEF_",
        "CAT_",
        "FILTER",
        "BA_DEF_DEF_",
        "EV_DATA_",
        "ENVVAR_DATA_",
        "SGTYPE_",
        "SGTYPE_VAL_",
        "BA_DEF_SGTYPE_",
        "BA_SGTYPE_",
        "SIG_TYPE_REF_",
        "VAL_TABLE_",
        "SIG_GROUP_",
        "SIG_VALTYPE_",
        "SIGTYPE_VALTYPE_",
        "BO_TX_BU_",
        "BA_DEF_REL_",
        "BA_REL_",
        "BA_DEF_DEF_REL_",
        "BU_SG_REL_",
        "BU_EV_REL_",
        "BU_BO_REL_",
        "SG_MUL_VAL_",
    ] {
        let _ = writeln!(s, "\t{ns}");
    }
    s.push_str("\nBS_:\n\nBU_: Controller");
    for n in nodes() {
        let _ = write!(s, " {}", node_name(n));
    }
    s.push_str("\n\n");
    for def in &defs {
        for n in nodes() {
            let (tx, rx) = match def.kind.direction() {
                fingertip_can::Direction::FromFingertip => (node_name(n), "Controller".to_string()),
                fingertip_can::Direction::ToFingertip => ("Controller".to_string(), node_name(n)),
            };
            let _ = writeln!(
                s,
                "BO_ {} {}: {} {}",
                def.kind.raw_id(n),
                message_name(def.kind, n),
                def.kind.dlc(),
                tx
            );
            for sg in &def.signals {
                let mux = match sg.mux {
                    Mux::Always => String::new(),
                    Mux::Selector => " M".into(),
                    Mux::Page(p) => format!(" m{p}"),
                };
                let _ = writeln!(
                    s,
                    " SG_ {}{} : {}|{}@1{} ({},0) [{}|{}] \"{}\" {}",
                    sg.name,
                    mux,
                    sg.start,
                    sg.len,
                    if sg.signed { '-' } else { '+' },
                    sg.factor,
                    sg.min,
                    sg.max,
                    sg.unit,
                    rx
                );
            }
            s.push('\n');
        }
    }
    s.push('\n');
    let _ = writeln!(
        s,
        "CM_ \"Fingertip event detector CAN protocol, version {}. Identifier = class << 4 | node (0..15). Little-endian signals. See docs/can-protocol.md.\";",
        fingertip_can::PROTOCOL_VERSION
    );
    for n in nodes() {
        let _ = writeln!(
            s,
            "CM_ BU_ {} \"Fingertip with node id {}\";",
            node_name(n),
            n.get()
        );
    }
    let _ = writeln!(
        s,
        "CM_ BU_ Controller \"The robot's high-level controller\";"
    );
    for def in &defs {
        for n in nodes() {
            let id = def.kind.raw_id(n);
            let _ = writeln!(s, "CM_ BO_ {id} \"{}\";", escape(def.comment));
            for sg in &def.signals {
                let _ = writeln!(s, "CM_ SG_ {id} {} \"{}\";", sg.name, escape(&sg.comment));
            }
        }
    }
    s.push_str("BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n");
    s.push_str("BA_DEF_DEF_ \"GenMsgCycleTime\" 0;\n");
    for def in &defs {
        if let Some(ms) = def.cycle_ms {
            for n in nodes() {
                let _ = writeln!(
                    s,
                    "BA_ \"GenMsgCycleTime\" BO_ {} {ms};",
                    def.kind.raw_id(n)
                );
            }
        }
    }
    for def in &defs {
        for n in nodes() {
            for sg in def.signals.iter().filter(|sg| !sg.values.is_empty()) {
                let _ = write!(s, "VAL_ {} {}", def.kind.raw_id(n), sg.name);
                for (v, name) in &sg.values {
                    let _ = write!(s, " {v} \"{name}\"");
                }
                s.push_str(" ;\n");
            }
        }
    }
    s
}

/// The physical values of a decoded message by DBC signal name, computed from the
/// codec's fields with the codec's own scales (not the table's), so a disagreement in
/// scaling shows. `crc` is byte 0 of protected frames.
pub fn signal_values(message: &Message, crc: u8) -> Vec<(String, f64)> {
    let mut v: Vec<(String, f64)> = Vec::new();
    let mut put = |name: &str, value: f64| v.push((name.to_string(), value));
    let conf = |c: Confidence| c.to_f64();
    if let Some(c) = message.counter() {
        put("Crc", f64::from(crc));
        put("Counter", f64::from(c.get()));
    }
    match message {
        Message::Event(m) => {
            put("EventId", f64::from(m.event.0));
            put("Level", f64::from(u8::from(m.level == Level::Confirm)));
            put("Confidence", conf(m.confidence));
            put("Tick", f64::from(m.tick));
            put("OnsetAge", f64::from(m.onset_age));
        }
        Message::Phase(m) => {
            put("PhaseId", f64::from(m.phase));
            put("PhaseSeq", f64::from(m.sequence));
        }
        Message::Context(m) => {
            put("VelDesX", f64::from(m.vel_des[0]) * ContextMsg::VEL_SCALE);
            put("VelDesY", f64::from(m.vel_des[1]) * ContextMsg::VEL_SCALE);
            put("AccDesX", f64::from(m.acc_des[0]) * ContextMsg::ACC_SCALE);
            put("AccDesY", f64::from(m.acc_des[1]) * ContextMsg::ACC_SCALE);
        }
        Message::TipState(m) => {
            put("PosErrX", f64::from(m.pos_err[0]) * TipStateMsg::POS_SCALE);
            put("PosErrY", f64::from(m.pos_err[1]) * TipStateMsg::POS_SCALE);
        }
        Message::Confidence(m) => {
            put("Seq", f64::from(m.seq));
            put("Page", f64::from(m.page));
            let slots = fingertip_can::ConfidenceMsg::slots(m.page);
            let first = 3 * usize::from(m.page);
            for k in 0..slots {
                put(
                    &format!("Evaluated{}", first + k),
                    f64::from((m.evaluated >> k) & 1),
                );
            }
            for k in 0..slots {
                put(
                    &format!("Unjudgeable{}", first + k),
                    f64::from((m.unjudgeable >> k) & 1),
                );
            }
            for (k, c) in m.confidences.iter().enumerate().take(slots) {
                put(&format!("Conf{}", first + k), conf(*c));
            }
        }
        Message::Status(p) => {
            put("Page", f64::from(p.page()));
            match *p {
                StatusPage::Health {
                    reset,
                    faults,
                    uptime,
                    phase,
                    phase_seq,
                } => {
                    put("ResetReason", f64::from(reset as u8));
                    for (i, name) in FaultFlags::NAMES.iter().enumerate() {
                        put(name, f64::from((faults.0 >> i) & 1));
                    }
                    put("Uptime", f64::from(uptime));
                    put("Phase", f64::from(phase.unwrap_or(255)));
                    put("PhaseSeq", f64::from(phase_seq));
                }
                StatusPage::Timing {
                    overruns,
                    worst_tick,
                    tick_rate_hz,
                    protocol,
                } => {
                    put("Overruns", f64::from(overruns));
                    put("WorstTick", f64::from(worst_tick) * 0.1);
                    put("TickRate", f64::from(tick_rate_hz));
                    put("ProtocolVersion", f64::from(protocol));
                }
                StatusPage::Link {
                    stale_episodes,
                    lost_frames,
                    bus_errors,
                } => {
                    put("StaleEpisodes", f64::from(stale_episodes));
                    put("LostFrames", f64::from(lost_frames));
                    put("BusErrors", f64::from(bus_errors));
                }
                StatusPage::FrameRejects {
                    wrong_length,
                    unknown_id,
                    bad_crc,
                } => {
                    put("RejWrongLength", f64::from(wrong_length));
                    put("RejUnknownId", f64::from(unknown_id));
                    put("RejBadCrc", f64::from(bad_crc));
                }
                StatusPage::ContentRejects {
                    sequence,
                    phase_not_configured,
                    out_of_range,
                } => {
                    put("RejSequence", f64::from(sequence));
                    put("RejPhaseNotConfigured", f64::from(phase_not_configured));
                    put("RejOutOfRange", f64::from(out_of_range));
                }
                StatusPage::Config {
                    checksum,
                    tx_dropped,
                } => {
                    put("ConfigChecksum", f64::from(checksum));
                    put("TxDropped", f64::from(tx_dropped));
                }
            }
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signals_fit_their_frames_and_do_not_overlap() {
        for def in messages() {
            let bits = 8 * def.kind.dlc() as u32;
            // Check every multiplexer value separately.
            for page in 0..8u8 {
                let mut used = 0u64;
                for sg in &def.signals {
                    if let Mux::Page(p) = sg.mux
                        && p != page
                    {
                        continue;
                    }
                    assert!(sg.start + sg.len <= bits, "{} {}", def.kind.name(), sg.name);
                    let mask = ((1u64 << sg.len) - 1) << sg.start;
                    assert_eq!(used & mask, 0, "{} {} overlaps", def.kind.name(), sg.name);
                    used |= mask;
                }
            }
        }
    }

    #[test]
    fn renders_every_message_for_every_node() {
        let text = render();
        assert_eq!(text.matches("\nBO_ ").count(), 6 * 16);
        assert!(text.contains("BO_ 128 Event_0: 8 Fingertip0"));
        assert!(text.contains("BO_ 159 Phase_15: 4 Controller"));
        assert!(
            text.contains(" SG_ VelDesX : 12|13@1- (0.0001,0) [-0.4095|0.4095] \"m/s\" Fingertip3")
        );
        assert!(
            text.contains(" SG_ Conf7 m2 : 32|16@1+ (0.000030517578125,0) [0|1] \"\" Controller")
        );
    }
}
