//! Property tests of the CAN protocol's no_std code over arbitrary input.
//!
//! Inputs run per `cargo test` (the case counts are set explicitly below):
//! - `receiver_handles_any_frame`: 100 000 arbitrary frames (any identifier, standard or
//!   extended, 0..=12 bytes, any tick), half of them with a correct CRC so the deeper
//!   checks (counter, phase, ranges) are reached, each into a receiver whose state was
//!   prepared by up to four earlier frames.
//! - `receiver_handles_any_sequence`: 5 000 sequences of up to 40 frames (200 000 frames at
//!   most), good and damaged, with advancing time.
//! - `decoder_handles_any_frame`: 100 000 arbitrary frames into `Message::decode`.
//! - `valid_messages_round_trip`: 20 000 messages built from in-range fields.
//! - `transmitter_reports_any_output`: 10 000 arbitrary detector outputs.
//!
//! The properties: nothing panics; a rejected frame changes nothing but the count of its
//! reason, which goes up by exactly one; an accepted frame changes no rejection count; the
//! reason is the first failed check in the documented order; what decodes re-encodes to
//! a frame that decodes the same.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use detector_core::{Confidence, Decision, EventId, Level, Output, Tick};
use fingertip_can::{
    Accepted, CanFrame, ConfidenceMsg, ContextMsg, Counter, EventMsg, ExtendedId, FaultFlags, Id,
    Message, MessageKind, NodeId, PhaseMsg, REJECT_REASONS, Receiver, RejectReason, ResetReason,
    RxState, StandardId, Status, StatusPage, TipStateMsg, Transmitter, TxState, e2e,
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
        6 => (0x080u16..=0x0DF).prop_map(|r| Id::Standard(StandardId::new(r).unwrap())),
        2 => (0u16..=0x7FF).prop_map(|r| Id::Standard(StandardId::new(r).unwrap())),
        1 => (0u32..=0x1FFF_FFFF).prop_map(|r| Id::Extended(ExtendedId::new(r).unwrap())),
    ]
}

/// A frame: arbitrary bytes, or arbitrary bytes with byte 0 made the correct CRC for the
/// identifier (when standard and long enough).
fn any_frame() -> impl Strategy<Value = (Id, Vec<u8>)> {
    (
        any_id(),
        prop_oneof![3 => 0usize..=8, 1 => 9usize..=12],
        any::<[u8; 12]>(),
        any::<bool>(),
    )
        .prop_map(|(id, len, bytes, fix_crc)| {
            let mut data = bytes[..len].to_vec();
            if let (true, Id::Standard(sid)) = (fix_crc, id)
                && let Some(c) = e2e::crc(sid, &data)
            {
                data[0] = c;
            }
            (id, data)
        })
}

/// A well-formed frame for `node` (phase, context or tip state), arbitrary in-range
/// content and counter.
fn good_frame(node: NodeId) -> impl Strategy<Value = (Id, Vec<u8>)> {
    let c = (0u8..=15).prop_map(|v| Counter::new(v).unwrap());
    let vel = -4095i16..=4095;
    let pos = -32767i16..=32767;
    prop_oneof![
        (c.clone(), 0u8..=7, any::<u8>()).prop_map(move |(counter, phase, sequence)| {
            PhaseMsg {
                counter,
                phase,
                sequence,
            }
            .encode(node)
            .unwrap()
        }),
        (c.clone(), [vel.clone(), vel.clone()], [vel.clone(), vel]).prop_map(
            move |(counter, vel_des, acc_des)| ContextMsg {
                counter,
                vel_des,
                acc_des
            }
            .encode(node)
            .unwrap()
        ),
        (c, [pos.clone(), pos]).prop_map(move |(counter, pos_err)| TipStateMsg {
            counter,
            pos_err
        }
        .encode(node)
        .unwrap()),
    ]
    .prop_map(|f: CanFrame| (Id::Standard(f.id()), f.data().to_vec()))
}

fn receiver() -> impl Strategy<Value = Receiver> {
    (0u8..=15, 1u8..=8, 1u32..=500, 1u32..=2000, 1u8..=14).prop_map(|(n, p, ct, pt, d)| {
        Receiver::new(NodeId::new(n).unwrap(), p, ct, pt)
            .unwrap()
            .with_max_counter_delta(d)
            .unwrap()
    })
}

/// The reasons decided before any state is consulted, in the documented order; `None`
/// when the frame passes them.
fn oracle(rx: &Receiver, id: Id, data: &[u8]) -> Option<RejectReason> {
    let Some((kind, node)) = MessageKind::from_id(id) else {
        return Some(RejectReason::UnknownId);
    };
    if node != rx.node()
        || !matches!(
            kind,
            MessageKind::Phase | MessageKind::Context | MessageKind::TipState
        )
    {
        return Some(RejectReason::UnknownId);
    }
    if data.len() != kind.dlc() {
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

/// Checks one frame against the properties; returns the outcome.
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
                Accepted::Context(m) => prop_assert_eq!(state.link().context(), Some(m)),
                Accepted::TipState(m) => prop_assert_eq!(state.link().tip_state(), Some(m)),
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
        if let Ok((node, m)) = Message::decode(id, &data) {
            // Canonical re-encoding (reserved bits cleared) decodes the same.
            let f = m.encode(node).expect("a decoded message re-encodes");
            prop_assert_eq!(Message::decode(Id::Standard(f.id()), f.data()), Ok((node, m)));
            prop_assert_eq!(f.len(), data.len());
        }
    }
}

proptest! {
    #![proptest_config(config(5_000))]

    #[test]
    fn receiver_handles_any_sequence(
        (rx, steps) in receiver().prop_flat_map(|rx| (
            Just(rx),
            prop::collection::vec(
                (prop_oneof![2 => any_frame(), 3 => good_frame(rx.node())], 0u32..300),
                1..40,
            ),
        )),
        start in any::<u32>(),
    ) {
        let mut state = RxState::new();
        let mut now = start;
        let (mut accepted, mut rejected) = (0u32, 0u32);
        for ((id, data), dt) in steps {
            now = now.wrapping_add(dt);
            rx.poll(&mut state, now);
            match check_one(&rx, &mut state, now, id, &data)? {
                Ok(_) => accepted += 1,
                Err(_) => rejected += 1,
            }
            // Stale context is never handed out.
            let f = rx.freshness(&state, now);
            let inputs = rx.inputs(&state, now);
            prop_assert_eq!(inputs.vel_des.is_some(), f.context);
            prop_assert_eq!(inputs.pos_err.is_some(), f.tip_state);
        }
        prop_assert_eq!(state.counts().rejected().total(), rejected);
        prop_assert!(accepted + rejected > 0);
        prop_assert_eq!(REJECT_REASONS, RejectReason::ALL.len());
    }
}

fn any_message() -> impl Strategy<Value = Message> {
    let c = (0u8..=15).prop_map(|v| Counter::new(v).unwrap());
    let conf = (0u16..=32768).prop_map(|b| Confidence::from_bits(b).unwrap());
    let u16s = any::<[u16; 3]>();
    prop_oneof![
        (
            c.clone(),
            0u8..=7,
            any::<bool>(),
            conf.clone(),
            any::<u16>(),
            any::<u16>()
        )
            .prop_map(
                |(counter, e, confirm, confidence, tick, onset_age)| Message::Event(EventMsg {
                    counter,
                    event: EventId(e),
                    level: if confirm {
                        Level::Confirm
                    } else {
                        Level::Alert
                    },
                    confidence,
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
            [-4095i16..=4095, -4095i16..=4095],
            [-4095i16..=4095, -4095i16..=4095]
        )
            .prop_map(|(counter, vel_des, acc_des)| Message::Context(ContextMsg {
                counter,
                vel_des,
                acc_des
            })),
        (c, [-32767i16..=32767, -32767i16..=32767])
            .prop_map(|(counter, pos_err)| Message::TipState(TipStateMsg { counter, pos_err })),
        (
            any::<u8>(),
            0u8..=2,
            any::<u8>(),
            any::<u8>(),
            [conf.clone(), conf.clone(), conf]
        )
            .prop_map(|(seq, page, ev, un, mut confidences)| {
                let slots = ConfidenceMsg::slots(page);
                let mask = ((1u16 << slots) - 1) as u8;
                for c in confidences.iter_mut().skip(slots) {
                    *c = Confidence::ZERO;
                }
                Message::Confidence(ConfidenceMsg {
                    seq,
                    page,
                    evaluated: ev & mask,
                    unjudgeable: un & mask,
                    confidences,
                })
            }),
        (
            0u8..6,
            0usize..9,
            any::<u8>(),
            any::<u32>(),
            prop::option::of(0u8..=7),
            any::<u8>(),
            u16s,
            any::<u32>()
        )
            .prop_map(
                |(page, reset, faults, uptime, phase, phase_seq, [a, b, c], word)| {
                    Message::Status(match page {
                        0 => StatusPage::Health {
                            reset: ResetReason::ALL[reset],
                            faults: FaultFlags(faults),
                            uptime,
                            phase,
                            phase_seq,
                        },
                        1 => StatusPage::Timing {
                            overruns: a,
                            worst_tick: b,
                            tick_rate_hz: c,
                            protocol: faults,
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
                        _ => StatusPage::Config {
                            checksum: word,
                            tx_dropped: a,
                        },
                    })
                }
            ),
    ]
}

proptest! {
    #![proptest_config(config(20_000))]

    #[test]
    fn valid_messages_round_trip(m in any_message(), n in 0u8..=15) {
        let node = NodeId::new(n).unwrap();
        let f = m.encode(node).expect("in-range message encodes");
        prop_assert_eq!(f.len(), m.kind().dlc());
        prop_assert_eq!(MessageKind::from_id(Id::Standard(f.id())), Some((m.kind(), node)));
        prop_assert_eq!(Message::decode(Id::Standard(f.id()), f.data()), Ok((node, m)));
        // Any single bit flipped in a protected frame is caught by the CRC.
        if m.kind().is_protected() {
            for bit in 0..8 * f.len() {
                let mut d = f.data().to_vec();
                d[bit / 8] ^= 1 << (bit % 8);
                prop_assert!(Message::decode(Id::Standard(f.id()), &d).is_err(), "bit {} flip passed", bit);
            }
        }
    }
}

fn any_output() -> impl Strategy<Value = Output> {
    (
        any::<u8>(),
        any::<u8>(),
        prop::array::uniform8(0u16..=32768),
        prop::collection::vec((0u8..8, any::<bool>(), 0u16..=32768, 0u32..100_000), 0..=16),
    )
        .prop_map(|(evaluated, unjudgeable, conf, decisions)| {
            let mut o = Output {
                evaluated,
                unjudgeable: unjudgeable & evaluated,
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
        })
}

proptest! {
    #![proptest_config(config(10_000))]

    #[test]
    fn transmitter_reports_any_output(out in any_output(), dec in 1u16..50, n in 0u8..=15) {
        let node = NodeId::new(n).unwrap();
        let tx = Transmitter::new(node, dec, 250).unwrap();
        let mut state = TxState::new();
        let frames = tx.tick(&mut state, 1_000_000, &out, &Status::default());
        prop_assert_eq!(state.dropped(), 0);
        let mut events = Vec::new();
        let mut stream = [None::<Confidence>; 8];
        for f in &frames {
            let (from, m) = Message::decode(Id::Standard(f.id()), f.data()).expect("our frames decode");
            prop_assert_eq!(from, node);
            match m {
                Message::Event(e) => events.push(e),
                Message::Confidence(p) => {
                    for k in 0..ConfidenceMsg::slots(p.page) {
                        let e = 3 * usize::from(p.page) + k;
                        let evaluated = p.evaluated & (1 << k) != 0;
                        prop_assert_eq!(evaluated, out.evaluated & (1 << e) != 0);
                        prop_assert_eq!(p.unjudgeable & (1 << k) != 0, out.unjudgeable & (1 << e) != 0);
                        if evaluated {
                            stream[e] = Some(p.confidences[k]);
                        }
                    }
                }
                Message::Status(_) => {}
                other => prop_assert!(false, "unexpected {:?}", other),
            }
        }
        prop_assert_eq!(events.len(), out.decisions.len());
        for (i, (e, d)) in events.iter().zip(&out.decisions).enumerate() {
            prop_assert_eq!(e.counter.get(), i as u8 % 16);
            prop_assert_eq!(e.event, d.event);
            prop_assert_eq!(e.level, d.level);
            prop_assert_eq!(e.confidence, d.confidence);
            prop_assert_eq!(u32::from(e.onset_age), (d.tick - d.onset).min(65535));
        }
        for (e, got) in stream.iter().enumerate() {
            if out.evaluated & (1 << e) != 0 {
                prop_assert_eq!(*got, Some(out.confidences[e]));
            } else {
                prop_assert_eq!(*got, None);
            }
        }
        // Highest priority first.
        prop_assert!(frames.windows(2).all(|w| w[0].id().as_raw() <= w[1].id().as_raw()));
    }
}
