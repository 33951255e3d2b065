//! The codec: one type per message, packed little-endian as the published databases
//! state.
//!
//! Every frame opens with the [`e2e`] header: the CRC-16 in bytes 0..2, the counter in
//! byte 2. Decoding checks, in order: the identifier, the length, the CRC, then the range
//! of every field. Reserved bits are sent as zero and ignored on receipt. Encoding checks
//! the same ranges, so a frame this module produces always decodes.
//!
//! Bit numbers count from bit 0 of byte 0 (the DBC's little-endian start bits).

use core::fmt;

use super::e2e::{self, Counter};
use super::{Address, BusFormat, CanFrame, ContextGroup, Id, MAX_DATA, MessageKind, NodeId};
use detector_core::{Confidence, Decision, EventId, Level, MAX_EVENTS, MAX_PHASES, Signal, Tick};

/// The protocol version, sent in the status frame's identity page.
pub const PROTOCOL_VERSION: u8 = 2;

/// Largest magnitude of a desired-velocity raw value; the unit is 10⁻⁴ m/s (0.1 mm/s),
/// so the range is ±0.4095 m/s. The raw value −4096 is not valid.
pub const VEL_DES_RAW_MAX: i16 = 4095;
/// Largest magnitude of a desired-acceleration raw value; the unit is 2·10⁻³ m/s², so the
/// range is ±8.19 m/s². The raw value −4096 is not valid.
pub const ACC_DES_RAW_MAX: i16 = 4095;
/// Largest magnitude of a position-error raw value; the unit is 1 µm, so the range is
/// ±32.767 mm. The raw value −32768 is not valid.
pub const POS_ERR_RAW_MAX: i16 = 32767;

/// Pages of the status message, `0..STATUS_PAGES`.
pub const STATUS_PAGES: u8 = 17;

/// The status health page's phase value meaning "no phase yet".
pub const NO_PHASE: u8 = 15;

/// A frame could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DecodeError {
    /// The identifier is extended, or not one of the protocol's.
    UnknownId,
    /// The frame has the wrong number of data bytes for its message.
    WrongLength {
        /// The message the identifier names.
        kind: MessageKind,
        /// Bytes the message has.
        expected: u8,
        /// Bytes the frame had.
        got: usize,
    },
    /// Bytes 0..2 are not the CRC of the rest.
    BadCrc {
        /// The message the identifier names.
        kind: MessageKind,
        /// The CRC the payload should carry.
        expected: u16,
        /// The CRC it carried.
        got: u16,
    },
    /// A field holds a value outside its range.
    OutOfRange {
        /// The message the identifier names.
        kind: MessageKind,
        /// The field's signal name in the DBC (without its node or event number).
        signal: &'static str,
        /// The raw value found.
        value: i64,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecodeError::UnknownId => write!(f, "identifier not in the fingertip protocol"),
            DecodeError::WrongLength {
                kind,
                expected,
                got,
            } => write!(
                f,
                "{} frame has {got} data bytes, expected {expected}",
                kind.name()
            ),
            DecodeError::BadCrc {
                kind,
                expected,
                got,
            } => write!(
                f,
                "{} frame has CRC 0x{got:04X}, expected 0x{expected:04X}",
                kind.name()
            ),
            DecodeError::OutOfRange {
                kind,
                signal,
                value,
            } => write!(
                f,
                "{} frame: {signal} = {value} is out of range",
                kind.name()
            ),
        }
    }
}

/// A message could not be encoded: a field is outside its range, or the address does
/// not fit the message (a group for a per-node message, or the reverse).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EncodeError {
    /// The message.
    pub kind: MessageKind,
    /// The field's signal name in the DBC, or `Address`.
    pub signal: &'static str,
    /// The offending raw value.
    pub value: i64,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "cannot encode {}: {} = {} is out of range",
            self.kind.name(),
            self.signal,
            self.value
        )
    }
}

impl From<EncodeError> for DecodeError {
    fn from(e: EncodeError) -> DecodeError {
        DecodeError::OutOfRange {
            kind: e.kind,
            signal: e.signal,
            value: e.value,
        }
    }
}

fn check_range(
    kind: MessageKind,
    signal: &'static str,
    value: i64,
    min: i64,
    max: i64,
) -> Result<(), EncodeError> {
    if (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(EncodeError {
            kind,
            signal,
            value,
        })
    }
}

/// `len` bits (1..=32) of `data` from bit `start`; bits past the end read as zero.
fn get(data: &[u8], start: u32, len: u32) -> u32 {
    let mut w = 0u64;
    for (i, b) in data.iter().skip((start / 8) as usize).take(5).enumerate() {
        w |= u64::from(*b) << (8 * i);
    }
    ((w >> (start % 8)) & ((1u64 << len) - 1)) as u32
}

/// As [`get`], sign-extended.
fn sget(data: &[u8], start: u32, len: u32) -> i32 {
    let shift = 32 - len;
    ((get(data, start, len) << shift) as i32) >> shift
}

/// Writes the low `len` bits (1..=32) of `v` at bit `start`.
fn put(data: &mut [u8], start: u32, len: u32, v: u32) {
    let shift = start % 8;
    let mask = ((1u64 << len) - 1) << shift;
    let bits = (u64::from(v) << shift) & mask;
    for (i, b) in data
        .iter_mut()
        .skip((start / 8) as usize)
        .take(5)
        .enumerate()
    {
        let m = (mask >> (8 * i)) as u8;
        *b = (*b & !m) | ((bits >> (8 * i)) as u8 & m);
    }
}

/// A payload being built: the message's bytes, zeroed, its counter in byte 2.
struct Payload {
    kind: MessageKind,
    bytes: [u8; MAX_DATA],
}

impl Payload {
    fn new(kind: MessageKind, counter: Counter) -> Payload {
        let mut bytes = [0u8; MAX_DATA];
        bytes[2] = counter.get();
        Payload { kind, bytes }
    }

    fn put(&mut self, start: u32, len: u32, v: u32) {
        put(&mut self.bytes, start, len, v);
    }

    /// The sealed frame: CAN FD for messages longer than 8 bytes, classic otherwise (the
    /// transmitter sends those as CAN FD on a CAN FD bus, see [`CanFrame::for_bus`]).
    fn seal(mut self, id: crate::StandardId) -> CanFrame {
        let n = self.kind.data_len();
        let data = self.bytes.get_mut(..n).unwrap_or(&mut []);
        e2e::seal(id, data);
        let format = if n > 8 {
            BusFormat::Fd
        } else {
            BusFormat::Classic
        };
        // Every message's length is a valid frame length; the fallback never runs.
        CanFrame::for_bus(format, id, data).unwrap_or(CanFrame {
            id,
            len: 0,
            fd: false,
            data: [0; MAX_DATA],
        })
    }

    fn for_node(self, node: NodeId) -> CanFrame {
        let id = self.kind.id(node);
        self.seal(id)
    }
}

/// The counter in byte 2 (the decoder checked the length first).
fn counter(d: &[u8]) -> Counter {
    Counter(d.get(2).copied().unwrap_or(0))
}

fn confidence(
    kind: MessageKind,
    signal: &'static str,
    raw: u32,
) -> Result<Confidence, DecodeError> {
    Confidence::from_bits(raw as u16)
        .filter(|_| raw <= u32::from(u16::MAX))
        .ok_or(DecodeError::OutOfRange {
            kind,
            signal,
            value: i64::from(raw),
        })
}

/// Rounds `n / d` to nearest, ties away from zero (`d > 0`).
const fn div_round(n: i32, d: i32) -> i32 {
    if n >= 0 {
        (n + d / 2) / d
    } else {
        (n - d / 2) / d
    }
}

/// `bits · num >> shift`, rounded to nearest, saturated to ±`max` (controller side only).
fn quantize(s: Signal, num: i64, shift: u32, max: i16) -> i16 {
    let p = i64::from(s.to_bits()) * num;
    let half = 1i64 << (shift - 1);
    let q = if p >= 0 {
        (p + half) >> shift
    } else {
        -((-p + half) >> shift)
    };
    q.clamp(-i64::from(max), i64::from(max)) as i16
}

// ---------------------------------------------------------------------------------------
// Event

/// A decision level was raised: sent at once, at the highest priority of the protocol.
/// 8 bytes, on both bus formats. The confidence travels in the stream.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16, see [`e2e`] |
/// | 16..24 | `Counter` | rolling counter |
/// | 24..27 | `EventId` | the event's index in the configuration, 0..=7 |
/// | 27 | `Level` | 0 alert, 1 confirm |
/// | 32..48 | `Tick` | low 16 bits of the detector tick of the decision |
/// | 48..64 | `OnsetAge` | ticks from the back-dated onset to the decision, saturating at 65535 |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EventMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// The event, `0..MAX_EVENTS` (8).
    pub event: EventId,
    /// The level raised.
    pub level: Level,
    /// The low 16 bits of the decision's tick (the fingertip's detector clock, 200 µs per
    /// tick at the default 5 kHz); the status frame's full uptime lets a receiver unwrap
    /// it.
    pub tick: u16,
    /// Ticks from the back-dated onset to the decision, saturated at 65535.
    pub onset_age: u16,
}

impl EventMsg {
    /// The frame for a core [`Decision`].
    pub fn from_decision(counter: Counter, d: &Decision) -> EventMsg {
        let age = d.tick.wrapping_sub(d.onset);
        EventMsg {
            counter,
            event: d.event,
            level: d.level,
            tick: d.tick as u16,
            onset_age: age.min(u32::from(u16::MAX)) as u16,
        }
    }

    /// The decision's full tick, given a full tick `near` it (within ±2¹⁵ ticks, e.g. the
    /// uptime of the last status frame): the wrapped 16-bit tick unwrapped around `near`.
    pub fn full_tick(&self, near: Tick) -> Tick {
        let delta = self.tick.wrapping_sub(near as u16) as i16;
        near.wrapping_add_signed(i32::from(delta))
    }

    fn validate(&self) -> Result<(), EncodeError> {
        check_range(
            MessageKind::Event,
            "EventId",
            i64::from(self.event.0),
            0,
            MAX_EVENTS as i64 - 1,
        )
    }

    /// The frame for `node`; fails only for an event id of 8 or more.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut p = Payload::new(MessageKind::Event, self.counter);
        p.put(24, 3, u32::from(self.event.0));
        p.put(27, 1, u32::from(self.level == Level::Confirm));
        p.put(32, 16, u32::from(self.tick));
        p.put(48, 16, u32::from(self.onset_age));
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<EventMsg, DecodeError> {
        Ok(EventMsg {
            counter: counter(d),
            event: EventId(get(d, 24, 3) as u8),
            level: if get(d, 27, 1) == 1 {
                Level::Confirm
            } else {
                Level::Alert
            },
            tick: get(d, 32, 16) as u16,
            onset_age: get(d, 48, 16) as u16,
        })
    }
}

// ---------------------------------------------------------------------------------------
// Phase

/// The phase the controller wants run. 5 bytes, on both bus formats. Sent on every change
/// and periodically; the fingertip treats it as stale after its phase timeout.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16 |
/// | 16..24 | `Counter` | rolling counter |
/// | 24..32 | `PhaseId` | the phase's index in the configuration, 0..=7 (and below the number of phases configured) |
/// | 32..40 | `PhaseSeq` | phase sequence: advanced by the controller at every phase entry, so re-entering the same phase is seen as new |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// The phase index, `0..=7`.
    pub phase: u8,
    /// The phase sequence number, wrapping.
    pub sequence: u8,
}

impl PhaseMsg {
    fn validate(&self) -> Result<(), EncodeError> {
        check_range(
            MessageKind::Phase,
            "PhaseId",
            i64::from(self.phase),
            0,
            MAX_PHASES as i64 - 1,
        )
    }

    /// The frame for `node`; fails for a phase index of 8 or more.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut p = Payload::new(MessageKind::Phase, self.counter);
        p.put(24, 8, u32::from(self.phase));
        p.put(32, 8, u32::from(self.sequence));
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<PhaseMsg, DecodeError> {
        let m = PhaseMsg {
            counter: counter(d),
            phase: get(d, 24, 8) as u8,
            sequence: get(d, 32, 8) as u8,
        };
        m.validate()?;
        Ok(m)
    }
}

// ---------------------------------------------------------------------------------------
// Context

/// One fingertip's context: the controller's commanded tip motion and the tip position
/// error, in the fingertip's frame, raw. 84 bits in a [`ContextMsg`] slot.
///
/// | bits (from the slot's first) | signal | unit | range |
/// |---|---|---|---|
/// | 0..13 | `VelDesX` | 10⁻⁴ m/s | ±0.4095 m/s (raw ±4095) |
/// | 13..26 | `VelDesY` | 10⁻⁴ m/s | ±0.4095 m/s |
/// | 26..39 | `AccDesX` | 2·10⁻³ m/s² | ±8.19 m/s² (raw ±4095) |
/// | 39..52 | `AccDesY` | 2·10⁻³ m/s² | ±8.19 m/s² |
/// | 52..68 | `PosErrX` | 1 µm | ±32.767 mm (raw ±32767) |
/// | 68..84 | `PosErrY` | 1 µm | ±32.767 mm |
///
/// Velocity and acceleration are signed 13-bit, position error signed 16-bit; the most
/// negative raw value of each is out of range (a sender saturates).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContextSlot {
    /// Desired tip velocity (x, y), raw, 10⁻⁴ m/s per unit, within ±[`VEL_DES_RAW_MAX`].
    pub vel_des: [i16; 2],
    /// Desired tip acceleration (x, y), raw, 2·10⁻³ m/s² per unit, within
    /// ±[`ACC_DES_RAW_MAX`].
    pub acc_des: [i16; 2],
    /// Tip position error (x, y; commanded minus actual), raw, 1 µm per unit, within
    /// ±[`POS_ERR_RAW_MAX`].
    pub pos_err: [i16; 2],
}

/// Bytes of one context slot (six fields and 4 reserved bits: 88 bits).
const SLOT_BYTES: usize = 11;
/// First byte of slot 0 in a [`ContextMsg`] (bit 64).
const SLOTS_START: usize = 8;

impl ContextSlot {
    /// Raw units of velocity per m/s.
    pub const VEL_PER_SI: u32 = 10_000;
    /// Raw units of acceleration per m/s².
    pub const ACC_PER_SI: u32 = 500;
    /// Raw units of position error per metre.
    pub const POS_PER_SI: u32 = 1_000_000;
    /// Metres per second per raw unit of velocity (1e-4).
    pub const VEL_SCALE: f64 = 1.0 / Self::VEL_PER_SI as f64;
    /// Metres per second squared per raw unit of acceleration (2e-3).
    pub const ACC_SCALE: f64 = 1.0 / Self::ACC_PER_SI as f64;
    /// Metres per raw unit of position error (1e-6).
    pub const POS_SCALE: f64 = 1.0 / Self::POS_PER_SI as f64;

    /// From SI values (m/s, m/s², m), rounded to nearest and saturated at the ends of the
    /// ranges.
    pub fn from_signals(vel_des: [Signal; 2], acc_des: [Signal; 2], pos_err: [Signal; 2]) -> Self {
        // raw = bits · 2⁻¹⁶ / 10⁻⁴ = bits · 625 / 4096; / 2·10⁻³ = bits · 125 / 16384;
        // / 10⁻⁶ = bits · 15625 / 1024.
        ContextSlot {
            vel_des: vel_des.map(|s| quantize(s, 625, 12, VEL_DES_RAW_MAX)),
            acc_des: acc_des.map(|s| quantize(s, 125, 14, ACC_DES_RAW_MAX)),
            pos_err: pos_err.map(|s| quantize(s, 15625, 10, POS_ERR_RAW_MAX)),
        }
    }

    /// Desired velocity (x, y) in m/s, as the core's [`Signal`] (rounded to 2⁻¹⁶).
    pub fn vel_des_signals(&self) -> [Signal; 2] {
        ContextPart::Velocity.signals(self.vel_des)
    }

    /// Desired acceleration (x, y) in m/s², as the core's [`Signal`] (rounded to 2⁻¹⁶).
    pub fn acc_des_signals(&self) -> [Signal; 2] {
        ContextPart::Acceleration.signals(self.acc_des)
    }

    /// Position error (x, y) in m, as the core's [`Signal`] (rounded to 2⁻¹⁶ m, 15 µm).
    pub fn pos_err_signals(&self) -> [Signal; 2] {
        ContextPart::PositionError.signals(self.pos_err)
    }

    /// The part `part` of the slot.
    pub const fn part(&self, part: ContextPart) -> [i16; 2] {
        match part {
            ContextPart::Velocity => self.vel_des,
            ContextPart::Acceleration => self.acc_des,
            ContextPart::PositionError => self.pos_err,
        }
    }

    fn validate(&self, kind: MessageKind) -> Result<(), EncodeError> {
        for part in ContextPart::ALL {
            part.validate(kind, self.part(part))?;
        }
        Ok(())
    }

    /// Writes the slot at byte `first` (slots start on a byte): the six fields packed in one
    /// 88-bit word, stored at once.
    fn write(&self, p: &mut Payload, first: usize) {
        let mut w = 0u128;
        for part in ContextPart::ALL {
            let (offset, len) = part.slot_field();
            for (k, v) in (0u32..).zip(self.part(part)) {
                w |= (u128::from(v as u16) & ((1 << len) - 1)) << (offset + k * len);
            }
        }
        if let Some(dst) = p.bytes.get_mut(first..first + SLOT_BYTES) {
            dst.copy_from_slice(&w.to_le_bytes()[..SLOT_BYTES]);
        }
    }

    /// Reads the slot at byte `first`: one 88-bit load, six fields shifted out.
    fn read(d: &[u8], first: usize) -> ContextSlot {
        let mut b = [0u8; 16];
        if let Some(src) = d.get(first..first + SLOT_BYTES) {
            b[..SLOT_BYTES].copy_from_slice(src);
        }
        let w = u128::from_le_bytes(b);
        let field = |part: ContextPart, k: u32| {
            let (offset, len) = part.slot_field();
            let shift = 32 - len;
            (((w >> (offset + k * len)) as u32) << shift) as i32 >> shift
        };
        let pair = |part| [field(part, 0) as i16, field(part, 1) as i16];
        ContextSlot {
            vel_des: pair(ContextPart::Velocity),
            acc_des: pair(ContextPart::Acceleration),
            pos_err: pair(ContextPart::PositionError),
        }
    }
}

/// One control cycle's context for the five fingertips of a [`ContextGroup`], broadcast by
/// the controller (CAN FD, 64 bytes).
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16 |
/// | 16..24 | `Counter` | rolling counter, +1 per cycle |
/// | 24..29 | `Valid{n}` | slot of node `n` filled (one bit per slot) |
/// | 32..64 | `Time` | the controller's clock, µs, wrapping |
/// | 64 + 88k .. 152 + 88k | slot `k` | node `5g + k`'s [`ContextSlot`] |
///
/// A slot not valid is sent as zeros and ignored on receipt: that fingertip's context
/// ages as if no frame had come.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContextMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// The controller's time at the control cycle, µs, wrapping after 71.6 minutes.
    pub time_us: u32,
    /// The fingertips' contexts, by slot; `None` for a slot the controller does not fill.
    pub slots: [Option<ContextSlot>; ContextGroup::SLOTS],
}

impl ContextMsg {
    /// `node`'s context, if its group is `group` and its slot is filled.
    pub fn slot_of(&self, group: ContextGroup, node: NodeId) -> Option<ContextSlot> {
        if ContextGroup::of(node) != group {
            return None;
        }
        self.slots
            .get(ContextGroup::slot_of(node))
            .copied()
            .flatten()
    }

    /// The frame for `group`; fails for a value outside its range.
    pub fn encode(&self, group: ContextGroup) -> Result<CanFrame, EncodeError> {
        let mut p = Payload::new(MessageKind::Context, self.counter);
        for (k, slot) in (0u32..).zip(&self.slots) {
            if let Some(s) = slot {
                s.validate(MessageKind::Context)?;
                p.put(24 + k, 1, 1);
                s.write(&mut p, SLOTS_START + k as usize * SLOT_BYTES);
            }
        }
        p.put(32, 32, self.time_us);
        let id = MessageKind::Context.raw_id_of(group.get());
        Ok(p.seal(crate::standard(id)))
    }

    fn decode(d: &[u8]) -> Result<ContextMsg, DecodeError> {
        let mut m = ContextMsg {
            counter: counter(d),
            time_us: get(d, 32, 32),
            slots: [None; ContextGroup::SLOTS],
        };
        for (k, slot) in (0u32..).zip(m.slots.iter_mut()) {
            if get(d, 24 + k, 1) == 1 {
                let s = ContextSlot::read(d, SLOTS_START + k as usize * SLOT_BYTES);
                s.validate(MessageKind::Context)?;
                *slot = Some(s);
            }
        }
        Ok(m)
    }
}

/// The three parts of a fingertip's context, as classic CAN carries them one per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ContextPart {
    /// Desired tip velocity.
    Velocity = 0,
    /// Desired tip acceleration.
    Acceleration = 1,
    /// Tip position error.
    PositionError = 2,
}

impl ContextPart {
    /// Every part, by raw value.
    pub const ALL: [ContextPart; 3] = [
        ContextPart::Velocity,
        ContextPart::Acceleration,
        ContextPart::PositionError,
    ];

    /// The largest raw magnitude of the part's values.
    pub const fn raw_max(self) -> i16 {
        match self {
            ContextPart::Velocity => VEL_DES_RAW_MAX,
            ContextPart::Acceleration => ACC_DES_RAW_MAX,
            ContextPart::PositionError => POS_ERR_RAW_MAX,
        }
    }

    /// SI units per raw unit (m/s, m/s², m).
    pub const fn scale(self) -> f64 {
        1.0 / self.per_si() as f64
    }

    /// Raw units per SI unit, exactly: a board converts without floating point.
    pub const fn per_si(self) -> u32 {
        match self {
            ContextPart::Velocity => ContextSlot::VEL_PER_SI,
            ContextPart::Acceleration => ContextSlot::ACC_PER_SI,
            ContextPart::PositionError => ContextSlot::POS_PER_SI,
        }
    }

    /// The DBC names of the part's two signals (x, y).
    pub const fn signal_names(self) -> [&'static str; 2] {
        match self {
            ContextPart::Velocity => ["VelDesX", "VelDesY"],
            ContextPart::Acceleration => ["AccDesX", "AccDesY"],
            ContextPart::PositionError => ["PosErrX", "PosErrY"],
        }
    }

    /// Where the part's x field starts in a slot, and each field's length, in bits.
    const fn slot_field(self) -> (u32, u32) {
        match self {
            ContextPart::Velocity => (0, 13),
            ContextPart::Acceleration => (26, 13),
            ContextPart::PositionError => (52, 16),
        }
    }

    /// The raw values as the core's [`Signal`]s, rounded to 2⁻¹⁶ (|raw| ≤ 32768 keeps
    /// every product inside i32).
    pub fn signals(self, raw: [i16; 2]) -> [Signal; 2] {
        // bits = raw · scale · 2¹⁶: · 4096 / 625, · 16384 / 125, · 1024 / 15625.
        let (num, den) = match self {
            ContextPart::Velocity => (4096, 625),
            ContextPart::Acceleration => (16384, 125),
            ContextPart::PositionError => (1024, 15625),
        };
        raw.map(|r| Signal::from_bits(div_round(i32::from(r) * num, den)))
    }

    fn validate(self, kind: MessageKind, values: [i16; 2]) -> Result<(), EncodeError> {
        let max = i64::from(self.raw_max());
        for (v, name) in values.into_iter().zip(self.signal_names()) {
            check_range(kind, name, i64::from(v), -max, max)?;
        }
        Ok(())
    }
}

/// One part of one fingertip's context (classic CAN, 8 bytes): the controller sends the
/// three parts every control cycle, each its own frame with its own counter value.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16 |
/// | 16..24 | `Counter` | rolling counter, +1 per frame |
/// | 24..26 | `Part` | multiplexer: 0 velocity, 1 acceleration, 2 position error |
/// | 32..48, 48..64 | x, y | the part's two values, signed 16-bit, the [`ContextSlot`]'s units and ranges |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContextPartMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// Which part.
    pub part: ContextPart,
    /// Its values (x, y), raw.
    pub value: [i16; 2],
}

impl ContextPartMsg {
    /// The frame for `node`; fails for a value outside its range.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.part.validate(MessageKind::ContextPart, self.value)?;
        let mut p = Payload::new(MessageKind::ContextPart, self.counter);
        p.put(24, 2, self.part as u32);
        p.put(32, 16, self.value[0] as u16 as u32);
        p.put(48, 16, self.value[1] as u16 as u32);
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<ContextPartMsg, DecodeError> {
        let raw = get(d, 24, 2);
        let part = *ContextPart::ALL
            .get(raw as usize)
            .ok_or(DecodeError::OutOfRange {
                kind: MessageKind::ContextPart,
                signal: "Part",
                value: i64::from(raw),
            })?;
        let value = [sget(d, 32, 16) as i16, sget(d, 48, 16) as i16];
        part.validate(MessageKind::ContextPart, value)?;
        Ok(ContextPartMsg {
            counter: counter(d),
            part,
            value,
        })
    }
}

// ---------------------------------------------------------------------------------------
// Stream

/// The decision level an event is at (the highest reached since the last stream sample).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum LevelState {
    /// No level up.
    #[default]
    None = 0,
    /// The alert level.
    Alert = 1,
    /// The confirm level (the alert level is up too).
    Confirm = 2,
}

impl LevelState {
    /// Every state, by raw value.
    pub const ALL: [LevelState; 3] = [LevelState::None, LevelState::Alert, LevelState::Confirm];

    /// The state of event `e` from masks of events alerting and confirmed.
    pub const fn from_masks(alerting: u8, confirmed: u8, e: usize) -> LevelState {
        if confirmed & (1 << e) != 0 {
            LevelState::Confirm
        } else if alerting & (1 << e) != 0 {
            LevelState::Alert
        } else {
            LevelState::None
        }
    }

    /// The name the tools print.
    pub const fn name(self) -> &'static str {
        match self {
            LevelState::None => "none",
            LevelState::Alert => "alert",
            LevelState::Confirm => "confirm",
        }
    }

    fn from_raw(kind: MessageKind, raw: u32) -> Result<LevelState, DecodeError> {
        LevelState::ALL
            .get(raw as usize)
            .copied()
            .ok_or(DecodeError::OutOfRange {
                kind,
                signal: "Level",
                value: i64::from(raw),
            })
    }
}

/// A sample of the confidence stream (CAN FD, 24 bytes): every event's confidence and
/// the level each reached since the previous sample, so a raised level is in at least one
/// stream frame besides its event frame. Sent every `stream_decimation` ticks.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16 |
/// | 16..24 | `Counter` | rolling counter, +1 per sample: a gap means lost samples |
/// | 24..32 | `Evaluated{e}` | event `e` belongs to the current phase |
/// | 32..40 | `Unjudgeable{e}` | event `e` cannot be judged (its context, or every sensor channel, is faulty) |
/// | 40..56 | `Level{e}` | two bits per event: 0 none, 1 alert, 2 confirm, the highest since the last sample |
/// | 56 + 16e .. 72 + 16e | `Conf{e}` | event `e`'s confidence, Q15: 0..=32768 is 0..=1; 0 when not evaluated |
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StreamMsg {
    /// The rolling counter (the sample's number).
    pub counter: Counter,
    /// Bit `e` set: event `e` is evaluated (belongs to the current phase).
    pub evaluated: u8,
    /// Bit `e` set: event `e` cannot be judged.
    pub unjudgeable: u8,
    /// Each event's level, the highest since the last sample.
    pub levels: [LevelState; MAX_EVENTS],
    /// Each event's confidence at the sample's tick.
    pub confidences: [Confidence; MAX_EVENTS],
}

impl StreamMsg {
    /// The frame for `node`.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        let mut p = Payload::new(MessageKind::Stream, self.counter);
        p.put(24, 8, u32::from(self.evaluated));
        p.put(32, 8, u32::from(self.unjudgeable));
        for (e, (level, conf)) in (0u32..).zip(self.levels.iter().zip(&self.confidences)) {
            p.put(40 + 2 * e, 2, *level as u32);
            p.put(56 + 16 * e, 16, u32::from(conf.to_bits()));
        }
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<StreamMsg, DecodeError> {
        let k = MessageKind::Stream;
        let mut m = StreamMsg {
            counter: counter(d),
            evaluated: get(d, 24, 8) as u8,
            unjudgeable: get(d, 32, 8) as u8,
            ..StreamMsg::default()
        };
        for (e, (level, conf)) in (0u32..).zip(m.levels.iter_mut().zip(&mut m.confidences)) {
            *level = LevelState::from_raw(k, get(d, 40 + 2 * e, 2))?;
            *conf = confidence(k, "Conf", get(d, 56 + 16 * e, 16))?;
        }
        Ok(m)
    }
}

/// One evaluated event of a stream sample (classic CAN, 8 bytes): a sample sends one page
/// per event of the current phase, all with the same `Sample` number.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..16 | `Crc` | CRC-16 |
/// | 16..24 | `Counter` | rolling counter, +1 per frame |
/// | 24..32 | `Sample` | the sample's number, +1 per sample: a gap means lost samples |
/// | 32..35 | `EventId` | multiplexer: the event, 0..=7 |
/// | 35 | `Unjudgeable{e}` | the event cannot be judged |
/// | 36..38 | `Level{e}` | 0 none, 1 alert, 2 confirm, the highest since the last sample |
/// | 40..56 | `Conf{e}` | the event's confidence, Q15 |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StreamPageMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// The sample's number.
    pub sample: u8,
    /// The event.
    pub event: EventId,
    /// The event cannot be judged.
    pub unjudgeable: bool,
    /// The event's level, the highest since the last sample.
    pub level: LevelState,
    /// The event's confidence.
    pub confidence: Confidence,
}

impl StreamPageMsg {
    /// The frame for `node`; fails for an event id of 8 or more.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        check_range(
            MessageKind::StreamPage,
            "EventId",
            i64::from(self.event.0),
            0,
            MAX_EVENTS as i64 - 1,
        )?;
        let mut p = Payload::new(MessageKind::StreamPage, self.counter);
        p.put(24, 8, u32::from(self.sample));
        p.put(32, 3, u32::from(self.event.0));
        p.put(35, 1, u32::from(self.unjudgeable));
        p.put(36, 2, self.level as u32);
        p.put(40, 16, u32::from(self.confidence.to_bits()));
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<StreamPageMsg, DecodeError> {
        let k = MessageKind::StreamPage;
        Ok(StreamPageMsg {
            counter: counter(d),
            sample: get(d, 24, 8) as u8,
            event: EventId(get(d, 32, 3) as u8),
            unjudgeable: get(d, 35, 1) == 1,
            level: LevelState::from_raw(k, get(d, 36, 2))?,
            confidence: confidence(k, "Conf", get(d, 40, 16))?,
        })
    }
}

// ---------------------------------------------------------------------------------------
// Status

/// Why the fingertip last reset, as its reset controller tells after boot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ResetReason {
    /// Not known.
    #[default]
    Unknown = 0,
    /// Power on.
    PowerOn = 1,
    /// The reset pin.
    Pin = 2,
    /// Brown-out.
    Brownout = 3,
    /// The independent watchdog.
    IndependentWatchdog = 4,
    /// The window watchdog.
    WindowWatchdog = 5,
    /// A software reset (including a panic handler's and the clock-failure handler's).
    Software = 6,
    /// An illegal low-power mode entry.
    LowPower = 7,
    /// An option-byte load.
    OptionBytes = 8,
}

impl ResetReason {
    /// Every reason, by raw value.
    pub const ALL: [ResetReason; 9] = [
        ResetReason::Unknown,
        ResetReason::PowerOn,
        ResetReason::Pin,
        ResetReason::Brownout,
        ResetReason::IndependentWatchdog,
        ResetReason::WindowWatchdog,
        ResetReason::Software,
        ResetReason::LowPower,
        ResetReason::OptionBytes,
    ];

    /// From the raw value; `None` above 8.
    pub fn from_raw(raw: u8) -> Option<ResetReason> {
        ResetReason::ALL.get(usize::from(raw)).copied()
    }

    /// The name as the DBC's value table writes it.
    pub const fn name(self) -> &'static str {
        match self {
            ResetReason::Unknown => "unknown",
            ResetReason::PowerOn => "power_on",
            ResetReason::Pin => "pin",
            ResetReason::Brownout => "brownout",
            ResetReason::IndependentWatchdog => "independent_watchdog",
            ResetReason::WindowWatchdog => "window_watchdog",
            ResetReason::Software => "software",
            ResetReason::LowPower => "low_power",
            ResetReason::OptionBytes => "option_bytes",
        }
    }
}

/// Where the fingertip took its node id from at boot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum NodeIdSource {
    /// The board's strap pins.
    #[default]
    Straps = 0,
    /// The flash key-value store.
    Store = 1,
}

impl NodeIdSource {
    /// Every source, by raw value.
    pub const ALL: [NodeIdSource; 2] = [NodeIdSource::Straps, NodeIdSource::Store];

    /// The name as the DBC's value table writes it.
    pub const fn name(self) -> &'static str {
        match self {
            NodeIdSource::Straps => "straps",
            NodeIdSource::Store => "store",
        }
    }
}

/// Fault flags of the status heartbeat, one bit each (16 bits, 10 used).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultFlags(pub u16);

impl FaultFlags {
    /// The fingertip's velocity or acceleration context is older than the context
    /// timeout: context-dependent events are not confirmed.
    pub const CONTEXT_STALE: FaultFlags = FaultFlags(1 << 0);
    /// The fingertip's position error is older than the context timeout.
    pub const TIP_STATE_STALE: FaultFlags = FaultFlags(1 << 1);
    /// No valid phase frame within the phase timeout (or none since boot).
    pub const PHASE_STALE: FaultFlags = FaultFlags(1 << 2);
    /// A tick ended after its deadline, or scans were lost, since the last heartbeat.
    pub const LATE: FaultFlags = FaultFlags(1 << 3);
    /// The CAN controller was error-passive or bus-off since the last heartbeat.
    pub const BUS_ERROR: FaultFlags = FaultFlags(1 << 4);
    /// A frame could not be queued or was flushed since the last heartbeat.
    pub const TX_DROPPED: FaultFlags = FaultFlags(1 << 5);
    /// The detector image was rejected (or the tick does not match it): the detector is out
    /// of service and the fingertip sends only its status heartbeat; or a detector saved
    /// in flash was chosen but none is whole, and the built-in one runs in its place
    /// (status page 11 says which).
    pub const CONFIG_FALLBACK: FaultFlags = FaultFlags(1 << 6);
    /// A sensor channel is flagged faulty.
    pub const SENSOR_FAULT: FaultFlags = FaultFlags(1 << 7);
    /// The crystal did not start: the fingertip runs from its internal oscillator, whose
    /// tolerance is outside the CAN FD data phase's.
    pub const CLOCK_FALLBACK: FaultFlags = FaultFlags(1 << 8);
    /// The fingertip is in its service state (its flash being written, which stalls the
    /// CPU): the detector is out of service, and the fingertip sends only its status
    /// heartbeat.
    pub const SERVICE: FaultFlags = FaultFlags(1 << 9);

    /// The flags' names as the DBC's signals write them, by bit.
    pub const NAMES: [&'static str; 10] = [
        "FaultContextStale",
        "FaultTipStateStale",
        "FaultPhaseStale",
        "FaultLate",
        "FaultBusError",
        "FaultTxDropped",
        "FaultConfigFallback",
        "FaultSensor",
        "FaultClockFallback",
        "FaultService",
    ];

    /// Whether every flag of `other` is set.
    pub const fn contains(self, other: FaultFlags) -> bool {
        self.0 & other.0 == other.0
    }

    /// Sets or clears the flags of `other`.
    pub fn set(&mut self, other: FaultFlags, on: bool) {
        if on {
            self.0 |= other.0;
        } else {
            self.0 &= !other.0;
        }
    }
}

impl core::ops::BitOr for FaultFlags {
    type Output = FaultFlags;
    fn bitor(self, rhs: FaultFlags) -> FaultFlags {
        FaultFlags(self.0 | rhs.0)
    }
}

/// One page of the multiplexed status heartbeat (8 bytes, both bus formats): the header,
/// the page number in byte 3 (`Page`, the multiplexer), 32 bits of content. Counters are
/// since boot and saturate at their maximum.
///
/// | page | bits 32..64 |
/// |---|---|
/// | 0 health | `ResetReason` 32..36, `Phase` 36..40 (0..=7, 15 none), nine `Fault*` flags 40..49, `PhaseSeq` 56..64 |
/// | 1 uptime | `Uptime` (ticks) |
/// | 2 identity | `TickRate` (Hz) 32..48, `ProtocolVersion` 48..56, `BusFormat` 56, `NodeIdSource` 57..60 |
/// | 3 lateness | `WorstLateness` (0.1 µs) 32..48, `LateTicks` 48..64 |
/// | 4 compute | `WorstTick` (0.1 µs) 32..48, `LostScans` 48..64 |
/// | 5 link | `StaleEpisodes` 32..48, `LostFrames` 48..64 |
/// | 6 bus | `BusErrors` 32..48, `TxDropped` 48..64 |
/// | 7 rejects | `RejWrongLength`, `RejBadCrc` |
/// | 8 rejects | `RejSequence`, `RejOutOfRange` |
/// | 9 rejects | `RejUnknownId`, `RejPhaseNotConfigured` |
/// | 10 configuration | `ConfigChecksum` |
/// | 11 firmware | `FirmwareMajor` 32..40, `FirmwareMinor` 40..48, `FirmwarePatch` 48..56, `DetectorMode` 56..60 (0 built-in, 1 loaded, 2 fallback) |
/// | 12 build | `BuildHash`: the first 32 bits of the firmware's commit |
/// | 13..=16 detector name | `DetectorName0`..`DetectorName3`: bytes 4k..4k+4 of the active detector's name (UTF-8, zero-padded) |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusPage {
    /// Page 0, sent every heartbeat.
    Health {
        /// Why the fingertip last reset.
        reset: ResetReason,
        /// The phase the detector runs, `0..=7`; `None` before the first valid phase
        /// frame (sent as [`NO_PHASE`]).
        phase: Option<u8>,
        /// Current faults.
        faults: FaultFlags,
        /// That phase's sequence number (0 when none).
        phase_seq: u8,
    },
    /// Page 1.
    Uptime {
        /// Detector ticks since boot, wrapping (at 5 kHz after 9.9 days).
        uptime: Tick,
    },
    /// Page 2.
    Identity {
        /// The detector rate in Hz (the tick unit of the other frames).
        tick_rate_hz: u16,
        /// [`PROTOCOL_VERSION`].
        protocol: u8,
        /// The bus format the fingertip runs.
        format: BusFormat,
        /// Where its node id came from.
        node_source: NodeIdSource,
    },
    /// Page 3.
    Lateness {
        /// Longest time from a sample's conversion to the end of its tick, 0.1 µs
        /// (saturating at 6.5535 ms).
        worst: u16,
        /// Ticks that ended after their deadline.
        late_ticks: u16,
    },
    /// Page 4.
    Compute {
        /// Longest tick computation, 0.1 µs.
        worst_tick: u16,
        /// Scans the detector lost (overwritten before it read them).
        lost_scans: u16,
    },
    /// Page 5.
    Link {
        /// Times the context or the tip state went stale.
        stale_episodes: u16,
        /// Controller frames lost, from gaps in their counters.
        lost_frames: u16,
    },
    /// Page 6.
    Bus {
        /// CAN error events (error-passive or bus-off entries, and protocol errors).
        bus_errors: u16,
        /// Frames the fingertip could not queue, or flushed after bus-off.
        tx_dropped: u16,
    },
    /// Page 7: rejected received frames, by reason.
    RejectsFrame {
        /// Wrong length.
        wrong_length: u16,
        /// CRC mismatch.
        bad_crc: u16,
    },
    /// Page 8: rejected received frames, by reason.
    RejectsContent {
        /// Counter or time did not advance (a repetition, an old frame).
        sequence: u16,
        /// A value out of its range.
        out_of_range: u16,
    },
    /// Page 9: rejected received frames, by reason.
    RejectsRoute {
        /// Identifier not one of this node's receive messages.
        unknown_id: u16,
        /// Phase index not configured.
        phase_not_configured: u16,
    },
    /// Page 10.
    Config {
        /// Checksum of the active configuration.
        checksum: u32,
    },
    /// Page 11.
    Firmware {
        /// The firmware's version: major, minor, patch.
        version: [u8; 3],
        /// What runs the detector.
        mode: crate::service::Mode,
    },
    /// Page 12.
    Build {
        /// The first 32 bits of the commit the firmware was built from (0 unknown).
        hash: u32,
    },
    /// Pages 13..=16: four bytes of the active detector's name.
    DetectorName {
        /// Which four: bytes `4 × part ..`, `0..=3`.
        part: u8,
        /// The bytes, zero-padded past the name's end.
        bytes: [u8; 4],
    },
}

impl StatusPage {
    /// The page number, `0..STATUS_PAGES`.
    pub const fn page(&self) -> u8 {
        match self {
            StatusPage::Health { .. } => 0,
            StatusPage::Uptime { .. } => 1,
            StatusPage::Identity { .. } => 2,
            StatusPage::Lateness { .. } => 3,
            StatusPage::Compute { .. } => 4,
            StatusPage::Link { .. } => 5,
            StatusPage::Bus { .. } => 6,
            StatusPage::RejectsFrame { .. } => 7,
            StatusPage::RejectsContent { .. } => 8,
            StatusPage::RejectsRoute { .. } => 9,
            StatusPage::Config { .. } => 10,
            StatusPage::Firmware { .. } => 11,
            StatusPage::Build { .. } => 12,
            StatusPage::DetectorName { part, .. } => 13 + (*part & 3),
        }
    }

    /// The two 16-bit counters of a counter page.
    const fn pair(&self) -> Option<(u16, u16)> {
        Some(match *self {
            StatusPage::Lateness { worst, late_ticks } => (worst, late_ticks),
            StatusPage::Compute {
                worst_tick,
                lost_scans,
            } => (worst_tick, lost_scans),
            StatusPage::Link {
                stale_episodes,
                lost_frames,
            } => (stale_episodes, lost_frames),
            StatusPage::Bus {
                bus_errors,
                tx_dropped,
            } => (bus_errors, tx_dropped),
            StatusPage::RejectsFrame {
                wrong_length,
                bad_crc,
            } => (wrong_length, bad_crc),
            StatusPage::RejectsContent {
                sequence,
                out_of_range,
            } => (sequence, out_of_range),
            StatusPage::RejectsRoute {
                unknown_id,
                phase_not_configured,
            } => (unknown_id, phase_not_configured),
            _ => return None,
        })
    }

    /// A counter page from its number and two counters.
    const fn from_pair(page: u8, a: u16, b: u16) -> Option<StatusPage> {
        Some(match page {
            3 => StatusPage::Lateness {
                worst: a,
                late_ticks: b,
            },
            4 => StatusPage::Compute {
                worst_tick: a,
                lost_scans: b,
            },
            5 => StatusPage::Link {
                stale_episodes: a,
                lost_frames: b,
            },
            6 => StatusPage::Bus {
                bus_errors: a,
                tx_dropped: b,
            },
            7 => StatusPage::RejectsFrame {
                wrong_length: a,
                bad_crc: b,
            },
            8 => StatusPage::RejectsContent {
                sequence: a,
                out_of_range: b,
            },
            9 => StatusPage::RejectsRoute {
                unknown_id: a,
                phase_not_configured: b,
            },
            _ => return None,
        })
    }

    fn validate(&self) -> Result<(), EncodeError> {
        let k = MessageKind::Status;
        if let StatusPage::Health { phase, faults, .. } = *self {
            if let Some(p) = phase {
                check_range(k, "Phase", i64::from(p), 0, MAX_PHASES as i64 - 1)?;
            }
            // Only the named flags exist; the reserved ones are sent as 0.
            check_range(
                k,
                "Fault",
                i64::from(faults.0 >> FaultFlags::NAMES.len()),
                0,
                0,
            )?;
        }
        Ok(())
    }

    fn write(&self, p: &mut Payload) {
        p.put(24, 8, u32::from(self.page()));
        if let Some((a, b)) = self.pair() {
            p.put(32, 16, u32::from(a));
            p.put(48, 16, u32::from(b));
            return;
        }
        match *self {
            StatusPage::Health {
                reset,
                phase,
                faults,
                phase_seq,
            } => {
                p.put(32, 4, reset as u32);
                p.put(36, 4, u32::from(phase.unwrap_or(NO_PHASE)));
                p.put(40, 16, u32::from(faults.0));
                p.put(56, 8, u32::from(phase_seq));
            }
            StatusPage::Uptime { uptime } => p.put(32, 32, uptime),
            StatusPage::Identity {
                tick_rate_hz,
                protocol,
                format,
                node_source,
            } => {
                p.put(32, 16, u32::from(tick_rate_hz));
                p.put(48, 8, u32::from(protocol));
                p.put(56, 1, u32::from(format == BusFormat::Classic));
                p.put(57, 3, node_source as u32);
            }
            StatusPage::Config { checksum } => p.put(32, 32, checksum),
            StatusPage::Firmware { version, mode } => {
                p.put(32, 8, u32::from(version[0]));
                p.put(40, 8, u32::from(version[1]));
                p.put(48, 8, u32::from(version[2]));
                p.put(56, 4, mode as u32);
            }
            StatusPage::Build { hash } => p.put(32, 32, hash),
            StatusPage::DetectorName { bytes, .. } => p.put(32, 32, u32::from_le_bytes(bytes)),
            // Counter pages were written above.
            _ => {}
        }
    }

    fn read(d: &[u8]) -> Result<StatusPage, DecodeError> {
        let k = MessageKind::Status;
        let out = |signal, value: u32| DecodeError::OutOfRange {
            kind: k,
            signal,
            value: i64::from(value),
        };
        let page = get(d, 24, 8);
        if let Some(p) =
            StatusPage::from_pair(page as u8, get(d, 32, 16) as u16, get(d, 48, 16) as u16)
        {
            return Ok(p);
        }
        Ok(match page {
            0 => {
                let raw_reset = get(d, 32, 4);
                let reset =
                    ResetReason::from_raw(raw_reset as u8).ok_or(out("ResetReason", raw_reset))?;
                let phase = match get(d, 36, 4) {
                    p if p == u32::from(NO_PHASE) => None,
                    p if (p as usize) < MAX_PHASES => Some(p as u8),
                    p => return Err(out("Phase", p)),
                };
                StatusPage::Health {
                    reset,
                    phase,
                    // Flags 9..16 are reserved: ignored.
                    faults: FaultFlags(get(d, 40, FaultFlags::NAMES.len() as u32) as u16),
                    phase_seq: get(d, 56, 8) as u8,
                }
            }
            1 => StatusPage::Uptime {
                uptime: get(d, 32, 32),
            },
            2 => {
                let raw_source = get(d, 57, 3);
                StatusPage::Identity {
                    tick_rate_hz: get(d, 32, 16) as u16,
                    protocol: get(d, 48, 8) as u8,
                    format: if get(d, 56, 1) == 1 {
                        BusFormat::Classic
                    } else {
                        BusFormat::Fd
                    },
                    node_source: *NodeIdSource::ALL
                        .get(raw_source as usize)
                        .ok_or(out("NodeIdSource", raw_source))?,
                }
            }
            10 => StatusPage::Config {
                checksum: get(d, 32, 32),
            },
            11 => {
                let raw_mode = get(d, 56, 4);
                StatusPage::Firmware {
                    version: [
                        get(d, 32, 8) as u8,
                        get(d, 40, 8) as u8,
                        get(d, 48, 8) as u8,
                    ],
                    mode: *crate::service::Mode::ALL
                        .get(raw_mode as usize)
                        .ok_or(out("DetectorMode", raw_mode))?,
                }
            }
            12 => StatusPage::Build {
                hash: get(d, 32, 32),
            },
            13..=16 => StatusPage::DetectorName {
                part: page as u8 - 13,
                bytes: get(d, 32, 32).to_le_bytes(),
            },
            p => return Err(out("Page", p)),
        })
    }
}

/// A status frame: its counter and its page.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StatusMsg {
    /// The rolling counter, +1 per status frame whatever its page.
    pub counter: Counter,
    /// The page.
    pub page: StatusPage,
}

impl StatusMsg {
    /// The frame for `node`; fails for a phase index of 8 or more or a reserved fault
    /// flag set.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.page.validate()?;
        let mut p = Payload::new(MessageKind::Status, self.counter);
        self.page.write(&mut p);
        Ok(p.for_node(node))
    }

    fn decode(d: &[u8]) -> Result<StatusMsg, DecodeError> {
        Ok(StatusMsg {
            counter: counter(d),
            page: StatusPage::read(d)?,
        })
    }
}

// ---------------------------------------------------------------------------------------
// Any message

/// Any message of the protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Message {
    /// An event frame.
    Event(EventMsg),
    /// A broadcast context frame.
    Context(ContextMsg),
    /// A context part frame (classic CAN).
    ContextPart(ContextPartMsg),
    /// A phase frame.
    Phase(PhaseMsg),
    /// A stream sample (CAN FD).
    Stream(StreamMsg),
    /// A stream page (classic CAN).
    StreamPage(StreamPageMsg),
    /// A status frame.
    Status(StatusMsg),
}

impl Message {
    /// Which message it is.
    pub const fn kind(&self) -> MessageKind {
        match self {
            Message::Event(_) => MessageKind::Event,
            Message::Context(_) => MessageKind::Context,
            Message::ContextPart(_) => MessageKind::ContextPart,
            Message::Phase(_) => MessageKind::Phase,
            Message::Stream(_) => MessageKind::Stream,
            Message::StreamPage(_) => MessageKind::StreamPage,
            Message::Status(_) => MessageKind::Status,
        }
    }

    /// The rolling counter.
    pub const fn counter(&self) -> Counter {
        match self {
            Message::Event(m) => m.counter,
            Message::Context(m) => m.counter,
            Message::ContextPart(m) => m.counter,
            Message::Phase(m) => m.counter,
            Message::Stream(m) => m.counter,
            Message::StreamPage(m) => m.counter,
            Message::Status(m) => m.counter,
        }
    }

    /// The frame for `address` (a group for a context frame, a node otherwise).
    pub fn encode(&self, address: Address) -> Result<CanFrame, EncodeError> {
        let mismatch = EncodeError {
            kind: self.kind(),
            signal: "Address",
            value: i64::from(address.index()),
        };
        match (self, address) {
            (Message::Context(m), Address::Group(g)) => m.encode(g),
            (Message::Context(_), Address::Node(_)) | (_, Address::Group(_)) => Err(mismatch),
            (Message::Event(m), Address::Node(n)) => m.encode(n),
            (Message::ContextPart(m), Address::Node(n)) => m.encode(n),
            (Message::Phase(m), Address::Node(n)) => m.encode(n),
            (Message::Stream(m), Address::Node(n)) => m.encode(n),
            (Message::StreamPage(m), Address::Node(n)) => m.encode(n),
            (Message::Status(m), Address::Node(n)) => m.encode(n),
        }
    }

    /// Decodes a frame: its address and its message. Checks the identifier, the length,
    /// the CRC and every field's range, in that order; never panics, whatever the input.
    /// The frame format (classic or CAN FD) does not matter, only the data.
    pub fn decode(id: Id, data: &[u8]) -> Result<(Address, Message), DecodeError> {
        let (kind, address) = MessageKind::from_id(id).ok_or(DecodeError::UnknownId)?;
        if data.len() != kind.data_len() {
            return Err(DecodeError::WrongLength {
                kind,
                expected: kind.data_len() as u8,
                got: data.len(),
            });
        }
        let sid = match id {
            Id::Standard(s) => s,
            Id::Extended(_) => return Err(DecodeError::UnknownId),
        };
        let expected = e2e::crc(sid, data).unwrap_or(0);
        let got = e2e::carried(data).unwrap_or(0);
        if expected != got {
            return Err(DecodeError::BadCrc {
                kind,
                expected,
                got,
            });
        }
        let m = match kind {
            MessageKind::Event => Message::Event(EventMsg::decode(data)?),
            MessageKind::Context => Message::Context(ContextMsg::decode(data)?),
            MessageKind::ContextPart => Message::ContextPart(ContextPartMsg::decode(data)?),
            MessageKind::Phase => Message::Phase(PhaseMsg::decode(data)?),
            MessageKind::Stream => Message::Stream(StreamMsg::decode(data)?),
            MessageKind::StreamPage => Message::StreamPage(StreamPageMsg::decode(data)?),
            MessageKind::Status => Message::Status(StatusMsg::decode(data)?),
        };
        Ok((address, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::StandardId;

    fn node(n: u8) -> NodeId {
        NodeId::new(n).unwrap()
    }

    fn group(g: u8) -> ContextGroup {
        ContextGroup::new(g).unwrap()
    }

    fn round_trip(m: Message, a: Address) -> CanFrame {
        let f = m.encode(a).unwrap();
        assert_eq!(f.len(), m.kind().data_len());
        assert_eq!(f.is_fd(), f.len() > 8);
        assert_eq!(
            Message::decode(Id::Standard(f.id()), f.data()),
            Ok((a, m)),
            "{m:?}"
        );
        f
    }

    fn slot(v: i16) -> ContextSlot {
        ContextSlot {
            vel_des: [v, -v],
            acc_des: [-v, v],
            pos_err: [8 * v, -8 * v],
        }
    }

    /// The scales derived from the whole raw units per SI unit are the decimal steps the
    /// DBC and the docs state, to the last bit.
    #[test]
    fn the_scales_are_the_decimal_steps() {
        assert_eq!(ContextPart::Velocity.scale(), 1e-4);
        assert_eq!(ContextPart::Acceleration.scale(), 2e-3);
        assert_eq!(ContextPart::PositionError.scale(), 1e-6);
        for part in ContextPart::ALL {
            assert_eq!(part.scale() * f64::from(part.per_si()), 1.0);
        }
    }

    #[test]
    fn bit_fields_round_trip_at_every_offset() {
        for start in 0..(512 - 32) {
            for len in [1, 3, 13, 16, 32] {
                let mut d = [0xA5u8; 64];
                let v = 0xDEAD_BEEFu32 & (((1u64 << len) - 1) as u32);
                put(&mut d, start, len, v);
                assert_eq!(get(&d, start, len), v);
                // Bits around the field are untouched.
                if start > 0 {
                    assert_eq!(get(&d, start - 1, 1), (0xA5u32 >> ((start - 1) % 8)) & 1);
                }
            }
        }
        let mut d = [0u8; 2];
        put(&mut d, 3, 13, 0x1FFF);
        assert_eq!(d, [0xF8, 0xFF]);
        assert_eq!(sget(&d, 3, 13), -1);
    }

    #[test]
    fn every_message_round_trips_at_its_extremes() {
        let conf = |b| Confidence::from_bits(b).unwrap();
        let mut stream = StreamMsg {
            counter: Counter(255),
            evaluated: 0xFF,
            unjudgeable: 0x81,
            levels: [LevelState::Confirm; MAX_EVENTS],
            confidences: [Confidence::ONE; MAX_EVENTS],
        };
        stream.levels[3] = LevelState::None;
        stream.confidences[4] = conf(1);
        let per_node = [
            Message::Event(EventMsg {
                counter: Counter(255),
                event: EventId(7),
                level: Level::Confirm,
                tick: u16::MAX,
                onset_age: u16::MAX,
            }),
            Message::Event(EventMsg {
                counter: Counter(0),
                event: EventId(0),
                level: Level::Alert,
                tick: 0,
                onset_age: 0,
            }),
            Message::Phase(PhaseMsg {
                counter: Counter(9),
                phase: 7,
                sequence: 255,
            }),
            Message::ContextPart(ContextPartMsg {
                counter: Counter(1),
                part: ContextPart::PositionError,
                value: [-32767, 32767],
            }),
            Message::ContextPart(ContextPartMsg {
                counter: Counter(2),
                part: ContextPart::Velocity,
                value: [4095, -4095],
            }),
            Message::Stream(stream),
            Message::Stream(StreamMsg::default()),
            Message::StreamPage(StreamPageMsg {
                counter: Counter(7),
                sample: 200,
                event: EventId(7),
                unjudgeable: true,
                level: LevelState::Alert,
                confidence: Confidence::ONE,
            }),
            Message::Status(StatusMsg {
                counter: Counter(4),
                page: StatusPage::Health {
                    reset: ResetReason::OptionBytes,
                    phase: None,
                    faults: FaultFlags(0x1FF),
                    phase_seq: 255,
                },
            }),
            Message::Status(StatusMsg {
                counter: Counter(5),
                page: StatusPage::Identity {
                    tick_rate_hz: 5000,
                    protocol: PROTOCOL_VERSION,
                    format: BusFormat::Classic,
                    node_source: NodeIdSource::Store,
                },
            }),
            Message::Status(StatusMsg {
                counter: Counter(6),
                page: StatusPage::Uptime { uptime: u32::MAX },
            }),
            Message::Status(StatusMsg {
                counter: Counter(6),
                page: StatusPage::Config {
                    checksum: 0xDEAD_BEEF,
                },
            }),
            Message::Status(StatusMsg {
                counter: Counter(7),
                page: StatusPage::Firmware {
                    version: [1, 255, 0],
                    mode: crate::service::Mode::Fallback,
                },
            }),
            Message::Status(StatusMsg {
                counter: Counter(8),
                page: StatusPage::Build { hash: 0x0123_4567 },
            }),
            Message::Status(StatusMsg {
                counter: Counter(9),
                page: StatusPage::DetectorName {
                    part: 3,
                    bytes: *b"ach\0",
                },
            }),
        ];
        for m in per_node {
            for n in [0, 5, 14] {
                round_trip(m, Address::Node(node(n)));
            }
        }
        for page in 3..=9 {
            let p = StatusPage::from_pair(page, 65535, page.into()).unwrap();
            assert_eq!(p.page(), page);
            round_trip(
                Message::Status(StatusMsg {
                    counter: Counter(page),
                    page: p,
                }),
                Address::Node(node(3)),
            );
        }
        let ctx = ContextMsg {
            counter: Counter(77),
            time_us: u32::MAX,
            slots: [
                Some(slot(4095)),
                None,
                Some(slot(-1)),
                Some(slot(0)),
                Some(slot(4095)),
            ],
        };
        for g in 0..3 {
            round_trip(Message::Context(ctx), Address::Group(group(g)));
        }
        assert_eq!(ctx.slot_of(group(1), node(7)), Some(slot(-1)));
        assert_eq!(ctx.slot_of(group(1), node(6)), None);
        assert_eq!(ctx.slot_of(group(0), node(7)), None, "another group's slot");
    }

    #[test]
    fn addresses_must_fit_the_message() {
        let ctx = Message::Context(ContextMsg::default());
        assert!(ctx.encode(Address::Node(node(1))).is_err());
        let ev = Message::Phase(PhaseMsg {
            counter: Counter(0),
            phase: 0,
            sequence: 0,
        });
        assert_eq!(
            ev.encode(Address::Group(group(2))).unwrap_err().signal,
            "Address"
        );
    }

    #[test]
    fn hand_packed_frames() {
        // VelDesX = -1 fills slot 0's first 13 bits (bits 64..77), node 5's valid bit is 24.
        let mut m = ContextMsg {
            counter: Counter(2),
            time_us: 0x0403_0201,
            ..ContextMsg::default()
        };
        m.slots[0] = Some(ContextSlot {
            vel_des: [-1, 0],
            acc_des: [0, 1],
            pos_err: [0, 0],
        });
        let f = m.encode(group(1)).unwrap();
        assert_eq!(f.id().as_raw(), 0x121);
        let d = f.data();
        assert_eq!((d[2], d[3]), (2, 0b1));
        assert_eq!(&d[4..8], &[1, 2, 3, 4]);
        assert_eq!((d[8], d[9]), (0xFF, 0x1F));
        // AccDesY = 1 at slot bit 39: bit 103, byte 12 bit 7.
        assert_eq!(d[12], 0x80);
        assert_eq!(
            u16::from_le_bytes([d[0], d[1]]),
            e2e::crc(f.id(), d).unwrap()
        );
        // An event: event 5, confirm in byte 3.
        let e = EventMsg {
            counter: Counter(9),
            event: EventId(5),
            level: Level::Confirm,
            tick: 0x1234,
            onset_age: 0x0506,
        }
        .encode(node(2))
        .unwrap();
        assert_eq!(e.id().as_raw(), 0x112);
        assert_eq!(&e.data()[2..], &[9, 0b1101, 0x34, 0x12, 0x06, 0x05]);
    }

    #[test]
    fn out_of_range_values_neither_encode_nor_decode() {
        let bad = ContextPartMsg {
            counter: Counter(0),
            part: ContextPart::Acceleration,
            value: [0, -4096],
        };
        assert_eq!(
            bad.encode(node(0)),
            Err(EncodeError {
                kind: MessageKind::ContextPart,
                signal: "AccDesY",
                value: -4096
            })
        );
        let mut ctx = ContextMsg::default();
        ctx.slots[4] = Some(ContextSlot {
            pos_err: [-32768, 0],
            ..ContextSlot::default()
        });
        assert!(ctx.encode(group(0)).is_err());
        // Build payloads by hand with a correct CRC: the decoder refuses them.
        let refused = |kind: MessageKind, fill: &dyn Fn(&mut [u8])| {
            let id = kind.id(node(0));
            let mut d = [0u8; 64];
            let d = &mut d[..kind.data_len()];
            fill(d);
            e2e::seal(id, d);
            Message::decode(Id::Standard(id), d).unwrap_err()
        };
        // Slot 0 valid, VelDesX = -4096 (its sign bit alone, bit 76).
        let e = refused(MessageKind::Context, &|d| {
            put(d, 24, 1, 1);
            put(d, 76, 1, 1);
        });
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "VelDesX",
                value: -4096,
                ..
            }
        ));
        // The same in a slot not valid is ignored.
        let id = MessageKind::Context.id(node(0));
        let mut d = [0u8; 64];
        put(&mut d, 76, 1, 1);
        e2e::seal(id, &mut d);
        assert!(Message::decode(Id::Standard(id), &d).is_ok());
        let e = refused(MessageKind::Phase, &|d| put(d, 24, 8, 8));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "PhaseId",
                value: 8,
                ..
            }
        ));
        let e = refused(MessageKind::ContextPart, &|d| put(d, 24, 2, 3));
        assert!(matches!(e, DecodeError::OutOfRange { signal: "Part", .. }));
        let e = refused(MessageKind::Stream, &|d| put(d, 40 + 2 * 6, 2, 3));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "Level",
                value: 3,
                ..
            }
        ));
        let e = refused(MessageKind::Stream, &|d| put(d, 56 + 16 * 7, 16, 32769));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "Conf",
                value: 32769,
                ..
            }
        ));
        let e = refused(MessageKind::Status, &|d| put(d, 24, 8, 17));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "Page",
                value: 17,
                ..
            }
        ));
        let e = refused(MessageKind::Status, &|d| {
            put(d, 24, 8, 11);
            put(d, 56, 4, 3);
        });
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "DetectorMode",
                value: 3,
                ..
            }
        ));
        let e = refused(MessageKind::Status, &|d| put(d, 36, 4, 9));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "Phase",
                value: 9,
                ..
            }
        ));
        let e = refused(MessageKind::Status, &|d| put(d, 32, 4, 9));
        assert!(matches!(
            e,
            DecodeError::OutOfRange {
                signal: "ResetReason",
                ..
            }
        ));
        assert!(
            EventMsg {
                counter: Counter(0),
                event: EventId(8),
                level: Level::Alert,
                tick: 0,
                onset_age: 0
            }
            .encode(node(0))
            .is_err()
        );
        let reserved_flag = StatusMsg {
            counter: Counter(0),
            page: StatusPage::Health {
                reset: ResetReason::Unknown,
                phase: None,
                faults: FaultFlags(1 << 10),
                phase_seq: 0,
            },
        };
        assert!(reserved_flag.encode(node(0)).is_err());
    }

    #[test]
    fn decoder_reports_what_is_wrong() {
        let id = |k: MessageKind| Id::Standard(k.id(node(1)));
        assert_eq!(
            Message::decode(Id::Standard(StandardId::new(0x7FF).unwrap()), &[]),
            Err(DecodeError::UnknownId)
        );
        assert_eq!(
            Message::decode(id(MessageKind::Phase), &[0; 8]),
            Err(DecodeError::WrongLength {
                kind: MessageKind::Phase,
                expected: 5,
                got: 8
            })
        );
        let f = PhaseMsg {
            counter: Counter(1),
            phase: 2,
            sequence: 3,
        }
        .encode(node(1))
        .unwrap();
        let mut d = [0u8; 5];
        d.copy_from_slice(f.data());
        d[0] ^= 1;
        assert!(matches!(
            Message::decode(id(MessageKind::Phase), &d),
            Err(DecodeError::BadCrc { .. })
        ));
        // A frame of node 1 presented as node 2's fails the CRC too.
        assert!(matches!(
            Message::decode(Id::Standard(MessageKind::Phase.id(node(2))), f.data()),
            Err(DecodeError::BadCrc { .. })
        ));
    }

    #[test]
    fn si_conversions_round_and_saturate() {
        let s = Signal::from_f64;
        let m =
            ContextSlot::from_signals([s(0.05), s(-0.02)], [s(1.0), s(-100.0)], [s(0.001), s(1.0)]);
        assert_eq!(m.vel_des, [500, -200]);
        assert_eq!(m.acc_des, [500, -4095]);
        // 1 mm is 65.536 steps of 2⁻¹⁶ m: the Signal holds 66 steps, 1.00708 mm.
        assert_eq!(m.pos_err, [1007, 32767]);
        assert!((m.vel_des_signals()[0].to_f64() - 0.05).abs() < 1.0 / 65536.0);
        assert!((m.acc_des_signals()[1].to_f64() + 8.19).abs() < 1.0 / 65536.0);
        assert!((m.pos_err_signals()[0].to_f64() - 0.001).abs() < 1.0 / 65536.0);
        // Every raw value converts within half a Signal step of its exact value.
        for part in ContextPart::ALL {
            let max = part.raw_max();
            for r in (-max..=max).step_by(7) {
                let v = part.signals([r, r])[0].to_f64();
                assert!((v - f64::from(r) * part.scale()).abs() <= 0.5 / 65536.0 + 1e-12);
            }
        }
    }

    #[test]
    fn event_tick_unwraps_around_a_reference() {
        let d = Decision {
            event: EventId(2),
            level: Level::Confirm,
            confidence: Confidence::ONE,
            onset: 0x0001_FFF0,
            tick: 0x0002_0005,
        };
        let m = EventMsg::from_decision(Counter(0), &d);
        assert_eq!(m.tick, 0x0005);
        assert_eq!(m.onset_age, 0x15);
        assert_eq!(m.full_tick(0x0001_FF00), 0x0002_0005);
        assert_eq!(m.full_tick(0x0002_0100), 0x0002_0005);
        let old = Decision {
            onset: 0,
            tick: 100_000,
            ..d
        };
        assert_eq!(
            EventMsg::from_decision(Counter(0), &old).onset_age,
            u16::MAX
        );
    }
}
