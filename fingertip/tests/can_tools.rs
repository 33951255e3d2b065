//! The PC-side CAN tools: decoding candump logs (both formats, classic and CAN FD frames)
//! with problems reported by line, the frames a fingertip sends surviving a trip through a
//! log, cantools reading our logs the same way, and the live monitor's error path (and,
//! with a virtual CAN interface named in `FINGERTIP_VCAN`, live decoding of CAN FD
//! traffic).

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use detector_core::{Confidence, Decision, EventId, Level, Output};
use fingertip::can_tools::decode::{DecodeOptions, Problem, decode_reader};
use fingertip::can_tools::{dbc, write_log_line};
use fingertip_can::{
    Address, BusFormat, CanFrame, ContextGroup, ContextMsg, ContextPart, ContextPartMsg,
    ContextSlot, Counter, Message, MessageKind, NodeId, PhaseMsg, Status, Transmitter, TxState,
};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn node(n: u8) -> NodeId {
    NodeId::new(n).unwrap()
}

/// The frames two fingertips send over `ticks` ticks on a bus of `format`: confidences
/// ramping, one event each, with a tick time of 200 µs from t = 100 s.
fn fingertip_traffic(format: BusFormat, ticks: u32) -> Vec<(Duration, CanFrame)> {
    let mut out = Vec::new();
    let txs = [node(1), node(2)].map(|n| Transmitter::with_defaults(n, format, 5000).unwrap());
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
                o.alerting = 1;
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

fn hex(f: &CanFrame) -> String {
    f.data().iter().map(|b| format!("{b:02X}")).collect()
}

#[test]
fn frames_survive_a_trip_through_a_log() {
    for format in [BusFormat::Fd, BusFormat::Classic] {
        let frames = fingertip_traffic(format, 1000);
        let text = log_text(&frames);
        assert_eq!(
            text.lines().filter(|l| l.contains("##1")).count(),
            if format == BusFormat::Fd {
                frames.len()
            } else {
                0
            },
            "every frame of a CAN FD bus is written CAN FD"
        );
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
            let (a, m) = Message::decode(fingertip_can::Id::Standard(f.id()), f.data()).unwrap();
            assert_eq!((r.address, r.message), (a, m));
            assert!((r.time.unwrap() - t.as_secs_f64()).abs() < 1e-6);
        }
        assert_eq!(log.events().count(), 2);
        // 1000 ticks at one sample per 20 (CAN FD: 50 samples per fingertip) or per 100
        // (classic: 10), three events each.
        let samples = 1000 / usize::from(format.default_stream_decimation());
        let values: usize = records.iter().map(|r| r.stream_values().len()).sum();
        assert_eq!(values, 2 * samples * 3, "{}", format.name());
    }
}

#[test]
fn problems_are_reported_by_line_and_decoding_goes_on() {
    let n = node(3);
    let part = |k: u8, vx: i16| {
        ContextPartMsg {
            counter: Counter(k),
            part: ContextPart::Velocity,
            value: [vx, 0],
        }
        .encode(n)
        .unwrap()
    };
    let phase = PhaseMsg {
        counter: Counter(0),
        phase: 1,
        sequence: 4,
    }
    .encode(n)
    .unwrap();
    let mut ctx = ContextMsg {
        counter: Counter(9),
        time_us: 1234,
        ..ContextMsg::default()
    };
    ctx.slots[3] = Some(ContextSlot {
        vel_des: [500, 0],
        ..ContextSlot::default()
    });
    let ctx = ctx.encode(ContextGroup::of(n)).unwrap();
    let spaced = |f: &CanFrame| {
        f.data()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let mut bad_crc = hex(&part(3, 30));
    bad_crc.replace_range(0..4, "0000");
    // A status frame of page 17 (past the last) with a good CRC.
    let mut page17 = [0u8, 0, 0, 17, 0, 0, 0, 0];
    fingertip_can::e2e::seal(MessageKind::Status.id(n), &mut page17);
    let page17: String = page17.iter().map(|b| format!("{b:02X}")).collect();
    let lines = [
        "# bench recording, controller -> fingertip 3".to_string(), // 1
        format!("(1.000000) can0 133#{}", hex(&part(0, 10))),       // 2
        format!("(1.001000) can0 133#{}", hex(&part(1, 11))),       // 3
        "(1.002000) can0 133#zz".to_string(),                       // 4 malformed
        format!("(1.003000) can0 133#{bad_crc}"),                   // 5 bad CRC
        format!("(1.004000) can0 133#{}", hex(&part(4, 14))),       // 6 gap: 2, 3 lost
        format!("(1.005000) can0 133#{}", hex(&part(4, 14))),       // 7 repeated
        format!("  can0  133   [8]  {}", spaced(&part(5, 15))),     // 8 screen format
        "(1.006000) can0 133#0102".to_string(),                     // 9 wrong length
        "(1.007000) can0 7FF#DEADBEEF".to_string(),                 // 10 foreign
        "(1.008000) can0 20000004#0000000000000000".to_string(),    // 11 error frame
        format!(" (1.009000)  can0  143   [5]  {}", spaced(&phase)), // 12 screen, timestamped
        "".to_string(),                                             // 13
        "(1.010000) can0 173#00000000000000000".to_string(),        // 14 odd digits
        format!("(1.011000) can0 173#{page17}"),                    // 15 page 17: out of range
        format!("(1.012000) can0 120##1{}", hex(&ctx)),             // 16 CAN FD context
        format!("(1.013000) can0 120##1{}", &hex(&ctx)[..96]),      // 17 48 bytes: wrong length
    ];
    let text = lines.join("\n");
    let mut printed = Vec::new();
    let log = decode_reader(Cursor::new(text), &DecodeOptions::default(), &mut printed).unwrap();
    let problems: Vec<(usize, &Problem)> = log.problems().map(|p| (p.line, &p.problem)).collect();
    let lines_with: Vec<usize> = problems.iter().map(|(l, _)| *l).collect();
    assert_eq!(lines_with, [4, 5, 6, 7, 9, 11, 14, 15, 17], "{problems:#?}");
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
            kind: MessageKind::ContextPart,
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
    assert!(matches!(
        problems[8].1,
        Problem::Invalid {
            address: Address::Group(_),
            error: fingertip_can::DecodeError::WrongLength {
                expected: 64,
                got: 48,
                ..
            },
        }
    ));
    // Every good frame was still decoded, the foreign one counted.
    let good: Vec<usize> = log.records().map(|r| r.line).collect();
    assert_eq!(good, [2, 3, 6, 7, 8, 12, 16]);
    assert_eq!(log.foreign_frames, 1);
    let printed = String::from_utf8(printed).unwrap();
    assert!(
        printed.contains("line 5: node 3: ContextPart frame has CRC 0x0000"),
        "{printed}"
    );
    assert!(
        printed.contains("line 6: node 3: ContextPart counter gap: expected 2, got 4 (2 lost)")
    );
    assert!(printed.contains("phase     1 (sequence 4)"));
    assert!(
        printed.contains("group 0  context   t 1234 us | 0: empty"),
        "{printed}"
    );
    assert!(
        printed.contains("| 3: vel_des (+0.0500, +0.0000) m/s"),
        "{printed}"
    );
}

/// An event the configuration does not have is a problem; so is a remote frame on the
/// protocol's identifiers.
#[test]
fn unknown_events_and_remote_frames_are_problems() {
    let event = |index: u8, counter: u8| {
        let d = Decision {
            event: EventId(index),
            level: Level::Confirm,
            confidence: Confidence::ONE,
            onset: 10,
            tick: 12,
        };
        hex(
            &fingertip_can::EventMsg::from_decision(Counter(counter), &d)
                .encode(node(2))
                .unwrap(),
        )
    };
    let lines = [
        format!("(1.0) can0 112#{}", event(1, 0)), // 1 a known event
        format!("(1.1) can0 112##1{}", event(1, 1)), // 2 the same as CAN FD: fine
        format!("(1.3) can0 112#{}", event(5, 2)), // 3 event 5 of 3
        "(1.4) can0 112#R".to_string(),            // 4 remote
        "(1.5) can0 7FF##1DEADBEEF".to_string(),   // 5 foreign, CAN FD
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
    assert_eq!(problems.len(), 2, "{problems:#?}");
    assert!(matches!(
        problems[0],
        (
            3,
            Problem::UnknownEvent {
                event: 5,
                known: 3,
                ..
            }
        )
    ));
    assert!(matches!(
        problems[1],
        (
            4,
            Problem::Remote {
                kind: MessageKind::Event,
                ..
            }
        )
    ));
    assert_eq!(log.foreign_frames, 1);
    let printed = String::from_utf8(printed).unwrap();
    assert!(
        printed.contains("event 5, but the configuration has 3 events"),
        "{printed}"
    );
}

/// The problems of a log of `frames` without the frames of identifier `id` whose rank
/// among them (from 1) is in `lost`.
fn problems_losing(
    frames: Vec<(Duration, CanFrame)>,
    id: u16,
    lost: std::ops::Range<usize>,
) -> Vec<Problem> {
    let mut seen = 0;
    let kept: Vec<_> = frames
        .into_iter()
        .filter(|(_, f)| {
            if f.id().as_raw() == id {
                seen += 1;
                return !lost.contains(&seen);
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
    log.problems().map(|p| p.problem.clone()).collect()
}

#[test]
fn a_lost_stream_sample_is_a_counter_gap() {
    // CAN FD: node 1's third sample is lost.
    let frames = fingertip_traffic(BusFormat::Fd, 200);
    let problems = problems_losing(frames, MessageKind::Stream.raw_id(node(1)), 3..4);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(matches!(
        problems[0],
        Problem::CounterGap {
            kind: MessageKind::Stream,
            expected: 2,
            got: 3,
            ..
        }
    ));
    // Classic (a sample every 100 ticks): every page of node 2's fourth sample is lost.
    let frames = fingertip_traffic(BusFormat::Classic, 1000);
    let problems = problems_losing(frames, MessageKind::StreamPage.raw_id(node(2)), 10..13);
    assert!(
        matches!(
            problems[..],
            [
                Problem::CounterGap {
                    kind: MessageKind::StreamPage,
                    expected: 9,
                    got: 12,
                    ..
                },
                Problem::SequenceGap {
                    expected: 3,
                    got: 4,
                    ..
                }
            ]
        ),
        "{problems:?}"
    );
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
    for format in [BusFormat::Fd, BusFormat::Classic] {
        let frames = fingertip_traffic(format, 400);
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
        let dir = std::env::temp_dir().join(format!(
            "fingertip-can-{}-{}",
            std::process::id(),
            format.name().replace(' ', "-")
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("traffic.log");
        std::fs::write(&path, &text).unwrap();
        let out = Command::new(&py)
            .arg(root().join("fingertip-can/python/candump_check.py"))
            .arg(root().join(dbc::file_name(format)))
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
                Some(dbc::message_name(r.message.kind(), r.address).as_str())
            );
            if let (Some(a), Some(b)) = (t["time"].as_f64(), r.time) {
                assert!((a - b).abs() < 1e-5, "line {}: {a} vs {b}", r.line);
            }
            let crc = t["signals"]["Crc"].as_f64().unwrap() as u16;
            for (name, v) in dbc::signal_values(r.address, &r.message, crc) {
                let w = t["signals"][&name].as_f64().unwrap();
                assert!((w - v).abs() <= 1e-9, "line {} {name}: {w} vs {v}", r.line);
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
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
/// vcan && ip link set vcan0 mtu 72 && ip link set up vcan0`), CAN FD frames sent on it
/// are decoded by the monitor.
#[cfg(target_os = "linux")]
#[test]
fn monitor_decodes_live_traffic_on_a_virtual_bus() {
    use fingertip::can_tools::monitor::{MonitorLimits, monitor};
    use socketcan::id::FdFlags;
    use socketcan::{CanFdFrame, CanFdSocket, Socket};
    let Ok(iface) = std::env::var("FINGERTIP_VCAN") else {
        eprintln!("SKIPPED: set FINGERTIP_VCAN to a virtual CAN interface to run the live test");
        return;
    };
    let frames: Vec<CanFrame> = fingertip_traffic(BusFormat::Fd, 100)
        .into_iter()
        .map(|(_, f)| f)
        .collect();
    let count = frames.len();
    let sender_iface = iface.clone();
    let sender = std::thread::spawn(move || {
        let s = CanFdSocket::open(&sender_iface).unwrap();
        std::thread::sleep(Duration::from_millis(200));
        for f in &frames {
            let sf = CanFdFrame::with_flags(f.id(), f.data(), FdFlags::BRS).unwrap();
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
