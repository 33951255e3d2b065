//! Codec cost per frame on the host: `cargo bench -p host-tests --bench can_codec`.
//!
//! Encodes and decodes every message kind, runs the receiver on a context frame and the
//! transmitter on a tick with a decision, each a million times, and prints nanoseconds
//! per call. A measurement, not a test: nothing here is asserted. The bench profile is
//! the release profile (detector-core at opt-level "s", as on the chip).

use std::hint::black_box;
use std::time::Instant;

use detector_core::{Confidence, Decision, EventId, Level, Output};
use fingertip_can::{
    ConfidenceMsg, ContextMsg, Counter, EventMsg, FaultFlags, Id, Message, NodeId, PhaseMsg,
    Receiver, ResetReason, RxState, Status, StatusPage, TipStateMsg, Transmitter, TxState,
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
    let c = Counter::new(3).unwrap_or_default();
    let one = Confidence::ONE;
    let messages = [
        (
            "Event",
            Message::Event(EventMsg {
                counter: c,
                event: EventId(2),
                level: Level::Confirm,
                confidence: one,
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
            "Context",
            Message::Context(ContextMsg {
                counter: c,
                vel_des: [500, -20],
                acc_des: [100, 0],
            }),
        ),
        (
            "TipState",
            Message::TipState(TipStateMsg {
                counter: c,
                pos_err: [-120, 33],
            }),
        ),
        (
            "Confidence",
            Message::Confidence(ConfidenceMsg {
                seq: 7,
                page: 0,
                evaluated: 0b111,
                unjudgeable: 0,
                confidences: [one, Confidence::ZERO, one],
            }),
        ),
        (
            "Status (health)",
            Message::Status(StatusPage::Health {
                reset: ResetReason::PowerOn,
                faults: FaultFlags::CONTEXT_STALE,
                uptime: 123_456,
                phase: Some(1),
                phase_seq: 9,
            }),
        ),
    ];
    println!("codec cost per call, {N} calls each");
    for (name, m) in &messages {
        time(&format!("encode {name}"), |_| {
            let _ = black_box(black_box(m).encode(node));
        });
        let Ok(f) = m.encode(node) else { continue };
        let id = Id::Standard(f.id());
        time(&format!("decode {name}"), |_| {
            let _ = black_box(Message::decode(black_box(id), black_box(f.data())));
        });
    }

    let rx = match Receiver::new(node, 4, 100, 500) {
        Ok(r) => r,
        Err(e) => panic!("{e}"),
    };
    let frames: Vec<_> = (0..16u8)
        .filter_map(|k| {
            ContextMsg {
                counter: Counter::new(k)?,
                vel_des: [500, 0],
                acc_des: [0, 0],
            }
            .encode(node)
            .ok()
        })
        .collect();
    let mut state = RxState::new();
    time("Receiver::receive (context)", |i| {
        let f = &frames[(i % 16) as usize];
        let _ = black_box(rx.receive(&mut state, i, Id::Standard(f.id()), f.data()));
    });

    let tx = match Transmitter::with_defaults(node, 5000) {
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
