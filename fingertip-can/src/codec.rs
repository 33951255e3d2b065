//! The codec: one type per message, packed little-endian as `fingertip-can/fingertip.dbc` states.
//!
//! Decoding checks, in order: the identifier, the length, the CRC of protected frames, then
//! the range of every field. Reserved bits are sent as zero and ignored on receipt.
//! Encoding checks the same ranges, so a frame this module produces always decodes.

use core::fmt;

use super::e2e::{self, Counter};
use super::{CanFrame, Id, MessageKind, NodeId};
use detector_core::{Confidence, Decision, EventId, Level, MAX_EVENTS, Signal, Tick};

/// The protocol version, sent in the status frame's timing page.
pub const PROTOCOL_VERSION: u8 = 1;

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
pub const STATUS_PAGES: u8 = 6;

/// A frame could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DecodeError {
    /// The identifier is extended, or outside the protocol's 0x080..=0x0DF.
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
    /// Byte 0 of a protected frame is not the CRC of the rest.
    BadCrc {
        /// The message the identifier names.
        kind: MessageKind,
        /// The CRC the payload should carry.
        expected: u8,
        /// The CRC it carried.
        got: u8,
    },
    /// A field holds a value outside its range.
    OutOfRange {
        /// The message the identifier names.
        kind: MessageKind,
        /// The field's signal name in the DBC.
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
                "{} frame has CRC 0x{got:02X}, expected 0x{expected:02X}",
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

/// A message could not be encoded: a field is outside its range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EncodeError {
    /// The message.
    pub kind: MessageKind,
    /// The field's signal name in the DBC.
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

/// The payload as a little-endian word; bytes past the end read as zero.
fn word(data: &[u8]) -> u64 {
    let mut b = [0u8; 8];
    for (d, s) in b.iter_mut().zip(data) {
        *d = *s;
    }
    u64::from_le_bytes(b)
}

/// `len` bits (1..=32) of `w` from bit `start`.
fn field(w: u64, start: u32, len: u32) -> u32 {
    ((w >> start) & ((1u64 << len) - 1)) as u32
}

/// As [`field`], sign-extended.
fn sfield(w: u64, start: u32, len: u32) -> i32 {
    let v = field(w, start, len);
    let shift = 32 - len;
    ((v << shift) as i32) >> shift
}

/// Writes the low `len` bits of `v` at bit `start`.
fn put(w: &mut u64, start: u32, len: u32, v: u64) {
    *w |= (v & ((1u64 << len) - 1)) << start;
}

/// Builds a frame of `kind` for `node` from a word, filling the CRC of protected messages.
fn frame(kind: MessageKind, node: NodeId, w: u64) -> CanFrame {
    let id = kind.id(node);
    let bytes = w.to_le_bytes();
    let mut data = [0u8; 8];
    let n = kind.dlc();
    for (d, s) in data.iter_mut().zip(bytes.iter()).take(n) {
        *d = *s;
    }
    if kind.is_protected()
        && let Some(c) = e2e::crc(id, data.get(..n).unwrap_or(&[]))
    {
        data[0] = c;
    }
    // n <= 8, so this always succeeds; the fallback is an empty frame.
    CanFrame::new(id, data.get(..n).unwrap_or(&[])).unwrap_or(CanFrame {
        id,
        len: 0,
        data: [0; 8],
    })
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
/// Protected by counter and CRC. 8 bytes.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..8 | `Crc` | CRC-8, see [`e2e`] |
/// | 8..12 | `Counter` | rolling counter |
/// | 12..15 | `EventId` | the event's index in the configuration, 0..=7 |
/// | 15 | `Level` | 0 alert, 1 confirm |
/// | 16..32 | `Confidence` | the event's confidence, Q15: 0..=32768 is 0..=1 |
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
    /// The event's confidence at the decision.
    pub confidence: Confidence,
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
            confidence: d.confidence,
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
        let mut w = 0u64;
        put(&mut w, 8, 4, u64::from(self.counter.get()));
        put(&mut w, 12, 3, u64::from(self.event.0));
        put(&mut w, 15, 1, u64::from(self.level == Level::Confirm));
        put(&mut w, 16, 16, u64::from(self.confidence.to_bits()));
        put(&mut w, 32, 16, u64::from(self.tick));
        put(&mut w, 48, 16, u64::from(self.onset_age));
        Ok(frame(MessageKind::Event, node, w))
    }

    fn decode(w: u64) -> Result<EventMsg, DecodeError> {
        Ok(EventMsg {
            counter: Counter::from_low_bits(field(w, 8, 4) as u8),
            event: EventId(field(w, 12, 3) as u8),
            level: if field(w, 15, 1) == 1 {
                Level::Confirm
            } else {
                Level::Alert
            },
            confidence: confidence(MessageKind::Event, "Confidence", field(w, 16, 16))?,
            tick: field(w, 32, 16) as u16,
            onset_age: field(w, 48, 16) as u16,
        })
    }
}

// ---------------------------------------------------------------------------------------
// Phase

/// The phase the controller wants run. Protected. 4 bytes. Sent on every change and
/// periodically; the fingertip treats it as stale after its phase timeout.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..8 | `Crc` | CRC-8 |
/// | 8..12 | `Counter` | rolling counter |
/// | 16..24 | `PhaseId` | the phase's index in the configuration, 0..=7 (and below the number of phases configured) |
/// | 24..32 | `PhaseSeq` | phase sequence: advanced by the controller at every phase entry, so re-entering the same phase is seen as new |
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
            detector_core::MAX_PHASES as i64 - 1,
        )
    }

    /// The frame for `node`; fails for a phase index of 8 or more.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut w = 0u64;
        put(&mut w, 8, 4, u64::from(self.counter.get()));
        put(&mut w, 16, 8, u64::from(self.phase));
        put(&mut w, 24, 8, u64::from(self.sequence));
        Ok(frame(MessageKind::Phase, node, w))
    }

    fn decode(w: u64) -> Result<PhaseMsg, DecodeError> {
        let m = PhaseMsg {
            counter: Counter::from_low_bits(field(w, 8, 4) as u8),
            phase: field(w, 16, 8) as u8,
            sequence: field(w, 24, 8) as u8,
        };
        m.validate()?;
        Ok(m)
    }
}

// ---------------------------------------------------------------------------------------
// Context

/// The controller's commanded tip motion, in the fingertip's frame. Protected. 8 bytes.
///
/// | bits | signal | unit | range |
/// |---|---|---|---|
/// | 0..8 | `Crc` | | |
/// | 8..12 | `Counter` | | 0..=15 |
/// | 12..25 | `VelDesX` | 10⁻⁴ m/s | ±0.4095 m/s (raw ±4095) |
/// | 25..38 | `VelDesY` | 10⁻⁴ m/s | ±0.4095 m/s |
/// | 38..51 | `AccDesX` | 2·10⁻³ m/s² | ±8.19 m/s² (raw ±4095) |
/// | 51..64 | `AccDesY` | 2·10⁻³ m/s² | ±8.19 m/s² |
///
/// Values are signed 13-bit; the raw value −4096 is out of range (a sender saturates at
/// ±4095).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContextMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// Desired tip velocity (x, y), raw, 10⁻⁴ m/s per unit, within ±[`VEL_DES_RAW_MAX`].
    pub vel_des: [i16; 2],
    /// Desired tip acceleration (x, y), raw, 2·10⁻³ m/s² per unit, within
    /// ±[`ACC_DES_RAW_MAX`].
    pub acc_des: [i16; 2],
}

const CONTEXT_SIGNALS: [&str; 4] = ["VelDesX", "VelDesY", "AccDesX", "AccDesY"];

impl ContextMsg {
    /// Metres per second per raw unit of velocity.
    pub const VEL_SCALE: f64 = 1e-4;
    /// Metres per second squared per raw unit of acceleration.
    pub const ACC_SCALE: f64 = 2e-3;

    /// From SI values, rounded to nearest and saturated at the ends of the ranges.
    pub fn from_signals(counter: Counter, vel_des: [Signal; 2], acc_des: [Signal; 2]) -> Self {
        // raw = bits · 2⁻¹⁶ / 10⁻⁴ = bits · 625 / 4096; raw = bits · 2⁻¹⁶ / 2·10⁻³ = bits · 125 / 16384.
        ContextMsg {
            counter,
            vel_des: vel_des.map(|s| quantize(s, 625, 12, VEL_DES_RAW_MAX)),
            acc_des: acc_des.map(|s| quantize(s, 125, 14, ACC_DES_RAW_MAX)),
        }
    }

    /// Desired velocity (x, y) in m/s, as the core's [`Signal`] (rounded to 2⁻¹⁶).
    pub fn vel_des_signals(&self) -> [Signal; 2] {
        // bits = raw · 10⁻⁴ · 2¹⁶ = raw · 4096 / 625; |raw| ≤ 4096 keeps it inside i32.
        self.vel_des
            .map(|r| Signal::from_bits(div_round(i32::from(r) * 4096, 625)))
    }

    /// Desired acceleration (x, y) in m/s², as the core's [`Signal`] (rounded to 2⁻¹⁶).
    pub fn acc_des_signals(&self) -> [Signal; 2] {
        // bits = raw · 2·10⁻³ · 2¹⁶ = raw · 16384 / 125.
        self.acc_des
            .map(|r| Signal::from_bits(div_round(i32::from(r) * 16384, 125)))
    }

    fn validate(&self) -> Result<(), EncodeError> {
        let values = [
            (self.vel_des[0], VEL_DES_RAW_MAX),
            (self.vel_des[1], VEL_DES_RAW_MAX),
            (self.acc_des[0], ACC_DES_RAW_MAX),
            (self.acc_des[1], ACC_DES_RAW_MAX),
        ];
        for (&(v, max), name) in values.iter().zip(CONTEXT_SIGNALS) {
            check_range(
                MessageKind::Context,
                name,
                i64::from(v),
                -i64::from(max),
                i64::from(max),
            )?;
        }
        Ok(())
    }

    /// The frame for `node`; fails for a value outside its range.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut w = 0u64;
        put(&mut w, 8, 4, u64::from(self.counter.get()));
        let values = [
            self.vel_des[0],
            self.vel_des[1],
            self.acc_des[0],
            self.acc_des[1],
        ];
        for (i, v) in (0u32..).zip(values) {
            put(&mut w, 12 + 13 * i, 13, v as u16 as u64);
        }
        Ok(frame(MessageKind::Context, node, w))
    }

    fn decode(w: u64) -> Result<ContextMsg, DecodeError> {
        let v = |i: u32| sfield(w, 12 + 13 * i, 13) as i16;
        let m = ContextMsg {
            counter: Counter::from_low_bits(field(w, 8, 4) as u8),
            vel_des: [v(0), v(1)],
            acc_des: [v(2), v(3)],
        };
        m.validate()?;
        Ok(m)
    }
}

// ---------------------------------------------------------------------------------------
// Tip state

/// The tip position error (commanded minus actual), in the fingertip's frame. Protected.
/// 6 bytes.
///
/// | bits | signal | unit | range |
/// |---|---|---|---|
/// | 0..8 | `Crc` | | |
/// | 8..12 | `Counter` | | 0..=15 |
/// | 16..32 | `PosErrX` | 1 µm | ±32.767 mm (raw ±32767) |
/// | 32..48 | `PosErrY` | 1 µm | ±32.767 mm |
///
/// The raw value −32768 is out of range (a sender saturates at ±32767).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TipStateMsg {
    /// The rolling counter.
    pub counter: Counter,
    /// Tip position error (x, y), raw, 1 µm per unit, within ±[`POS_ERR_RAW_MAX`].
    pub pos_err: [i16; 2],
}

impl TipStateMsg {
    /// Metres per raw unit.
    pub const POS_SCALE: f64 = 1e-6;

    /// From SI values (m), rounded to nearest and saturated at ±32.767 mm.
    pub fn from_signals(counter: Counter, pos_err: [Signal; 2]) -> TipStateMsg {
        // raw = bits · 2⁻¹⁶ / 10⁻⁶ = bits · 15625 / 1024.
        TipStateMsg {
            counter,
            pos_err: pos_err.map(|s| quantize(s, 15625, 10, POS_ERR_RAW_MAX)),
        }
    }

    /// Position error (x, y) in m, as the core's [`Signal`] (rounded to 2⁻¹⁶ m, 15 µm).
    pub fn pos_err_signals(&self) -> [Signal; 2] {
        // bits = raw · 10⁻⁶ · 2¹⁶ = raw · 1024 / 15625.
        self.pos_err
            .map(|r| Signal::from_bits(div_round(i32::from(r) * 1024, 15625)))
    }

    fn validate(&self) -> Result<(), EncodeError> {
        for (&v, name) in self.pos_err.iter().zip(["PosErrX", "PosErrY"]) {
            check_range(
                MessageKind::TipState,
                name,
                i64::from(v),
                -i64::from(POS_ERR_RAW_MAX),
                i64::from(POS_ERR_RAW_MAX),
            )?;
        }
        Ok(())
    }

    /// The frame for `node`; fails for −32768.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut w = 0u64;
        put(&mut w, 8, 4, u64::from(self.counter.get()));
        put(&mut w, 16, 16, self.pos_err[0] as u16 as u64);
        put(&mut w, 32, 16, self.pos_err[1] as u16 as u64);
        Ok(frame(MessageKind::TipState, node, w))
    }

    fn decode(w: u64) -> Result<TipStateMsg, DecodeError> {
        let m = TipStateMsg {
            counter: Counter::from_low_bits(field(w, 8, 4) as u8),
            pos_err: [sfield(w, 16, 16) as i16, sfield(w, 32, 16) as i16],
        };
        m.validate()?;
        Ok(m)
    }
}

// ---------------------------------------------------------------------------------------
// Confidence stream

/// One page of a sample of the confidence stream: up to three events' confidences.
/// Not CRC-protected; the sequence number tells lost samples. 8 bytes.
///
/// Page `p` carries events `3p`, `3p + 1`, `3p + 2` (page 2: events 6 and 7 only). A
/// sample sends the pages that hold at least one event of the current phase, all with
/// the same sequence number.
///
/// | bits | signal | meaning |
/// |---|---|---|
/// | 0..8 | `Seq` | sample sequence number, wrapping |
/// | 8..10 | `Page` | multiplexer, 0..=2 |
/// | 10..13 | `Evaluated{e}` | event `e` belongs to the current phase |
/// | 13..16 | `Unjudgeable{e}` | event `e` cannot be judged (a context or every sensor channel faulty) |
/// | 16..32, 32..48, 48..64 | `Conf{e}` | the events' confidences, Q15: 0..=32768 is 0..=1 |
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ConfidenceMsg {
    /// The sample sequence number.
    pub seq: u8,
    /// The page, `0..=2`.
    pub page: u8,
    /// Bit `k` set: event `3·page + k` is evaluated (belongs to the current phase).
    pub evaluated: u8,
    /// Bit `k` set: event `3·page + k` cannot be judged.
    pub unjudgeable: u8,
    /// Confidences of events `3·page + k`; zero for events not evaluated.
    pub confidences: [Confidence; 3],
}

impl ConfidenceMsg {
    /// Pages needed for all [`MAX_EVENTS`] events.
    pub const PAGES: u8 = 3;

    /// Events on `page`: 3 on pages 0 and 1, 2 on page 2, 0 on others.
    pub const fn slots(page: u8) -> usize {
        match page {
            0 | 1 => 3,
            2 => 2,
            _ => 0,
        }
    }

    fn slot_mask(&self) -> u8 {
        (1u8 << ConfidenceMsg::slots(self.page)) - 1
    }

    fn validate(&self) -> Result<(), EncodeError> {
        let k = MessageKind::Confidence;
        check_range(k, "Page", i64::from(self.page), 0, 2)?;
        let mask = self.slot_mask();
        check_range(k, "Evaluated", i64::from(self.evaluated & !mask), 0, 0)?;
        check_range(k, "Unjudgeable", i64::from(self.unjudgeable & !mask), 0, 0)?;
        if let Some(c) = self.confidences.get(ConfidenceMsg::slots(self.page)..) {
            for c in c {
                check_range(k, "Conf", i64::from(c.to_bits()), 0, 0)?;
            }
        }
        Ok(())
    }

    /// The frame for `node`; fails for a page above 2 or a flag or confidence set for an
    /// event that does not exist (event 8).
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut w = 0u64;
        put(&mut w, 0, 8, u64::from(self.seq));
        put(&mut w, 8, 2, u64::from(self.page));
        put(&mut w, 10, 3, u64::from(self.evaluated));
        put(&mut w, 13, 3, u64::from(self.unjudgeable));
        for (i, c) in (0u32..).zip(self.confidences) {
            put(&mut w, 16 + 16 * i, 16, u64::from(c.to_bits()));
        }
        Ok(frame(MessageKind::Confidence, node, w))
    }

    fn decode(w: u64) -> Result<ConfidenceMsg, DecodeError> {
        let k = MessageKind::Confidence;
        let page = field(w, 8, 2) as u8;
        let mut m = ConfidenceMsg {
            seq: field(w, 0, 8) as u8,
            page,
            ..ConfidenceMsg::default()
        };
        check_range(k, "Page", i64::from(page), 0, 2)?;
        let mask = m.slot_mask();
        // Slots past the page's events are reserved: ignored.
        m.evaluated = field(w, 10, 3) as u8 & mask;
        m.unjudgeable = field(w, 13, 3) as u8 & mask;
        let n = ConfidenceMsg::slots(page);
        for (i, c) in (0u32..).zip(m.confidences.iter_mut()).take(n) {
            *c = confidence(k, "Conf", field(w, 16 + 16 * i, 16))?;
        }
        Ok(m)
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
    /// A software reset (including a panic handler's).
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

/// Fault flags of the status heartbeat, one bit each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultFlags(pub u8);

impl FaultFlags {
    /// No valid context frame within the context timeout: context-dependent events are
    /// not confirmed.
    pub const CONTEXT_STALE: FaultFlags = FaultFlags(1 << 0);
    /// No valid tip state frame within the context timeout.
    pub const TIP_STATE_STALE: FaultFlags = FaultFlags(1 << 1);
    /// No valid phase frame within the phase timeout (or none since boot).
    pub const PHASE_STALE: FaultFlags = FaultFlags(1 << 2);
    /// A tick overran its period since the last heartbeat.
    pub const OVERRUN: FaultFlags = FaultFlags(1 << 3);
    /// The CAN controller was error-passive or bus-off since the last heartbeat.
    pub const BUS_ERROR: FaultFlags = FaultFlags(1 << 4);
    /// A frame could not be queued for sending since the last heartbeat.
    pub const TX_DROPPED: FaultFlags = FaultFlags(1 << 5);
    /// The detector image was rejected (or the tick does not match it): the detector is out
    /// of service and the fingertip sends only its status heartbeat.
    pub const CONFIG_FALLBACK: FaultFlags = FaultFlags(1 << 6);
    /// A sensor channel is flagged faulty.
    pub const SENSOR_FAULT: FaultFlags = FaultFlags(1 << 7);

    /// The flags' names as the DBC's signals write them, by bit.
    pub const NAMES: [&'static str; 8] = [
        "FaultContextStale",
        "FaultTipStateStale",
        "FaultPhaseStale",
        "FaultOverrun",
        "FaultBusError",
        "FaultTxDropped",
        "FaultConfigFallback",
        "FaultSensor",
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

/// One page of the multiplexed status heartbeat. Not protected. 8 bytes.
///
/// Byte 0 bits 3..0 hold the page (`Page`, the multiplexer). Counters are since boot and
/// saturate at their maximum. Layout by page:
///
/// | page | bits | signals |
/// |---|---|---|
/// | 0 health | 4..8, 8..16, 16..48, 48..56, 56..64 | `ResetReason`, eight `Fault*` flags (bit 8 + flag), `Uptime` (ticks), `Phase` (0..=7, 255 none), `PhaseSeq` |
/// | 1 timing | 8..24, 24..40, 40..56, 56..64 | `Overruns`, `WorstTick` (0.1 µs), `TickRate` (Hz), `ProtocolVersion` |
/// | 2 link | 8..24, 24..40, 40..56 | `StaleEpisodes`, `LostFrames`, `BusErrors` |
/// | 3 frame rejects | 8..24, 24..40, 40..56 | `RejWrongLength`, `RejUnknownId`, `RejBadCrc` |
/// | 4 content rejects | 8..24, 24..40, 40..56 | `RejSequence`, `RejPhaseNotConfigured`, `RejOutOfRange` |
/// | 5 configuration | 8..40, 40..56 | `ConfigChecksum`, `TxDropped` |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StatusPage {
    /// Page 0, sent every heartbeat.
    Health {
        /// Why the fingertip last reset.
        reset: ResetReason,
        /// Current faults.
        faults: FaultFlags,
        /// Detector ticks since boot, wrapping (at 5 kHz after 9.9 days).
        uptime: Tick,
        /// The phase the detector runs, `0..=7`; `None` before the first valid phase
        /// frame (sent as 255).
        phase: Option<u8>,
        /// That phase's sequence number (0 when none).
        phase_seq: u8,
    },
    /// Page 1.
    Timing {
        /// Ticks that overran their period.
        overruns: u16,
        /// Longest tick computation seen, in 0.1 µs (so up to 6.5535 ms).
        worst_tick: u16,
        /// The detector rate in Hz (the tick unit of the other frames).
        tick_rate_hz: u16,
        /// [`PROTOCOL_VERSION`].
        protocol: u8,
    },
    /// Page 2.
    Link {
        /// Times the context or tip state went stale.
        stale_episodes: u16,
        /// Controller frames lost, from gaps in their counters.
        lost_frames: u16,
        /// CAN error events (error-passive or bus-off entries, and protocol errors).
        bus_errors: u16,
    },
    /// Page 3: rejected received frames, by reason.
    FrameRejects {
        /// Wrong length.
        wrong_length: u16,
        /// Identifier not one of this node's receive messages.
        unknown_id: u16,
        /// CRC mismatch.
        bad_crc: u16,
    },
    /// Page 4: rejected received frames, by reason.
    ContentRejects {
        /// Counter did not advance correctly (repeated, out of order, jumped).
        sequence: u16,
        /// Phase index not configured.
        phase_not_configured: u16,
        /// A value out of its range.
        out_of_range: u16,
    },
    /// Page 5.
    Config {
        /// Checksum of the active configuration.
        checksum: u32,
        /// Frames the fingertip could not queue for sending.
        tx_dropped: u16,
    },
}

impl StatusPage {
    /// The page number, `0..STATUS_PAGES`.
    pub const fn page(&self) -> u8 {
        match self {
            StatusPage::Health { .. } => 0,
            StatusPage::Timing { .. } => 1,
            StatusPage::Link { .. } => 2,
            StatusPage::FrameRejects { .. } => 3,
            StatusPage::ContentRejects { .. } => 4,
            StatusPage::Config { .. } => 5,
        }
    }

    fn validate(&self) -> Result<(), EncodeError> {
        if let StatusPage::Health { phase: Some(p), .. } = *self {
            check_range(
                MessageKind::Status,
                "Phase",
                i64::from(p),
                0,
                detector_core::MAX_PHASES as i64 - 1,
            )?;
        }
        Ok(())
    }

    /// The frame for `node`; fails for a phase index of 8 or more.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        self.validate()?;
        let mut w = 0u64;
        put(&mut w, 0, 4, u64::from(self.page()));
        let three = |w: &mut u64, a: u16, b: u16, c: u16| {
            put(w, 8, 16, u64::from(a));
            put(w, 24, 16, u64::from(b));
            put(w, 40, 16, u64::from(c));
        };
        match *self {
            StatusPage::Health {
                reset,
                faults,
                uptime,
                phase,
                phase_seq,
            } => {
                put(&mut w, 4, 4, reset as u64);
                put(&mut w, 8, 8, u64::from(faults.0));
                put(&mut w, 16, 32, u64::from(uptime));
                put(&mut w, 48, 8, u64::from(phase.unwrap_or(u8::MAX)));
                put(&mut w, 56, 8, u64::from(phase_seq));
            }
            StatusPage::Timing {
                overruns,
                worst_tick,
                tick_rate_hz,
                protocol,
            } => {
                three(&mut w, overruns, worst_tick, tick_rate_hz);
                put(&mut w, 56, 8, u64::from(protocol));
            }
            StatusPage::Link {
                stale_episodes,
                lost_frames,
                bus_errors,
            } => three(&mut w, stale_episodes, lost_frames, bus_errors),
            StatusPage::FrameRejects {
                wrong_length,
                unknown_id,
                bad_crc,
            } => three(&mut w, wrong_length, unknown_id, bad_crc),
            StatusPage::ContentRejects {
                sequence,
                phase_not_configured,
                out_of_range,
            } => three(&mut w, sequence, phase_not_configured, out_of_range),
            StatusPage::Config {
                checksum,
                tx_dropped,
            } => {
                put(&mut w, 8, 32, u64::from(checksum));
                put(&mut w, 40, 16, u64::from(tx_dropped));
            }
        }
        Ok(frame(MessageKind::Status, node, w))
    }

    fn decode(w: u64) -> Result<StatusPage, DecodeError> {
        let k = MessageKind::Status;
        let u16_at = |start| field(w, start, 16) as u16;
        let (a, b, c) = (u16_at(8), u16_at(24), u16_at(40));
        Ok(match field(w, 0, 4) {
            0 => {
                let raw_reset = field(w, 4, 4) as u8;
                let reset = ResetReason::from_raw(raw_reset).ok_or(DecodeError::OutOfRange {
                    kind: k,
                    signal: "ResetReason",
                    value: i64::from(raw_reset),
                })?;
                let raw_phase = field(w, 48, 8) as u8;
                let phase = match raw_phase {
                    u8::MAX => None,
                    p if usize::from(p) < detector_core::MAX_PHASES => Some(p),
                    p => {
                        return Err(DecodeError::OutOfRange {
                            kind: k,
                            signal: "Phase",
                            value: i64::from(p),
                        });
                    }
                };
                StatusPage::Health {
                    reset,
                    faults: FaultFlags(field(w, 8, 8) as u8),
                    uptime: field(w, 16, 32),
                    phase,
                    phase_seq: field(w, 56, 8) as u8,
                }
            }
            1 => StatusPage::Timing {
                overruns: a,
                worst_tick: b,
                tick_rate_hz: c,
                protocol: field(w, 56, 8) as u8,
            },
            2 => StatusPage::Link {
                stale_episodes: a,
                lost_frames: b,
                bus_errors: c,
            },
            3 => StatusPage::FrameRejects {
                wrong_length: a,
                unknown_id: b,
                bad_crc: c,
            },
            4 => StatusPage::ContentRejects {
                sequence: a,
                phase_not_configured: b,
                out_of_range: c,
            },
            5 => StatusPage::Config {
                checksum: field(w, 8, 32),
                tx_dropped: c,
            },
            p => {
                return Err(DecodeError::OutOfRange {
                    kind: k,
                    signal: "Page",
                    value: i64::from(p),
                });
            }
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
    /// A phase frame.
    Phase(PhaseMsg),
    /// A context frame.
    Context(ContextMsg),
    /// A tip state frame.
    TipState(TipStateMsg),
    /// A confidence stream page.
    Confidence(ConfidenceMsg),
    /// A status page.
    Status(StatusPage),
}

impl Message {
    /// Which message it is.
    pub const fn kind(&self) -> MessageKind {
        match self {
            Message::Event(_) => MessageKind::Event,
            Message::Phase(_) => MessageKind::Phase,
            Message::Context(_) => MessageKind::Context,
            Message::TipState(_) => MessageKind::TipState,
            Message::Confidence(_) => MessageKind::Confidence,
            Message::Status(_) => MessageKind::Status,
        }
    }

    /// The rolling counter of a protected message.
    pub const fn counter(&self) -> Option<Counter> {
        match self {
            Message::Event(m) => Some(m.counter),
            Message::Phase(m) => Some(m.counter),
            Message::Context(m) => Some(m.counter),
            Message::TipState(m) => Some(m.counter),
            Message::Confidence(_) | Message::Status(_) => None,
        }
    }

    /// The frame for `node`.
    pub fn encode(&self, node: NodeId) -> Result<CanFrame, EncodeError> {
        match self {
            Message::Event(m) => m.encode(node),
            Message::Phase(m) => m.encode(node),
            Message::Context(m) => m.encode(node),
            Message::TipState(m) => m.encode(node),
            Message::Confidence(m) => m.encode(node),
            Message::Status(m) => m.encode(node),
        }
    }

    /// Decodes a frame: the node it belongs to and its message. Checks the identifier,
    /// the length, the CRC of protected messages and every field's range, in that order;
    /// never panics, whatever the input.
    pub fn decode(id: Id, data: &[u8]) -> Result<(NodeId, Message), DecodeError> {
        let (kind, node) = MessageKind::from_id(id).ok_or(DecodeError::UnknownId)?;
        if data.len() != kind.dlc() {
            return Err(DecodeError::WrongLength {
                kind,
                expected: kind.dlc() as u8,
                got: data.len(),
            });
        }
        if kind.is_protected() {
            let expected = e2e::crc(kind.id(node), data).unwrap_or(0);
            let got = data.first().copied().unwrap_or(0);
            if expected != got {
                return Err(DecodeError::BadCrc {
                    kind,
                    expected,
                    got,
                });
            }
        }
        let w = word(data);
        let m = match kind {
            MessageKind::Event => Message::Event(EventMsg::decode(w)?),
            MessageKind::Phase => Message::Phase(PhaseMsg::decode(w)?),
            MessageKind::Context => Message::Context(ContextMsg::decode(w)?),
            MessageKind::TipState => Message::TipState(TipStateMsg::decode(w)?),
            MessageKind::Confidence => Message::Confidence(ConfidenceMsg::decode(w)?),
            MessageKind::Status => Message::Status(StatusPage::decode(w)?),
        };
        Ok((node, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::StandardId;

    fn node(n: u8) -> NodeId {
        NodeId::new(n).unwrap()
    }

    fn c(n: u8) -> Counter {
        Counter::new(n).unwrap()
    }

    fn round_trip(m: Message, n: NodeId) -> CanFrame {
        let f = m.encode(n).unwrap();
        assert_eq!(f.len(), m.kind().dlc());
        assert_eq!(
            Message::decode(Id::Standard(f.id()), f.data()),
            Ok((n, m)),
            "{m:?}"
        );
        f
    }

    #[test]
    fn every_message_round_trips_at_its_extremes() {
        let conf = |b| Confidence::from_bits(b).unwrap();
        let samples = [
            Message::Event(EventMsg {
                counter: c(15),
                event: EventId(7),
                level: Level::Confirm,
                confidence: Confidence::ONE,
                tick: u16::MAX,
                onset_age: u16::MAX,
            }),
            Message::Event(EventMsg {
                counter: c(0),
                event: EventId(0),
                level: Level::Alert,
                confidence: Confidence::ZERO,
                tick: 0,
                onset_age: 0,
            }),
            Message::Phase(PhaseMsg {
                counter: c(9),
                phase: 7,
                sequence: 255,
            }),
            Message::Context(ContextMsg {
                counter: c(3),
                vel_des: [4095, -4095],
                acc_des: [-4095, 4095],
            }),
            Message::TipState(TipStateMsg {
                counter: c(1),
                pos_err: [-32767, 32767],
            }),
            Message::Confidence(ConfidenceMsg {
                seq: 200,
                page: 2,
                evaluated: 0b11,
                unjudgeable: 0b10,
                confidences: [Confidence::ONE, conf(1), Confidence::ZERO],
            }),
            Message::Status(StatusPage::Health {
                reset: ResetReason::OptionBytes,
                faults: FaultFlags(0xFF),
                uptime: u32::MAX,
                phase: None,
                phase_seq: 255,
            }),
            Message::Status(StatusPage::Timing {
                overruns: 1,
                worst_tick: 2,
                tick_rate_hz: 5000,
                protocol: PROTOCOL_VERSION,
            }),
            Message::Status(StatusPage::Link {
                stale_episodes: 3,
                lost_frames: 4,
                bus_errors: 65535,
            }),
            Message::Status(StatusPage::FrameRejects {
                wrong_length: 5,
                unknown_id: 6,
                bad_crc: 7,
            }),
            Message::Status(StatusPage::ContentRejects {
                sequence: 8,
                phase_not_configured: 9,
                out_of_range: 10,
            }),
            Message::Status(StatusPage::Config {
                checksum: 0xDEAD_BEEF,
                tx_dropped: 11,
            }),
        ];
        for m in samples {
            for n in [0, 5, 15] {
                round_trip(m, node(n));
            }
        }
    }

    #[test]
    fn hand_packed_context_frame() {
        // VelDesX = -1 fills bits 12..25, counter 2 sits in bits 8..12.
        let m = ContextMsg {
            counter: c(2),
            vel_des: [-1, 0],
            acc_des: [0, 1],
        };
        let f = m.encode(node(3)).unwrap();
        assert_eq!(f.id().as_raw(), 0x0A3);
        let d = f.data();
        assert_eq!(d[1], 0xF2);
        assert_eq!(d[2], 0xFF);
        assert_eq!(d[3], 0x01);
        // AccDesY = 1 at bit 51: byte 6, bit 3.
        assert_eq!(d[6], 0x08);
        assert_eq!(d[7], 0x00);
    }

    #[test]
    fn out_of_range_values_neither_encode_nor_decode() {
        let bad = ContextMsg {
            counter: c(0),
            vel_des: [-4096, 0],
            acc_des: [0, 0],
        };
        assert_eq!(
            bad.encode(node(0)),
            Err(EncodeError {
                kind: MessageKind::Context,
                signal: "VelDesX",
                value: -4096
            })
        );
        // Build the same payload by hand with a correct CRC: the decoder refuses it.
        let id = MessageKind::Context.id(node(0));
        let mut d = [0u8; 8];
        d[3] = 0x01; // bit 24 = sign bit of VelDesX, rest zero: -4096
        d[0] = e2e::crc(id, &d).unwrap();
        assert!(matches!(
            Message::decode(Id::Standard(id), &d),
            Err(DecodeError::OutOfRange {
                signal: "VelDesX",
                value: -4096,
                ..
            })
        ));
        assert!(
            EventMsg {
                counter: c(0),
                event: EventId(8),
                level: Level::Alert,
                confidence: Confidence::ZERO,
                tick: 0,
                onset_age: 0
            }
            .encode(node(0))
            .is_err()
        );
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
                expected: 4,
                got: 8
            })
        );
        let f = PhaseMsg {
            counter: c(1),
            phase: 2,
            sequence: 3,
        }
        .encode(node(1))
        .unwrap();
        let mut d = [0u8; 4];
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
        let mut conf = [0u8; 8];
        conf[2] = 0x01;
        conf[3] = 0x80; // 32769
        assert!(matches!(
            Message::decode(id(MessageKind::Confidence), &conf),
            Err(DecodeError::OutOfRange { signal: "Conf", .. })
        ));
        conf = [0, 3, 0, 0, 0, 0, 0, 0];
        assert!(matches!(
            Message::decode(id(MessageKind::Confidence), &conf),
            Err(DecodeError::OutOfRange { signal: "Page", .. })
        ));
        let status = [6u8, 0, 0, 0, 0, 0, 0, 0];
        assert!(matches!(
            Message::decode(id(MessageKind::Status), &status),
            Err(DecodeError::OutOfRange { signal: "Page", .. })
        ));
    }

    #[test]
    fn si_conversions_round_and_saturate() {
        let s = Signal::from_f64;
        let m = ContextMsg::from_signals(c(0), [s(0.05), s(-0.02)], [s(1.0), s(-100.0)]);
        assert_eq!(m.vel_des, [500, -200]);
        assert_eq!(m.acc_des, [500, -4095]);
        let back = m.vel_des_signals();
        assert!((back[0].to_f64() - 0.05).abs() < 1.0 / 65536.0);
        assert!((m.acc_des_signals()[1].to_f64() + 8.19).abs() < 1.0 / 65536.0);
        let t = TipStateMsg::from_signals(c(0), [s(0.001), s(1.0)]);
        // 1 mm is 65.536 steps of 2⁻¹⁶ m: the Signal holds 66 steps, 1.00708 mm.
        assert_eq!(t.pos_err, [1007, 32767]);
        assert!((t.pos_err_signals()[0].to_f64() - 0.001).abs() < 1.0 / 65536.0);
        // Every raw value converts within half a Signal step of its exact value.
        for r in -4095i16..=4095 {
            let m = ContextMsg {
                counter: c(0),
                vel_des: [r, r],
                acc_des: [r, r],
            };
            let v = m.vel_des_signals()[0].to_f64();
            let a = m.acc_des_signals()[0].to_f64();
            assert!((v - f64::from(r) * 1e-4).abs() <= 0.5 / 65536.0 + 1e-12);
            assert!((a - f64::from(r) * 2e-3).abs() <= 0.5 / 65536.0 + 1e-12);
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
        let m = EventMsg::from_decision(c(0), &d);
        assert_eq!(m.tick, 0x0005);
        assert_eq!(m.onset_age, 0x15);
        assert_eq!(m.full_tick(0x0001_FF00), 0x0002_0005);
        assert_eq!(m.full_tick(0x0002_0100), 0x0002_0005);
        let old = Decision {
            onset: 0,
            tick: 100_000,
            ..d
        };
        assert_eq!(EventMsg::from_decision(c(0), &old).onset_age, u16::MAX);
    }
}
