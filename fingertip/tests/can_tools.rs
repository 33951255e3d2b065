//! The PC-side CAN tools: decoding candump logs (both formats) with problems reported by
//! line, the frames a fingertip sends surviving a trip through a log, cantools reading
//! our logs the same way, and the live monitor's error path (and, with a virtual CAN
//! interface named in `FINGERTIP_VCAN`, live decoding).

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use detector_core::{Confidence, Decision, EventId, Level, Output};
use fingertip::can_tools::decode::{DecodeOptions, Problem, decode_reader};
use fingertip::can_tools::{dbc, write_log_line};
use fingertip_can::{
    CanFrame, ContextMsg, Counter, Message, MessageKind, NodeId, PhaseMsg, Status, Transmitter,
    TxState,
};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn node(n: u8) -> NodeId {
    NodeId::new(n).unwrap()
}

/// The frames two fingertips send over `ticks` ticks: confidences ramping, one event
/// pair each, with a tick time of 200 µs from t = 100 s.
fn fingertip_traffic(ticks: u32) -> Vec<(Duration, CanFrame)> {
    let mut out = Vec::new();
    let txs = [node(1), node(2)].map(|n| Transmitter::with_defaults(n, 5000).unwrap());
    let mut states = [TxState::new(); 2];
    let status = Status {
        tick_rate_hz: 5000,
        ..Status::default()
    };
    for t in 0..ticks {
        for (i, (tx, st)) in txs.iter().zip(states.iter_mut()).enumerate() {
            let mut o = Output {
                evaluated: 0b0111,
                ..Output::default()
            };
            o.confidences[0] = Confidence::from_bits((t * 40).min(32768) as u16).unwrap();
            o.confidences[2] = Confidence::from_bits(100 * i as u16).unwrap();
            if t == 300 + 10 * i as u32 {
                o.decisions
                    .push(Decision {
                        event: EventId(0),
                        level: Level::Alert,
                        confidence: o.confidences[0],
                        onset: t - 25,
                        tick: t,
                    })
                    .unwrap();
            }
            let time = Duration::from_micros(100_000_000 + 200 * u64::from(t));
            for f in tx.tick(st, t, &o, &status) {
                out.push((time, f));
            }
        }
    }
    out
}

fn log_text(frames: &[(Duration, CanFrame)]) -> String {
    let mut buf = Vec::new();
    for (t, f) in frames {
        write_log_line(&mut buf, *t, "can0", f).unwrap();
    }
    String::from_utf8(buf).unwrap()
}

#[test]
fn frames_survive_a_trip_through_a_log() {
    let frames = fingertip_traffic(1000);
    let text = log_text(&frames);
    let log = decode_reader(
        Cursor::new(text),
        &DecodeOptions::default(),
        &mut std::io::sink(),
    )
    .unwrap();
    assert_eq!(
        log.problems().count(),
        0,
        "{:?}",
        log.problems().collect::<Vec<_>>()
    );
    let records: Vec<_> = log.records().collect();
    assert_eq!(records.len(), frames.len());
    for ((t, f), r) in frames.iter().zip(&records) {
        let (n, m) = Message::decode(fingertip_can::Id::Standard(f.id()), f.data()).unwrap();
        assert_eq!((r.node, r.message), (n, m));
        assert!((r.time.unwrap() - t.as_secs_f64()).abs() < 1e-6);
    }
    assert_eq!(log.events().count(), 2);
    // 1000 ticks at one sample per 20: 50 samples per fingertip.
    let stream = records
        .iter()
        .filter(|r| r.message.kind() == MessageKind::Confidence)
        .count();
    assert_eq!(stream, 2 * 50);
}

#[test]
fn problems_are_reported_by_line_and_decoding_goes_on() {
    let n = node(3);
    let c = |v| Counter::new(v).unwrap();
    let ctx = |k, vx| {
        ContextMsg {
            counter: c(k),
            vel_des: [vx, 0],
            acc_des: [0, 0],
        }
        .encode(n)
        .unwrap()
    };
    let phase = PhaseMsg {
        counter: c(0),
        phase: 1,
        sequence: 4,
    }
    .encode(n)
    .unwrap();
    let hexs = |f: &CanFrame| {
        f.data()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<String>()
    };
    let spaced = |f: &CanFrame| {
        f.data()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut bad_crc = hexs(&ctx(3, 30));
    bad_crc.replace_range(0..2, "00");
    let lines = [
        "# bench recording, controller -> fingertip 3".to_string(), // 1
        format!("(1.000000) can0 0A3#{}", hexs(&ctx(0, 10))),       // 2
        format!("(1.001000) can0 0A3#{}", hexs(&ctx(1, 11))),       // 3
        "(1.002000) can0 0A3#zz".to_string(),                       // 4 malformed
        format!("(1.003000) can0 0A3#{bad_crc}"),                   // 5 bad CRC
        format!("(1.004000) can0 0A3#{}", hexs(&ctx(4, 14))),       // 6 gap: 2, 3 lost
        format!("(1.005000) can0 0A3#{}", hexs(&ctx(4, 14))),       // 7 repeated
        format!("  can0  0A3   [8]  {}", spaced(&ctx(5, 15))),      // 8 screen format
        "(1.006000) can0 0A3#0102".to_string(),                     // 9 wrong length
        "(1.007000) can0 7FF#DEADBEEF".to_string(),                 // 10 foreign
        "(1.008000) can0 20000004#0000000000000000".to_string(),    // 11 error frame
        format!(" (1.009000)  can0  093   [4]  {}", spaced(&phase)), // 12 screen, timestamped
        "".to_string(),                                             // 13
        "(1.010000) can0 0C3#00030000000000000".to_string(),        // 14 odd digits
        "(1.011000) can0 0C3#0003000000000000".to_string(),         // 15 page 3: out of range
    ];
    let text = lines.join("\n");
    let mut printed = Vec::new();
    let log = decode_reader(Cursor::new(text), &DecodeOptions::default(), &mut printed).unwrap();
    let problems: Vec<(usize, &Problem)> = log.problems().map(|p| (p.line, &p.problem)).collect();
    let lines_with: Vec<usize> = problems.iter().map(|(l, _)| *l).collect();
    assert_eq!(lines_with, [4, 5, 6, 7, 9, 11, 14, 15], "{problems:#?}");
    assert!(matches!(problems[0].1, Problem::Malformed { .. }));
    assert!(matches!(
        problems[1].1,
        Problem::Invalid {
            error: fingertip_can::DecodeError::BadCrc { .. },
            ..
        }
    ));
    assert!(matches!(
        problems[2].1,
        Problem::CounterGap {
            expected: 2,
            got: 4,
            kind: MessageKind::Context,
            ..
        }
    ));
    assert!(matches!(
        problems[3].1,
        Problem::CounterRepeated { counter: 4, .. }
    ));
    assert!(matches!(
        problems[4].1,
        Problem::Invalid {
            error: fingertip_can::DecodeError::WrongLength { .. },
            ..
        }
    ));
    assert!(matches!(problems[5].1, Problem::ErrorFrame));
    assert!(matches!(problems[6].1, Problem::Malformed { .. }));
    assert!(matches!(
        problems[7].1,
        Problem::Invalid {
            error: fingertip_can::DecodeError::OutOfRange { signal: "Page", .. },
            ..
        }
    ));
    // Every good frame was still decoded, the foreign one counted.
    let good: Vec<usize> = log.records().map(|r| r.line).collect();
    assert_eq!(good, [2, 3, 6, 7, 8, 12]);
    assert_eq!(log.foreign_frames, 1);
    let printed = String::from_utf8(printed).unwrap();
    assert!(
        printed.contains("line 5: node 3: Context frame has CRC 0x00"),
        "{printed}"
    );
    assert!(printed.contains("line 6: node 3: Context counter gap: expected 2, got 4 (2 lost)"));
    assert!(printed.contains("phase     1 (sequence 4)"));
}

/// Frames on the protocol's identifiers that it cannot carry are problems, not foreign
/// frames: CAN FD frames (of any length, 9 bytes included), and an event the configuration
/// does not have.
#[test]
fn fd_frames_and_unknown_events_are_problems() {
    let event = |index: u8, counter: u8| {
        let d = Decision {
            event: EventId(index),
            level: Level::Confirm,
            confidence: Confidence::ONE,
            onset: 10,
            tick: 12,
        };
        let f = fingertip_can::EventMsg::from_decision(Counter::new(counter).unwrap(), &d)
            .encode(node(2))
            .unwrap();
        f.data()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<String>()
    };
    let lines = [
        format!("(1.0) can0 082#{}", event(1, 0)), // 1 a known event
        format!("(1.1) can0 082##1{}", event(1, 0)), // 2 the same bytes as CAN FD
        format!("(1.2) can0 082##1{}00", event(1, 0)), // 3 nine bytes, CAN FD
        format!("(1.3) can0 082#{}", event(5, 1)), // 4 event 5 of 3
        "(1.4) can0 7FF##1DEADBEEF".to_string(),   // 5 foreign, CAN FD
    ];
    let opts = DecodeOptions {
        event_names: vec![
            "contact".into(),
            "link_collision".into(),
            "disturbance".into(),
        ],
        ..DecodeOptions::default()
    };
    let mut printed = Vec::new();
    let log = decode_reader(Cursor::new(lines.join("\n")), &opts, &mut printed).unwrap();
    let problems: Vec<(usize, &Problem)> = log.problems().map(|p| (p.line, &p.problem)).collect();
    assert_eq!(problems.len(), 3, "{problems:#?}");
    assert!(matches!(
        problems[0],
        (
            2,
            Problem::FdFrame {
                kind: MessageKind::Event,
                len: 8,
                ..
            }
        )
    ));
    assert!(matches!(problems[1], (3, Problem::FdFrame { len: 9, .. })));
    assert!(matches!(
        problems[2],
        (
            4,
            Problem::UnknownEvent {
                event: 5,
                known: 3,
                ..
            }
        )
    ));
    assert_eq!(log.foreign_frames, 1);
    let printed = String::from_utf8(printed).unwrap();
    assert!(printed.contains("CAN FD frame (9 bytes)"), "{printed}");
    assert!(
        printed.contains("event 5, but the configuration has 3 events"),
        "{printed}"
    );
}

#[test]
fn a_lost_stream_sample_is_a_sequence_gap() {
    let frames = fingertip_traffic(200);
    // Drop node 1's third stream sample.
    let mut seen = 0;
    let kept: Vec<_> = frames
        .into_iter()
        .filter(|(_, f)| {
            if f.id().as_raw() == 0x0C1 {
                seen += 1;
                return seen != 3;
            }
            true
        })
        .collect();
    let log = decode_reader(
        Cursor::new(log_text(&kept)),
        &DecodeOptions::default(),
        &mut std::io::sink(),
    )
    .unwrap();
    let problems: Vec<_> = log.problems().collect();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(matches!(
        problems[0].problem,
        Problem::SequenceGap {
            expected: 2,
            got: 3,
            ..
        }
    ));
}

/// The venv's interpreter, if it has cantools; otherwise skip, or fail when required.
fn python() -> Option<PathBuf> {
    let py = root().join(".venv/bin/python");
    let ok = Command::new(&py)
        .args(["-c", "import cantools"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    let msg = format!("no cantools at {}", py.display());
    if std::env::var("FINGERTIP_REQUIRE_PYTHON").as_deref() == Ok("1") {
        panic!("FINGERTIP_REQUIRE_PYTHON=1 but {msg}");
    }
    eprintln!("SKIPPED: {msg}");
    None
}

#[test]
fn cantools_reads_our_logs_the_same() {
    let Some(py) = python() else { return };
    let frames = fingertip_traffic(400);
    let mut text = log_text(&frames);
    // Plus a few lines in the screen format.
    for (_, f) in frames.iter().take(5) {
        let bytes: Vec<String> = f.data().iter().map(|b| format!("{b:02X}")).collect();
        text.push_str(&format!(
            "  can0  {:03X}   [{}]  {}\n",
            f.id().as_raw(),
            f.len(),
            bytes.join(" ")
        ));
    }
    let dir = std::env::temp_dir().join(format!("fingertip-can-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("traffic.log");
    std::fs::write(&path, &text).unwrap();
    let out = Command::new(&py)
        .arg(root().join("fingertip-can/python/candump_check.py"))
        .arg(root().join("fingertip-can/fingertip.dbc"))
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let theirs: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    let ours = decode_reader(
        Cursor::new(text.clone()),
        &DecodeOptions::default(),
        &mut std::io::sink(),
    )
    .unwrap();
    let records: Vec<_> = ours.records().collect();
    assert_eq!(theirs.len(), records.len());
    assert_eq!(records.len(), frames.len() + 5);
    for (t, r) in theirs.iter().zip(&records) {
        assert_eq!(t["line"].as_u64(), Some(r.line as u64));
        assert!(t.get("error").is_none(), "{t}");
        assert_eq!(
            t["name"].as_str(),
            Some(dbc::message_name(r.message.kind(), r.node).as_str())
        );
        if let (Some(a), Some(b)) = (t["time"].as_f64(), r.time) {
            assert!((a - b).abs() < 1e-5, "line {}: {a} vs {b}", r.line);
        }
        let crc = match r.message.kind().is_protected() {
            true => t["signals"]["Crc"].as_f64().unwrap() as u8,
            false => 0,
        };
        for (name, v) in dbc::signal_values(&r.message, crc) {
            let w = t["signals"][&name].as_f64().unwrap();
            assert!((w - v).abs() <= 1e-9, "line {} {name}: {w} vs {v}", r.line);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[cfg(target_os = "linux")]
#[test]
fn monitor_reports_a_missing_interface() {
    use fingertip::can_tools::CanToolError;
    use fingertip::can_tools::monitor::{MonitorLimits, monitor};
    let r = monitor(
        "nosuchcan9",
        &DecodeOptions::default(),
        &MonitorLimits::default(),
        &mut std::io::sink(),
        None,
        &|| true,
    );
    match r {
        Err(CanToolError::Socket { iface, .. }) => assert_eq!(iface, "nosuchcan9"),
        other => panic!("{other:?}"),
    }
}

/// Live: with `FINGERTIP_VCAN=vcan0` (an interface made with `ip link add dev vcan0 type
/// vcan && ip link set up vcan0`), frames sent on it are decoded by the monitor.
#[cfg(target_os = "linux")]
#[test]
fn monitor_decodes_live_traffic_on_a_virtual_bus() {
    use fingertip::can_tools::monitor::{MonitorLimits, monitor};
    use socketcan::{CanSocket, EmbeddedFrame, Socket};
    let Ok(iface) = std::env::var("FINGERTIP_VCAN") else {
        eprintln!("SKIPPED: set FINGERTIP_VCAN to a virtual CAN interface to run the live test");
        return;
    };
    let frames: Vec<CanFrame> = fingertip_traffic(100).into_iter().map(|(_, f)| f).collect();
    let count = frames.len();
    let sender_iface = iface.clone();
    let sender = std::thread::spawn(move || {
        let s = CanSocket::open(&sender_iface).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        for f in &frames {
            let sf = socketcan::CanFrame::new(f.id(), f.data()).unwrap();
            s.write_frame(&sf).unwrap();
        }
    });
    let mut printed = Vec::new();
    let log = monitor(
        &iface,
        &DecodeOptions::default(),
        &MonitorLimits {
            max_frames: Some(count),
            duration: Some(Duration::from_secs(10)),
        },
        &mut printed,
        None,
        &|| false,
    )
    .unwrap();
    sender.join().unwrap();
    assert_eq!(log.records().count(), count);
    assert_eq!(log.problems().count(), 0);
}
