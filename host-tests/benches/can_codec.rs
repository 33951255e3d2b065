//! Codec cost per frame on the host: `cargo bench -p host-tests --bench can_codec`.
//!
//! Encodes and decodes every message kind, runs the receiver on a broadcast context frame
//! and the transmitter on a tick with a decision, each a million times, and prints
//! nanoseconds per call. A measurement, not a test: nothing here is asserted. The bench
//! profile is the release profile (detector-core at opt-level "s", as on the chip).

use std::hint::black_box;
use std::time::Instant;

use detector_core::{Confidence, Decision, EventId, Level, Output};
use fingertip_can::{
    Address, BusFormat, ContextGroup, ContextMsg, ContextPart, ContextPartMsg, ContextSlot,
    Counter, EventMsg, FaultFlags, Id, LevelState, Message, NodeId, PhaseMsg, Receiver,
    ResetReason, RxState, Status, StatusMsg, StatusPage, StreamMsg, Transmitter, TxState,
};

const N: u32 = 1_000_000;

fn time(name: &str, mut f: impl FnMut(u32)) {
    // Warm up, then measure.
    for i in 0..N / 10 {
        f(i);
    }
    let start = Instant::now();
    for i in 0..N {
        f(i);
    }
    let ns = start.elapsed().as_nanos() as f64 / f64::from(N);
    println!("{name:<34} {ns:8.1} ns");
}

fn main() {
    let node = NodeId::new(5).unwrap_or_default();
    let group = ContextGroup::of(node);
    let c = Counter(3);
    let one = Confidence::ONE;
    let slot = ContextSlot {
        vel_des: [500, -20],
        acc_des: [100, 0],
        pos_err: [-120, 33],
    };
    let messages = [
        (
            "Event",
            Message::Event(EventMsg {
                counter: c,
                event: EventId(2),
                level: Level::Confirm,
                tick: 1234,
                onset_age: 17,
            }),
        ),
        (
            "Phase",
            Message::Phase(PhaseMsg {
                counter: c,
                phase: 1,
                sequence: 9,
            }),
        ),
        (
            "Context (5 slots)",
            Message::Context(ContextMsg {
                counter: c,
                time_us: 1_000_000,
                slots: [Some(slot); 5],
            }),
        ),
        (
            "ContextPart",
            Message::ContextPart(ContextPartMsg {
                counter: c,
                part: ContextPart::Velocity,
                value: [500, -20],
            }),
        ),
        (
            "Stream",
            Message::Stream(StreamMsg {
                counter: c,
                evaluated: 0b111,
                unjudgeable: 0,
                levels: [LevelState::Alert; 8],
                confidences: [one; 8],
            }),
        ),
        (
            "Status (health)",
            Message::Status(StatusMsg {
                counter: c,
                page: StatusPage::Health {
                    reset: ResetReason::PowerOn,
                    phase: Some(1),
                    faults: FaultFlags::CONTEXT_STALE,
                    phase_seq: 9,
                },
            }),
        ),
    ];
    println!("codec cost per call, {N} calls each");
    for (name, m) in &messages {
        let address = if m.kind().is_broadcast() {
            Address::Group(group)
        } else {
            Address::Node(node)
        };
        time(&format!("encode {name}"), |_| {
            let _ = black_box(black_box(m).encode(address));
        });
        let Ok(f) = m.encode(address) else { continue };
        let id = Id::Standard(f.id());
        time(&format!("decode {name}"), |_| {
            let _ = black_box(Message::decode(black_box(id), black_box(f.data())));
        });
    }

    let rx = match Receiver::new(node, 4, 100, 500) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    };
    let frames: Vec<_> = (0..=255u8)
        .filter_map(|k| {
            ContextMsg {
                counter: Counter(k),
                time_us: 1000 * u32::from(k),
                slots: [Some(slot); 5],
            }
            .encode(group)
            .ok()
        })
        .collect();
    let mut state = RxState::new();
    time("Receiver::receive (context)", |i| {
        // The controller's time goes round with the counter: start over each round.
        if i % 256 == 0 {
            state = RxState::new();
        }
        let f = &frames[(i % 256) as usize];
        let _ = black_box(rx.receive(&mut state, i, Id::Standard(f.id()), f.data()));
    });

    let tx = match Transmitter::with_defaults(node, BusFormat::Fd, 5000) {
        Ok(t) => t,
        Err(e) => panic!("{e}"),
    };
    let mut out = Output {
        evaluated: 0b111,
        ..Output::default()
    };
    let _ = out.decisions.push(Decision {
        event: EventId(0),
        level: Level::Alert,
        confidence: one,
        onset: 0,
        tick: 10,
    });
    let status = Status::default();
    let mut ts = TxState::new();
    time("Transmitter::tick (1 decision)", |i| {
        let _ = black_box(tx.tick(&mut ts, i, black_box(&out), &status));
    });
}
