//! The fingertip's CAN protocol (version 2): identifiers, a frame type, the codec of every
//! message, end-to-end protection, and the fingertip's receive and transmit logic.
//!
//! CAN FD by default: 1 Mbit/s arbitration, 5 Mbit/s data with bit-rate switching,
//! standard 11-bit identifiers, little-endian signals. Classic CAN (frames of at most 8
//! bytes) is a [`BusFormat`] option with its own two messages in place of the two long
//! ones. The published databases `fingertip-can/fingertip.dbc` (CAN FD) and
//! `fingertip-can/fingertip-classic.dbc` describe the same frames; the host tests hold this
//! code and those files to each other through a third-party decoder (cantools).
//! `docs/can-protocol.md` is the human-readable specification.
//!
//! # Identifiers
//!
//! `id = class << 4 | index`: the message [class](MessageKind::class) in bits 10..4, the
//! [`NodeId`] (0..=14) or, for the broadcast context, the [`ContextGroup`] (0..=2) in bits
//! 3..0. Every identifier lies in 0x110..=0x17F: above CANopen's NMT (0x000), SYNC (0x080),
//! EMCY (0x081..=0x0FF) and TIME (0x100), below its PDOs (0x181 and up), so a lower
//! identifier of this protocol wins arbitration over every CANopen object but those four.
//!
//! | class | message | direction | bytes | format |
//! |---|---|---|---|---|
//! | 0x11 | [`EventMsg`] | fingertip → controller | 8 | both |
//! | 0x12 | [`ContextMsg`] (per group of five fingertips) | controller → fingertips | 64 | CAN FD |
//! | 0x13 | [`ContextPartMsg`] | controller → fingertip | 8 | classic |
//! | 0x14 | [`PhaseMsg`] | controller → fingertip | 5 | both |
//! | 0x15 | [`StreamMsg`] | fingertip → controller | 24 | CAN FD |
//! | 0x16 | [`StreamPageMsg`] | fingertip → controller | 8 | classic |
//! | 0x17 | [`StatusPage`] | fingertip → controller | 8 | both |
//!
//! Every frame carries a CRC-16 and an 8-bit counter ([`e2e`], AUTOSAR E2E profile 5
//! layout). Identifiers 0x001..=0x07F stay free for traffic that must beat everything
//! (an emergency stop); [`SERVICE_REQUEST_CLASS`] and [`SERVICE_RESPONSE_CLASS`] carry
//! the per-node service channel ([`service`]).
//!
//! # Modules
//! - [`e2e`]: the CRC-16 and the rolling counter.
//! - the codec: [`Message::decode`], [`Message::encode`] and one type per message.
//! - [`rx`] ([`Receiver`]): validates the controller's frames, counts rejections and lost
//!   frames, keeps the context and tells when it has gone stale.
//! - [`tx`] ([`Transmitter`]): turns each tick's detector output into the frames to send.
//! - [`transfer`]: the segmented transfer (ISO 15765-2 framing on CAN FD, flow control) on
//!   a node's request and response identifiers, [`SERVICE_REQUEST_CLASS`] and
//!   [`SERVICE_RESPONSE_CLASS`].
//! - [`service`]: the requests and responses it carries (load a detector, read and write
//!   the store's keys, identify), each with a CRC-32.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

mod codec;
pub mod e2e;
pub mod rx;
pub mod service;
pub mod transfer;
pub mod tx;

pub use codec::{
    ACC_DES_RAW_MAX, ContextMsg, ContextPart, ContextPartMsg, ContextSlot, DecodeError,
    EncodeError, EventMsg, FaultFlags, LevelState, Message, NO_PHASE, NodeIdSource,
    POS_ERR_RAW_MAX, PROTOCOL_VERSION, PhaseMsg, ResetReason, STATUS_PAGES, StatusMsg, StatusPage,
    StreamMsg, StreamPageMsg, VEL_DES_RAW_MAX,
};
pub use e2e::Counter;
pub use rx::{
    Accepted, ControllerInputs, Decoded, Freshness, REJECT_REASONS, Receiver, RejectCounts,
    RejectReason, RxConfigError, RxCounts, RxLink, RxState,
};
pub use tx::{
    DEFAULT_CLASSIC_STREAM_DECIMATION, DEFAULT_HEARTBEAT_MS, DEFAULT_STREAM_DECIMATION,
    MAX_TX_FRAMES, Status, Transmitter, TxConfigError, TxFrames, TxState,
};

pub use embedded_can::{ExtendedId, Id, StandardId};

/// The node id of a fingertip on the bus, `0..=14`: the low four bits of each of its
/// identifiers, and its slot in the broadcast context ([`ContextGroup::of`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeId(u8);

impl NodeId {
    /// The largest node id.
    pub const MAX: u8 = 14;
    /// Node ids available on one bus: three context groups of five.
    pub const COUNT: usize = 15;

    /// A node id; `None` above [`NodeId::MAX`].
    pub const fn new(raw: u8) -> Option<NodeId> {
        if raw <= NodeId::MAX {
            Some(NodeId(raw))
        } else {
            None
        }
    }

    /// The raw value, `0..=14`.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// Every node id, in order.
    pub fn all() -> impl Iterator<Item = NodeId> {
        (0..=NodeId::MAX).map(NodeId)
    }
}

/// A group of five fingertips whose context travels in one broadcast [`ContextMsg`]:
/// group `g` carries nodes `5g..=5g + 4` in slots 0..=4. `0..=2`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContextGroup(u8);

impl ContextGroup {
    /// Groups on one bus.
    pub const COUNT: usize = 3;
    /// Fingertips (slots) per group.
    pub const SLOTS: usize = 5;

    /// A group; `None` above 2.
    pub const fn new(raw: u8) -> Option<ContextGroup> {
        if (raw as usize) < ContextGroup::COUNT {
            Some(ContextGroup(raw))
        } else {
            None
        }
    }

    /// The raw value, `0..=2`.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// The group holding `node`'s context.
    pub const fn of(node: NodeId) -> ContextGroup {
        ContextGroup(node.0 / ContextGroup::SLOTS as u8)
    }

    /// `node`'s slot in its group, `0..=4`.
    pub const fn slot_of(node: NodeId) -> usize {
        node.0 as usize % ContextGroup::SLOTS
    }

    /// The node in slot `slot` (`0..=4`) of this group.
    pub const fn node(self, slot: usize) -> Option<NodeId> {
        if slot < ContextGroup::SLOTS {
            NodeId::new(self.0 * ContextGroup::SLOTS as u8 + slot as u8)
        } else {
            None
        }
    }

    /// Every group, in order.
    pub fn all() -> impl Iterator<Item = ContextGroup> {
        (0..ContextGroup::COUNT as u8).map(ContextGroup)
    }
}

/// What the low four bits of an identifier name: a fingertip, or a context group.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Address {
    /// A fingertip: the sender of its frames, or the one the controller addresses.
    Node(NodeId),
    /// The fingertips of a broadcast context frame.
    Group(ContextGroup),
}

impl Address {
    /// The fingertip, for a per-node frame.
    pub const fn node(self) -> Option<NodeId> {
        match self {
            Address::Node(n) => Some(n),
            Address::Group(_) => None,
        }
    }

    /// The four low bits of the identifier.
    pub const fn index(self) -> u8 {
        match self {
            Address::Node(n) => n.0,
            Address::Group(g) => g.0,
        }
    }
}

/// Who sends a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// The robot's controller sends it to the fingertips.
    ToFingertip,
    /// A fingertip sends it to the controller.
    FromFingertip,
}

/// The link layer a bus runs: which frames exist on it and how long they may be.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusFormat {
    /// CAN FD with bit-rate switching: frames up to 64 bytes. The default.
    #[default]
    Fd,
    /// Classic CAN: frames of at most 8 bytes. The broadcast context becomes three
    /// [`ContextPartMsg`] per fingertip, the stream one [`StreamPageMsg`] per event.
    Classic,
}

impl BusFormat {
    /// The name the tools print.
    pub const fn name(self) -> &'static str {
        match self {
            BusFormat::Fd => "CAN FD",
            BusFormat::Classic => "classic CAN",
        }
    }

    /// Ticks per confidence-stream sample by default on this format:
    /// [`DEFAULT_STREAM_DECIMATION`] on CAN FD, [`DEFAULT_CLASSIC_STREAM_DECIMATION`] on
    /// classic CAN (which cannot carry the faster stream next to a hand's context).
    pub const fn default_stream_decimation(self) -> u16 {
        match self {
            BusFormat::Fd => DEFAULT_STREAM_DECIMATION,
            BusFormat::Classic => DEFAULT_CLASSIC_STREAM_DECIMATION,
        }
    }
}

/// The class of the service request identifiers (controller → fingertip, `0x680 | node`):
/// the [`service`] channel's requests, in [`transfer`] frames. Low priority on purpose, and
/// outside CANopen's predefined objects.
pub const SERVICE_REQUEST_CLASS: u16 = 0x68;
/// The class of the service response identifiers (fingertip → controller,
/// `0x690 | node`); see [`SERVICE_REQUEST_CLASS`].
pub const SERVICE_RESPONSE_CLASS: u16 = 0x69;

/// The identifier of `node`'s service requests, `0x680 + node`.
pub const fn service_request_id(node: NodeId) -> StandardId {
    standard(SERVICE_REQUEST_CLASS << 4 | node.0 as u16)
}

/// The identifier of `node`'s service responses, `0x690 + node`.
pub const fn service_response_id(node: NodeId) -> StandardId {
    standard(SERVICE_RESPONSE_CLASS << 4 | node.0 as u16)
}

/// The messages of the protocol, in priority order (highest first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MessageKind {
    /// A decision level was raised ([`EventMsg`]).
    Event,
    /// The broadcast context of five fingertips ([`ContextMsg`], CAN FD).
    Context,
    /// One part of a fingertip's context ([`ContextPartMsg`], classic CAN).
    ContextPart,
    /// The phase to run ([`PhaseMsg`]).
    Phase,
    /// Every event's confidence and level ([`StreamMsg`], CAN FD).
    Stream,
    /// One event's confidence and level ([`StreamPageMsg`], classic CAN).
    StreamPage,
    /// The multiplexed status heartbeat ([`StatusPage`]).
    Status,
}

impl MessageKind {
    /// Every message, highest priority first.
    pub const ALL: [MessageKind; 7] = [
        MessageKind::Event,
        MessageKind::Context,
        MessageKind::ContextPart,
        MessageKind::Phase,
        MessageKind::Stream,
        MessageKind::StreamPage,
        MessageKind::Status,
    ];

    /// The class: bits 10..4 of the identifier, `0x11..=0x17`.
    pub const fn class(self) -> u16 {
        match self {
            MessageKind::Event => 0x11,
            MessageKind::Context => 0x12,
            MessageKind::ContextPart => 0x13,
            MessageKind::Phase => 0x14,
            MessageKind::Stream => 0x15,
            MessageKind::StreamPage => 0x16,
            MessageKind::Status => 0x17,
        }
    }

    /// Whether the low four bits name a [`ContextGroup`] rather than a [`NodeId`].
    pub const fn is_broadcast(self) -> bool {
        matches!(self, MessageKind::Context)
    }

    /// The raw 11-bit identifier of this message for the node or group `index`.
    pub const fn raw_id_of(self, index: u8) -> u16 {
        (self.class() << 4) | (index & 0x0F) as u16
    }

    /// The raw identifier of this message for `node` (for [`MessageKind::Context`], the
    /// node's group's).
    pub const fn raw_id(self, node: NodeId) -> u16 {
        if self.is_broadcast() {
            self.raw_id_of(ContextGroup::of(node).0)
        } else {
            self.raw_id_of(node.0)
        }
    }

    /// The identifier of this message for `node` (for [`MessageKind::Context`], the node's
    /// group's).
    pub const fn id(self, node: NodeId) -> StandardId {
        standard(self.raw_id(node))
    }

    /// The identifier of this message for `address`; `None` when the address does not
    /// fit the message (a group for a per-node message, or the reverse).
    pub const fn id_for(self, address: Address) -> Option<StandardId> {
        match (self.is_broadcast(), address) {
            (true, Address::Group(g)) => Some(standard(self.raw_id_of(g.0))),
            (false, Address::Node(n)) => Some(standard(self.raw_id_of(n.0))),
            _ => None,
        }
    }

    /// The message and address an identifier belongs to; `None` for extended identifiers
    /// and for standard identifiers outside the protocol.
    pub fn from_id(id: Id) -> Option<(MessageKind, Address)> {
        match id {
            Id::Standard(sid) => MessageKind::from_raw_id(sid.as_raw()),
            Id::Extended(_) => None,
        }
    }

    /// As [`MessageKind::from_id`], from a raw standard identifier.
    pub fn from_raw_id(raw: u16) -> Option<(MessageKind, Address)> {
        let class = raw >> 4;
        let index = (raw & 0x0F) as u8;
        let kind = *MessageKind::ALL.iter().find(|k| k.class() == class)?;
        let address = if kind.is_broadcast() {
            Address::Group(ContextGroup::new(index)?)
        } else {
            Address::Node(NodeId::new(index)?)
        };
        Some((kind, address))
    }

    /// The data length: every frame of a message has exactly this many bytes.
    pub const fn data_len(self) -> usize {
        match self {
            MessageKind::Context => 64,
            MessageKind::Stream => 24,
            MessageKind::Phase => 5,
            _ => 8,
        }
    }

    /// The bus formats that carry this message.
    pub const fn carried_by(self, format: BusFormat) -> bool {
        match self {
            MessageKind::Context | MessageKind::Stream => matches!(format, BusFormat::Fd),
            MessageKind::ContextPart | MessageKind::StreamPage => {
                matches!(format, BusFormat::Classic)
            }
            _ => true,
        }
    }

    /// Who sends it.
    pub const fn direction(self) -> Direction {
        match self {
            MessageKind::Context | MessageKind::ContextPart | MessageKind::Phase => {
                Direction::ToFingertip
            }
            _ => Direction::FromFingertip,
        }
    }

    /// The message's name as the DBC and the tools write it.
    pub const fn name(self) -> &'static str {
        match self {
            MessageKind::Event => "Event",
            MessageKind::Context => "Context",
            MessageKind::ContextPart => "ContextPart",
            MessageKind::Phase => "Phase",
            MessageKind::Stream => "Stream",
            MessageKind::StreamPage => "StreamPage",
            MessageKind::Status => "Status",
        }
    }
}

/// A raw identifier below 0x800 as a [`StandardId`].
const fn standard(raw: u16) -> StandardId {
    match StandardId::new(raw) {
        Some(id) => id,
        // Unreachable: every class is below 0x80, so raw < 0x800.
        None => StandardId::ZERO,
    }
}

/// The most data bytes of a frame (CAN FD).
pub const MAX_DATA: usize = 64;

/// The data lengths a CAN FD frame can have: 0..=8, then 12, 16, 20, 24, 32, 48, 64.
pub const fn is_fd_length(len: usize) -> bool {
    matches!(len, 0..=8 | 12 | 16 | 20 | 24 | 32 | 48 | 64)
}

/// A data frame with a standard identifier: classic (0..=8 bytes) or CAN FD (a
/// [valid FD length](is_fd_length) up to 64 bytes, sent with bit-rate switching). What the
/// codec produces and what the firmware hands to the CAN controller.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: StandardId,
    len: u8,
    fd: bool,
    data: [u8; MAX_DATA],
}

impl CanFrame {
    /// A classic frame; `None` if `data` is longer than 8 bytes.
    pub fn new(id: StandardId, data: &[u8]) -> Option<CanFrame> {
        if data.len() > 8 {
            return None;
        }
        CanFrame::with_format(id, data, false)
    }

    /// A CAN FD frame; `None` if `data`'s length is not a CAN FD length.
    pub fn new_fd(id: StandardId, data: &[u8]) -> Option<CanFrame> {
        CanFrame::with_format(id, data, true)
    }

    /// A frame in the format `format` asks for.
    pub fn for_bus(format: BusFormat, id: StandardId, data: &[u8]) -> Option<CanFrame> {
        match format {
            BusFormat::Fd => CanFrame::new_fd(id, data),
            BusFormat::Classic => CanFrame::new(id, data),
        }
    }

    fn with_format(id: StandardId, data: &[u8], fd: bool) -> Option<CanFrame> {
        if !is_fd_length(data.len()) {
            return None;
        }
        let mut buf = [0u8; MAX_DATA];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(CanFrame {
            id,
            len: data.len() as u8,
            fd,
            data: buf,
        })
    }

    /// The identifier.
    pub const fn id(&self) -> StandardId {
        self.id
    }

    /// The data bytes (0..=64 of them).
    pub fn data(&self) -> &[u8] {
        // len <= 64 by construction; the fallback never runs.
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// The number of data bytes, 0..=64.
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the frame has no data bytes.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether it is a CAN FD frame (sent with bit-rate switching).
    pub const fn is_fd(&self) -> bool {
        self.fd
    }

    /// The same frame in the format `format` asks for; `None` for a classic frame longer
    /// than 8 bytes.
    pub fn in_format(&self, format: BusFormat) -> Option<CanFrame> {
        CanFrame::for_bus(format, self.id, self.data())
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for CanFrame {
    fn format(&self, f: defmt::Formatter<'_>) {
        let sep = if self.fd { "##1" } else { "#" };
        defmt::write!(
            f,
            "{=u16:03X}{=str}{=[u8]:02X}",
            self.id.as_raw(),
            sep,
            self.data()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_follow_the_layout_and_events_win_arbitration() {
        let n = |i| NodeId::new(i).unwrap();
        assert_eq!(MessageKind::Event.raw_id(n(0)), 0x110);
        assert_eq!(MessageKind::Event.raw_id(n(14)), 0x11E);
        assert_eq!(MessageKind::Context.raw_id(n(7)), 0x121);
        assert_eq!(MessageKind::Status.raw_id(n(14)), 0x17E);
        // The lowest-priority event frame still beats the highest-priority other frame.
        for k in &MessageKind::ALL[1..] {
            assert!(MessageKind::Event.raw_id(n(14)) < k.raw_id(n(0)));
        }
        for k in MessageKind::ALL {
            for node in NodeId::all() {
                let want = if k.is_broadcast() {
                    Address::Group(ContextGroup::of(node))
                } else {
                    Address::Node(node)
                };
                assert_eq!(MessageKind::from_raw_id(k.raw_id(node)), Some((k, want)));
                assert_eq!(k.id_for(want), Some(k.id(node)));
            }
        }
        assert_eq!(MessageKind::from_raw_id(0x10F), None);
        assert_eq!(
            MessageKind::from_raw_id(0x11F),
            None,
            "node 15 does not exist"
        );
        assert_eq!(
            MessageKind::from_raw_id(0x123),
            None,
            "group 3 does not exist"
        );
        assert_eq!(MessageKind::from_raw_id(0x180), None);
        assert_eq!(NodeId::new(15), None);
        assert_eq!(
            MessageKind::Event.id_for(Address::Group(ContextGroup(0))),
            None
        );
    }

    #[test]
    fn the_plan_leaves_canopen_and_the_reserved_channel_alone() {
        let ours: Vec<u16> = MessageKind::ALL
            .iter()
            .flat_map(|k| NodeId::all().map(move |n| k.raw_id(n)))
            .collect();
        for &id in &ours {
            // NMT, SYNC, EMCY and TIME below; PDOs, SDOs and heartbeats from 0x181 up.
            assert!((0x101..=0x17F).contains(&id), "{id:#05X}");
        }
        for node in NodeId::all() {
            for class in [SERVICE_REQUEST_CLASS, SERVICE_RESPONSE_CLASS] {
                let id = class << 4 | u16::from(node.get());
                assert!(!ours.contains(&id));
                // Not CANopen's SDOs (0x581..=0x67F) nor heartbeats (0x701..=0x77F).
                assert!((0x680..=0x6DF).contains(&id), "{id:#05X}");
            }
            assert_eq!(
                service_request_id(node).as_raw(),
                0x680 + u16::from(node.get())
            );
            assert_eq!(
                service_response_id(node).as_raw(),
                0x690 + u16::from(node.get())
            );
        }
    }

    #[test]
    fn groups_hold_five_nodes_each() {
        let g = ContextGroup::of(NodeId::new(12).unwrap());
        assert_eq!(g.get(), 2);
        assert_eq!(ContextGroup::slot_of(NodeId::new(12).unwrap()), 2);
        assert_eq!(g.node(2), NodeId::new(12));
        assert_eq!(g.node(5), None);
        assert_eq!(ContextGroup::new(3), None);
        let mut covered = 0;
        for g in ContextGroup::all() {
            for s in 0..ContextGroup::SLOTS {
                let n = g.node(s).unwrap();
                assert_eq!((ContextGroup::of(n), ContextGroup::slot_of(n)), (g, s));
                covered += 1;
            }
        }
        assert_eq!(covered, NodeId::COUNT);
    }

    #[test]
    fn frames_have_their_formats_lengths() {
        let id = StandardId::new(0x123).unwrap();
        assert!(CanFrame::new(id, &[0; 9]).is_none());
        assert!(CanFrame::new_fd(id, &[0; 9]).is_none());
        assert!(CanFrame::new_fd(id, &[0; 65]).is_none());
        let f = CanFrame::new_fd(id, &[7; 24]).unwrap();
        assert_eq!((f.len(), f.is_fd(), f.data()[23]), (24, true, 7));
        let c = CanFrame::new(id, &[1, 2, 3]).unwrap();
        assert_eq!((c.data(), c.is_fd()), (&[1u8, 2, 3][..], false));
        assert!(CanFrame::for_bus(BusFormat::Classic, id, &[0; 24]).is_none());
        for k in MessageKind::ALL {
            assert!(is_fd_length(k.data_len()));
            assert_eq!(k.carried_by(BusFormat::Classic), k.data_len() <= 8, "{k:?}");
        }
    }
}
