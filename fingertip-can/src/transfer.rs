//! The segmented transfer on a fingertip's request and response identifiers
//! (`0x680 + node` from the controller, `0x690 + node` from the fingertip): ISO 15765-2
//! (ISO-TP) framing on CAN FD, so that a message of up to [`MAX_MESSAGE`] bytes (a detector
//! image, a flight recording's chunk) crosses the bus in 64-byte frames with flow control.
//!
//! | frame | byte 0 | then |
//! |---|---|---|
//! | single | `0x0L` (L = 1..=7), or `0x00` and a length byte (8..=62) | the message |
//! | first | `0x1H` `LL` (length ≤ 4095, 12 bits, big-endian), or `0x10 0x00` and a 32-bit length | the message's first 62 (58) bytes |
//! | consecutive | `0x2S` (S = sequence number, 1, 2, ... 15, 0, 1, ...) | the next 63 bytes |
//! | flow control | `0x3F` (F = 0 continue, 1 wait, 2 overflow) | block size (frames, 0 = all), STmin (ms 0..=127, or 0xF1..=0xF9: 100..=900 µs) |
//!
//! Frames are padded with `0xCC` to the next CAN FD length. The receiver answers a first
//! frame with a flow control, and again after every block; the sender stops at the end of
//! each block until it has one. A frame lost or out of order breaks the sequence: the
//! receiver drops the message ([`TransferError::Sequence`]), the sender then waits for a
//! flow control that never comes and times out ([`TransferError::Timeout`]). Nothing of a
//! broken message is ever handed on; the layer above ([`crate::service`]) carries a
//! CRC-32 in every message against corruption this framing cannot see, and retries.
//!
//! Both ends are plain state machines driven by the frames that arrive and the time
//! (µs, any monotonic origin): no allocation, no clock of their own, the same code in the
//! firmware and in the PC tool.

use crate::{MAX_DATA, is_fd_length};

/// The largest message either end accepts, bytes: a detector image of the largest
/// configuration with its header and CRC (see `docs/can-protocol.md`).
pub const MAX_MESSAGE: usize = 8192;

/// Bytes a single frame carries.
pub const SINGLE_MAX: usize = MAX_DATA - 2;
/// Bytes a first frame carries with the 12-bit length.
const FIRST_SHORT: usize = MAX_DATA - 2;
/// Bytes a first frame carries with the 32-bit length (messages above 4095 bytes).
const FIRST_LONG: usize = MAX_DATA - 6;
/// Bytes a consecutive frame carries.
pub const CONSECUTIVE_MAX: usize = MAX_DATA - 1;
/// How long a sender waits for a flow control, and a receiver for the next consecutive
/// frame, µs (ISO 15765-2's N_Bs and N_Cr are 1 s; a fingertip answers within
/// milliseconds, so a lost frame is noticed sooner).
pub const TIMEOUT_US: u64 = 250_000;
/// The flow controls asking to wait that a sender accepts in a row before giving up.
pub const MAX_WAITS: u8 = 10;
/// The padding byte.
const PAD: u8 = 0xCC;

/// Why a transfer failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TransferError {
    /// The message is longer than the other end (or [`MAX_MESSAGE`]) takes.
    TooLong(u32),
    /// A frame that is not a frame of this framing, or not the one expected now.
    Malformed,
    /// A consecutive frame out of sequence: a frame was lost or repeated.
    Sequence,
    /// No flow control, or no next frame, within [`TIMEOUT_US`].
    Timeout,
    /// The receiver reported an overflow, or asked to wait more than [`MAX_WAITS`] times.
    Refused,
}

impl core::fmt::Display for TransferError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TransferError::TooLong(n) => write!(f, "a message of {n} bytes is too long"),
            TransferError::Malformed => write!(f, "a frame out of place in the transfer"),
            TransferError::Sequence => write!(f, "a frame of the transfer was lost or repeated"),
            TransferError::Timeout => write!(f, "the other end went silent mid-transfer"),
            TransferError::Refused => write!(f, "the other end refused the transfer"),
        }
    }
}

/// One frame's data bytes, padded to a CAN FD length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Payload {
    len: u8,
    bytes: [u8; MAX_DATA],
}

impl Payload {
    fn new(head: &[u8], body: &[u8]) -> Payload {
        let mut bytes = [PAD; MAX_DATA];
        let n = (head.len() + body.len()).min(MAX_DATA);
        let mut len = n;
        while !is_fd_length(len) {
            len += 1;
        }
        for (dst, src) in bytes.iter_mut().zip(head.iter().chain(body)) {
            *dst = *src;
        }
        Payload {
            len: len as u8,
            bytes,
        }
    }

    /// The data bytes, 1..=64 of them.
    pub fn data(&self) -> &[u8] {
        self.bytes.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

/// A flow control: continue (with the block size and the gap between frames), wait, or
/// overflow.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Flow {
    /// Send `block_size` frames (0: the rest), at least `st_min_us` apart.
    Continue {
        /// Consecutive frames before the next flow control; 0 for all of them.
        block_size: u8,
        /// Least gap between two consecutive frames, µs (0..=127 000).
        st_min_us: u32,
    },
    /// Hold on: another flow control follows.
    Wait,
    /// The message does not fit: give up.
    Overflow,
}

impl Flow {
    /// The frame.
    pub fn payload(&self) -> Payload {
        match *self {
            Flow::Continue {
                block_size,
                st_min_us,
            } => Payload::new(&[0x30, block_size, st_min_byte(st_min_us)], &[]),
            Flow::Wait => Payload::new(&[0x31, 0, 0], &[]),
            Flow::Overflow => Payload::new(&[0x32, 0, 0], &[]),
        }
    }

    /// A flow control from a frame's data; `None` for any other frame.
    pub fn read(data: &[u8]) -> Option<Flow> {
        match *data {
            [0x30, block_size, st, ..] => Some(Flow::Continue {
                block_size,
                st_min_us: st_min_us(st),
            }),
            [0x31, ..] => Some(Flow::Wait),
            [0x32, ..] => Some(Flow::Overflow),
            _ => None,
        }
    }
}

/// ISO 15765-2's STmin byte for a gap in µs (rounded up to what it can say).
fn st_min_byte(us: u32) -> u8 {
    match us {
        0 => 0,
        1..=900 => 0xF0 + us.div_ceil(100) as u8,
        _ => us.div_ceil(1000).min(127) as u8,
    }
}

/// The gap an STmin byte asks for, µs; reserved values ask for the most, 127 ms.
fn st_min_us(b: u8) -> u32 {
    match b {
        0..=0x7F => u32::from(b) * 1000,
        0xF1..=0xF9 => u32::from(b - 0xF0) * 100,
        _ => 127_000,
    }
}

/// The sending end of one message: [`Sender::new`] gives the first frame, then
/// [`Sender::on_flow`] takes the receiver's flow controls and [`Sender::poll`] gives the
/// consecutive frames as they may go.
#[derive(Clone, Debug)]
pub struct Sender<'a> {
    message: &'a [u8],
    /// Bytes sent so far.
    sent: usize,
    sn: u8,
    /// Frames left in this block; `None` while waiting for a flow control.
    block_left: Option<u16>,
    block_size: u8,
    st_min_us: u32,
    /// When the next consecutive frame may go, or when waiting times out, µs.
    at_us: u64,
    waits: u8,
}

impl<'a> Sender<'a> {
    /// Starts sending `message` at `now_us`: the first frame (a single frame when the
    /// message fits in one, which completes the transfer).
    pub fn new(message: &'a [u8], now_us: u64) -> Result<(Sender<'a>, Payload), TransferError> {
        let len = message.len();
        if len == 0 || len > MAX_MESSAGE {
            return Err(TransferError::TooLong(len as u32));
        }
        let (first, sent) = if len <= 7 {
            (Payload::new(&[len as u8], message), len)
        } else if len <= SINGLE_MAX {
            (Payload::new(&[0, len as u8], message), len)
        } else if len <= 4095 {
            let n = FIRST_SHORT;
            let head = [0x10 | (len >> 8) as u8, len as u8];
            (Payload::new(&head, &message[..n]), n)
        } else {
            let n = FIRST_LONG;
            let l = (len as u32).to_be_bytes();
            let head = [0x10, 0, l[0], l[1], l[2], l[3]];
            (Payload::new(&head, &message[..n]), n)
        };
        Ok((
            Sender {
                message,
                sent,
                sn: 1,
                block_left: None,
                block_size: 0,
                st_min_us: 0,
                at_us: now_us + TIMEOUT_US,
                waits: 0,
            },
            first,
        ))
    }

    /// Whether every byte has gone.
    pub fn is_done(&self) -> bool {
        self.sent >= self.message.len()
    }

    /// A frame from the receiver at `now_us`: a flow control. A flow control that comes
    /// while none is awaited is ignored (as ISO 15765-2 says); anything else is an error
    /// that ends the transfer.
    pub fn on_flow(&mut self, data: &[u8], now_us: u64) -> Result<(), TransferError> {
        let flow = Flow::read(data).ok_or(TransferError::Malformed)?;
        if self.is_done() || self.block_left.is_some() {
            return Ok(());
        }
        match flow {
            Flow::Continue {
                block_size,
                st_min_us,
            } => {
                self.block_size = block_size;
                self.st_min_us = st_min_us;
                self.block_left = Some(if block_size == 0 {
                    u16::MAX
                } else {
                    u16::from(block_size)
                });
                self.waits = 0;
                self.at_us = now_us;
                Ok(())
            }
            Flow::Wait if self.waits < MAX_WAITS => {
                self.waits += 1;
                self.at_us = now_us + TIMEOUT_US;
                Ok(())
            }
            Flow::Wait | Flow::Overflow => Err(TransferError::Refused),
        }
    }

    /// The next consecutive frame, if one may go at `now_us`; an error once the receiver
    /// has been silent for [`TIMEOUT_US`].
    pub fn poll(&mut self, now_us: u64) -> Result<Option<Payload>, TransferError> {
        if self.is_done() {
            return Ok(None);
        }
        let Some(left) = self.block_left else {
            return if now_us >= self.at_us {
                Err(TransferError::Timeout)
            } else {
                Ok(None)
            };
        };
        if now_us < self.at_us {
            return Ok(None);
        }
        let end = (self.sent + CONSECUTIVE_MAX).min(self.message.len());
        let frame = Payload::new(&[0x20 | self.sn], &self.message[self.sent..end]);
        self.sent = end;
        self.sn = (self.sn + 1) & 0x0F;
        self.at_us = now_us + u64::from(self.st_min_us);
        let left = left.saturating_sub(1);
        self.block_left = if left == 0 && !self.is_done() {
            self.at_us = now_us + TIMEOUT_US;
            None
        } else {
            Some(left)
        };
        Ok(Some(frame))
    }

    /// When [`Sender::poll`] has something to say next (a frame, or the timeout), µs.
    pub fn next_at(&self) -> u64 {
        self.at_us
    }
}

/// What a frame did to a [`Reassembler`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Received {
    /// Taken; nothing to answer.
    Pending,
    /// Taken; send this flow control.
    Flow(Payload),
    /// The message is complete: [`Reassembler::message`] holds it until the next frame.
    Complete,
    /// The frame broke the transfer (the message so far is dropped); an overflow is
    /// answered with this flow control.
    Failed(TransferError, Option<Payload>),
}

/// The receiving end: reassembles one message at a time into a buffer of `N` bytes,
/// answering flow controls with its block size and gap.
#[derive(Clone, Debug)]
pub struct Reassembler<const N: usize> {
    buf: [u8; N],
    len: usize,
    got: usize,
    sn: u8,
    /// Frames left in this block before the next flow control.
    block_left: u8,
    block_size: u8,
    st_min_us: u32,
    /// Receiving a multi-frame message: the time its next frame is due by, µs.
    due_us: Option<u64>,
    complete: bool,
}

impl<const N: usize> Reassembler<N> {
    /// An idle receiver asking for blocks of `block_size` frames (0: all at once) at least
    /// `st_min_us` apart.
    pub const fn new(block_size: u8, st_min_us: u32) -> Reassembler<N> {
        Reassembler {
            buf: [0; N],
            len: 0,
            got: 0,
            sn: 0,
            block_left: 0,
            block_size,
            st_min_us,
            due_us: None,
            complete: false,
        }
    }

    fn flow(&self) -> Payload {
        Flow::Continue {
            block_size: self.block_size,
            st_min_us: self.st_min_us,
        }
        .payload()
    }

    fn fail(&mut self, e: TransferError) -> Received {
        self.due_us = None;
        self.got = 0;
        Received::Failed(e, None)
    }

    /// A frame from the sender at `now_us`. A single or first frame starts a new message,
    /// dropping one in progress.
    pub fn on_frame(&mut self, data: &[u8], now_us: u64) -> Received {
        self.complete = false;
        let Some(&pci) = data.first() else {
            return self.fail(TransferError::Malformed);
        };
        match pci >> 4 {
            0 => {
                let (len, body) = match (pci & 0x0F, data.get(1)) {
                    (0, Some(&n)) if usize::from(n) > 7 => (usize::from(n), data.get(2..)),
                    (n @ 1..=7, _) => (usize::from(n), data.get(1..)),
                    _ => return self.fail(TransferError::Malformed),
                };
                let Some(body) = body.and_then(|b| b.get(..len)) else {
                    return self.fail(TransferError::Malformed);
                };
                if len > N {
                    return self.fail(TransferError::TooLong(len as u32));
                }
                self.buf[..len].copy_from_slice(body);
                self.len = len;
                self.due_us = None;
                self.complete = true;
                Received::Complete
            }
            1 => {
                let (len, body) = match data {
                    [_, 0, a, b, c, d, rest @ ..] => {
                        (u32::from_be_bytes([*a, *b, *c, *d]) as usize, rest)
                    }
                    [_, lo, rest @ ..] => (usize::from(pci & 0x0F) << 8 | usize::from(*lo), rest),
                    _ => return self.fail(TransferError::Malformed),
                };
                if len <= SINGLE_MAX || body.len() >= len {
                    return self.fail(TransferError::Malformed);
                }
                if len > N {
                    self.due_us = None;
                    return Received::Failed(
                        TransferError::TooLong(len as u32),
                        Some(Flow::Overflow.payload()),
                    );
                }
                self.buf[..body.len()].copy_from_slice(body);
                self.len = len;
                self.got = body.len();
                self.sn = 1;
                self.block_left = self.block_size;
                self.due_us = Some(now_us + TIMEOUT_US);
                Received::Flow(self.flow())
            }
            2 => {
                if self.due_us.is_none() {
                    // Not receiving: a stray frame (a transfer already dropped).
                    return Received::Failed(TransferError::Malformed, None);
                }
                if pci & 0x0F != self.sn {
                    return self.fail(TransferError::Sequence);
                }
                let n = (self.len - self.got).min(CONSECUTIVE_MAX);
                let Some(body) = data.get(1..1 + n) else {
                    return self.fail(TransferError::Malformed);
                };
                self.buf[self.got..self.got + n].copy_from_slice(body);
                self.got += n;
                self.sn = (self.sn + 1) & 0x0F;
                if self.got == self.len {
                    self.due_us = None;
                    self.complete = true;
                    return Received::Complete;
                }
                self.due_us = Some(now_us + TIMEOUT_US);
                if self.block_size != 0 {
                    self.block_left -= 1;
                    if self.block_left == 0 {
                        self.block_left = self.block_size;
                        return Received::Flow(self.flow());
                    }
                }
                Received::Pending
            }
            _ => self.fail(TransferError::Malformed),
        }
    }

    /// Drops a message whose sender has been silent for [`TIMEOUT_US`] at `now_us`;
    /// returns whether it did.
    pub fn poll(&mut self, now_us: u64) -> bool {
        match self.due_us {
            Some(due) if now_us >= due => {
                self.fail(TransferError::Timeout);
                true
            }
            _ => false,
        }
    }

    /// Whether a multi-frame message is coming in.
    pub fn is_busy(&self) -> bool {
        self.due_us.is_some()
    }

    /// The message just completed (empty otherwise).
    pub fn message(&self) -> &[u8] {
        if self.complete {
            self.buf.get(..self.len).unwrap_or(&[])
        } else {
            &[]
        }
    }
}

/// The frames a message of `len` bytes takes: the first (or single) frame and the
/// consecutive frames, and the data bytes of each; for the transfer time (see
/// `docs/can-protocol.md`).
pub fn frames_for(len: usize) -> (usize, usize) {
    if len <= SINGLE_MAX {
        return (1, 0);
    }
    let first = if len <= 4095 { FIRST_SHORT } else { FIRST_LONG };
    (1, (len - first).div_ceil(CONSECUTIVE_MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs a whole transfer of `message` with a receiver of blocks of `bs`; returns the
    /// message received and the frames each way.
    fn run(message: &[u8], bs: u8) -> (Vec<u8>, usize, usize) {
        let mut rx = Reassembler::<MAX_MESSAGE>::new(bs, 0);
        let (mut tx, first) = Sender::new(message, 0).unwrap();
        let (mut down, mut up) = (1, 0);
        let mut pending = Some(first);
        let mut now = 0;
        loop {
            if let Some(frame) = pending.take() {
                match rx.on_frame(frame.data(), now) {
                    Received::Complete => return (rx.message().to_vec(), down, up),
                    Received::Flow(f) => {
                        up += 1;
                        tx.on_flow(f.data(), now).unwrap();
                    }
                    Received::Pending => {}
                    Received::Failed(e, _) => panic!("{e}"),
                }
            }
            now += 100;
            pending = tx.poll(now).unwrap();
            if pending.is_some() {
                down += 1;
            }
            assert!(now < 10_000_000, "stalled");
        }
    }

    #[test]
    fn messages_of_every_size_class_cross_whole() {
        for len in [1, 7, 8, 62, 63, 64, 125, 126, 4095, 4096, 5000, MAX_MESSAGE] {
            let m: Vec<u8> = (0..len).map(|i| (i * 7 + 3) as u8).collect();
            for bs in [0, 1, 8] {
                let (got, down, up) = run(&m, bs);
                assert_eq!(got, m, "len {len} bs {bs}");
                let (f, c) = frames_for(len);
                assert_eq!(down, f + c, "len {len}");
                let blocks = if c == 0 {
                    0
                } else if bs == 0 {
                    1
                } else {
                    1 + (c - 1) / usize::from(bs)
                };
                assert_eq!(up, blocks, "len {len} bs {bs}");
            }
        }
    }

    /// A transfer of `m` past its first flow control (no block limit).
    fn started(m: &[u8]) -> (Reassembler<MAX_MESSAGE>, Sender<'_>) {
        let mut rx = Reassembler::<MAX_MESSAGE>::new(0, 0);
        let (mut tx, first) = Sender::new(m, 0).unwrap();
        let Received::Flow(f) = rx.on_frame(first.data(), 0) else {
            panic!("a first frame is answered with a flow control")
        };
        tx.on_flow(f.data(), 0).unwrap();
        (rx, tx)
    }

    #[test]
    fn a_lost_or_repeated_frame_breaks_the_transfer_and_hands_on_nothing() {
        let m: Vec<u8> = (0..1000).map(|i| i as u8).collect();
        let (mut rx, mut tx) = started(&m);
        let a = tx.poll(1).unwrap().unwrap();
        let _lost = tx.poll(2).unwrap().unwrap();
        let c = tx.poll(3).unwrap().unwrap();
        assert_eq!(rx.on_frame(a.data(), 3), Received::Pending);
        assert_eq!(
            rx.on_frame(c.data(), 4),
            Received::Failed(TransferError::Sequence, None)
        );
        assert!(rx.message().is_empty() && !rx.is_busy());
        // The rest of the frames are strays now.
        while let Some(f) = tx.poll(5).unwrap() {
            assert!(matches!(rx.on_frame(f.data(), 5), Received::Failed(..)));
        }
        // Repeated: the same frame twice.
        let (mut rx, mut tx) = started(&m);
        let a = tx.poll(1).unwrap().unwrap();
        assert_eq!(rx.on_frame(a.data(), 1), Received::Pending);
        assert!(matches!(
            rx.on_frame(a.data(), 2),
            Received::Failed(TransferError::Sequence, _)
        ));
    }

    #[test]
    fn silence_times_out_both_ends() {
        let m = [9u8; 300];
        let mut rx = Reassembler::<MAX_MESSAGE>::new(2, 0);
        let (mut tx, first) = Sender::new(&m, 0).unwrap();
        // The flow control is lost: the sender gives up after the timeout.
        assert!(matches!(rx.on_frame(first.data(), 0), Received::Flow(_)));
        assert_eq!(tx.poll(TIMEOUT_US - 1), Ok(None));
        assert_eq!(tx.poll(TIMEOUT_US), Err(TransferError::Timeout));
        // And the receiver drops what it had.
        assert!(rx.is_busy());
        assert!(!rx.poll(TIMEOUT_US - 1));
        assert!(rx.poll(TIMEOUT_US));
        assert!(!rx.is_busy() && rx.message().is_empty());
    }

    #[test]
    fn too_long_messages_are_refused_with_an_overflow() {
        let m = [1u8; 600];
        let mut rx = Reassembler::<512>::new(0, 0);
        let (mut tx, first) = Sender::new(&m, 0).unwrap();
        let Received::Failed(TransferError::TooLong(600), Some(f)) = rx.on_frame(first.data(), 0)
        else {
            panic!()
        };
        assert_eq!(tx.on_flow(f.data(), 0), Err(TransferError::Refused));
        assert_eq!(
            Sender::new(&[0; MAX_MESSAGE + 1], 0).err(),
            Some(TransferError::TooLong(MAX_MESSAGE as u32 + 1))
        );
        assert!(Sender::new(&[], 0).is_err());
    }

    #[test]
    fn waits_extend_the_senders_patience_a_few_times() {
        let m = [2u8; 200];
        let (mut tx, _) = Sender::new(&m, 0).unwrap();
        let wait = Flow::Wait.payload();
        for k in 0..MAX_WAITS {
            tx.on_flow(wait.data(), u64::from(k) * 1000).unwrap();
        }
        assert_eq!(tx.on_flow(wait.data(), 99_000), Err(TransferError::Refused));
    }

    #[test]
    fn a_flow_control_not_awaited_is_ignored() {
        let m = [4u8; 300];
        let (mut tx, _) = Sender::new(&m, 0).unwrap();
        let go = Flow::Continue {
            block_size: 0,
            st_min_us: 0,
        }
        .payload();
        tx.on_flow(go.data(), 0).unwrap();
        assert!(tx.poll(0).unwrap().is_some());
        // Sending: another flow control (say, a corrupted block size made the sender
        // send on) changes nothing; a frame that is no flow control ends the transfer.
        assert_eq!(tx.on_flow(Flow::Wait.payload().data(), 1), Ok(()));
        assert!(tx.poll(1).unwrap().is_some());
        assert_eq!(tx.on_flow(&[0x21, 0, 0], 2), Err(TransferError::Malformed));
    }

    #[test]
    fn st_min_is_kept_and_encoded_as_iso_15765_2_says() {
        for (us, byte) in [
            (0, 0),
            (100, 0xF1),
            (250, 0xF3),
            (900, 0xF9),
            (1000, 1),
            (5000, 5),
        ] {
            assert_eq!(st_min_byte(us), byte);
            assert!(st_min_us(byte) >= us);
        }
        assert_eq!(st_min_us(0x80), 127_000);
        let m = [3u8; 200];
        let (mut tx, _) = Sender::new(&m, 0).unwrap();
        let flow = Flow::Continue {
            block_size: 0,
            st_min_us: 2000,
        };
        tx.on_flow(flow.payload().data(), 10).unwrap();
        assert!(tx.poll(10).unwrap().is_some());
        assert_eq!(tx.poll(2009).unwrap(), None);
        assert!(tx.poll(2010).unwrap().is_some());
    }

    #[test]
    fn frames_are_padded_to_fd_lengths() {
        let p = Payload::new(&[0x21], &[5; 20]);
        assert_eq!(p.data().len(), 24);
        assert_eq!(p.data()[21..], [PAD; 3]);
        assert!(is_fd_length(Flow::Wait.payload().data().len()));
    }
}
