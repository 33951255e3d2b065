//! The fingertip's CAN protocol: identifiers, a frame type, the codec of every message,
//! end-to-end protection, and the fingertip's receive and transmit logic.
//!
//! Classic CAN, standard 11-bit identifiers, at most 8 data bytes, little-endian signals.
//! The published database `fingertip-can/fingertip.dbc` describes the same frames; the host tests
//! hold this code and that file to each other through a third-party decoder (cantools).
//! `docs/can-protocol.md` is the human-readable specification.
//!
//! # Identifiers
//!
//! `id = class << 4 | node`: the message [class](MessageKind::class) in bits 10..4, the
//! [`NodeId`] (0..=15) in bits 3..0. A lower identifier wins arbitration, so every event
//! frame (class 0x08) beats every other frame of the protocol, whatever the node.
//!
//! | class | message | direction | bytes | protected |
//! |---|---|---|---|---|
//! | 0x08 | [`EventMsg`] | fingertip → controller | 8 | counter + CRC-8 |
//! | 0x09 | [`PhaseMsg`] | controller → fingertip | 4 | counter + CRC-8 |
//! | 0x0A | [`ContextMsg`] | controller → fingertip | 8 | counter + CRC-8 |
//! | 0x0B | [`TipStateMsg`] | controller → fingertip | 6 | counter + CRC-8 |
//! | 0x0C | [`ConfidenceMsg`] | fingertip → controller | 8 | sequence number |
//! | 0x0D | [`StatusPage`] | fingertip → controller | 8 | — |
//!
//! Identifiers below 0x080 are left to traffic that must win over the fingertips' (an
//! emergency stop, say).
//!
//! # Modules
//! - [`e2e`]: the rolling counter and the CRC-8 (AUTOSAR E2E profile 2 layout).
//! - the codec: [`Message::decode`], [`Message::encode`] and one type per message.
//! - [`rx`] ([`Receiver`]): validates the controller's frames, counts rejections by reason,
//!   keeps the context and tells when it has gone stale.
//! - [`tx`] ([`Transmitter`]): turns each tick's detector output into the frames to send.

#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

mod codec;
pub mod e2e;
pub mod rx;
pub mod tx;

pub use codec::{
    ACC_DES_RAW_MAX, ConfidenceMsg, ContextMsg, DecodeError, EncodeError, EventMsg, FaultFlags,
    Message, POS_ERR_RAW_MAX, PROTOCOL_VERSION, PhaseMsg, ResetReason, STATUS_PAGES, StatusPage,
    TipStateMsg, VEL_DES_RAW_MAX,
};
pub use e2e::Counter;
pub use rx::{
    Accepted, ControllerInputs, Freshness, REJECT_REASONS, Receiver, RejectCounts, RejectReason,
    RxConfigError, RxCounts, RxLink, RxState,
};
pub use tx::{
    DEFAULT_HEARTBEAT_MS, DEFAULT_STREAM_DECIMATION, MAX_TX_FRAMES, Status, Transmitter,
    TxConfigError, TxFrames, TxState,
};

pub use embedded_can::{ExtendedId, Id, StandardId};

/// The node id of a fingertip on the bus, `0..=15`: the low four bits of each of its
/// identifiers. The controller addresses a fingertip's phase, context and tip state
/// frames with it too.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeId(u8);

impl NodeId {
    /// The largest node id.
    pub const MAX: u8 = 15;
    /// Node ids available on one bus.
    pub const COUNT: usize = 16;

    /// A node id; `None` above [`NodeId::MAX`].
    pub const fn new(raw: u8) -> Option<NodeId> {
        if raw <= NodeId::MAX {
            Some(NodeId(raw))
        } else {
            None
        }
    }

    /// The raw value, `0..=15`.
    pub const fn get(self) -> u8 {
        self.0
    }
}

/// Who sends a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// The robot's controller sends it to one fingertip.
    ToFingertip,
    /// A fingertip sends it to the controller.
    FromFingertip,
}

/// The messages of the protocol, in priority order (highest first).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MessageKind {
    /// A decision level was raised ([`EventMsg`]).
    Event,
    /// The phase to run ([`PhaseMsg`]).
    Phase,
    /// The controller's commanded motion ([`ContextMsg`]).
    Context,
    /// The tip position error ([`TipStateMsg`]).
    TipState,
    /// The decimated confidence stream ([`ConfidenceMsg`]).
    Confidence,
    /// The multiplexed status heartbeat ([`StatusPage`]).
    Status,
}

impl MessageKind {
    /// Every message, highest priority first.
    pub const ALL: [MessageKind; 6] = [
        MessageKind::Event,
        MessageKind::Phase,
        MessageKind::Context,
        MessageKind::TipState,
        MessageKind::Confidence,
        MessageKind::Status,
    ];

    /// The class: bits 10..4 of the identifier, `0x08..=0x0D`.
    pub const fn class(self) -> u16 {
        match self {
            MessageKind::Event => 0x08,
            MessageKind::Phase => 0x09,
            MessageKind::Context => 0x0A,
            MessageKind::TipState => 0x0B,
            MessageKind::Confidence => 0x0C,
            MessageKind::Status => 0x0D,
        }
    }

    /// The raw 11-bit identifier of this message for `node`, `0x080..=0x0DF`.
    pub const fn raw_id(self, node: NodeId) -> u16 {
        (self.class() << 4) | node.0 as u16
    }

    /// The identifier of this message for `node`.
    pub const fn id(self, node: NodeId) -> StandardId {
        match StandardId::new(self.raw_id(node)) {
            Some(id) => id,
            // Unreachable: raw_id is at most 0x0DF < 0x800.
            None => StandardId::ZERO,
        }
    }

    /// The message and node an identifier belongs to; `None` for extended identifiers and
    /// for standard identifiers outside the protocol.
    pub fn from_id(id: Id) -> Option<(MessageKind, NodeId)> {
        match id {
            Id::Standard(sid) => MessageKind::from_raw_id(sid.as_raw()),
            Id::Extended(_) => None,
        }
    }

    /// As [`MessageKind::from_id`], from a raw standard identifier.
    pub fn from_raw_id(raw: u16) -> Option<(MessageKind, NodeId)> {
        let class = raw >> 4;
        let node = NodeId((raw & 0x0F) as u8);
        MessageKind::ALL
            .iter()
            .find(|k| k.class() == class)
            .map(|&k| (k, node))
    }

    /// The data length code: every frame of a message has exactly this many bytes.
    pub const fn dlc(self) -> usize {
        match self {
            MessageKind::Phase => 4,
            MessageKind::TipState => 6,
            _ => 8,
        }
    }

    /// Who sends it.
    pub const fn direction(self) -> Direction {
        match self {
            MessageKind::Phase | MessageKind::Context | MessageKind::TipState => {
                Direction::ToFingertip
            }
            _ => Direction::FromFingertip,
        }
    }

    /// Whether the payload carries a rolling counter and a CRC-8 ([`e2e`]).
    pub const fn is_protected(self) -> bool {
        matches!(
            self,
            MessageKind::Event | MessageKind::Phase | MessageKind::Context | MessageKind::TipState
        )
    }

    /// The message's name as the DBC and the tools write it.
    pub const fn name(self) -> &'static str {
        match self {
            MessageKind::Event => "Event",
            MessageKind::Phase => "Phase",
            MessageKind::Context => "Context",
            MessageKind::TipState => "TipState",
            MessageKind::Confidence => "Confidence",
            MessageKind::Status => "Status",
        }
    }
}

/// A classic CAN data frame with a standard identifier and 0..=8 data bytes: what the
/// codec produces and what the firmware hands to the CAN peripheral.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: StandardId,
    len: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// A frame; `None` if `data` is longer than 8 bytes.
    pub fn new(id: StandardId, data: &[u8]) -> Option<CanFrame> {
        let mut buf = [0u8; 8];
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(CanFrame {
            id,
            len: data.len() as u8,
            data: buf,
        })
    }

    /// The identifier.
    pub const fn id(&self) -> StandardId {
        self.id
    }

    /// The data bytes (0..=8 of them).
    pub fn data(&self) -> &[u8] {
        // len <= 8 by construction; the fallback never runs.
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// The number of data bytes, 0..=8.
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the frame has no data bytes.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for CanFrame {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(f, "{=u16:03X}#{=[u8]:02X}", self.id.as_raw(), self.data());
    }
}

impl embedded_can::Frame for CanFrame {
    /// Standard identifiers and up to 8 bytes only; `None` otherwise.
    fn new(id: impl Into<Id>, data: &[u8]) -> Option<Self> {
        match id.into() {
            Id::Standard(sid) => CanFrame::new(sid, data),
            Id::Extended(_) => None,
        }
    }

    /// The protocol uses no remote frames: always `None`.
    fn new_remote(_id: impl Into<Id>, _dlc: usize) -> Option<Self> {
        None
    }

    fn is_extended(&self) -> bool {
        false
    }

    fn is_remote_frame(&self) -> bool {
        false
    }

    fn id(&self) -> Id {
        Id::Standard(self.id)
    }

    fn dlc(&self) -> usize {
        self.len()
    }

    fn data(&self) -> &[u8] {
        CanFrame::data(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_follow_the_layout_and_events_win_arbitration() {
        let n = |i| NodeId::new(i).unwrap();
        assert_eq!(MessageKind::Event.raw_id(n(0)), 0x080);
        assert_eq!(MessageKind::Event.raw_id(n(15)), 0x08F);
        assert_eq!(MessageKind::Status.raw_id(n(15)), 0x0DF);
        // The lowest-priority event frame still beats the highest-priority other frame.
        for k in &MessageKind::ALL[1..] {
            assert!(MessageKind::Event.raw_id(n(15)) < k.raw_id(n(0)));
        }
        for k in MessageKind::ALL {
            for i in 0..=15 {
                assert_eq!(MessageKind::from_raw_id(k.raw_id(n(i))), Some((k, n(i))));
            }
        }
        assert_eq!(MessageKind::from_raw_id(0x07F), None);
        assert_eq!(MessageKind::from_raw_id(0x0E0), None);
        assert_eq!(NodeId::new(16), None);
    }

    #[test]
    fn frames_hold_at_most_eight_bytes() {
        let id = StandardId::new(0x123).unwrap();
        assert!(CanFrame::new(id, &[0; 9]).is_none());
        let f = CanFrame::new(id, &[1, 2, 3]).unwrap();
        assert_eq!(f.data(), &[1, 2, 3]);
        assert_eq!(f.len(), 3);
        assert!(<CanFrame as embedded_can::Frame>::new(ExtendedId::ZERO, &[]).is_none());
    }
}
