//! The CAN transmit path between the protocol's frames and the FDCAN's three transmit
//! buffers: one software queue per message class, the highest-priority class always fed
//! first, and one hardware buffer kept for event frames.
//!
//! - **Events** queue in order (16 deep: every level of every event at once). They may take
//!   any free buffer; when all three are full and one holds a stream or status frame, that
//!   frame is cancelled to make room, and put back in its queue when the cancellation
//!   finishes (unless it went out meanwhile).
//! - **Stream** frames: a sample replaces the unsent frames of the one before (on classic
//!   CAN a sample is up to eight pages); they never hold more than two buffers.
//! - **Status** frames queue in order (4 deep, the oldest dropped when full); they share
//!   the two buffers with the stream, after it.
//!
//! The buffers run as the FDCAN's transmit *queue* (not FIFO): the controller sends the
//! lowest identifier pending first, so an event frame in a buffer beats the others on the
//! bus too. After bus-off, [`TxScheduler::flush`] drops everything queued and cancels the
//! buffers: frames built before the bus went away are stale when it comes back (the
//! stream's latched levels report any event again).
//!
//! Everything here runs on the PC against [`TxBuffers`]; the board implements it over
//! the FDCAN's registers, and calls [`TxScheduler::pump`] after every tick and from the
//! transmit-complete and cancellation-finished interrupts.

use heapless::Deque;

use fingertip_can::{CanFrame, MessageKind, NodeId, SERVICE_RESPONSE_CLASS};

/// The FDCAN's transmit buffers.
pub const HW_BUFFERS: usize = 3;

/// Longest frame the fingertip sends (a service channel response: a whole CAN FD frame),
/// bytes.
pub const MAX_TX_DATA: usize = 64;

/// Event frames waiting for a buffer: two levels for each of eight events.
pub const EVENT_QUEUE: usize = 16;
/// Stream frames waiting: one sample (a CAN FD frame, or up to eight classic pages).
pub const STREAM_QUEUE: usize = 8;
/// Status frames waiting: two heartbeats.
pub const STATUS_QUEUE: usize = 4;

/// The data length code of a frame of `len` bytes: `len` up to 8, then 9..=15 for 12, 16,
/// 20, 24, 32, 48 and 64 bytes (CAN FD); `None` for other lengths.
pub const fn dlc_code(len: usize) -> Option<u8> {
    match len {
        0..=8 => Some(len as u8),
        12 => Some(9),
        16 => Some(10),
        20 => Some(11),
        24 => Some(12),
        32 => Some(13),
        48 => Some(14),
        64 => Some(15),
        _ => None,
    }
}

/// The message classes, in the order they are fed to the buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxClass {
    /// Event frames.
    Event,
    /// The confidence stream.
    Stream,
    /// The status heartbeat, and the service channel's responses (rare, and retried by
    /// the tool when one is lost): the lowest priority, in the status queue.
    Status,
}

impl TxClass {
    /// The class of a message the fingertip sends; `None` for the controller's.
    pub const fn of(kind: MessageKind) -> Option<TxClass> {
        match kind {
            MessageKind::Event => Some(TxClass::Event),
            MessageKind::Stream | MessageKind::StreamPage => Some(TxClass::Stream),
            MessageKind::Status => Some(TxClass::Status),
            _ => None,
        }
    }
}

/// A frame to send, compact: at most [`MAX_TX_DATA`] bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxFrame {
    id: u16,
    class: TxClass,
    len: u8,
    fd: bool,
    data: [u8; MAX_TX_DATA],
}

impl TxFrame {
    /// The frame for `frame`; `None` for a message the fingertip does not send or a frame
    /// longer than [`MAX_TX_DATA`].
    pub fn new(frame: &CanFrame) -> Option<TxFrame> {
        let id = frame.id().as_raw();
        let class = if id >> 4 == SERVICE_RESPONSE_CLASS && id & 0xF <= u16::from(NodeId::MAX) {
            TxClass::Status
        } else {
            TxClass::of(MessageKind::from_raw_id(id)?.0)?
        };
        let mut data = [0u8; MAX_TX_DATA];
        data.get_mut(..frame.len())?.copy_from_slice(frame.data());
        Some(TxFrame {
            id,
            class,
            len: frame.len() as u8,
            fd: frame.is_fd(),
            data,
        })
    }

    /// The raw standard identifier.
    pub const fn id(&self) -> u16 {
        self.id
    }

    /// The class.
    pub const fn class(&self) -> TxClass {
        self.class
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }

    /// Whether it is a CAN FD frame (sent with bit-rate switching).
    pub const fn is_fd(&self) -> bool {
        self.fd
    }
}

/// The transmit buffers of a CAN controller run as a priority queue (the FDCAN's Tx
/// queue mode): the board's registers, or a model on the PC.
pub trait TxBuffers {
    /// Bit `i` set: buffer `i` holds a frame waiting for the bus or on it (TXBRP).
    fn pending(&self) -> u8;
    /// The buffer the next frame goes into (TXFQS.TFQPI), `None` when all are pending
    /// (TXFQS.TFQF).
    fn put_index(&self) -> Option<usize>;
    /// Writes `frame` into buffer `index` and requests its transmission (TXBAR).
    fn put(&mut self, index: usize, frame: &TxFrame);
    /// Requests the cancellation of buffer `index` (TXBCR). It finishes at once unless the
    /// frame is on the bus, then when its transmission ends, successfully or not; the
    /// buffer is no longer pending then.
    fn cancel(&mut self, index: usize);
    /// Bit `i` set: buffer `i`'s last frame was sent successfully (TXBTO).
    fn transmitted(&self) -> u8;
}

/// What a buffer holds, as far as the scheduler knows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Slot {
    #[default]
    Free,
    /// Waiting for the bus or on it.
    Sending(TxFrame),
    /// Being cancelled to make room for an event: put back in its queue unless sent.
    Cancelling(TxFrame),
    /// Being cancelled after bus-off: dropped unless sent.
    Discarding(TxFrame),
}

/// Frames that did not go out, since boot (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxCounts {
    /// Refused: their queue was full (events), or pushed out (the oldest status frames).
    pub dropped: u32,
    /// Stream frames replaced by a newer sample before they went out (not faults: the
    /// stream's counter shows the gap).
    pub replaced: u32,
    /// Frames cancelled to make room for an event and put back.
    pub requeued: u32,
    /// Frames dropped after bus-off.
    pub flushed: u32,
    /// Frames sent.
    pub sent: u32,
}

impl TxCounts {
    /// Frames that will never go out: dropped and flushed (saturating).
    pub const fn lost(&self) -> u32 {
        self.dropped.saturating_add(self.flushed)
    }
}

/// What [`TxScheduler::push`] did with a tick's frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pushed {
    /// Frames of this tick refused (queue full, or not the fingertip's).
    pub refused: u32,
    /// A status frame was refused or pushed out: the heartbeat it belonged to (or an
    /// earlier one) reported nothing.
    pub status_lost: bool,
    /// Frames not sent since boot: refused, pushed out, flushed after bus-off
    /// ([`TxCounts::lost`]), saturating.
    pub lost: u32,
}

/// The transmit queues and what each hardware buffer holds. See the
/// [module docs](crate::txqueue).
#[derive(Clone, Debug, Default)]
pub struct TxScheduler {
    events: Deque<TxFrame, EVENT_QUEUE>,
    stream: Deque<TxFrame, STREAM_QUEUE>,
    status: Deque<TxFrame, STATUS_QUEUE>,
    slots: [Slot; HW_BUFFERS],
    counts: TxCounts,
}

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

impl TxScheduler {
    /// Nothing queued, every buffer free.
    pub const fn new() -> TxScheduler {
        TxScheduler {
            events: Deque::new(),
            stream: Deque::new(),
            status: Deque::new(),
            slots: [Slot::Free; HW_BUFFERS],
            counts: TxCounts {
                dropped: 0,
                replaced: 0,
                requeued: 0,
                flushed: 0,
                sent: 0,
            },
        }
    }

    /// The counters.
    pub const fn counts(&self) -> &TxCounts {
        &self.counts
    }

    /// Frames waiting in the software queues.
    pub fn queued(&self) -> usize {
        self.events.len() + self.stream.len() + self.status.len()
    }

    /// Event frames waiting in the software queue.
    pub fn queued_events(&self) -> usize {
        self.events.len()
    }

    /// Queues one tick's frames (highest priority first, as the transmitter makes them).
    /// A stream frame of this tick replaces the unsent ones of earlier ticks. Call
    /// [`pump`](TxScheduler::pump) next.
    pub fn push(&mut self, frames: &[CanFrame]) -> Pushed {
        let mut pushed = Pushed::default();
        let mut new_sample = true;
        for f in frames {
            let Some(frame) = TxFrame::new(f) else {
                bump(&mut pushed.refused);
                bump(&mut self.counts.dropped);
                continue;
            };
            let ok = match frame.class {
                TxClass::Event => self.events.push_back(frame).is_ok(),
                TxClass::Stream => {
                    if new_sample {
                        new_sample = false;
                        while self.stream.pop_front().is_some() {
                            bump(&mut self.counts.replaced);
                        }
                    }
                    self.stream.push_back(frame).is_ok()
                }
                TxClass::Status => {
                    if self.status.is_full() && self.status.pop_front().is_some() {
                        bump(&mut self.counts.dropped);
                        pushed.status_lost = true;
                    }
                    self.status.push_back(frame).is_ok()
                }
            };
            if !ok {
                bump(&mut pushed.refused);
                bump(&mut self.counts.dropped);
                pushed.status_lost |= frame.class == TxClass::Status;
            }
        }
        pushed.lost = self.counts.lost();
        pushed
    }

    /// Brings the buffers up to date: collects what the controller finished (sent, or
    /// cancelled: then put back in its queue), and fills free buffers, events first,
    /// stream and status frames in at most two of the three; cancels a stream or status
    /// frame when an event finds every buffer full.
    // Called from the detector and from the FDCAN's interrupt: one copy in flash.
    #[inline(never)]
    pub fn pump(&mut self, hw: &mut impl TxBuffers) {
        self.collect(hw);
        loop {
            let Some(next) = self.head() else { return };
            let others = self.slots.iter().filter(|s| holds_other(s)).count();
            if next != TxClass::Event && others >= HW_BUFFERS - 1 {
                return;
            }
            match hw.put_index() {
                Some(i) if matches!(self.slots.get(i), Some(Slot::Free)) => {
                    let Some(frame) = self.pop(next) else { return };
                    hw.put(i, &frame);
                    if let Some(s) = self.slots.get_mut(i) {
                        *s = Slot::Sending(frame);
                    }
                }
                // Every buffer full: an event makes room, cancelling the stream or status
                // frame of lowest priority, unless a cancellation is under way.
                _ => {
                    let making_room = self.slots.iter().any(|s| matches!(s, Slot::Cancelling(_)));
                    if next != TxClass::Event || making_room {
                        return;
                    }
                    let victim = (0..HW_BUFFERS)
                        .filter_map(|i| match self.slots.get(i) {
                            Some(Slot::Sending(f)) if f.class != TxClass::Event => Some((f.id, i)),
                            _ => None,
                        })
                        .max();
                    let Some((_, i)) = victim else { return };
                    if let Some(Slot::Sending(f)) = self.slots.get(i).copied() {
                        hw.cancel(i);
                        self.slots[i] = Slot::Cancelling(f);
                    }
                    // A frame not yet on the bus is cancelled at once: go on.
                    self.collect(hw);
                    if !matches!(self.slots.get(i), Some(Slot::Free)) {
                        return;
                    }
                }
            }
        }
    }

    /// The bus went off: drops every frame queued (stale by the time it comes back) and
    /// cancels the buffers; [`pump`](TxScheduler::pump) collects them.
    pub fn flush(&mut self, hw: &mut impl TxBuffers) {
        for q in [self.events.len(), self.stream.len(), self.status.len()] {
            self.counts.flushed = self.counts.flushed.saturating_add(q as u32);
        }
        self.events.clear();
        self.stream.clear();
        self.status.clear();
        for (i, s) in self.slots.iter_mut().enumerate() {
            if let Slot::Sending(f) | Slot::Cancelling(f) = *s {
                hw.cancel(i);
                *s = Slot::Discarding(f);
            }
        }
        self.collect(hw);
    }

    /// Frees the buffers the controller is done with.
    fn collect(&mut self, hw: &impl TxBuffers) {
        let (pending, sent) = (hw.pending(), hw.transmitted());
        for i in 0..HW_BUFFERS {
            let bit = 1u8 << i;
            if pending & bit != 0 {
                continue;
            }
            let Some(slot) = self.slots.get_mut(i) else {
                continue;
            };
            let was_sent = sent & bit != 0;
            match core::mem::replace(slot, Slot::Free) {
                Slot::Free => {}
                Slot::Sending(_) => bump(&mut self.counts.sent),
                Slot::Cancelling(_) | Slot::Discarding(_) if was_sent => {
                    bump(&mut self.counts.sent)
                }
                Slot::Cancelling(f) => self.requeue(f),
                Slot::Discarding(_) => bump(&mut self.counts.flushed),
            }
        }
    }

    /// A cancelled frame goes back to the front of its queue; a stream frame only if no
    /// newer sample came meanwhile.
    fn requeue(&mut self, f: TxFrame) {
        let back = match f.class {
            TxClass::Event => self.events.push_front(f).is_ok(),
            TxClass::Stream if self.stream.is_empty() => self.stream.push_front(f).is_ok(),
            TxClass::Stream => {
                bump(&mut self.counts.replaced);
                return;
            }
            TxClass::Status => self.status.push_front(f).is_ok(),
        };
        if back {
            bump(&mut self.counts.requeued);
        } else {
            bump(&mut self.counts.dropped);
        }
    }

    fn head(&self) -> Option<TxClass> {
        if !self.events.is_empty() {
            Some(TxClass::Event)
        } else if !self.stream.is_empty() {
            Some(TxClass::Stream)
        } else if !self.status.is_empty() {
            Some(TxClass::Status)
        } else {
            None
        }
    }

    fn pop(&mut self, class: TxClass) -> Option<TxFrame> {
        match class {
            TxClass::Event => self.events.pop_front(),
            TxClass::Stream => self.stream.pop_front(),
            TxClass::Status => self.status.pop_front(),
        }
    }

    /// What buffer `i` holds, if anything (for tests and logs).
    pub fn in_buffer(&self, i: usize) -> Option<&TxFrame> {
        match self.slots.get(i)? {
            Slot::Free => None,
            Slot::Sending(f) | Slot::Cancelling(f) | Slot::Discarding(f) => Some(f),
        }
    }
}

/// A buffer holding a stream or status frame (counted against the two they may use).
fn holds_other(s: &Slot) -> bool {
    match s {
        Slot::Free => false,
        Slot::Sending(f) | Slot::Cancelling(f) | Slot::Discarding(f) => f.class != TxClass::Event,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use detector_core::{EventId, Level};
    use fingertip_can::{
        Counter, EventMsg, NodeId, StatusMsg, StatusPage, StreamMsg, StreamPageMsg,
    };

    /// Three buffers whose frames stay until the test sends or cancels them.
    #[derive(Default)]
    struct Hw {
        bufs: [Option<TxFrame>; HW_BUFFERS],
        /// A buffer whose frame is on the bus: its cancellation waits for the end.
        on_bus: Option<usize>,
        cancel_asked: u8,
        sent: u8,
    }

    impl TxBuffers for Hw {
        fn pending(&self) -> u8 {
            (0..HW_BUFFERS)
                .filter(|&i| self.bufs[i].is_some())
                .fold(0, |m, i| m | 1 << i)
        }
        fn put_index(&self) -> Option<usize> {
            self.bufs.iter().position(Option::is_none)
        }
        fn put(&mut self, index: usize, frame: &TxFrame) {
            assert!(self.bufs[index].is_none(), "buffer {index} overwritten");
            self.bufs[index] = Some(*frame);
            self.sent &= !(1 << index);
        }
        fn cancel(&mut self, index: usize) {
            if self.on_bus == Some(index) {
                self.cancel_asked |= 1 << index;
            } else {
                self.bufs[index] = None;
            }
        }
        fn transmitted(&self) -> u8 {
            self.sent
        }
    }

    impl Hw {
        /// The bus sends the lowest identifier pending; `None` when nothing is.
        fn send_one(&mut self) -> Option<TxFrame> {
            let i = (0..HW_BUFFERS)
                .filter(|&i| self.bufs[i].is_some())
                .min_by_key(|&i| self.bufs[i].map(|f| f.id))?;
            self.sent |= 1 << i;
            self.on_bus = None;
            self.bufs[i].take()
        }

        fn classes(&self) -> Vec<TxClass> {
            self.bufs.iter().flatten().map(|f| f.class).collect()
        }
    }

    fn node() -> NodeId {
        NodeId::new(4).unwrap()
    }

    fn event(c: u8) -> CanFrame {
        let m = EventMsg {
            counter: Counter(c),
            event: EventId(1),
            level: Level::Confirm,
            tick: u16::from(c),
            onset_age: 3,
        };
        m.encode(node())
            .unwrap()
            .in_format(fingertip_can::BusFormat::Fd)
            .unwrap()
    }

    fn stream(c: u8) -> CanFrame {
        StreamMsg {
            counter: Counter(c),
            ..StreamMsg::default()
        }
        .encode(node())
        .unwrap()
    }

    fn page(c: u8, e: u8) -> CanFrame {
        StreamPageMsg {
            counter: Counter(c),
            sample: c,
            event: EventId(e),
            unjudgeable: false,
            level: fingertip_can::LevelState::None,
            confidence: detector_core::Confidence::ZERO,
        }
        .encode(node())
        .unwrap()
    }

    fn status(c: u8) -> CanFrame {
        StatusMsg {
            counter: Counter(c),
            page: StatusPage::Uptime {
                uptime: u32::from(c),
            },
        }
        .encode(node())
        .unwrap()
    }

    fn counter(f: &TxFrame) -> u8 {
        f.data()[2]
    }

    #[test]
    fn data_length_codes() {
        let codes: Vec<Option<u8>> = [0, 8, 9, 12, 16, 20, 24, 32, 48, 64, 65]
            .iter()
            .map(|&n| dlc_code(n))
            .collect();
        let want = [0, 8, 0xFF, 9, 10, 11, 12, 13, 14, 15, 0xFF].map(|c| (c != 0xFF).then_some(c));
        assert_eq!(codes, want);
    }

    #[test]
    fn stream_and_status_leave_a_buffer_for_events() {
        let (mut s, mut hw) = (TxScheduler::new(), Hw::default());
        s.push(&[stream(0), status(0), status(1)]);
        s.pump(&mut hw);
        assert_eq!(hw.classes(), [TxClass::Stream, TxClass::Status]);
        assert_eq!(s.queued(), 1, "the second status frame waits");
        // An event goes straight into the kept buffer.
        s.push(&[event(0)]);
        s.pump(&mut hw);
        assert_eq!(
            hw.classes(),
            [TxClass::Stream, TxClass::Status, TxClass::Event]
        );
        // The bus sends it first: the lowest identifier.
        assert_eq!(hw.send_one().map(|f| f.class), Some(TxClass::Event));
        s.pump(&mut hw);
        assert_eq!(hw.bufs[2], None, "still kept for events");
    }

    #[test]
    fn a_second_event_cancels_the_lowest_priority_frame_which_goes_back() {
        let (mut s, mut hw) = (TxScheduler::new(), Hw::default());
        s.push(&[event(0), stream(0), status(0)]);
        s.pump(&mut hw);
        assert_eq!(
            hw.classes(),
            [TxClass::Event, TxClass::Stream, TxClass::Status]
        );
        s.push(&[event(1)]);
        s.pump(&mut hw);
        // The status frame (highest identifier) made room at once.
        assert_eq!(
            hw.classes(),
            [TxClass::Event, TxClass::Stream, TxClass::Event]
        );
        assert_eq!(s.counts().requeued, 1);
        assert_eq!(s.queued(), 1);
        // It goes out later all the same.
        let mut out = Vec::new();
        while let Some(f) = hw.send_one() {
            out.push((f.class, counter(&f)));
            s.pump(&mut hw);
        }
        assert_eq!(
            out,
            [
                (TxClass::Event, 0),
                (TxClass::Event, 1),
                (TxClass::Stream, 0),
                (TxClass::Status, 0)
            ]
        );
        assert_eq!(s.counts().sent, 4);
    }

    #[test]
    fn a_frame_on_the_bus_finishes_before_its_buffer_is_taken() {
        let (mut s, mut hw) = (TxScheduler::new(), Hw::default());
        s.push(&[event(0), stream(0), status(0)]);
        s.pump(&mut hw);
        hw.on_bus = Some(2);
        s.push(&[event(1)]);
        s.pump(&mut hw);
        assert_eq!(hw.cancel_asked, 0b100);
        assert_eq!(s.queued_events(), 1, "waits for the cancellation");
        // The status frame was sent after all: not put back.
        hw.bufs[2] = None;
        hw.sent |= 0b100;
        s.pump(&mut hw);
        assert_eq!(
            hw.classes(),
            [TxClass::Event, TxClass::Stream, TxClass::Event]
        );
        assert_eq!(
            (s.counts().requeued, s.counts().sent, s.queued()),
            (0, 1, 0)
        );
    }

    #[test]
    fn a_new_sample_replaces_the_unsent_one() {
        let (mut s, mut hw) = (TxScheduler::new(), Hw::default());
        // Classic pages: three of sample 0 fill the two buffers and wait.
        s.push(&[page(0, 0), page(0, 1), page(0, 2)]);
        s.pump(&mut hw);
        assert_eq!(s.queued(), 1);
        s.push(&[page(1, 0), page(1, 1), page(1, 2)]);
        assert_eq!(s.counts().replaced, 1);
        assert_eq!(s.queued(), 3);
        // A status frame pushed in the same tick does not replace the stream.
        s.push(&[status(0)]);
        assert_eq!((s.queued(), s.counts().replaced), (4, 1));
    }

    #[test]
    fn full_queues_refuse_and_say_so() {
        let mut s = TxScheduler::new();
        let events: Vec<CanFrame> = (0..20).map(event).collect();
        let p = s.push(&events);
        assert_eq!((p.refused, p.lost), (4, 4));
        assert!(!p.status_lost);
        let statuses: Vec<CanFrame> = (0..5).map(status).collect();
        let p = s.push(&statuses);
        assert_eq!(p.refused, 0);
        assert!(p.status_lost, "the oldest status frame was pushed out");
        assert_eq!(s.counts().dropped, 5);
        // The controller's frames are not the fingertip's to send.
        let ctx = fingertip_can::ContextMsg::default()
            .encode(fingertip_can::ContextGroup::of(node()))
            .unwrap();
        assert_eq!(s.push(&[ctx]).refused, 1);
        assert_eq!(s.counts().lost(), 6);
    }

    #[test]
    fn service_responses_go_out_whole_in_the_status_class() {
        let node = NodeId::new(4).unwrap();
        let f = CanFrame::new_fd(fingertip_can::service_response_id(node), &[7; 64]).unwrap();
        let t = TxFrame::new(&f).unwrap();
        assert_eq!(
            (t.class(), t.data(), t.id()),
            (TxClass::Status, &[7u8; 64][..], 0x694)
        );
        // A request identifier is not the fingertip's to send.
        let request = CanFrame::new_fd(fingertip_can::service_request_id(node), &[0; 8]).unwrap();
        assert!(TxFrame::new(&request).is_none());
    }

    #[test]
    fn bus_off_flushes_everything_stale() {
        let (mut s, mut hw) = (TxScheduler::new(), Hw::default());
        s.push(&[event(0), event(1), event(2), event(3), stream(0), status(0)]);
        s.pump(&mut hw);
        hw.on_bus = Some(0);
        s.flush(&mut hw);
        assert_eq!(s.queued(), 0);
        assert_eq!(hw.classes().len(), 1, "the frame on the bus finishes");
        // It was on the bus when the bus went off: it failed, and is dropped.
        hw.bufs[0] = None;
        s.pump(&mut hw);
        assert_eq!(s.counts().flushed, 6);
        assert_eq!(s.counts().sent, 0);
        s.push(&[event(4)]);
        s.pump(&mut hw);
        assert_eq!(hw.classes(), [TxClass::Event]);
    }
}
