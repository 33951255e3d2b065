//! The published CAN databases, `fingertip-can/fingertip.dbc` (CAN FD) and
//! `fingertip-can/fingertip-classic.dbc` (classic CAN): their specification as a table, the
//! text rendered from it, and the signal values of a decoded message by DBC name.
//!
//! The table states bit positions, scaling and ranges as literals, independently of the
//! codec's packing code; the host tests hold the two to each other through cantools, and
//! hold the committed files to [`render`].

use std::fmt::Write as _;

use detector_core::{Confidence, Level, MAX_EVENTS};
use fingertip_can::{
    Address, BusFormat, ContextGroup, ContextPart, ContextSlot, FaultFlags, LevelState, Message,
    MessageKind, NodeId, NodeIdSource, ResetReason, StatusPage,
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
    /// The fingertips receiving it (the controller's frames); empty for the controller.
    pub receivers: Vec<NodeId>,
}

impl SignalDef {
    /// The factor as a number.
    pub fn factor_value(&self) -> f64 {
        self.factor.parse().unwrap_or(f64::NAN)
    }
}

/// One message of a database: one identifier.
#[derive(Clone, Debug, PartialEq)]
pub struct MessageDef {
    /// The message.
    pub kind: MessageKind,
    /// The node or group its identifier names.
    pub address: Address,
    /// Its description.
    pub comment: &'static str,
    /// Cycle time in ms at the defaults, for periodic messages.
    pub cycle_ms: Option<u32>,
    /// Its signals.
    pub signals: Vec<SignalDef>,
}

impl MessageDef {
    /// The raw identifier.
    pub fn raw_id(&self) -> u16 {
        self.kind.raw_id_of(self.address.index())
    }

    /// The DBC message name: `Event_3`, `Context_1` (a group).
    pub fn name(&self) -> String {
        message_name(self.kind, self.address)
    }
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
        receivers: Vec::new(),
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

fn with_values(mut s: SignalDef, values: Vec<(i64, &'static str)>) -> SignalDef {
    s.values = values;
    s
}

fn header() -> Vec<SignalDef> {
    vec![
        sig(
            "Crc",
            0,
            16,
            "CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 2..len then the data id (the CAN id, low byte first): AUTOSAR E2E profile 5",
        ),
        sig(
            "Counter",
            16,
            8,
            "Rolling counter, +1 per frame sent, wraps 255 -> 0",
        ),
    ]
}

fn level_values() -> Vec<(i64, &'static str)> {
    LevelState::ALL
        .iter()
        .map(|&l| (l as i64, l.name()))
        .collect()
}

/// One context signal's name, factor, range, unit and description.
type PartSignal = (
    &'static str,
    &'static str,
    (&'static str, &'static str),
    &'static str,
    &'static str,
);

/// A context part's two signals, as the classic message and a broadcast slot write them.
fn part_signals(part: ContextPart) -> [PartSignal; 2] {
    let [x, y] = part.signal_names();
    match part {
        ContextPart::Velocity => [
            (
                x,
                "0.0001",
                ("-0.4095", "0.4095"),
                "m/s",
                "Desired tip velocity along the pad normal (fingertip frame)",
            ),
            (
                y,
                "0.0001",
                ("-0.4095", "0.4095"),
                "m/s",
                "Desired tip velocity, tangential",
            ),
        ],
        ContextPart::Acceleration => [
            (
                x,
                "0.002",
                ("-8.19", "8.19"),
                "m/s^2",
                "Desired tip acceleration along the pad normal",
            ),
            (
                y,
                "0.002",
                ("-8.19", "8.19"),
                "m/s^2",
                "Desired tip acceleration, tangential",
            ),
        ],
        ContextPart::PositionError => [
            (
                x,
                "0.000001",
                ("-0.032767", "0.032767"),
                "m",
                "Tip position error (commanded - actual) along the pad normal",
            ),
            (
                y,
                "0.000001",
                ("-0.032767", "0.032767"),
                "m",
                "Tip position error, tangential",
            ),
        ],
    }
}

fn event(node: NodeId) -> MessageDef {
    let mut s = header();
    s.extend([
        ranged(
            "EventId",
            24,
            3,
            7,
            "Index of the event in the fingertip's configuration",
        ),
        with_values(
            sig("Level", 27, 1, "Decision level raised"),
            vec![(0, "alert"), (1, "confirm")],
        ),
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
    MessageDef {
        kind: MessageKind::Event,
        address: Address::Node(node),
        comment: "A decision level was raised; sent at once, highest priority of the protocol",
        cycle_ms: None,
        signals: s,
    }
}

fn context(group: ContextGroup) -> MessageDef {
    let nodes: Vec<NodeId> = (0..ContextGroup::SLOTS)
        .filter_map(|k| group.node(k))
        .collect();
    let mut s: Vec<SignalDef> = header()
        .into_iter()
        .map(|h| SignalDef {
            receivers: nodes.clone(),
            ..h
        })
        .collect();
    for (k, &n) in (0u32..).zip(&nodes) {
        s.push(SignalDef {
            receivers: vec![n],
            ..sig(
                &format!("Valid_{}", n.get()),
                24 + k,
                1,
                &format!(
                    "Slot of fingertip {} filled; its values are ignored when 0",
                    n.get()
                ),
            )
        });
    }
    s.push(SignalDef {
        unit: "us",
        receivers: nodes.clone(),
        ..sig(
            "Time",
            32,
            32,
            "The controller's clock at the control cycle, wrapping",
        )
    });
    for (k, &n) in (0u32..).zip(&nodes) {
        let slot = 64 + 88 * k;
        let fields = ContextPart::ALL.iter().flat_map(|&p| part_signals(p));
        for ((name, factor, range, unit, what), (offset, len)) in
            fields.zip([(0, 13), (13, 13), (26, 13), (39, 13), (52, 16), (68, 16)])
        {
            s.push(SignalDef {
                receivers: vec![n],
                ..scaled(
                    &format!("{name}_{}", n.get()),
                    slot + offset,
                    len,
                    factor,
                    range,
                    unit,
                    &format!(
                        "{what}, fingertip {}; most negative raw value invalid",
                        n.get()
                    ),
                )
            });
        }
    }
    MessageDef {
        kind: MessageKind::Context,
        address: Address::Group(group),
        comment: "Broadcast context of five fingertips, one frame per control cycle; a slot goes stale after the context timeout",
        cycle_ms: None,
        signals: s,
    }
}

fn context_part(node: NodeId) -> MessageDef {
    let mut s = header();
    s.push(SignalDef {
        mux: Mux::Selector,
        ..with_values(
            ranged("Part", 24, 2, 2, "Which part of the context"),
            vec![(0, "velocity"), (1, "acceleration"), (2, "position_error")],
        )
    });
    for part in ContextPart::ALL {
        for (k, (name, factor, range, unit, what)) in (0u32..).zip(part_signals(part)) {
            s.push(on_page(
                scaled(
                    name,
                    32 + 16 * k,
                    16,
                    factor,
                    range,
                    unit,
                    &format!("{what}; most negative raw value invalid"),
                ),
                part as u8,
            ));
        }
    }
    for sg in &mut s {
        sg.receivers = vec![node];
    }
    MessageDef {
        kind: MessageKind::ContextPart,
        address: Address::Node(node),
        comment: "One part of a fingertip's context (classic CAN: three frames per control cycle); stale after the context timeout",
        cycle_ms: None,
        signals: s,
    }
}

fn phase(node: NodeId) -> MessageDef {
    let mut s = header();
    s.extend([
        ranged(
            "PhaseId",
            24,
            8,
            7,
            "Phase to run: index in the fingertip's configuration (must be configured)",
        ),
        sig(
            "PhaseSeq",
            32,
            8,
            "Phase sequence, advanced by the controller at every phase entry",
        ),
    ]);
    for sg in &mut s {
        sg.receivers = vec![node];
    }
    MessageDef {
        kind: MessageKind::Phase,
        address: Address::Node(node),
        comment: "Phase to run; sent on every change and periodically",
        cycle_ms: None,
        signals: s,
    }
}

fn stream(node: NodeId) -> MessageDef {
    let mut s = header();
    for e in 0..MAX_EVENTS as u32 {
        s.push(sig(
            &format!("Evaluated{e}"),
            24 + e,
            1,
            &format!("Event {e} belongs to the current phase"),
        ));
    }
    for e in 0..MAX_EVENTS as u32 {
        s.push(sig(
            &format!("Unjudgeable{e}"),
            32 + e,
            1,
            &format!("Event {e} cannot be judged (faulty context or sensors)"),
        ));
    }
    for e in 0..MAX_EVENTS as u32 {
        s.push(with_values(
            ranged(
                &format!("Level{e}"),
                40 + 2 * e,
                2,
                2,
                &format!("Highest level of event {e} since the last sample"),
            ),
            level_values(),
        ));
    }
    for e in 0..MAX_EVENTS as u32 {
        s.push(scaled(
            &format!("Conf{e}"),
            56 + 16 * e,
            16,
            CONFIDENCE_FACTOR,
            ("0", "1"),
            "",
            &format!("Confidence of event {e}, Q15; 0 when not evaluated"),
        ));
    }
    MessageDef {
        kind: MessageKind::Stream,
        address: Address::Node(node),
        comment: "Confidence stream: every event's confidence and level (every 20 ticks = 4 ms by default)",
        cycle_ms: Some(4),
        signals: s,
    }
}

fn stream_page(node: NodeId) -> MessageDef {
    let mut s = header();
    s.extend([
        sig(
            "Sample",
            24,
            8,
            "Sample number; all pages of a sample share it",
        ),
        SignalDef {
            mux: Mux::Selector,
            ..ranged("EventId", 32, 3, 7, "The event of this page")
        },
    ]);
    for e in 0..MAX_EVENTS as u8 {
        s.extend([
            on_page(
                sig(
                    &format!("Unjudgeable{e}"),
                    35,
                    1,
                    &format!("Event {e} cannot be judged (faulty context or sensors)"),
                ),
                e,
            ),
            on_page(
                with_values(
                    ranged(
                        &format!("Level{e}"),
                        36,
                        2,
                        2,
                        &format!("Highest level of event {e} since the last sample"),
                    ),
                    level_values(),
                ),
                e,
            ),
            on_page(
                scaled(
                    &format!("Conf{e}"),
                    40,
                    16,
                    CONFIDENCE_FACTOR,
                    ("0", "1"),
                    "",
                    &format!("Confidence of event {e}, Q15"),
                ),
                e,
            ),
        ]);
    }
    MessageDef {
        kind: MessageKind::StreamPage,
        address: Address::Node(node),
        comment: "Confidence stream, classic CAN: one page per event of the current phase per sample (every 100 ticks = 20 ms by default)",
        cycle_ms: Some(20),
        signals: s,
    }
}

fn status(node: NodeId) -> MessageDef {
    let mut s = header();
    s.push(SignalDef {
        mux: Mux::Selector,
        ..ranged(
            "Page",
            24,
            8,
            16,
            "Status page; page 0 every heartbeat, pages 1..16 in turn",
        )
    });
    s.extend([
        on_page(
            with_values(
                ranged("ResetReason", 32, 4, 8, "Why the fingertip last reset"),
                ResetReason::ALL
                    .iter()
                    .map(|&r| (r as i64, r.name()))
                    .collect(),
            ),
            0,
        ),
        on_page(
            with_values(
                sig(
                    "Phase",
                    36,
                    4,
                    "Phase the detector runs, 0..7; 15 before the first phase frame",
                ),
                vec![(15, "none")],
            ),
            0,
        ),
    ]);
    let flag_comments = [
        "Velocity or acceleration context older than the context timeout: context-dependent events not confirmed",
        "Position error older than the context timeout",
        "No valid phase frame within the phase timeout",
        "A tick ended after its deadline, or scans were lost, since the last heartbeat",
        "CAN controller error-passive or bus-off since the last heartbeat",
        "A frame could not be queued, or was flushed, since the last heartbeat",
        "Detector image rejected: detector out of service, status heartbeats only; or no saved detector whole: the built-in one runs (DetectorMode)",
        "A sensor channel is flagged faulty",
        "Crystal not running: internal oscillator, outside the CAN FD data phase's tolerance",
        "Service state (flash being written): detector out of service, status heartbeats only",
    ];
    for (i, (name, comment)) in FaultFlags::NAMES.iter().zip(flag_comments).enumerate() {
        s.push(on_page(sig(name, 40 + i as u32, 1, comment), 0));
    }
    let counter =
        |name: &str, start, comment: &str, page| on_page(sig(name, start, 16, comment), page);
    let tenths = |name: &str, comment: &str, page| {
        on_page(
            scaled(name, 32, 16, "0.1", ("0", "6553.5"), "us", comment),
            page,
        )
    };
    s.extend([
        on_page(sig("PhaseSeq", 56, 8, "Sequence number of that phase"), 0),
        on_page(
            SignalDef {
                unit: "tick",
                ..sig("Uptime", 32, 32, "Detector ticks since boot, wrapping")
            },
            1,
        ),
        on_page(
            SignalDef {
                unit: "Hz",
                ..sig(
                    "TickRate",
                    32,
                    16,
                    "Detector rate: the unit of every tick signal",
                )
            },
            2,
        ),
        on_page(sig("ProtocolVersion", 48, 8, "Protocol version"), 2),
        on_page(
            with_values(
                sig("BusFormat", 56, 1, "The bus format the fingertip runs"),
                vec![(0, "can_fd"), (1, "classic")],
            ),
            2,
        ),
        on_page(
            with_values(
                ranged(
                    "NodeIdSource",
                    57,
                    3,
                    1,
                    "Where the node id came from at boot",
                ),
                NodeIdSource::ALL
                    .iter()
                    .map(|&n| (n as i64, n.name()))
                    .collect(),
            ),
            2,
        ),
        tenths(
            "WorstLateness",
            "Longest time from a sample's conversion to the end of its tick, saturating",
            3,
        ),
        counter(
            "LateTicks",
            48,
            "Ticks that ended after their deadline, saturating",
            3,
        ),
        tenths(
            "WorstTick",
            "Longest tick computation since boot, saturating",
            4,
        ),
        counter("LostScans", 48, "Scans the detector lost, saturating", 4),
        counter(
            "StaleEpisodes",
            32,
            "Times context or tip state went stale, saturating",
            5,
        ),
        counter(
            "LostFrames",
            48,
            "Controller frames lost (counter gaps), saturating",
            5,
        ),
        counter("BusErrors", 32, "CAN error events, saturating", 6),
        counter(
            "TxDropped",
            48,
            "Frames the fingertip could not queue or flushed, saturating",
            6,
        ),
        counter(
            "RejWrongLength",
            32,
            "Received frames rejected: wrong length",
            7,
        ),
        counter("RejBadCrc", 48, "Received frames rejected: bad CRC", 7),
        counter(
            "RejSequence",
            32,
            "Received frames rejected: repeated, or an old context frame",
            8,
        ),
        counter(
            "RejOutOfRange",
            48,
            "Received frames rejected: value out of range",
            8,
        ),
        counter(
            "RejUnknownId",
            32,
            "Received frames rejected: unknown identifier",
            9,
        ),
        counter(
            "RejPhaseNotConfigured",
            48,
            "Received frames rejected: phase not configured",
            9,
        ),
        on_page(
            sig(
                "ConfigChecksum",
                32,
                32,
                "Checksum of the active configuration",
            ),
            10,
        ),
        on_page(sig("FirmwareMajor", 32, 8, "Firmware version, major"), 11),
        on_page(sig("FirmwareMinor", 40, 8, "Firmware version, minor"), 11),
        on_page(sig("FirmwarePatch", 48, 8, "Firmware version, patch"), 11),
        on_page(
            with_values(
                ranged("DetectorMode", 56, 4, 2, "What runs the detector"),
                fingertip_can::service::Mode::ALL
                    .iter()
                    .map(|&m| (m as i64, m.name()))
                    .collect(),
            ),
            11,
        ),
        on_page(
            sig(
                "BuildHash",
                32,
                32,
                "First 32 bits of the commit the firmware was built from",
            ),
            12,
        ),
    ]);
    for part in 0..4u8 {
        s.push(on_page(
            SignalDef {
                name: format!("DetectorName{part}"),
                ..sig(
                    "DetectorName",
                    32,
                    32,
                    "Four bytes of the active detector's name (UTF-8, zero-padded, little-endian)",
                )
            },
            13 + part,
        ));
    }
    MessageDef {
        kind: MessageKind::Status,
        address: Address::Node(node),
        comment: "Status heartbeat: page 0 and one of pages 1..16 every 50 ms by default",
        cycle_ms: Some(50),
        signals: s,
    }
}

/// The database's messages for a bus of `format`, in priority order, every node and group.
pub fn messages(format: BusFormat) -> Vec<MessageDef> {
    let mut out = Vec::new();
    for kind in MessageKind::ALL {
        if !kind.carried_by(format) {
            continue;
        }
        if kind.is_broadcast() {
            out.extend(ContextGroup::all().map(context));
            continue;
        }
        out.extend(NodeId::all().map(|n| match kind {
            MessageKind::Event => event(n),
            MessageKind::ContextPart => context_part(n),
            MessageKind::Phase => phase(n),
            MessageKind::Stream => stream(n),
            MessageKind::StreamPage => stream_page(n),
            _ => status(n),
        }));
    }
    out
}

/// The DBC message name of `kind` at `address`: `Event_3`, `Context_1`.
pub fn message_name(kind: MessageKind, address: Address) -> String {
    format!("{}_{}", kind.name(), address.index())
}

fn node_name(node: NodeId) -> String {
    format!("Fingertip{}", node.get())
}

fn escape(s: &str) -> String {
    s.replace('"', "'")
}

/// The database file of `format`, relative to the workspace root.
pub fn file_name(format: BusFormat) -> &'static str {
    match format {
        BusFormat::Fd => "fingertip-can/fingertip.dbc",
        BusFormat::Classic => "fingertip-can/fingertip-classic.dbc",
    }
}

/// The database text for a bus of `format`.
pub fn render(format: BusFormat) -> String {
    let defs = messages(format);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "VERSION \"fingertip-can {} {}\"",
        fingertip_can::PROTOCOL_VERSION,
        format.name()
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
    for n in NodeId::all() {
        let _ = write!(s, " {}", node_name(n));
    }
    s.push_str("\n\n");
    for def in &defs {
        let tx = match (def.kind.direction(), def.address) {
            (fingertip_can::Direction::FromFingertip, Address::Node(n)) => node_name(n),
            _ => "Controller".to_string(),
        };
        let _ = writeln!(
            s,
            "BO_ {} {}: {} {}",
            def.raw_id(),
            def.name(),
            def.kind.data_len(),
            tx
        );
        for sg in &def.signals {
            let mux = match sg.mux {
                Mux::Always => String::new(),
                Mux::Selector => " M".into(),
                Mux::Page(p) => format!(" m{p}"),
            };
            let rx = if sg.receivers.is_empty() {
                "Controller".to_string()
            } else {
                sg.receivers
                    .iter()
                    .map(|&n| node_name(n))
                    .collect::<Vec<_>>()
                    .join(",")
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
    s.push('\n');
    let _ = writeln!(
        s,
        "CM_ \"Fingertip event detector CAN protocol, version {}, {}. Identifier = class << 4 | node (0..14), or group (0..2) for the broadcast context. Little-endian signals; every frame AUTOSAR E2E profile 5 protected, data id = CAN id. See docs/can-protocol.md.\";",
        fingertip_can::PROTOCOL_VERSION,
        match format {
            BusFormat::Fd => "CAN FD (1 Mbit/s arbitration, 5 Mbit/s data, bit-rate switching)",
            BusFormat::Classic => "classic CAN (1 Mbit/s)",
        }
    );
    for n in NodeId::all() {
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
        let id = def.raw_id();
        let _ = writeln!(s, "CM_ BO_ {id} \"{}\";", escape(def.comment));
        for sg in &def.signals {
            let _ = writeln!(s, "CM_ SG_ {id} {} \"{}\";", sg.name, escape(&sg.comment));
        }
    }
    s.push_str("BA_DEF_ \"BusType\" STRING ;\n");
    s.push_str("BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n");
    s.push_str("BA_DEF_ BO_ \"VFrameFormat\" ENUM \"StandardCAN\",\"ExtendedCAN\",\"reserved\",\"J1939PG\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\",\"ExtendedCAN_FD\";\n");
    s.push_str("BA_DEF_ BO_ \"CANFD_BRS\" ENUM \"0\",\"1\";\n");
    let fd = format == BusFormat::Fd;
    let _ = writeln!(
        s,
        "BA_DEF_DEF_ \"BusType\" \"{}\";",
        if fd { "CAN FD" } else { "CAN" }
    );
    s.push_str("BA_DEF_DEF_ \"GenMsgCycleTime\" 0;\n");
    let _ = writeln!(
        s,
        "BA_DEF_DEF_ \"VFrameFormat\" \"{}\";",
        if fd { "StandardCAN_FD" } else { "StandardCAN" }
    );
    let _ = writeln!(s, "BA_DEF_DEF_ \"CANFD_BRS\" \"{}\";", u8::from(fd));
    let _ = writeln!(
        s,
        "BA_ \"BusType\" \"{}\";",
        if fd { "CAN FD" } else { "CAN" }
    );
    for def in &defs {
        if let Some(ms) = def.cycle_ms {
            let _ = writeln!(s, "BA_ \"GenMsgCycleTime\" BO_ {} {ms};", def.raw_id());
        }
    }
    for def in &defs {
        // Every frame of a CAN FD bus is CAN FD with bit-rate switching, 8-byte ones too.
        let _ = writeln!(
            s,
            "BA_ \"VFrameFormat\" BO_ {} {};",
            def.raw_id(),
            if fd { 14 } else { 0 }
        );
    }
    for def in &defs {
        for sg in def.signals.iter().filter(|sg| !sg.values.is_empty()) {
            let _ = write!(s, "VAL_ {} {}", def.raw_id(), sg.name);
            for (v, name) in &sg.values {
                let _ = write!(s, " {v} \"{name}\"");
            }
            s.push_str(" ;\n");
        }
    }
    s
}

/// The physical values of a decoded message by DBC signal name, computed from the
/// codec's fields with the codec's own scales (not the table's), so a disagreement in
/// scaling shows. `crc` is the frame's bytes 0..2. `address` names the node numbers of a
/// broadcast context's signals.
pub fn signal_values(address: Address, message: &Message, crc: u16) -> Vec<(String, f64)> {
    let mut v: Vec<(String, f64)> = Vec::new();
    let mut put = |name: &str, value: f64| v.push((name.to_string(), value));
    let conf = |c: Confidence| c.to_f64();
    put("Crc", f64::from(crc));
    put("Counter", f64::from(message.counter().get()));
    let pair = |put: &mut dyn FnMut(&str, f64), part: ContextPart, raw: [i16; 2], suffix: &str| {
        for (name, r) in part.signal_names().iter().zip(raw) {
            put(&format!("{name}{suffix}"), f64::from(r) * part.scale());
        }
    };
    match message {
        Message::Event(m) => {
            put("EventId", f64::from(m.event.0));
            put("Level", f64::from(u8::from(m.level == Level::Confirm)));
            put("Tick", f64::from(m.tick));
            put("OnsetAge", f64::from(m.onset_age));
        }
        Message::Phase(m) => {
            put("PhaseId", f64::from(m.phase));
            put("PhaseSeq", f64::from(m.sequence));
        }
        Message::Context(m) => {
            let Address::Group(g) = address else {
                return v;
            };
            put("Time", f64::from(m.time_us));
            for (k, slot) in m.slots.iter().enumerate() {
                let Some(n) = g.node(k) else { continue };
                let suffix = format!("_{}", n.get());
                put(
                    &format!("Valid{suffix}"),
                    f64::from(u8::from(slot.is_some())),
                );
                let s = slot.unwrap_or(ContextSlot::default());
                for part in ContextPart::ALL {
                    pair(&mut put, part, s.part(part), &suffix);
                }
            }
        }
        Message::ContextPart(m) => {
            put("Part", f64::from(m.part as u8));
            pair(&mut put, m.part, m.value, "");
        }
        Message::Stream(m) => {
            for e in 0..MAX_EVENTS {
                put(&format!("Evaluated{e}"), f64::from((m.evaluated >> e) & 1));
                put(
                    &format!("Unjudgeable{e}"),
                    f64::from((m.unjudgeable >> e) & 1),
                );
                put(&format!("Level{e}"), f64::from(m.levels[e] as u8));
                put(&format!("Conf{e}"), conf(m.confidences[e]));
            }
        }
        Message::StreamPage(m) => {
            let e = m.event.0;
            put("Sample", f64::from(m.sample));
            put("EventId", f64::from(e));
            put(
                &format!("Unjudgeable{e}"),
                f64::from(u8::from(m.unjudgeable)),
            );
            put(&format!("Level{e}"), f64::from(m.level as u8));
            put(&format!("Conf{e}"), conf(m.confidence));
        }
        Message::Status(m) => {
            put("Page", f64::from(m.page.page()));
            let mut two = |a: &str, x: u16, b: &str, y: u16| {
                put(a, f64::from(x));
                put(b, f64::from(y));
            };
            match m.page {
                StatusPage::Health {
                    reset,
                    phase,
                    faults,
                    phase_seq,
                } => {
                    two("ResetReason", reset as u16, "PhaseSeq", phase_seq.into());
                    put("Phase", f64::from(phase.unwrap_or(fingertip_can::NO_PHASE)));
                    for (i, name) in FaultFlags::NAMES.iter().enumerate() {
                        put(name, f64::from((faults.0 >> i) & 1));
                    }
                }
                StatusPage::Uptime { uptime } => put("Uptime", f64::from(uptime)),
                StatusPage::Identity {
                    tick_rate_hz,
                    protocol,
                    format,
                    node_source,
                } => {
                    two("TickRate", tick_rate_hz, "ProtocolVersion", protocol.into());
                    put(
                        "BusFormat",
                        f64::from(u8::from(format == BusFormat::Classic)),
                    );
                    put("NodeIdSource", f64::from(node_source as u8));
                }
                StatusPage::Lateness { worst, late_ticks } => {
                    put("WorstLateness", f64::from(worst) * 0.1);
                    put("LateTicks", f64::from(late_ticks));
                }
                StatusPage::Compute {
                    worst_tick,
                    lost_scans,
                } => {
                    put("WorstTick", f64::from(worst_tick) * 0.1);
                    put("LostScans", f64::from(lost_scans));
                }
                StatusPage::Link {
                    stale_episodes,
                    lost_frames,
                } => two("StaleEpisodes", stale_episodes, "LostFrames", lost_frames),
                StatusPage::Bus {
                    bus_errors,
                    tx_dropped,
                } => two("BusErrors", bus_errors, "TxDropped", tx_dropped),
                StatusPage::RejectsFrame {
                    wrong_length,
                    bad_crc,
                } => two("RejWrongLength", wrong_length, "RejBadCrc", bad_crc),
                StatusPage::RejectsContent {
                    sequence,
                    out_of_range,
                } => two("RejSequence", sequence, "RejOutOfRange", out_of_range),
                StatusPage::RejectsRoute {
                    unknown_id,
                    phase_not_configured,
                } => two(
                    "RejUnknownId",
                    unknown_id,
                    "RejPhaseNotConfigured",
                    phase_not_configured,
                ),
                StatusPage::Config { checksum } => put("ConfigChecksum", f64::from(checksum)),
                StatusPage::Firmware { version, mode } => {
                    put("FirmwareMajor", f64::from(version[0]));
                    put("FirmwareMinor", f64::from(version[1]));
                    put("FirmwarePatch", f64::from(version[2]));
                    put("DetectorMode", f64::from(mode as u8));
                }
                StatusPage::Build { hash } => put("BuildHash", f64::from(hash)),
                StatusPage::DetectorName { part, bytes } => put(
                    &format!("DetectorName{part}"),
                    f64::from(u32::from_le_bytes(bytes)),
                ),
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
        for format in [BusFormat::Fd, BusFormat::Classic] {
            for def in messages(format) {
                let bits = 8 * def.kind.data_len() as u32;
                // Check every multiplexer value separately.
                for page in 0..16u8 {
                    let mut used = vec![false; bits as usize];
                    for sg in &def.signals {
                        if let Mux::Page(p) = sg.mux
                            && p != page
                        {
                            continue;
                        }
                        assert!(sg.start + sg.len <= bits, "{} {}", def.name(), sg.name);
                        for b in sg.start..sg.start + sg.len {
                            assert!(!used[b as usize], "{} {} overlaps", def.name(), sg.name);
                            used[b as usize] = true;
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn renders_every_message_for_every_node() {
        let fd = render(BusFormat::Fd);
        // Event, Phase, Stream, Status per node, and three context groups.
        assert_eq!(fd.matches("\nBO_ ").count(), 4 * 15 + 3);
        assert!(fd.contains("BO_ 272 Event_0: 8 Fingertip0"));
        assert!(fd.contains("BO_ 289 Context_1: 64 Controller"));
        assert!(
            fd.contains(" SG_ VelDesX_5 : 64|13@1- (0.0001,0) [-0.4095|0.4095] \"m/s\" Fingertip5")
        );
        assert!(fd.contains(" SG_ Time : 32|32@1+ (1,0) [0|4294967295] \"us\" Fingertip5,Fingertip6,Fingertip7,Fingertip8,Fingertip9"));
        assert!(fd.contains("BA_ \"VFrameFormat\" BO_ 272 14;"));
        let classic = render(BusFormat::Classic);
        assert_eq!(classic.matches("\nBO_ ").count(), 5 * 15);
        assert!(classic.contains("BO_ 311 ContextPart_7: 8 Controller"));
        assert!(!classic.contains("Context_"));
        assert!(
            classic
                .contains(" SG_ Conf7 m7 : 40|16@1+ (0.000030517578125,0) [0|1] \"\" Controller")
        );
    }
}
