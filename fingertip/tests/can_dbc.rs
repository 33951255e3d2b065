//! The DBCs are the contract: the published `fingertip-can/fingertip.dbc` (CAN FD) and
//! `fingertip-can/fingertip-classic.dbc` and the codec in `fingertip_can` must agree, as
//! judged by a third-party decoder (cantools, run from the venv at `.venv`, driven by
//! `fingertip-can/python/dbc_check.py`).
//!
//! - Frames our codec encodes, cantools decodes to the same values, and its AUTOSAR E2E
//!   profile 5 check accepts their CRC.
//! - Values cantools encodes from the DBC (CRC applied by cantools), our codec decodes to
//!   the same values, byte for byte the frames it would send itself.
//! - Values just outside each range are refused by both.
//! - cantools reads each database as the specification table says, CAN FD frames as CAN FD.
//!
//! Every message kind, every node and group, and the extremes of every range. Without the
//! venv the cantools tests print a skip notice and pass, unless
//! `FINGERTIP_REQUIRE_PYTHON=1`, when they fail. `FINGERTIP_BLESS=1` rewrites the committed
//! DBCs from the specification.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use detector_core::{Confidence, EventId, Level, MAX_EVENTS};
use fingertip::can_tools::dbc::{self, Mux};
use fingertip_can::{
    Address, BusFormat, CanFrame, ContextGroup, ContextMsg, ContextPart, ContextPartMsg,
    ContextSlot, Counter, EventMsg, FaultFlags, Id, LevelState, Message, MessageKind, NodeId,
    NodeIdSource, PhaseMsg, ResetReason, StatusMsg, StatusPage, StreamMsg, StreamPageMsg,
};
use serde_json::{Value, json};

const FORMATS: [BusFormat; 2] = [BusFormat::Fd, BusFormat::Classic];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn dbc_path(format: BusFormat) -> PathBuf {
    root().join(dbc::file_name(format))
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
    let msg = format!(
        "no cantools at {} (create it: python3 -m venv .venv && .venv/bin/pip install cantools)",
        py.display()
    );
    if std::env::var("FINGERTIP_REQUIRE_PYTHON").as_deref() == Ok("1") {
        panic!("FINGERTIP_REQUIRE_PYTHON=1 but {msg}");
    }
    eprintln!("SKIPPED: {msg}");
    None
}

fn run_python(py: &Path, request: &Value) -> Value {
    let mut child = Command::new(py)
        .arg(root().join("fingertip-can/python/dbc_check.py"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start python");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(request.to_string().as_bytes())
        .expect("write request");
    let out = child.wait_with_output().expect("python ran");
    assert!(
        out.status.success(),
        "dbc_check.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON answer")
}

fn conf(bits: u16) -> Confidence {
    Confidence::from_bits(bits).unwrap()
}

fn slot(v: i16, p: i16) -> ContextSlot {
    ContextSlot {
        vel_des: [v, -v],
        acc_des: [-v, v],
        pos_err: [p, -p],
    }
}

/// Per-node messages covering every kind, page, flag and the ends of every range.
fn node_samples() -> Vec<Message> {
    let mut v = Vec::new();
    for (i, (e, level, tick, age)) in [
        (0u8, Level::Alert, 0u16, 0u16),
        (7, Level::Confirm, 65535, 65535),
        (3, Level::Confirm, 1, 1),
    ]
    .into_iter()
    .enumerate()
    {
        v.push(Message::Event(EventMsg {
            counter: Counter([0, 255, 7][i]),
            event: EventId(e),
            level,
            tick,
            onset_age: age,
        }));
    }
    for (ctr, phase, seq) in [(0, 0, 0), (255, 7, 255), (4, 3, 128)] {
        v.push(Message::Phase(PhaseMsg {
            counter: Counter(ctr),
            phase,
            sequence: seq,
        }));
    }
    for (part, x) in [
        (ContextPart::Velocity, 4095i16),
        (ContextPart::Acceleration, -4095),
        (ContextPart::PositionError, 32767),
        (ContextPart::Velocity, 0),
    ] {
        v.push(Message::ContextPart(ContextPartMsg {
            counter: Counter(x as u8),
            part,
            value: [x, -x],
        }));
    }
    let mut full = StreamMsg {
        counter: Counter(255),
        evaluated: 0xFF,
        unjudgeable: 0xA5,
        ..StreamMsg::default()
    };
    for e in 0..MAX_EVENTS {
        full.levels[e] = LevelState::ALL[e % 3];
        full.confidences[e] = conf([32768, 0, 1, 32767][e % 4]);
    }
    v.extend([Message::Stream(full), Message::Stream(StreamMsg::default())]);
    for e in 0..MAX_EVENTS as u8 {
        v.push(Message::StreamPage(StreamPageMsg {
            counter: Counter(e),
            sample: 255 - e,
            event: EventId(e),
            unjudgeable: e % 2 == 1,
            level: LevelState::ALL[usize::from(e) % 3],
            confidence: conf([32768, 0, 1][usize::from(e) % 3]),
        }));
    }
    let status = |c: u8, page| {
        Message::Status(StatusMsg {
            counter: Counter(c),
            page,
        })
    };
    for reset in ResetReason::ALL {
        v.push(status(
            reset as u8,
            StatusPage::Health {
                reset,
                phase: Some(reset as u8 % 8),
                faults: FaultFlags(1 << (reset as u8 % 9)),
                phase_seq: reset as u8,
            },
        ));
    }
    v.push(status(
        255,
        StatusPage::Health {
            reset: ResetReason::Unknown,
            phase: None,
            faults: FaultFlags(0x1FF),
            phase_seq: 255,
        },
    ));
    for x in [0u16, u16::MAX] {
        v.extend([
            status(
                1,
                StatusPage::Uptime {
                    uptime: u32::from(x) * 65537,
                },
            ),
            status(
                2,
                StatusPage::Identity {
                    tick_rate_hz: x,
                    protocol: x as u8,
                    format: if x == 0 {
                        BusFormat::Fd
                    } else {
                        BusFormat::Classic
                    },
                    node_source: if x == 0 {
                        NodeIdSource::Straps
                    } else {
                        NodeIdSource::Store
                    },
                },
            ),
            status(
                3,
                StatusPage::Lateness {
                    worst: x,
                    late_ticks: x,
                },
            ),
            status(
                4,
                StatusPage::Compute {
                    worst_tick: x,
                    lost_scans: x,
                },
            ),
            status(
                5,
                StatusPage::Link {
                    stale_episodes: x,
                    lost_frames: x,
                },
            ),
            status(
                6,
                StatusPage::Bus {
                    bus_errors: x,
                    tx_dropped: x,
                },
            ),
            status(
                7,
                StatusPage::RejectsFrame {
                    wrong_length: x,
                    bad_crc: x,
                },
            ),
            status(
                8,
                StatusPage::RejectsContent {
                    sequence: x,
                    out_of_range: x,
                },
            ),
            status(
                9,
                StatusPage::RejectsRoute {
                    unknown_id: x,
                    phase_not_configured: x,
                },
            ),
            status(
                10,
                StatusPage::Config {
                    checksum: u32::from(x) * 65537,
                },
            ),
        ]);
    }
    v
}

/// Broadcast context frames: full, partly filled, empty, at the ends of every range.
fn context_samples() -> Vec<Message> {
    let full = ContextMsg {
        counter: Counter(255),
        time_us: u32::MAX,
        slots: [
            Some(slot(4095, 32767)),
            Some(slot(-4095, -32767)),
            Some(slot(1, -1)),
            Some(slot(0, 0)),
            Some(slot(1234, 5678)),
        ],
    };
    let mut some = full;
    some.counter = Counter(0);
    some.time_us = 0;
    some.slots[1] = None;
    some.slots[4] = None;
    vec![
        Message::Context(full),
        Message::Context(some),
        Message::Context(ContextMsg::default()),
    ]
}

/// Every sample at several addresses, and one sample of each kind at every address, so
/// every message of both databases is exercised.
fn cases() -> Vec<(Address, Message, CanFrame)> {
    let mut out = Vec::new();
    let samples = node_samples();
    for (i, m) in samples.iter().enumerate() {
        for n in [0u8, 7, 14] {
            let a = Address::Node(NodeId::new((n + i as u8) % 15).unwrap());
            out.push((a, *m, m.encode(a).expect("sample encodes")));
        }
    }
    for kind in MessageKind::ALL.iter().filter(|k| !k.is_broadcast()) {
        let m = samples
            .iter()
            .find(|m| m.kind() == *kind)
            .expect("kind sampled");
        for n in NodeId::all() {
            out.push((Address::Node(n), *m, m.encode(Address::Node(n)).unwrap()));
        }
    }
    for m in context_samples() {
        for g in ContextGroup::all() {
            out.push((Address::Group(g), m, m.encode(Address::Group(g)).unwrap()));
        }
    }
    out
}

fn hex(d: &[u8]) -> String {
    d.iter().map(|b| format!("{b:02x}")).collect()
}

fn signal_map(a: Address, m: &Message, f: &CanFrame) -> BTreeMap<String, f64> {
    let crc = u16::from_le_bytes([f.data()[0], f.data()[1]]);
    dbc::signal_values(a, m, crc).into_iter().collect()
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

#[test]
fn committed_dbcs_are_the_rendered_specification() {
    for format in FORMATS {
        let text = dbc::render(format);
        if std::env::var("FINGERTIP_BLESS").as_deref() == Ok("1") {
            std::fs::write(dbc_path(format), &text).expect("write the DBC");
        }
        let committed = std::fs::read_to_string(dbc_path(format)).expect("the DBC exists");
        assert!(
            committed == text,
            "{} differs from can_tools::dbc::render(); regenerate with FINGERTIP_BLESS=1 cargo test -p fingertip --test can_dbc",
            dbc::file_name(format)
        );
    }
}

#[test]
fn codec_and_cantools_agree_both_ways() {
    let Some(py) = python() else { return };
    for format in FORMATS {
        let cases: Vec<_> = cases()
            .into_iter()
            .filter(|(_, m, _)| m.kind().carried_by(format))
            .collect();
        let request = json!({
            "dbc": dbc_path(format),
            "decode": cases.iter().map(|(_, _, f)| json!({
                "id": f.id().as_raw(), "data": hex(f.data())
            })).collect::<Vec<_>>(),
            "encode": cases.iter().map(|(a, m, f)| json!({
                "id": f.id().as_raw(), "signals": signal_map(*a, m, f)
            })).collect::<Vec<_>>(),
        });
        let answer = run_python(&py, &request);
        let decoded = answer["decoded"].as_array().expect("decoded");
        let encoded = answer["encoded"].as_array().expect("encoded");
        assert_eq!(decoded.len(), cases.len());
        assert_eq!(encoded.len(), cases.len());
        let mut names = std::collections::BTreeSet::new();
        for ((a, m, f), (dec, enc)) in cases.iter().zip(decoded.iter().zip(encoded)) {
            let what = format!("{m:?} at {a:?} on {}", format.name());
            // Our frame, cantools' decoding.
            assert!(dec.get("error").is_none(), "{what}: {dec}");
            assert_eq!(
                dec["name"].as_str(),
                Some(dbc::message_name(m.kind(), *a).as_str()),
                "{what}"
            );
            names.insert(dec["name"].as_str().unwrap_or("").to_string());
            let theirs: BTreeMap<String, f64> = dec["signals"]
                .as_object()
                .expect("signals")
                .iter()
                .map(|(k, v)| (k.clone(), v.as_f64().expect("number")))
                .collect();
            let ours = signal_map(*a, m, f);
            assert_eq!(
                theirs.keys().collect::<Vec<_>>(),
                ours.keys().collect::<Vec<_>>(),
                "{what}: signal sets differ"
            );
            for (k, v) in &ours {
                assert!(
                    same(theirs[k], *v),
                    "{what}: {k} = {} by cantools, {v} by us",
                    theirs[k]
                );
            }
            assert_eq!(
                dec["crc_ok"],
                json!(true),
                "{what}: cantools' E2E check fails our CRC"
            );
            // cantools' frame, our decoding.
            assert!(
                enc.get("error").is_none(),
                "{what}: cantools refused to encode: {enc}"
            );
            let text = enc["data"].as_str().unwrap();
            let data: Vec<u8> = (0..text.len() / 2)
                .map(|i| u8::from_str_radix(&text[2 * i..2 * i + 2], 16).unwrap())
                .collect();
            assert_eq!(data, f.data(), "{what}: cantools' bytes differ from ours");
            assert_eq!(
                Message::decode(Id::Standard(f.id()), &data),
                Ok((*a, *m)),
                "{what}"
            );
        }
        // Every message of the database was exercised.
        assert_eq!(
            names.len(),
            dbc::messages(format).len(),
            "{}",
            format.name()
        );
        eprintln!(
            "{}: {} frames checked both ways against cantools, {} messages",
            format.name(),
            cases.len(),
            names.len()
        );
    }
}

#[test]
fn values_outside_the_ranges_are_refused_by_both() {
    let Some(py) = python() else { return };
    let node = NodeId::new(3).unwrap();
    let id = |k: MessageKind| k.raw_id(node);
    let header = |extra: Value| {
        let mut v = json!({"Crc": 0, "Counter": 1});
        v.as_object_mut()
            .unwrap()
            .extend(extra.as_object().unwrap().clone());
        v
    };
    let part = |p: u8, x: f64| {
        let names = ContextPart::ALL[usize::from(p)].signal_names();
        header(json!({"Part": p, names[0]: x, names[1]: 0}))
    };
    let context = |name: &str, x: f64| {
        let mut v = json!({"Time": 0});
        for n in 0..5 {
            let o = v.as_object_mut().unwrap();
            o.insert(format!("Valid_{n}"), json!(1));
            for s in [
                "VelDesX", "VelDesY", "AccDesX", "AccDesY", "PosErrX", "PosErrY",
            ] {
                o.insert(format!("{s}_{n}"), json!(0));
            }
        }
        v[name] = json!(x);
        header(v)
    };
    let stream = |name: &str, x: f64| {
        let mut v = json!({});
        for e in 0..MAX_EVENTS {
            let o = v.as_object_mut().unwrap();
            for s in ["Evaluated", "Unjudgeable", "Level", "Conf"] {
                o.insert(format!("{s}{e}"), json!(0));
            }
        }
        v[name] = json!(x);
        header(v)
    };
    let health = |name: &str, x: f64| {
        let mut v = json!({"Page": 0, "ResetReason": 0, "Phase": 0, "PhaseSeq": 0});
        for f in FaultFlags::NAMES {
            v[f] = json!(0);
        }
        v[name] = json!(x);
        header(v)
    };
    let fd = vec![
        (
            MessageKind::Context.raw_id(node),
            context("VelDesX_2", -0.4096),
        ),
        (
            MessageKind::Context.raw_id(node),
            context("AccDesY_4", 8.192),
        ),
        (
            MessageKind::Context.raw_id(node),
            context("PosErrX_0", 0.032768),
        ),
        (id(MessageKind::Stream), stream("Level3", 3.0)),
        (id(MessageKind::Stream), stream("Conf7", 1.0000305)),
        (
            id(MessageKind::Phase),
            header(json!({"PhaseId": 8, "PhaseSeq": 0})),
        ),
        (
            id(MessageKind::Event),
            header(json!({"EventId": 8, "Level": 0, "Tick": 0, "OnsetAge": 0})),
        ),
        (id(MessageKind::Status), health("ResetReason", 9.0)),
        (id(MessageKind::Status), header(json!({"Page": 11}))),
        (
            id(MessageKind::Status),
            header(
                json!({"Page": 2, "TickRate": 0, "ProtocolVersion": 2, "BusFormat": 0, "NodeIdSource": 2}),
            ),
        ),
    ];
    let classic = vec![
        (id(MessageKind::ContextPart), part(0, 0.4096)),
        (id(MessageKind::ContextPart), part(2, -0.032768)),
        (id(MessageKind::ContextPart), header(json!({"Part": 3}))),
        (
            id(MessageKind::StreamPage),
            header(json!({"Sample": 0, "EventId": 2, "Unjudgeable2": 0, "Level2": 3, "Conf2": 0})),
        ),
    ];
    for (format, invalid) in [(BusFormat::Fd, fd), (BusFormat::Classic, classic)] {
        let request = json!({
            "dbc": dbc_path(format),
            "encode_invalid": invalid.iter().map(|(id, s)| json!({"id": id, "signals": s})).collect::<Vec<_>>(),
        });
        let answer = run_python(&py, &request);
        for ((id, s), res) in invalid
            .iter()
            .zip(answer["encode_invalid"].as_array().unwrap())
        {
            assert!(
                res.get("error").is_some(),
                "cantools encoded out-of-range values for 0x{id:03X} {s}: {res}"
            );
        }
    }
    // Our codec refuses the same values.
    let mut ctx = ContextMsg::default();
    ctx.slots[2] = Some(ContextSlot {
        vel_des: [-4096, 0],
        ..ContextSlot::default()
    });
    assert!(ctx.encode(ContextGroup::of(node)).is_err());
    let bad_part = ContextPartMsg {
        counter: Counter(1),
        part: ContextPart::PositionError,
        value: [-32768, 0],
    };
    assert!(bad_part.encode(node).is_err());
    let bad_phase = PhaseMsg {
        counter: Counter(1),
        phase: 8,
        sequence: 0,
    };
    assert!(bad_phase.encode(node).is_err());
    assert!(Confidence::from_bits(32769).is_none());
    assert!(ResetReason::from_raw(9).is_none());
}

#[test]
fn cantools_reads_the_databases_as_specified() {
    let Some(py) = python() else { return };
    for format in FORMATS {
        let answer = run_python(&py, &json!({"dbc": dbc_path(format)}));
        let messages = answer["messages"].as_array().expect("messages");
        let defs = dbc::messages(format);
        assert_eq!(messages.len(), defs.len());
        for msg in messages {
            let raw = msg["id"].as_u64().expect("id") as u16;
            let (kind, address) =
                MessageKind::from_raw_id(raw).expect("an identifier of the protocol");
            let def = defs
                .iter()
                .find(|d| d.raw_id() == raw)
                .expect("identifier in the table");
            let what = dbc::message_name(kind, address);
            assert_eq!(msg["name"], json!(what));
            assert_eq!(msg["length"], json!(kind.data_len()), "{what}");
            assert_eq!(msg["extended"], json!(false), "{what}");
            assert_eq!(msg["fd"], json!(format == BusFormat::Fd), "{what}");
            let sender = match (kind.direction(), address) {
                (fingertip_can::Direction::FromFingertip, Address::Node(n)) => {
                    format!("Fingertip{}", n.get())
                }
                _ => "Controller".to_string(),
            };
            assert_eq!(msg["senders"], json!([sender]), "{what}");
            assert_eq!(msg["cycle_time"], json!(def.cycle_ms), "{what}");
            let sigs = msg["signals"].as_array().expect("signals");
            assert_eq!(sigs.len(), def.signals.len(), "{what}");
            for d in &def.signals {
                let w = format!("{what}.{}", d.name);
                let s = sigs
                    .iter()
                    .find(|s| s["name"] == json!(d.name))
                    .unwrap_or_else(|| panic!("{w} missing"));
                assert_eq!(s["start"], json!(d.start), "{w}");
                assert_eq!(s["length"], json!(d.len), "{w}");
                assert_eq!(s["byte_order"], json!("little_endian"), "{w}");
                assert_eq!(s["signed"], json!(d.signed), "{w}");
                assert!(same(s["scale"].as_f64().unwrap(), d.factor_value()), "{w}");
                assert!(
                    same(s["minimum"].as_f64().unwrap(), d.min.parse().unwrap()),
                    "{w}"
                );
                assert!(
                    same(s["maximum"].as_f64().unwrap(), d.max.parse().unwrap()),
                    "{w}"
                );
                assert_eq!(s["unit"], json!(d.unit), "{w}");
                match d.mux {
                    Mux::Always => {
                        assert_eq!(s["is_multiplexer"], json!(false), "{w}");
                        assert!(s["multiplexer_ids"].is_null(), "{w}");
                    }
                    Mux::Selector => assert_eq!(s["is_multiplexer"], json!(true), "{w}"),
                    Mux::Page(p) => assert_eq!(s["multiplexer_ids"], json!([p]), "{w}"),
                }
                for (v, name) in &d.values {
                    assert_eq!(s["choices"][v.to_string()], json!(name), "{w}");
                }
            }
        }
    }
}
