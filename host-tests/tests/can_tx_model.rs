//! The firmware's transmit path (`firmware::txqueue`) on a model of a CAN FD bus: what the
//! board does after every tick, against three transmit buffers that a bus with other
//! nodes' traffic drains, lowest identifier first.
//!
//! The model: a tick every 200 µs runs the protocol's transmitter on a detector output
//! with random decisions (bursts of up to six levels at once), queues its frames and pumps
//! them into the buffers, as the board's detector does; the bus, 1 and 5 Mbit/s, carries
//! the controller's broadcast context every millisecond (64 bytes, 169.6 µs) and four other
//! fingertips' events and streams; a frame's time on the bus is `busload`'s worst case; a
//! transmit-complete interrupt pumps again; a cancellation finishes at once, or at the end
//! of the frame on the bus; sometimes the bus goes off and comes back.
//!
//! The properties, over 300 runs of 0.2 s: an event frame is in a transmit buffer within one
//! tick of the tick that made it whenever fewer than three event frames were ahead of it;
//! an event frame is refused only beyond the room its queue has (a burst while the bus is
//! off);
//! stream and status frames never hold the third buffer; a frame cancelled for an event is
//! sent later; nothing queued before a bus-off is sent after it; every frame is sent or
//! counted (dropped, replaced, flushed). `--nocapture` prints the worst delay seen.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::collections::HashMap;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

use detector_core::{Confidence, Decision, EventId, Level, Output};
use fingertip::can_tools::busload::fd_frame_bits;
use fingertip_can::{BusFormat, MessageKind, NodeId, Status, Transmitter, TxState};
use firmware::txqueue::{EVENT_QUEUE, HW_BUFFERS, TxBuffers, TxClass, TxFrame, TxScheduler};
use proptest::prelude::*;

const TICK_NS: u64 = 200_000;

/// A frame's worst-case time on the bus at 1 and 5 Mbit/s, ns.
fn frame_ns(len: usize) -> u64 {
    (fd_frame_bits(len).micros(1_000_000, 5_000_000) * 1000.0).round() as u64
}

/// Who is on the bus.
#[derive(Clone, Copy, Debug, PartialEq)]
enum OnBus {
    Ours(usize),
    Other(u16),
}

/// Three transmit buffers and the bus that drains them.
#[derive(Default)]
struct Bus {
    now: u64,
    bufs: [Option<TxFrame>; HW_BUFFERS],
    /// When each buffer's frame was put in (ns).
    put_at: [u64; HW_BUFFERS],
    sent_bits: u8,
    /// A frame on the bus and when it ends.
    on_bus: Option<(OnBus, u64)>,
    /// Cancellations asked for the frame on the bus.
    cancel_on_bus: bool,
    /// Other nodes' frames waiting: identifier, bytes.
    others: Vec<(u16, usize)>,
    /// The bus is off (no frame starts) until then.
    off_until: u64,
    /// Our frames as they went out: identifier, counter, time put in, time sent.
    sent: Vec<(u16, u8, u64, u64)>,
    /// Our event frames as they were put in: counter, time.
    event_puts: Vec<(u8, u64)>,
}

impl TxBuffers for Bus {
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
        self.put_at[index] = self.now;
        self.sent_bits &= !(1 << index);
        if frame.class() == TxClass::Event {
            self.event_puts.push((frame.data()[2], self.now));
        }
    }
    fn cancel(&mut self, index: usize) {
        if self.on_bus.is_some_and(|(w, _)| w == OnBus::Ours(index)) {
            self.cancel_on_bus = true;
        } else {
            self.bufs[index] = None;
        }
    }
    fn transmitted(&self) -> u8 {
        self.sent_bits
    }
}

impl Bus {
    /// Advances to `t`, finishing the frame on the bus and starting others; returns whether
    /// one of ours finished (the transmit-complete interrupt).
    fn run_until(&mut self, t: u64) -> bool {
        loop {
            if let Some((who, end)) = self.on_bus {
                if end > t {
                    break;
                }
                self.now = end;
                self.on_bus = None;
                self.cancel_on_bus = false;
                match who {
                    OnBus::Ours(i) => {
                        let f = self.bufs[i].take().unwrap();
                        self.sent_bits |= 1 << i;
                        self.sent.push((f.id(), f.data()[2], self.put_at[i], end));
                        // The interrupt pumps before the next frame starts.
                        return true;
                    }
                    OnBus::Other(id) => {
                        let k = self.others.iter().position(|o| o.0 == id).unwrap();
                        self.others.remove(k);
                    }
                }
            }
            if self.now.max(self.off_until) > t {
                break;
            }
            self.now = self.now.max(self.off_until);
            // Arbitration: the lowest identifier waiting.
            let ours = (0..HW_BUFFERS)
                .filter_map(|i| self.bufs[i].map(|f| (f.id(), OnBus::Ours(i), f.data().len())));
            let theirs = self
                .others
                .iter()
                .map(|&(id, len)| (id, OnBus::Other(id), len));
            let Some((_, who, len)) = ours.chain(theirs).min_by_key(|c| c.0) else {
                break;
            };
            self.on_bus = Some((who, self.now + frame_ns(len)));
        }
        self.now = self.now.max(t);
        false
    }
}

/// A detector output with `levels` decisions at `tick`.
fn output(tick: u32, levels: u8) -> Output {
    let mut o = Output {
        evaluated: 0b111,
        ..Output::default()
    };
    o.confidences[0] = Confidence::from_bits((tick % 32768) as u16).unwrap();
    for k in 0..levels {
        let d = Decision {
            event: EventId(k / 2 % 3),
            level: if k % 2 == 0 {
                Level::Alert
            } else {
                Level::Confirm
            },
            confidence: Confidence::ONE,
            onset: tick.saturating_sub(5),
            tick,
        };
        o.decisions.push(d).unwrap();
    }
    o
}

fn id(kind: MessageKind, n: u8) -> u16 {
    kind.raw_id(NodeId::new(n).unwrap())
}

/// One run: the worst push-to-buffer delay of an event frame that had fewer than three
/// event frames ahead of it (ns), and the scheduler at the end.
fn run(
    bursts: &[(u32, u8)],
    other_events: &[(u32, u8)],
    bus_off: Option<(u32, u32)>,
) -> Result<(u64, TxScheduler), TestCaseError> {
    let node = NodeId::new(4).unwrap();
    let tx = Transmitter::with_defaults(node, BusFormat::Fd, 5000).unwrap();
    let mut state = TxState::new();
    let mut sched = TxScheduler::new();
    let mut bus = Bus::default();
    let status = Status::default();
    let bursts: HashMap<u32, u8> = bursts.iter().copied().collect();
    let mut pushed_events: Vec<(u8, u64, usize)> = Vec::new();
    let (mut worst, mut pushed, mut flushed_before) = (0u64, 0u32, None);
    for tick in 0..1000u32 {
        let t = u64::from(tick) * TICK_NS;
        // The bus runs up to the tick; each of our frames that finishes pumps the queues.
        while bus.run_until(t) {
            sched.pump(&mut bus);
        }
        // Other traffic: the controller's context each millisecond, the others' streams
        // every 4 ms, their events now and then.
        if tick % 5 == 0 {
            bus.others.push((0x120, 64));
        }
        if tick % 20 == 0 {
            for n in 0..4 {
                bus.others.push((id(MessageKind::Stream, n), 24));
            }
        }
        for &(_, n) in other_events.iter().filter(|o| o.0 == tick) {
            bus.others.push((id(MessageKind::Event, n % 4), 8));
        }
        if let Some((at, len)) = bus_off
            && tick == at
        {
            // The bus goes off: the frame on it fails, everything queued is stale.
            if let Some((OnBus::Ours(i), _)) = bus.on_bus {
                bus.bufs[i] = None;
            }
            bus.on_bus = None;
            sched.flush(&mut bus);
            sched.pump(&mut bus);
            prop_assert!(
                bus.bufs.iter().all(Option::is_none),
                "buffers left after bus-off"
            );
            bus.off_until = t + u64::from(len) * TICK_NS;
            flushed_before = Some(t);
        }
        // The tick.
        let out = output(tick, bursts.get(&tick).copied().unwrap_or(0));
        let frames = tx.tick(&mut state, tick, &out, &status);
        let ahead_in_hw = bus
            .bufs
            .iter()
            .flatten()
            .filter(|f| f.class() == TxClass::Event)
            .count();
        let ahead = ahead_in_hw + sched.queued_events();
        let ours = frames
            .iter()
            .filter(|f| f.id().as_raw() == id(MessageKind::Event, 4));
        for (k, f) in ours.enumerate() {
            pushed_events.push((f.data()[2], t, ahead + k));
        }
        pushed += frames.len() as u32;
        // Only an event queue that overflows refuses (a burst while the bus is off, or
        // before its backlog has gone out): each frame beyond its room, counted dropped.
        let room = EVENT_QUEUE - sched.queued_events();
        let new_events = frames
            .iter()
            .filter(|f| TxFrame::new(f).is_some_and(|t| t.class() == TxClass::Event))
            .count();
        let p = sched.push(&frames);
        prop_assert_eq!(p.refused as usize, new_events.saturating_sub(room));
        sched.pump(&mut bus);
        // Stream and status frames never hold the third buffer.
        let others_in_hw = bus
            .bufs
            .iter()
            .flatten()
            .filter(|f| f.class() != TxClass::Event)
            .count();
        prop_assert!(others_in_hw < HW_BUFFERS);
    }
    // Let the bus drain.
    let end = 1000 * TICK_NS + 20_000_000;
    while bus.run_until(end) {
        sched.pump(&mut bus);
    }
    // Match each event frame pushed with its counter's first put at or after the push.
    let mut used = vec![false; bus.event_puts.len()];
    for &(counter, at, ahead) in &pushed_events {
        let put = (0..bus.event_puts.len())
            .find(|&k| !used[k] && bus.event_puts[k].0 == counter && bus.event_puts[k].1 >= at);
        if let Some(k) = put {
            used[k] = true;
        }
        if ahead < HW_BUFFERS && flushed_before.is_none_or(|f| at >= f) {
            let put = put.expect("an event frame never reached a buffer");
            let delay = bus.event_puts[put].1 - at;
            prop_assert!(
                delay <= TICK_NS,
                "event {} waited {} ns for a buffer with {} ahead",
                counter,
                delay,
                ahead
            );
            worst = worst.max(delay);
        }
    }
    // Nothing queued before the bus went off went out after it.
    if let Some(f) = flushed_before {
        for &(id, c, put, sent) in &bus.sent {
            prop_assert!(
                !(put < f && sent > f),
                "stale frame {:03X}/{} sent after bus-off",
                id,
                c
            );
        }
    }
    // Every frame is accounted for.
    let c = sched.counts();
    prop_assert_eq!(sched.queued(), 0);
    prop_assert_eq!(
        pushed,
        bus.sent.len() as u32 + c.dropped + c.replaced + c.flushed,
        "{:?}",
        c
    );
    prop_assert_eq!(c.sent as usize, bus.sent.len());
    Ok((worst, sched))
}

/// Random runs, and what they showed across all of them (printed after the last).
const CASES: u32 = 300;
static RUNS: AtomicU32 = AtomicU32::new(0);
static WORST: AtomicU64 = AtomicU64::new(0);
static REQUEUED: AtomicU32 = AtomicU32::new(0);

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn event_frames_reach_a_buffer_within_a_tick(
        bursts in prop::collection::vec((0u32..1000, 1u8..=6), 0..40),
        other_events in prop::collection::vec((0u32..1000, any::<u8>()), 0..200),
        bus_off in prop::option::weighted(0.3, (100u32..900, 1u32..50)),
    ) {
        let (worst, sched) = run(&bursts, &other_events, bus_off)?;
        let worst = WORST.fetch_max(worst, Ordering::Relaxed).max(worst);
        let requeued = REQUEUED.fetch_add(sched.counts().requeued, Ordering::Relaxed)
            + sched.counts().requeued;
        if RUNS.fetch_add(1, Ordering::Relaxed) + 1 == CASES {
            eprintln!(
                "{CASES} random runs: worst push-to-buffer {:.1} µs with fewer than three event frames ahead; {requeued} frames cancelled and requeued",
                worst as f64 / 1000.0
            );
        }
    }
}

#[test]
fn a_busy_hand_makes_the_scheduler_cancel_and_requeue() {
    // Right after each stream sample, the other fingertips' events hold the bus while ours
    // come in a burst of six: events beyond the kept buffer take the stream's and the
    // status' buffers, and the frames they cancel go out later.
    let bursts: Vec<(u32, u8)> = (1..1000).step_by(20).map(|t| (t, 6)).collect();
    let others: Vec<(u32, u8)> = (0..1000)
        .filter(|t| t % 20 < 2)
        .flat_map(|t| (0..4).map(move |n| (t, n)))
        .collect();
    let (worst, sched) = run(&bursts, &others, None).unwrap();
    assert!(sched.counts().requeued > 0, "{:?}", sched.counts());
    eprintln!(
        "busy hand: worst push-to-buffer {:.1} µs with fewer than three event frames ahead; {:?}",
        worst as f64 / 1000.0,
        sched.counts()
    );
}
