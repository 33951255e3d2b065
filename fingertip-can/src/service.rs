//! The service channel: requests from the controller (or the `fingertip` tool) to one
//! fingertip and its responses, each one message of the segmented [`crate::transfer`] on
//! the node's request identifier (`0x680 + node`) and response identifier
//! (`0x690 + node`).
//!
//! A message is a code byte, its body and a CRC-32 (ISO-HDLC, as zlib's, little-endian)
//! of the code and the body: a message whose CRC does not match is refused whole
//! ([`ServiceError::Corrupt`]), so a frame corrupted in a way the transfer cannot see
//! never reaches the fingertip's logic. A response repeats its request's code with bit 7
//! set, then a status byte (0 for success, else an [`ErrorCode`]) and the body.
//!
//! | request | code | body | response body |
//! |---|---|---|---|
//! | [`Request::Identify`] | 0x01 | — | [`Identity`] |
//! | [`Request::Load`] | 0x10 | name length, name (UTF-8, ≤ [`NAME_MAX`]), detector image | CRC-32 of the image (`u32`), staged |
//! | [`Request::Activate`] | 0x11 | — | CRC-32 of the detector now running |
//! | [`Request::Save`] | 0x12 | as Load | CRC-32 (`u32`), the slot written (1 A, 2 B, `u8`), the CPU's worst-case stall (ms, `u16`) |
//! | [`Request::EnterService`] | 0x30 | — | — |
//! | [`Request::LeaveService`] | 0x31 | — | — |
//! | [`Request::LastCrash`] | 0x40 | — | 0 (none), or 1, the [`CrashKind`], the program counter (`u32`), the message (length, UTF-8) |
//! | [`Request::ReadKey`] | 0x20 | key (`u16`) | value (4 bytes) |
//! | [`Request::WriteKey`] | 0x21 | key (`u16`), value (4 bytes) | — |
//! | [`Request::RecordingInfo`] | 0x50 | — | [`RecordingInfo`] |
//! | [`Request::RecordingRead`] | 0x51 | offset (`u32`) | offset (`u32`), up to [`PAGE_MAX`] bytes of the readout |
//! | [`Request::RecordingRearm`] | 0x52 | — | — |
//!
//! Numbers are little-endian. An error response's body is a short UTF-8 text naming what
//! was wrong (a channel, a value, a section of the image).

use crate::transfer::MAX_MESSAGE;

/// CRC-32/ISO-HDLC (zlib's): the checksum of detector images and of every service message.
/// Without a table: it runs on messages and images, never in a tick, and the table would
/// cost 1 KiB of flash.
const CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// CRC-32/ISO-HDLC of `bytes` (check value: `crc32(b"123456789") == 0xCBF4_3926`).
pub const fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}

/// The longest detector name a fingertip keeps and reports, bytes.
pub const NAME_MAX: usize = 16;
/// The longest error text a response carries, bytes.
pub const DETAIL_MAX: usize = 48;
/// Bytes of a message around its body: the code and the CRC-32.
const FRAMING: usize = 1 + 4;

/// The longest crash message a fingertip keeps, bytes.
pub const MESSAGE_MAX: usize = 48;

/// Why the firmware stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CrashKind {
    /// A panic: the message says what and where.
    Panic = 1,
    /// A hard fault: the program counter says where.
    HardFault = 2,
}

impl CrashKind {
    /// From the raw value; `None` for one that names nothing.
    pub const fn from_raw(raw: u8) -> Option<CrashKind> {
        match raw {
            1 => Some(CrashKind::Panic),
            2 => Some(CrashKind::HardFault),
            _ => None,
        }
    }

    /// The name the tools print.
    pub const fn name(self) -> &'static str {
        match self {
            CrashKind::Panic => "panic",
            CrashKind::HardFault => "hard fault",
        }
    }
}

/// What the firmware knew when it stopped, kept across the reset.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CrashReport {
    /// Why.
    pub kind: CrashKind,
    /// The program counter at a fault (0 for a panic).
    pub pc: u32,
    /// A panic's message and place, cut to [`MESSAGE_MAX`] bytes at a character.
    pub message: heapless::String<MESSAGE_MAX>,
}

impl CrashReport {
    /// A crash of `kind` at `pc`, no message yet (write it with `core::fmt::Write`).
    pub const fn new(kind: CrashKind, pc: u32) -> CrashReport {
        CrashReport {
            kind,
            pc,
            message: heapless::String::new(),
        }
    }
}

impl core::fmt::Write for CrashReport {
    /// Appends what fits; the rest is cut at a character.
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for c in s.chars() {
            if self.message.push(c).is_err() {
                break;
            }
        }
        Ok(())
    }
}

/// A detector's name as the fingertip reports it: 0 to [`NAME_MAX`] bytes of UTF-8.
pub type DetectorName = heapless::String<NAME_MAX>;
/// An error response's text.
pub type Detail = heapless::String<DETAIL_MAX>;

/// A calibration or identity key of the fingertip's store, `u16` on the bus.
///
/// | key | raw | value |
/// |---|---|---|
/// | [`Key::NodeId`] | 0x0001 | node id, 0..=14 (`u32`) |
/// | [`Key::Calibration`] | 0x0100 + 4 × channel + parameter | `f32`: gain (units per count), zero (counts), drift (counts per °C), reference temperature (°C) |
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Key {
    /// The node id the fingertip takes at its next boot, before its strap pins.
    NodeId,
    /// One parameter of one analog channel's calibration.
    Calibration {
        /// The channel, by its place in [`CALIBRATED_CHANNELS`].
        channel: u8,
        /// Which parameter.
        parameter: CalibrationParameter,
    },
}

/// The analog channels a fingertip calibrates, in the order of the calibration keys (the
/// firmware's ADC scan order).
pub const CALIBRATED_CHANNELS: [&str; 4] = ["force_x", "force_y", "skin_accel", "stress_rate"];

/// A parameter of a channel's calibration: `value = (counts − zero(T)) × gain`,
/// `zero(T) = zero + drift × (T − t_ref)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationParameter {
    /// Units per ADC count.
    Gain = 0,
    /// Counts read at a zero of the quantity, at the reference temperature.
    Zero = 1,
    /// The zero's temperature coefficient, counts per °C.
    Drift = 2,
    /// The reference temperature, °C.
    Reference = 3,
}

impl CalibrationParameter {
    /// Every parameter, by raw value.
    pub const ALL: [CalibrationParameter; 4] = [
        CalibrationParameter::Gain,
        CalibrationParameter::Zero,
        CalibrationParameter::Drift,
        CalibrationParameter::Reference,
    ];

    /// The name in a key's text form (`force_x.gain`).
    pub const fn name(self) -> &'static str {
        match self {
            CalibrationParameter::Gain => "gain",
            CalibrationParameter::Zero => "zero",
            CalibrationParameter::Drift => "drift",
            CalibrationParameter::Reference => "t_ref",
        }
    }
}

impl Key {
    /// The raw key.
    pub const fn raw(self) -> u16 {
        match self {
            Key::NodeId => 0x0001,
            Key::Calibration { channel, parameter } => {
                0x0100 + 4 * channel as u16 + parameter as u16
            }
        }
    }

    /// The key of a raw value; `None` for one that names nothing.
    pub fn from_raw(raw: u16) -> Option<Key> {
        match raw {
            0x0001 => Some(Key::NodeId),
            0x0100.. => {
                let k = raw - 0x0100;
                let channel = u8::try_from(k / 4).ok()?;
                if usize::from(channel) >= CALIBRATED_CHANNELS.len() {
                    return None;
                }
                Some(Key::Calibration {
                    channel,
                    parameter: CalibrationParameter::ALL[usize::from(k % 4)],
                })
            }
            _ => None,
        }
    }

    /// Every key, in raw order.
    pub fn all() -> impl Iterator<Item = Key> {
        core::iter::once(Key::NodeId).chain((0..CALIBRATED_CHANNELS.len() as u8).flat_map(
            |channel| {
                CalibrationParameter::ALL
                    .into_iter()
                    .map(move |parameter| Key::Calibration { channel, parameter })
            },
        ))
    }

    /// A key from its text form: `node_id`, or `CHANNEL.PARAMETER` (`force_x.gain`).
    pub fn parse(text: &str) -> Option<Key> {
        Key::all().find(|k| k.matches(text))
    }

    fn matches(self, text: &str) -> bool {
        match self {
            Key::NodeId => text == "node_id",
            Key::Calibration { channel, parameter } => {
                text.split_once('.').is_some_and(|(c, p)| {
                    CALIBRATED_CHANNELS.get(usize::from(channel)) == Some(&c)
                        && p == parameter.name()
                })
            }
        }
    }

    /// Whether the value is an `f32` (a calibration parameter) rather than a `u32`.
    pub const fn is_float(self) -> bool {
        matches!(self, Key::Calibration { .. })
    }
}

impl core::fmt::Display for Key {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Key::NodeId => f.write_str("node_id"),
            Key::Calibration { channel, parameter } => write!(
                f,
                "{}.{}",
                CALIBRATED_CHANNELS
                    .get(usize::from(channel))
                    .unwrap_or(&"?"),
                parameter.name()
            ),
        }
    }
}

/// Bytes of a flight recording one [`Request::RecordingRead`] returns at most: what a
/// single-frame response carries beside its code, status, offset and CRC-32.
pub const PAGE_MAX: usize = crate::transfer::SINGLE_MAX - FRAMING - 1 - 4;

/// What froze a flight recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordingCause {
    /// The event of this index (in the detector's configuration) was confirmed.
    Confirmed(u8),
    /// These channels went bad (bit `i` for the detector's channel `i`).
    Fault(u16),
}

/// The flight recorder, as [`Request::RecordingInfo`] reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RecordingInfo {
    /// Recording stopped, the readout ready; else still recording (or nothing yet).
    pub frozen: bool,
    /// What triggered the freeze (set from the trigger on, before the freeze).
    pub cause: Option<RecordingCause>,
    /// The trigger's tick (0 without one).
    pub trigger_tick: u32,
    /// The tick of the first row.
    pub first_tick: u32,
    /// Rows held, one per tick from `first_tick` on.
    pub rows: u32,
    /// The detector's channel count: each row's samples.
    pub channels: u8,
    /// The detector rate, Hz.
    pub rate_hz: u32,
    /// The CRC-32 of the detector's image.
    pub detector_crc: u32,
    /// Bytes of the readout: the saved state, then the rows.
    pub bytes: u32,
}

/// What the fingertip runs, as [`Request::Identify`] reports it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Mode {
    /// The detector built into the firmware image, through its generated tick.
    #[default]
    BuiltIn = 0,
    /// A detector loaded over the bus or from a flash slot, through the interpreter.
    Loaded = 1,
    /// Out of service: no detector could be put in service (`FaultConfigFallback`).
    Fallback = 2,
}

impl Mode {
    /// Every mode, by raw value.
    pub const ALL: [Mode; 3] = [Mode::BuiltIn, Mode::Loaded, Mode::Fallback];

    /// The name the tools print.
    pub const fn name(self) -> &'static str {
        match self {
            Mode::BuiltIn => "built-in",
            Mode::Loaded => "loaded",
            Mode::Fallback => "fallback",
        }
    }
}

/// The answer to [`Request::Identify`]: the firmware and the detector it runs.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Identity {
    /// The firmware's version, major, minor, patch.
    pub version: [u8; 3],
    /// The first 32 bits of the commit the firmware was built from (0 when unknown).
    pub build: u32,
    /// What runs.
    pub mode: Mode,
    /// The CRC-32 of the running detector's image.
    pub detector_crc: u32,
    /// The running detector's name.
    pub detector_name: DetectorName,
    /// The CRC-32 of an image loaded and waiting for its phase boundary, if any.
    pub staged_crc: Option<u32>,
}

/// A request to a fingertip.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request<'a> {
    /// What it runs.
    Identify,
    /// Stage this detector image: it takes effect at the next phase entry the controller
    /// commands, or at [`Request::Activate`].
    Load {
        /// The detector's name (≤ [`NAME_MAX`] bytes).
        name: &'a str,
        /// The image (`detector_core::image`'s layout).
        image: &'a [u8],
    },
    /// Put the staged detector in service at the next tick, in its first phase.
    Activate,
    /// Stage this detector image as [`Request::Load`] does and save it to a flash slot,
    /// for the next boots; only in the service state.
    Save {
        /// The detector's name (≤ [`NAME_MAX`] bytes).
        name: &'a str,
        /// The image.
        image: &'a [u8],
    },
    /// Enter the service state: the detector out of service (only the heartbeat goes
    /// out, with `FaultService`), the flash writable. Writes of the store and saves are
    /// refused outside it: a flash write stalls the CPU.
    EnterService,
    /// Leave the service state: the detector back in service, from a fresh state.
    LeaveService,
    /// Why the firmware last stopped, if it could tell (a panic, a hard fault).
    LastCrash,
    /// Read a key of the store.
    ReadKey(Key),
    /// Write a key of the store.
    WriteKey(Key, [u8; 4]),
    /// What the flight recorder holds.
    RecordingInfo,
    /// A page of a frozen recording's readout, from this byte on.
    RecordingRead(u32),
    /// Drop the recording held and record again.
    RecordingRearm,
}

/// Why a request was not carried out: the status byte of a response.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[repr(u8)]
pub enum ErrorCode {
    /// The request's CRC-32 did not match: it was corrupted on its way.
    Corrupt = 1,
    /// The request code is unknown, or its body is not that request's.
    Malformed = 2,
    /// The detector image was rejected (the text names why).
    Image = 3,
    /// The image needs a channel the fingertip does not feed (the text names it).
    Channel = 4,
    /// Nothing is staged.
    NothingStaged = 5,
    /// The key is unknown, or its value out of range (the text says which).
    Key = 6,
    /// The store could not be read or written.
    Store = 7,
    /// The fingertip cannot do it in its present state.
    Busy = 8,
    /// A flash write outside the service state.
    NotInService = 9,
}

impl ErrorCode {
    /// Every code, by raw value minus one.
    pub const ALL: [ErrorCode; 9] = [
        ErrorCode::Corrupt,
        ErrorCode::Malformed,
        ErrorCode::Image,
        ErrorCode::Channel,
        ErrorCode::NothingStaged,
        ErrorCode::Key,
        ErrorCode::Store,
        ErrorCode::Busy,
        ErrorCode::NotInService,
    ];

    fn from_raw(raw: u8) -> Option<ErrorCode> {
        ErrorCode::ALL
            .get(usize::from(raw).checked_sub(1)?)
            .copied()
    }

    /// A short description.
    pub const fn name(self) -> &'static str {
        match self {
            ErrorCode::Corrupt => "request corrupted",
            ErrorCode::Malformed => "malformed request",
            ErrorCode::Image => "image rejected",
            ErrorCode::Channel => "channel not fed",
            ErrorCode::NothingStaged => "nothing staged",
            ErrorCode::Key => "bad key or value",
            ErrorCode::Store => "store failed",
            ErrorCode::Busy => "busy",
            ErrorCode::NotInService => "not in the service state",
        }
    }
}

/// A response from a fingertip.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Response {
    /// To [`Request::Identify`].
    Identity(Identity),
    /// To [`Request::Load`]: staged, with its CRC-32.
    Staged(u32),
    /// To [`Request::Activate`]: the CRC-32 of the detector now in service.
    Active(u32),
    /// To [`Request::ReadKey`]: the value.
    Value([u8; 4]),
    /// To [`Request::WriteKey`].
    Written,
    /// To [`Request::Save`]: staged and saved.
    Saved {
        /// The image's CRC-32.
        crc: u32,
        /// The slot written: 1 A, 2 B.
        slot: u8,
        /// The worst-case time the CPU stalled for the flash, ms.
        stall_ms: u16,
    },
    /// To [`Request::EnterService`] and [`Request::LeaveService`].
    Done,
    /// To [`Request::LastCrash`]: the crash found at the last boot, if any.
    Crash(Option<CrashReport>),
    /// To [`Request::RecordingInfo`].
    Recording(RecordingInfo),
    /// To [`Request::RecordingRead`]: the bytes from `offset` on (none past the end).
    Page {
        /// Where they start in the readout.
        offset: u32,
        /// Up to [`PAGE_MAX`] bytes.
        data: heapless::Vec<u8, PAGE_MAX>,
    },
    /// The request failed.
    Error(ErrorCode, Detail),
}

/// A message that is not one of the service channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ServiceError {
    /// The CRC-32 does not match.
    Corrupt,
    /// Too short, an unknown code, or a body that is not its code's.
    Malformed,
    /// Longer than a transfer carries.
    TooLong,
}

impl core::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ServiceError::Corrupt => "the message's CRC-32 does not match",
            ServiceError::Malformed => "not a message of the service channel",
            ServiceError::TooLong => "the message is longer than a transfer carries",
        })
    }
}

/// Builds a message in a caller's buffer.
struct Writer<'b> {
    buf: &'b mut [u8],
    len: usize,
    overflow: bool,
}

impl<'b> Writer<'b> {
    fn new(buf: &'b mut [u8], code: u8) -> Writer<'b> {
        let mut w = Writer {
            buf,
            len: 0,
            overflow: false,
        };
        w.put(&[code]);
        w
    }

    fn put(&mut self, bytes: &[u8]) {
        match self.buf.get_mut(self.len..self.len + bytes.len()) {
            Some(dst) => {
                dst.copy_from_slice(bytes);
                self.len += bytes.len();
            }
            None => self.overflow = true,
        }
    }

    fn finish(mut self) -> Result<usize, ServiceError> {
        let crc = crc32(self.buf.get(..self.len).unwrap_or(&[]));
        self.put(&crc.to_le_bytes());
        if self.overflow || self.len > MAX_MESSAGE {
            Err(ServiceError::TooLong)
        } else {
            Ok(self.len)
        }
    }
}

/// Checks a message's CRC-32; gives its code and body.
fn open(message: &[u8]) -> Result<(u8, &[u8]), ServiceError> {
    if message.len() < FRAMING {
        return Err(ServiceError::Malformed);
    }
    let (content, crc) = message.split_at(message.len() - 4);
    let carried = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if crc32(content) != carried {
        return Err(ServiceError::Corrupt);
    }
    Ok((content[0], &content[1..]))
}

/// Reads a body front to back.
struct Body<'a>(&'a [u8]);

impl<'a> Body<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], ServiceError> {
        let (head, rest) = self.0.split_at_checked(n).ok_or(ServiceError::Malformed)?;
        self.0 = rest;
        Ok(head)
    }

    fn u8(&mut self) -> Result<u8, ServiceError> {
        Ok(self.take(1)?[0])
    }

    fn u16(&mut self) -> Result<u16, ServiceError> {
        let b = self.take(2)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&mut self) -> Result<u32, ServiceError> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    fn array(&mut self) -> Result<[u8; 4], ServiceError> {
        let b = self.take(4)?;
        Ok([b[0], b[1], b[2], b[3]])
    }

    fn text<const N: usize>(&mut self, len: usize) -> Result<heapless::String<N>, ServiceError> {
        let t = core::str::from_utf8(self.take(len)?).map_err(|_| ServiceError::Malformed)?;
        let mut s = heapless::String::new();
        s.push_str(t).map_err(|_| ServiceError::Malformed)?;
        Ok(s)
    }

    fn end(&self) -> Result<(), ServiceError> {
        if self.0.is_empty() {
            Ok(())
        } else {
            Err(ServiceError::Malformed)
        }
    }
}

const IDENTIFY: u8 = 0x01;
const LOAD: u8 = 0x10;
const ACTIVATE: u8 = 0x11;
const READ_KEY: u8 = 0x20;
const WRITE_KEY: u8 = 0x21;
const SAVE: u8 = 0x12;
const ENTER_SERVICE: u8 = 0x30;
const LEAVE_SERVICE: u8 = 0x31;
const LAST_CRASH: u8 = 0x40;
const RECORDING_INFO: u8 = 0x50;
const RECORDING_READ: u8 = 0x51;
const RECORDING_REARM: u8 = 0x52;
/// Bit 7 marks a response.
const RESPONSE: u8 = 0x80;

impl<'a> Request<'a> {
    const fn code(&self) -> u8 {
        match self {
            Request::Identify => IDENTIFY,
            Request::Load { .. } => LOAD,
            Request::Activate => ACTIVATE,
            Request::ReadKey(_) => READ_KEY,
            Request::WriteKey(..) => WRITE_KEY,
            Request::Save { .. } => SAVE,
            Request::EnterService => ENTER_SERVICE,
            Request::LeaveService => LEAVE_SERVICE,
            Request::LastCrash => LAST_CRASH,
            Request::RecordingInfo => RECORDING_INFO,
            Request::RecordingRead(_) => RECORDING_READ,
            Request::RecordingRearm => RECORDING_REARM,
        }
    }

    /// Writes the message into `buf`; returns its length.
    pub fn encode(&self, buf: &mut [u8]) -> Result<usize, ServiceError> {
        let mut w = Writer::new(buf, self.code());
        match *self {
            Request::Identify
            | Request::Activate
            | Request::EnterService
            | Request::LeaveService
            | Request::LastCrash
            | Request::RecordingInfo
            | Request::RecordingRearm => {}
            Request::RecordingRead(offset) => w.put(&offset.to_le_bytes()),
            Request::Load { name, image } | Request::Save { name, image } => {
                if name.len() > NAME_MAX {
                    return Err(ServiceError::Malformed);
                }
                w.put(&[name.len() as u8]);
                w.put(name.as_bytes());
                w.put(image);
            }
            Request::ReadKey(k) => w.put(&k.raw().to_le_bytes()),
            Request::WriteKey(k, v) => {
                w.put(&k.raw().to_le_bytes());
                w.put(&v);
            }
        }
        w.finish()
    }

    /// The request in `message`, checked.
    pub fn decode(message: &'a [u8]) -> Result<Request<'a>, ServiceError> {
        let (code, body) = open(message)?;
        let mut b = Body(body);
        let key = |b: &mut Body<'_>| Key::from_raw(b.u16()?).ok_or(ServiceError::Malformed);
        let r = match code {
            IDENTIFY => Request::Identify,
            ACTIVATE => Request::Activate,
            ENTER_SERVICE => Request::EnterService,
            LEAVE_SERVICE => Request::LeaveService,
            LAST_CRASH => Request::LastCrash,
            RECORDING_INFO => Request::RecordingInfo,
            RECORDING_READ => Request::RecordingRead(b.u32()?),
            RECORDING_REARM => Request::RecordingRearm,
            LOAD | SAVE => {
                let n = usize::from(b.u8()?);
                if n > NAME_MAX {
                    return Err(ServiceError::Malformed);
                }
                let name = core::str::from_utf8(b.take(n)?).map_err(|_| ServiceError::Malformed)?;
                let image = b.take(b.0.len())?;
                if code == LOAD {
                    Request::Load { name, image }
                } else {
                    Request::Save { name, image }
                }
            }
            READ_KEY => Request::ReadKey(key(&mut b)?),
            WRITE_KEY => {
                let k = key(&mut b)?;
                Request::WriteKey(k, b.array()?)
            }
            _ => return Err(ServiceError::Malformed),
        };
        b.end()?;
        Ok(r)
    }

    /// The code of the request a message holds, if its CRC-32 matches (so that a
    /// malformed request is answered under its own code).
    pub fn code_of(message: &[u8]) -> Option<u8> {
        open(message).ok().map(|(c, _)| c)
    }
}

impl Response {
    /// Writes the response to the request of code `request` into `buf`; returns its
    /// length.
    pub fn encode(&self, request: u8, buf: &mut [u8]) -> Result<usize, ServiceError> {
        let mut w = Writer::new(buf, request | RESPONSE);
        match self {
            Response::Error(code, detail) => {
                w.put(&[*code as u8]);
                w.put(detail.as_bytes());
            }
            ok => {
                w.put(&[0]);
                match ok {
                    Response::Identity(i) => {
                        w.put(&i.version);
                        w.put(&i.build.to_le_bytes());
                        w.put(&[i.mode as u8]);
                        w.put(&i.detector_crc.to_le_bytes());
                        w.put(&[i.detector_name.len() as u8]);
                        w.put(i.detector_name.as_bytes());
                        if let Some(s) = i.staged_crc {
                            w.put(&s.to_le_bytes());
                        }
                    }
                    Response::Staged(crc) | Response::Active(crc) => w.put(&crc.to_le_bytes()),
                    Response::Value(v) => w.put(v),
                    Response::Saved {
                        crc,
                        slot,
                        stall_ms,
                    } => {
                        w.put(&crc.to_le_bytes());
                        w.put(&[*slot]);
                        w.put(&stall_ms.to_le_bytes());
                    }
                    Response::Crash(None) => w.put(&[0]),
                    Response::Crash(Some(c)) => {
                        w.put(&[1, c.kind as u8]);
                        w.put(&c.pc.to_le_bytes());
                        w.put(&[c.message.len() as u8]);
                        w.put(c.message.as_bytes());
                    }
                    Response::Recording(r) => {
                        let (kind, value) = match r.cause {
                            None => (0u8, 0u32),
                            Some(RecordingCause::Confirmed(e)) => (1, u32::from(e)),
                            Some(RecordingCause::Fault(m)) => (2, u32::from(m)),
                        };
                        w.put(&[u8::from(r.frozen), kind]);
                        w.put(&value.to_le_bytes());
                        w.put(&r.trigger_tick.to_le_bytes());
                        w.put(&r.first_tick.to_le_bytes());
                        w.put(&r.rows.to_le_bytes());
                        w.put(&[r.channels]);
                        w.put(&r.rate_hz.to_le_bytes());
                        w.put(&r.detector_crc.to_le_bytes());
                        w.put(&r.bytes.to_le_bytes());
                    }
                    Response::Page { offset, data } => {
                        w.put(&offset.to_le_bytes());
                        w.put(data);
                    }
                    Response::Written | Response::Done | Response::Error(..) => {}
                }
            }
        }
        w.finish()
    }

    /// The response in `message` to a request of code `request`, checked: a response to
    /// another request is malformed.
    pub fn decode(request: u8, message: &[u8]) -> Result<Response, ServiceError> {
        let (code, body) = open(message)?;
        if code != request | RESPONSE {
            return Err(ServiceError::Malformed);
        }
        let mut b = Body(body);
        let status = b.u8()?;
        if status != 0 {
            let code = ErrorCode::from_raw(status).ok_or(ServiceError::Malformed)?;
            let len = b.0.len();
            return Ok(Response::Error(code, b.text(len)?));
        }
        let r = match request {
            IDENTIFY => {
                let version = [b.u8()?, b.u8()?, b.u8()?];
                let build = b.u32()?;
                let mode = *Mode::ALL
                    .get(usize::from(b.u8()?))
                    .ok_or(ServiceError::Malformed)?;
                let detector_crc = b.u32()?;
                let n = usize::from(b.u8()?);
                let detector_name = b.text(n)?;
                let staged_crc = if b.0.is_empty() { None } else { Some(b.u32()?) };
                Response::Identity(Identity {
                    version,
                    build,
                    mode,
                    detector_crc,
                    detector_name,
                    staged_crc,
                })
            }
            LOAD => Response::Staged(b.u32()?),
            ACTIVATE => Response::Active(b.u32()?),
            READ_KEY => Response::Value(b.array()?),
            WRITE_KEY => Response::Written,
            SAVE => Response::Saved {
                crc: b.u32()?,
                slot: b.u8()?,
                stall_ms: b.u16()?,
            },
            ENTER_SERVICE | LEAVE_SERVICE | RECORDING_REARM => Response::Done,
            RECORDING_INFO => {
                let frozen = match b.u8()? {
                    0 => false,
                    1 => true,
                    _ => return Err(ServiceError::Malformed),
                };
                let kind = b.u8()?;
                let value = b.u32()?;
                let cause = match kind {
                    0 => None,
                    1 => Some(RecordingCause::Confirmed(
                        u8::try_from(value).map_err(|_| ServiceError::Malformed)?,
                    )),
                    2 => Some(RecordingCause::Fault(
                        u16::try_from(value).map_err(|_| ServiceError::Malformed)?,
                    )),
                    _ => return Err(ServiceError::Malformed),
                };
                Response::Recording(RecordingInfo {
                    frozen,
                    cause,
                    trigger_tick: b.u32()?,
                    first_tick: b.u32()?,
                    rows: b.u32()?,
                    channels: b.u8()?,
                    rate_hz: b.u32()?,
                    detector_crc: b.u32()?,
                    bytes: b.u32()?,
                })
            }
            RECORDING_READ => {
                let offset = b.u32()?;
                let rest = b.take(b.0.len())?;
                Response::Page {
                    offset,
                    data: heapless::Vec::from_slice(rest).map_err(|_| ServiceError::Malformed)?,
                }
            }
            LAST_CRASH => Response::Crash(match b.u8()? {
                0 => None,
                1 => {
                    let kind = CrashKind::from_raw(b.u8()?).ok_or(ServiceError::Malformed)?;
                    let pc = b.u32()?;
                    let n = usize::from(b.u8()?);
                    Some(CrashReport {
                        kind,
                        pc,
                        message: b.text(n)?,
                    })
                }
                _ => return Err(ServiceError::Malformed),
            }),
            _ => return Err(ServiceError::Malformed),
        };
        b.end()?;
        Ok(r)
    }
}

/// An error text, cut to [`DETAIL_MAX`] bytes at a character boundary.
pub fn detail(args: core::fmt::Arguments<'_>) -> Detail {
    struct Cut(Detail);
    impl core::fmt::Write for Cut {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            for c in s.chars() {
                if self.0.push(c).is_err() {
                    break;
                }
            }
            Ok(())
        }
    }
    let mut cut = Cut(Detail::new());
    let _ = core::fmt::write(&mut cut, args);
    cut.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(r: Request<'_>) {
        let mut buf = [0u8; 256];
        let n = r.encode(&mut buf).unwrap();
        assert_eq!(Request::decode(&buf[..n]), Ok(r));
        // Every single-bit error is caught by the CRC-32 (or leaves it malformed).
        for bit in 0..n * 8 {
            let mut bad = buf;
            bad[bit / 8] ^= 1 << (bit % 8);
            assert!(Request::decode(&bad[..n]).is_err(), "bit {bit}");
        }
    }

    #[test]
    fn requests_round_trip_and_every_bit_error_is_caught() {
        round_trip(Request::Identify);
        round_trip(Request::Activate);
        round_trip(Request::EnterService);
        round_trip(Request::LastCrash);
        round_trip(Request::LeaveService);
        round_trip(Request::Save {
            name: "fitted",
            image: &[9; 40],
        });
        round_trip(Request::Load {
            name: "approach",
            image: &[1, 2, 3, 4, 5],
        });
        round_trip(Request::ReadKey(Key::NodeId));
        round_trip(Request::RecordingInfo);
        round_trip(Request::RecordingRead(0x0001_2345));
        round_trip(Request::RecordingRearm);
        round_trip(Request::WriteKey(
            Key::parse("skin_accel.drift").unwrap(),
            1.5f32.to_le_bytes(),
        ));
    }

    #[test]
    fn responses_round_trip() {
        let mut name = DetectorName::new();
        name.push_str("approach").unwrap();
        for (code, r) in [
            (
                IDENTIFY,
                Response::Identity(Identity {
                    version: [0, 1, 0],
                    build: 0x1234_5678,
                    mode: Mode::Loaded,
                    detector_crc: 0xDEAD_BEEF,
                    detector_name: name.clone(),
                    staged_crc: Some(7),
                }),
            ),
            (
                IDENTIFY,
                Response::Identity(Identity {
                    staged_crc: None,
                    ..Identity::default()
                }),
            ),
            (LOAD, Response::Staged(42)),
            (ACTIVATE, Response::Active(43)),
            (READ_KEY, Response::Value([1, 2, 3, 4])),
            (WRITE_KEY, Response::Written),
            (
                SAVE,
                Response::Saved {
                    crc: 5,
                    slot: 2,
                    stall_ms: 180,
                },
            ),
            (ENTER_SERVICE, Response::Done),
            (LAST_CRASH, Response::Crash(None)),
            (LAST_CRASH, {
                let mut c = CrashReport::new(CrashKind::Panic, 0);
                core::fmt::Write::write_str(&mut c, &"é".repeat(40)).unwrap();
                assert_eq!(c.message.len(), MESSAGE_MAX);
                Response::Crash(Some(c))
            }),
            (
                LAST_CRASH,
                Response::Crash(Some(CrashReport::new(CrashKind::HardFault, 0x0800_1234))),
            ),
            (LEAVE_SERVICE, Response::Done),
            (RECORDING_REARM, Response::Done),
            (
                RECORDING_INFO,
                Response::Recording(RecordingInfo::default()),
            ),
            (
                RECORDING_INFO,
                Response::Recording(RecordingInfo {
                    frozen: true,
                    cause: Some(RecordingCause::Confirmed(2)),
                    trigger_tick: u32::MAX,
                    first_tick: 7,
                    rows: 750,
                    channels: 10,
                    rate_hz: 5000,
                    detector_crc: 0xDEAD_BEEF,
                    bytes: 35_255,
                }),
            ),
            (
                RECORDING_INFO,
                Response::Recording(RecordingInfo {
                    cause: Some(RecordingCause::Fault(0x8001)),
                    ..RecordingInfo::default()
                }),
            ),
            (
                RECORDING_READ,
                Response::Page {
                    offset: 3005,
                    data: heapless::Vec::from_slice(&[0xA5; PAGE_MAX]).unwrap(),
                },
            ),
            (
                RECORDING_READ,
                Response::Page {
                    offset: 99,
                    data: heapless::Vec::new(),
                },
            ),
            (
                LOAD,
                Response::Error(
                    ErrorCode::Channel,
                    detail(format_args!("channel `{}` has no source", "wrist")),
                ),
            ),
        ] {
            let mut buf = [0u8; 256];
            let n = r.encode(code, &mut buf).unwrap();
            assert_eq!(Response::decode(code, &buf[..n]), Ok(r.clone()));
            // A response to another request is refused.
            assert_eq!(
                Response::decode(code ^ 0x40, &buf[..n]),
                Err(ServiceError::Malformed)
            );
            buf[n / 2] ^= 0x10;
            assert!(Response::decode(code, &buf[..n]).is_err());
        }
    }

    #[test]
    fn a_full_page_and_a_recording_info_fit_a_single_frame() {
        let mut buf = [0u8; 256];
        let page = Response::Page {
            offset: u32::MAX,
            data: heapless::Vec::from_slice(&[0; PAGE_MAX]).unwrap(),
        };
        assert_eq!(
            page.encode(RECORDING_READ, &mut buf).unwrap(),
            crate::transfer::SINGLE_MAX
        );
        let info = Response::Recording(RecordingInfo {
            cause: Some(RecordingCause::Confirmed(0)),
            ..RecordingInfo::default()
        });
        assert!(info.encode(RECORDING_INFO, &mut buf).unwrap() <= crate::transfer::SINGLE_MAX);
    }

    #[test]
    fn bad_messages_are_named() {
        assert_eq!(Request::decode(&[1, 2]), Err(ServiceError::Malformed));
        let mut buf = [0u8; 16];
        // An unknown code with a good CRC.
        let n = Writer::new(&mut buf, 0x55).finish().unwrap();
        assert_eq!(Request::decode(&buf[..n]), Err(ServiceError::Malformed));
        assert_eq!(Request::code_of(&buf[..n]), Some(0x55));
        // Too small a buffer, a name too long.
        assert_eq!(
            Request::WriteKey(Key::NodeId, [0; 4]).encode(&mut [0u8; 6]),
            Err(ServiceError::TooLong)
        );
        let long = "a".repeat(NAME_MAX + 1);
        assert!(
            Request::Load {
                name: &long,
                image: &[]
            }
            .encode(&mut [0u8; 64])
            .is_err()
        );
    }

    #[test]
    fn keys_have_one_raw_value_and_one_name_each() {
        let all: Vec<Key> = Key::all().collect();
        assert_eq!(all.len(), 1 + 4 * CALIBRATED_CHANNELS.len());
        for k in &all {
            assert_eq!(Key::from_raw(k.raw()), Some(*k));
            assert_eq!(Key::parse(&k.to_string()), Some(*k));
        }
        assert_eq!(Key::parse("force_y.t_ref").unwrap().raw(), 0x0107);
        assert_eq!(Key::from_raw(0x0110), None);
        assert_eq!(Key::from_raw(0x0002), None);
        assert_eq!(Key::parse("force_z.gain"), None);
    }

    #[test]
    fn crc32_is_zlibs() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn details_are_cut_at_a_character() {
        let d = detail(format_args!("{}", "é".repeat(40)));
        assert!(d.len() <= DETAIL_MAX && d.chars().all(|c| c == 'é'));
    }
}
