//! Property tests of the CAN protocol's no_std code over arbitrary input.
//!
//! Inputs run per `cargo test` (the case counts are set explicitly below):
//! - `receiver_handles_any_frame`: 100 000 arbitrary frames (any identifier, standard or
//!   extended, classic and CAN FD lengths up to 64 bytes, any tick), half of them with a
//!   correct CRC so the deeper checks are reached, each into a receiver whose state was
//!   prepared by up to four earlier frames.
//! - `receiver_over_a_lossy_channel`: 3 000 controller streams of up to 600 frames (the
//!   broadcast context, the classic context parts, or the phase), counters starting
//!   anywhere so they wrap, through a channel that loses, repeats, corrupts and delays
//!   frames (silences beyond the timeout included).
//! - `old_context_is_refused_while_fresh`: 5 000 replays of an earlier context frame.
//! - `decoder_handles_any_frame`: 100 000 arbitrary frames into `Message::decode`.
//! - `valid_messages_round_trip`: 20 000 messages built from in-range fields, with every
//!   single-bit corruption and random double-bit corruptions.
//! - `transmitter_reports_any_output`: 10 000 arbitrary detector outputs, both bus formats.
//!
//! The properties: nothing panics; a rejected frame changes nothing but the count of its
//! reason, which goes up by exactly one; the reason is the first failed check in the
//! documented order; every frame lost on the channel is counted, no more; no good frame is
//! rejected, whatever was lost, repeated or corrupted before it, after any silence; a
//! repetition is rejected; no context is handed out longer than the timeout after the
//! frame that carried it arrived; what decodes re-encodes to a frame that decodes the same.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use detector_core::{Confidence, Decision, EventId, Level, MAX_EVENTS, Output, Tick};
use fingertip_can::{
    Accepted, Address, BusFormat, CanFrame, ContextGroup, ContextMsg, ContextPart, ContextPartMsg,
    ContextSlot, Counter, EventMsg, ExtendedId, FaultFlags, Id, LevelState, Message, MessageKind,
    NodeId, NodeIdSource, PhaseMsg, REJECT_REASONS, Receiver, RejectReason, ResetReason, RxState,
    StandardId, Status, StatusMsg, StatusPage, StreamMsg, StreamPageMsg, Transmitter, TxState, e2e,
    is_fd_length,
};
use proptest::prelude::*;

fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        // Keep the source tree read-only; a failure prints its minimal input.
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// An identifier: mostly the protocol's range (so each message and node is hit often),
/// sometimes anything standard, sometimes extended.
fn any_id() -> impl Strategy<Value = Id> {
    prop_oneof![
        6 => (0x110u16..=0x17F).prop_map(|r| Id::Standard(StandardId::new(r).unwrap())),
        2 => (0u16..=0x7FF).prop_map(|r| Id::Standard(StandardId::new(r).unwrap())),
        1 => (0u32..=0x1FFF_FFFF).prop_map(|r| Id::Extended(ExtendedId::new(r).unwrap())),
    ]
}

/// A length: classic, the protocol's own, any CAN FD length, or none the bus allows.
fn any_len() -> impl Strategy<Value = usize> {
    prop_oneof![
        3 => 0usize..=8,
        3 => prop::sample::select(vec![5usize, 8, 24, 64]),
        1 => prop::sample::select(vec![12usize, 16, 20, 32, 48]),
        1 => 9usize..=64,
    ]
}

/// A frame: arbitrary bytes, or arbitrary bytes with bytes 0..2 made the correct CRC for
/// the identifier (when standard and long enough).
fn any_frame() -> impl Strategy<Value = (Id, Vec<u8>)> {
    (
        any_id(),
        any_len(),
        prop::collection::vec(any::<u8>(), 64),
        any::<bool>(),
    )
        .prop_map(|(id, len, bytes, fix_crc)| {
            let mut data = bytes[..len].to_vec();
            if let (true, Id::Standard(sid)) = (fix_crc, id) {
                e2e::seal(sid, &mut data);
            }
            (id, data)
        })
}

fn receiver() -> impl Strategy<Value = Receiver> {
    (0u8..=14, 1u8..=8, 1u32..=500, 1u32..=2000)
        .prop_map(|(n, p, ct, pt)| Receiver::new(NodeId::new(n).unwrap(), p, ct, pt).unwrap())
}

/// The reasons decided before any state is consulted, in the documented order; `None`
/// when the frame passes them.
fn oracle(rx: &Receiver, id: Id, data: &[u8]) -> Option<RejectReason> {
    let Some((kind, address)) = MessageKind::from_id(id) else {
        return Some(RejectReason::UnknownId);
    };
    let mine = match (kind, address) {
        (MessageKind::Phase | MessageKind::ContextPart, Address::Node(n)) => n == rx.node(),
        (MessageKind::Context, Address::Group(g)) => g == ContextGroup::of(rx.node()),
        _ => false,
    };
    if !mine {
        return Some(RejectReason::UnknownId);
    }
    if data.len() != kind.data_len() {
        return Some(RejectReason::WrongLength);
    }
    let Id::Standard(sid) = id else {
        return Some(RejectReason::UnknownId);
    };
    if !e2e::check(sid, data) {
        return Some(RejectReason::BadCrc);
    }
    None
}

/// Checks one frame against the state-free properties; returns the outcome.
fn check_one(
    rx: &Receiver,
    state: &mut RxState,
    now: Tick,
    id: Id,
    data: &[u8],
) -> Result<Result<Accepted, RejectReason>, TestCaseError> {
    let before = *state;
    let result = rx.receive(state, now, id, data);
    let (b, a) = (before.counts().rejected(), state.counts().rejected());
    match result {
        Err(reason) => {
            prop_assert_eq!(
                state.link(),
                before.link(),
                "a rejected frame changed the link"
            );
            prop_assert_eq!(state.counts().lost_frames(), before.counts().lost_frames());
            for r in RejectReason::ALL {
                let want = b.get(r) + u32::from(r == reason);
                prop_assert_eq!(a.get(r), want, "count of {:?}", r);
            }
            if let Some(pre) = oracle(rx, id, data) {
                prop_assert_eq!(reason, pre, "wrong reason");
            }
        }
        Ok(accepted) => {
            prop_assert_eq!(a, b, "an accepted frame changed the rejection counts");
            prop_assert_eq!(oracle(rx, id, data), None);
            match accepted {
                Accepted::Phase { command, .. } => {
                    prop_assert_eq!(state.link().phase(), Some(command))
                }
                Accepted::Context {
                    slot: Some(s),
                    time_us,
                    ..
                } => {
                    for p in ContextPart::ALL {
                        prop_assert_eq!(state.link().part(p), Some(s.part(p)));
                    }
                    prop_assert_eq!(state.link().controller_time(), Some(time_us));
                }
                Accepted::Context { slot: None, .. } => {
                    for p in ContextPart::ALL {
                        prop_assert_eq!(state.link().part(p), before.link().part(p));
                    }
                }
                Accepted::ContextPart(m) => {
                    prop_assert_eq!(state.link().part(m.part), Some(m.value))
                }
            }
        }
    }
    prop_assert_eq!(
        state.counts().stale_episodes(),
        before.counts().stale_episodes()
    );
    Ok(result)
}

proptest! {
    #![proptest_config(config(100_000))]

    #[test]
    fn receiver_handles_any_frame(
        rx in receiver(),
        warmup in prop::collection::vec((any_frame(), 0u32..50), 0..4),
        (id, data) in any_frame(),
        now in any::<u32>(),
    ) {
        let mut state = RxState::new();
        let mut t = now.wrapping_sub(200);
        for ((wid, wdata), dt) in warmup {
            t = t.wrapping_add(dt);
            let _ = rx.receive(&mut state, t, wid, &wdata);
        }
        let _ = check_one(&rx, &mut state, now, id, &data)?;
    }

    #[test]
    fn decoder_handles_any_frame((id, data) in any_frame()) {
        if let Ok((address, m)) = Message::decode(id, &data) {
            // Canonical re-encoding (reserved bits cleared) decodes the same.
            let f = m.encode(address).expect("a decoded message re-encodes");
            prop_assert_eq!(Message::decode(Id::Standard(f.id()), f.data()), Ok((address, m)));
            prop_assert_eq!(f.len(), data.len());
        }
    }
}

/// What the controller streams in a channel test.
#[derive(Clone, Copy, Debug)]
enum Stream {
    /// The broadcast context (CAN FD), with the controller's time.
    Context,
    /// The classic context parts, in turn.
    Parts,
    /// Phase commands.
    Phase,
}

/// What the channel does to one frame of the controller's.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fate {
    /// Delivered once.
    Deliver,
    /// Lost.
    Drop,
    /// Delivered twice in a row (a repetition).
    Repeat,
    /// Delivered with one bit flipped.
    Corrupt(u16),
}

fn fate() -> impl Strategy<Value = Fate> {
    prop_oneof![
        12 => Just(Fate::Deliver),
        4 => Just(Fate::Drop),
        1 => Just(Fate::Repeat),
        1 => (0u16..512).prop_map(Fate::Corrupt),
    ]
}

/// The parts of the fingertip's context a frame fills, and their value.
type Fills = Option<(Vec<ContextPart>, [i16; 2])>;

/// The controller's frame `k` of `stream` for `node`: its frame, and the parts it fills.
fn controller_frame(
    stream: Stream,
    node: NodeId,
    counter: u8,
    time_us: u32,
    k: u32,
) -> (CanFrame, Fills) {
    let v = [(k % 4000) as i16, -((k % 3000) as i16)];
    match stream {
        Stream::Context => {
            let mut m = ContextMsg {
                counter: Counter(counter),
                time_us,
                ..ContextMsg::default()
            };
            // One cycle in seven leaves this fingertip's slot empty.
            let filled = k % 7 != 3;
            if filled {
                m.slots[ContextGroup::slot_of(node)] = Some(ContextSlot {
                    vel_des: v,
                    acc_des: v,
                    pos_err: v,
                });
            }
            let f = m.encode(ContextGroup::of(node)).unwrap();
            (f, filled.then(|| (ContextPart::ALL.to_vec(), v)))
        }
        Stream::Parts => {
            let part = ContextPart::ALL[(k % 3) as usize];
            let f = ContextPartMsg {
                counter: Counter(counter),
                part,
                value: v,
            }
            .encode(node)
            .unwrap();
            (f, Some((vec![part], v)))
        }
        Stream::Phase => {
            let f = PhaseMsg {
                counter: Counter(counter),
                phase: (k % 2) as u8,
                sequence: (k / 2) as u8,
            }
            .encode(node)
            .unwrap();
            (f, None)
        }
    }
}

proptest! {
    #![proptest_config(config(3_000))]

    #[test]
    fn receiver_over_a_lossy_channel(
        n in 0u8..=14,
        timeout in 5u32..200,
        stream in prop_oneof![Just(Stream::Context), Just(Stream::Parts), Just(Stream::Phase)],
        first_counter in any::<u8>(),
        first_time in any::<u32>(),
        period_us in 200u32..5000,
        steps in prop::collection::vec((fate(), prop_oneof![8 => 0u32..8, 1 => 0u32..400]), 1..600),
        start in any::<u32>(),
    ) {
        let node = NodeId::new(n).unwrap();
        let rx = Receiver::new(node, 2, timeout, timeout).unwrap();
        let mut state = RxState::new();
        let mut now = start;
        // Oracle: the originals accepted (their index), and each part's value and arrival.
        let mut accepted: Vec<u32> = Vec::new();
        let mut held: [Option<([i16; 2], Tick)>; 3] = [None; 3];
        let mut phase_at: Option<Tick> = None;
        let mut run = 0u32;
        for (k, (fate, gap)) in (0u32..).zip(steps) {
            now = now.wrapping_add(gap);
            rx.poll(&mut state, now);
            // No context handed out after its timeout, none withheld within it.
            let fresh = |h: Option<([i16; 2], Tick)>| h.filter(|(_, at)| now.wrapping_sub(*at) <= timeout);
            let inputs = rx.inputs(&state, now);
            let [vel, acc, pos] = held.map(fresh);
            let context = vel.is_some() && acc.is_some();
            prop_assert_eq!(inputs.vel_des, vel.filter(|_| context).map(|(v, _)| v));
            prop_assert_eq!(inputs.acc_des, acc.filter(|_| context).map(|(v, _)| v));
            prop_assert_eq!(inputs.pos_err, pos.map(|(v, _)| v));
            let f = rx.freshness(&state, now);
            prop_assert_eq!(f.phase, phase_at.is_some_and(|at| now.wrapping_sub(at) <= timeout));

            // At most 255 frames in a row are lost: the counter's reach.
            let fate = if run == 255 { Fate::Deliver } else { fate };
            let counter = first_counter.wrapping_add(k as u8);
            let time = first_time.wrapping_add(k.wrapping_mul(period_us));
            let (frame, fills) = controller_frame(stream, node, counter, time, k);
            let id = Id::Standard(frame.id());
            let deliver = |data: &[u8], state: &mut RxState| check_one(&rx, state, now, id, data);
            match fate {
                Fate::Drop => run += 1,
                Fate::Corrupt(bit) => {
                    let mut d = frame.data().to_vec();
                    let bit = usize::from(bit) % (8 * d.len());
                    d[bit / 8] ^= 1 << (bit % 8);
                    prop_assert_eq!(deliver(&d, &mut state)?, Err(RejectReason::BadCrc));
                    run += 1;
                }
                Fate::Deliver | Fate::Repeat => {
                    let r = deliver(frame.data(), &mut state)?;
                    prop_assert!(r.is_ok(), "good frame {} rejected: {:?}", k, r);
                    accepted.push(k);
                    run = 0;
                    if let Some((parts, v)) = &fills {
                        for p in parts {
                            held[*p as usize] = Some((*v, now));
                        }
                    }
                    if matches!(stream, Stream::Phase) {
                        phase_at = Some(now);
                    }
                    if fate == Fate::Repeat {
                        prop_assert_eq!(deliver(frame.data(), &mut state)?, Err(RejectReason::Sequence));
                    }
                }
            }
        }
        // Every frame lost between the first and the last accepted is counted, no more.
        let lost = match (accepted.first(), accepted.last()) {
            (Some(a), Some(b)) => b - a + 1 - accepted.len() as u32,
            _ => 0,
        };
        prop_assert_eq!(state.counts().lost_frames(), lost);
        prop_assert_eq!(REJECT_REASONS, RejectReason::ALL.len());
    }
}

proptest! {
    #![proptest_config(config(5_000))]

    #[test]
    fn old_context_is_refused_while_fresh(
        n in 0u8..=14,
        sent in 2u32..300,
        replay in any::<prop::sample::Index>(),
        first_counter in any::<u8>(),
        first_time in any::<u32>(),
    ) {
        let node = NodeId::new(n).unwrap();
        let rx = Receiver::new(node, 1, 100, 100).unwrap();
        let mut state = RxState::new();
        let frames: Vec<CanFrame> = (0..sent)
            .map(|k| {
                let counter = first_counter.wrapping_add(k as u8);
                let time = first_time.wrapping_add(1000 * k);
                controller_frame(Stream::Context, node, counter, time, k).0
            })
            .collect();
        for (t, f) in (0u32..).zip(&frames) {
            rx.receive(&mut state, t, Id::Standard(f.id()), f.data()).unwrap();
        }
        // Any frame sent before, delivered again within the timeout: refused, nothing
        // changes.
        let old = &frames[replay.index(frames.len())];
        let r = check_one(&rx, &mut state, sent, Id::Standard(old.id()), old.data())?;
        prop_assert_eq!(r, Err(RejectReason::Sequence));
    }
}

fn any_confidence() -> impl Strategy<Value = Confidence> {
    (0u16..=32768).prop_map(|b| Confidence::from_bits(b).unwrap())
}

fn any_level() -> impl Strategy<Value = LevelState> {
    prop::sample::select(LevelState::ALL.to_vec())
}

fn any_slot() -> impl Strategy<Value = ContextSlot> {
    let vel = || -4095i16..=4095;
    let pos = || -32767i16..=32767;
    ([vel(), vel()], [vel(), vel()], [pos(), pos()]).prop_map(|(vel_des, acc_des, pos_err)| {
        ContextSlot {
            vel_des,
            acc_des,
            pos_err,
        }
    })
}

fn any_status_page() -> impl Strategy<Value = StatusPage> {
    (
        0u8..11,
        0usize..9,
        prop::option::of(0u8..=7),
        0u16..(1 << 9),
        any::<[u16; 2]>(),
        any::<u32>(),
        any::<bool>(),
    )
        .prop_map(
            |(page, reset, phase, faults, [a, b], word, flag)| match page {
                0 => StatusPage::Health {
                    reset: ResetReason::ALL[reset],
                    phase,
                    faults: FaultFlags(faults),
                    phase_seq: a as u8,
                },
                1 => StatusPage::Uptime { uptime: word },
                2 => StatusPage::Identity {
                    tick_rate_hz: a,
                    protocol: b as u8,
                    format: if flag {
                        BusFormat::Classic
                    } else {
                        BusFormat::Fd
                    },
                    node_source: NodeIdSource::ALL[usize::from(flag)],
                },
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
                _ => StatusPage::Config { checksum: word },
            },
        )
}

fn any_message() -> impl Strategy<Value = Message> {
    let c = any::<u8>().prop_map(Counter);
    prop_oneof![
        (
            c.clone(),
            0u8..=7,
            any::<bool>(),
            any::<u16>(),
            any::<u16>()
        )
            .prop_map(
                |(counter, e, confirm, tick, onset_age)| Message::Event(EventMsg {
                    counter,
                    event: EventId(e),
                    level: if confirm {
                        Level::Confirm
                    } else {
                        Level::Alert
                    },
                    tick,
                    onset_age,
                })
            ),
        (c.clone(), 0u8..=7, any::<u8>()).prop_map(|(counter, phase, sequence)| {
            Message::Phase(PhaseMsg {
                counter,
                phase,
                sequence,
            })
        }),
        (
            c.clone(),
            any::<u32>(),
            prop::array::uniform5(prop::option::of(any_slot()))
        )
            .prop_map(|(counter, time_us, slots)| Message::Context(ContextMsg {
                counter,
                time_us,
                slots,
            })),
        (c.clone(), 0usize..3, any_slot()).prop_map(|(counter, p, s)| {
            let part = ContextPart::ALL[p];
            Message::ContextPart(ContextPartMsg {
                counter,
                part,
                value: s.part(part),
            })
        }),
        (
            c.clone(),
            any::<u8>(),
            any::<u8>(),
            prop::array::uniform8(any_level()),
            prop::array::uniform8(any_confidence())
        )
            .prop_map(|(counter, evaluated, unjudgeable, levels, confidences)| {
                Message::Stream(StreamMsg {
                    counter,
                    evaluated,
                    unjudgeable,
                    levels,
                    confidences,
                })
            }),
        (
            c.clone(),
            any::<u8>(),
            0u8..8,
            any::<bool>(),
            any_level(),
            any_confidence()
        )
            .prop_map(|(counter, sample, e, unjudgeable, level, confidence)| {
                Message::StreamPage(StreamPageMsg {
                    counter,
                    sample,
                    event: EventId(e),
                    unjudgeable,
                    level,
                    confidence,
                })
            }),
        (c, any_status_page())
            .prop_map(|(counter, page)| Message::Status(StatusMsg { counter, page })),
    ]
}

proptest! {
    #![proptest_config(config(20_000))]

    #[test]
    fn valid_messages_round_trip(
        m in any_message(),
        index in 0u8..=14,
        pairs in prop::collection::vec((any::<prop::sample::Index>(), any::<prop::sample::Index>()), 4),
    ) {
        let address = if m.kind().is_broadcast() {
            Address::Group(ContextGroup::new(index % 3).unwrap())
        } else {
            Address::Node(NodeId::new(index).unwrap())
        };
        let f = m.encode(address).expect("in-range message encodes");
        prop_assert_eq!(f.len(), m.kind().data_len());
        prop_assert!(is_fd_length(f.len()));
        prop_assert_eq!(MessageKind::from_id(Id::Standard(f.id())), Some((m.kind(), address)));
        prop_assert_eq!(Message::decode(Id::Standard(f.id()), f.data()), Ok((address, m)));
        // Every single-bit and any double-bit corruption is caught by the CRC-16.
        let bits = 8 * f.len();
        for bit in 0..bits {
            let mut d = f.data().to_vec();
            d[bit / 8] ^= 1 << (bit % 8);
            prop_assert!(Message::decode(Id::Standard(f.id()), &d).is_err(), "bit {} flip passed", bit);
        }
        for (a, b) in pairs {
            let (a, b) = (a.index(bits), b.index(bits));
            if a == b {
                continue;
            }
            let mut d = f.data().to_vec();
            d[a / 8] ^= 1 << (a % 8);
            d[b / 8] ^= 1 << (b % 8);
            prop_assert!(Message::decode(Id::Standard(f.id()), &d).is_err(), "bits {} and {} passed", a, b);
        }
    }
}

fn any_output() -> impl Strategy<Value = Output> {
    (
        any::<u8>(),
        any::<u8>(),
        any::<u8>(),
        any::<u8>(),
        prop::array::uniform8(0u16..=32768),
        prop::collection::vec((0u8..8, any::<bool>(), 0u16..=32768, 0u32..100_000), 0..=16),
    )
        .prop_map(
            |(evaluated, unjudgeable, alerting, confirmed, conf, decisions)| {
                let mut o = Output {
                    evaluated,
                    unjudgeable: unjudgeable & evaluated,
                    alerting: alerting & evaluated,
                    confirmed: confirmed & alerting & evaluated,
                    ..Output::default()
                };
                for (i, c) in o.confidences.iter_mut().enumerate() {
                    if evaluated & (1 << i) != 0 {
                        *c = Confidence::from_bits(conf[i]).unwrap();
                    }
                }
                for (e, confirm, c, age) in decisions {
                    let _ = o.decisions.push(Decision {
                        event: EventId(e),
                        level: if confirm {
                            Level::Confirm
                        } else {
                            Level::Alert
                        },
                        confidence: Confidence::from_bits(c).unwrap(),
                        onset: 1_000_000u32.wrapping_sub(age),
                        tick: 1_000_000,
                    });
                }
                o
            },
        )
}

proptest! {
    #![proptest_config(config(10_000))]

    #[test]
    fn transmitter_reports_any_output(out in any_output(), dec in 1u16..50, n in 0u8..=14, classic in any::<bool>()) {
        let node = NodeId::new(n).unwrap();
        let format = if classic { BusFormat::Classic } else { BusFormat::Fd };
        let tx = Transmitter::new(node, format, dec, 250).unwrap();
        let mut state = TxState::new();
        let frames = tx.tick(&mut state, 1_000_000, &out, &Status::default());
        prop_assert_eq!(state.dropped(), 0);
        let mut events = Vec::new();
        let mut stream = [None::<(Confidence, LevelState, bool)>; MAX_EVENTS];
        for f in &frames {
            prop_assert_eq!(f.is_fd(), format == BusFormat::Fd);
            let (from, m) = Message::decode(Id::Standard(f.id()), f.data()).expect("our frames decode");
            prop_assert_eq!(from, Address::Node(node));
            prop_assert!(m.kind().carried_by(format));
            match m {
                Message::Event(e) => events.push(e),
                Message::Stream(s) => {
                    prop_assert_eq!(s.evaluated, out.evaluated);
                    for (e, slot) in stream.iter_mut().enumerate() {
                        if out.evaluated & (1 << e) != 0 {
                            *slot = Some((s.confidences[e], s.levels[e], s.unjudgeable & (1 << e) != 0));
                        }
                    }
                }
                Message::StreamPage(p) => {
                    let e = usize::from(p.event.0);
                    prop_assert!(stream[e].is_none(), "event {} paged twice", e);
                    stream[e] = Some((p.confidence, p.level, p.unjudgeable));
                }
                Message::Status(_) => {}
                other => prop_assert!(false, "unexpected {:?}", other),
            }
        }
        prop_assert_eq!(events.len(), out.decisions.len());
        for (i, (e, d)) in events.iter().zip(&out.decisions).enumerate() {
            prop_assert_eq!(e.counter.get(), i as u8);
            prop_assert_eq!(e.event, d.event);
            prop_assert_eq!(e.level, d.level);
            prop_assert_eq!(u32::from(e.onset_age), (d.tick - d.onset).min(65535));
        }
        for (e, got) in stream.iter().enumerate() {
            if out.evaluated & (1 << e) != 0 {
                let (c, level, unjudgeable) = got.expect("every evaluated event streamed");
                prop_assert_eq!(c, out.confidences[e]);
                prop_assert_eq!(unjudgeable, out.unjudgeable & (1 << e) != 0);
                // The level: at least the one up now, and at least any raised this tick.
                let raised = out.decisions.iter().filter(|d| usize::from(d.event.0) == e);
                let want = raised
                    .map(|d| if d.level == Level::Confirm { LevelState::Confirm } else { LevelState::Alert })
                    .chain([LevelState::from_masks(out.alerting, out.confirmed, e)])
                    .max()
                    .unwrap_or(LevelState::None);
                prop_assert_eq!(level, want);
            } else {
                prop_assert!(format == BusFormat::Fd || got.is_none());
            }
        }
        // Highest priority first.
        prop_assert!(frames.windows(2).all(|w| w[0].id().as_raw() <= w[1].id().as_raw()));
    }
}
