//! The DBC is the contract: the published `fingertip-can/fingertip.dbc` and the codec in
//! `fingertip_can` must agree, as judged by a third-party decoder (cantools, run from
//! the venv at `.venv`, driven by `fingertip-can/python/dbc_check.py`).
//!
//! - Frames our codec encodes, cantools decodes to the same values, and its AUTOSAR E2E
//!   profile 2 check accepts their CRC.
//! - Values cantools encodes from the DBC (CRC applied by cantools), our codec decodes to
//!   the same values, byte for byte the frames it would send itself.
//! - Values just outside each range are refused by both.
//! - cantools reads the database as the specification table says.
//!
//! Every message kind, every node, and the extremes of every range. Without the venv the
//! cantools tests print a skip notice and pass, unless `FINGERTIP_REQUIRE_PYTHON=1`, when
//! they fail. `FINGERTIP_BLESS=1` rewrites the committed DBC from the specification.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use detector_core::{Confidence, EventId, Level};
use fingertip::can_tools::dbc::{self, Mux};
use fingertip_can::{
    CanFrame, ConfidenceMsg, ContextMsg, Counter, EventMsg, FaultFlags, Id, Message, MessageKind,
    NodeId, PhaseMsg, ResetReason, StatusPage, TipStateMsg,
};
use serde_json::{Value, json};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn dbc_path() -> PathBuf {
    root().join("fingertip-can/fingertip.dbc")
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

fn c(n: u8) -> Counter {
    Counter::new(n).unwrap()
}

fn conf(bits: u16) -> Confidence {
    Confidence::from_bits(bits).unwrap()
}

/// Messages covering every kind, page, flag and the ends of every range.
fn samples() -> Vec<Message> {
    let mut v = Vec::new();
    for (i, (e, level, cb, tick, age)) in [
        (0u8, Level::Alert, 0u16, 0u16, 0u16),
        (7, Level::Confirm, 32768, 65535, 65535),
        (3, Level::Confirm, 1, 1, 1),
        (5, Level::Alert, 32767, 40000, 123),
    ]
    .into_iter()
    .enumerate()
    {
        v.push(Message::Event(EventMsg {
            counter: c([0, 15, 7, 1][i]),
            event: EventId(e),
            level,
            confidence: conf(cb),
            tick,
            onset_age: age,
        }));
    }
    for (ctr, phase, seq) in [(0, 0, 0), (15, 7, 255), (4, 3, 128)] {
        v.push(Message::Phase(PhaseMsg {
            counter: c(ctr),
            phase,
            sequence: seq,
        }));
    }
    for (ctr, vel, acc) in [
        (0, [0, 0], [0, 0]),
        (15, [4095, -4095], [-4095, 4095]),
        (6, [-4095, 4095], [4095, -4095]),
        (9, [1, -1], [-1, 1]),
        (3, [500, -200], [1234, -2048]),
    ] {
        v.push(Message::Context(ContextMsg {
            counter: c(ctr),
            vel_des: vel,
            acc_des: acc,
        }));
    }
    for (ctr, p) in [
        (0, [0, 0]),
        (15, [32767, -32767]),
        (8, [-32767, 32767]),
        (2, [1, -1]),
    ] {
        v.push(Message::TipState(TipStateMsg {
            counter: c(ctr),
            pos_err: p,
        }));
    }
    for page in 0..3u8 {
        let full = if page == 2 { 0b011 } else { 0b111 };
        let last = if page == 2 { 0 } else { 32767 };
        v.push(Message::Confidence(ConfidenceMsg {
            seq: 255,
            page,
            evaluated: full,
            unjudgeable: full,
            confidences: [conf(32768), conf(1), conf(last)],
        }));
        v.push(Message::Confidence(ConfidenceMsg {
            seq: 0,
            page,
            evaluated: 0b001,
            unjudgeable: 0,
            confidences: [conf(0), conf(0), conf(0)],
        }));
    }
    for reset in ResetReason::ALL {
        v.push(Message::Status(StatusPage::Health {
            reset,
            faults: FaultFlags(1 << (reset as u8 % 8)),
            uptime: u32::from(reset as u8) * 1_000_003,
            phase: Some(reset as u8 % 8),
            phase_seq: reset as u8,
        }));
    }
    v.push(Message::Status(StatusPage::Health {
        reset: ResetReason::Unknown,
        faults: FaultFlags(0xFF),
        uptime: u32::MAX,
        phase: None,
        phase_seq: 255,
    }));
    for x in [0u16, u16::MAX] {
        v.extend([
            Message::Status(StatusPage::Timing {
                overruns: x,
                worst_tick: x,
                tick_rate_hz: x,
                protocol: x as u8,
            }),
            Message::Status(StatusPage::Link {
                stale_episodes: x,
                lost_frames: x,
                bus_errors: x,
            }),
            Message::Status(StatusPage::FrameRejects {
                wrong_length: x,
                unknown_id: x,
                bad_crc: x,
            }),
            Message::Status(StatusPage::ContentRejects {
                sequence: x,
                phase_not_configured: x,
                out_of_range: x,
            }),
            Message::Status(StatusPage::Config {
                checksum: u32::from(x) * 65537,
                tx_dropped: x,
            }),
        ]);
    }
    v.push(Message::Status(StatusPage::Timing {
        overruns: 1,
        worst_tick: 1234,
        tick_rate_hz: 5000,
        protocol: fingertip_can::PROTOCOL_VERSION,
    }));
    v
}

/// Each sample on three nodes in turn, plus one sample of each kind on every node, so every
/// message of the database is exercised.
fn cases() -> Vec<(NodeId, Message, CanFrame)> {
    let samples = samples();
    let mut out = Vec::new();
    for (i, m) in samples.iter().enumerate() {
        for n in [0u8, 7, 15] {
            let node = NodeId::new((n + i as u8) % 16).unwrap();
            out.push((node, *m, m.encode(node).expect("sample encodes")));
        }
    }
    for kind in MessageKind::ALL {
        let m = samples
            .iter()
            .find(|m| m.kind() == kind)
            .expect("kind sampled");
        for n in 0..16 {
            let node = NodeId::new(n).unwrap();
            out.push((node, *m, m.encode(node).unwrap()));
        }
    }
    out
}

fn hex(d: &[u8]) -> String {
    d.iter().map(|b| format!("{b:02x}")).collect()
}

fn signal_map(m: &Message, f: &CanFrame) -> BTreeMap<String, f64> {
    dbc::signal_values(m, f.data().first().copied().unwrap_or(0))
        .into_iter()
        .collect()
}

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs().max(1.0)
}

#[test]
fn committed_dbc_is_the_rendered_specification() {
    let text = dbc::render();
    if std::env::var("FINGERTIP_BLESS").as_deref() == Ok("1") {
        std::fs::write(dbc_path(), &text).expect("write the DBC");
    }
    let committed =
        std::fs::read_to_string(dbc_path()).expect("fingertip-can/fingertip.dbc exists");
    assert!(
        committed == text,
        "fingertip-can/fingertip.dbc differs from can_tools::dbc::render(); regenerate with FINGERTIP_BLESS=1 cargo test -p fingertip --test can_dbc"
    );
}

#[test]
fn codec_and_cantools_agree_both_ways() {
    let Some(py) = python() else { return };
    let cases = cases();
    let request = json!({
        "dbc": dbc_path(),
        "decode": cases.iter().map(|(_, _, f)| json!({
            "id": f.id().as_raw(), "data": hex(f.data())
        })).collect::<Vec<_>>(),
        "encode": cases.iter().map(|(_, m, f)| json!({
            "id": f.id().as_raw(), "signals": signal_map(m, f)
        })).collect::<Vec<_>>(),
    });
    let answer = run_python(&py, &request);
    let decoded = answer["decoded"].as_array().expect("decoded");
    let encoded = answer["encoded"].as_array().expect("encoded");
    assert_eq!(decoded.len(), cases.len());
    assert_eq!(encoded.len(), cases.len());
    let mut names = std::collections::BTreeSet::new();
    for ((node, m, f), (dec, enc)) in cases.iter().zip(decoded.iter().zip(encoded)) {
        let what = format!("{m:?} on node {}", node.get());
        // Our frame, cantools' decoding.
        assert!(dec.get("error").is_none(), "{what}: {dec}");
        assert_eq!(
            dec["name"].as_str(),
            Some(dbc::message_name(m.kind(), *node).as_str()),
            "{what}"
        );
        names.insert(dec["name"].as_str().unwrap_or("").to_string());
        let theirs: BTreeMap<String, f64> = dec["signals"]
            .as_object()
            .expect("signals")
            .iter()
            .map(|(k, v)| (k.clone(), v.as_f64().expect("number")))
            .collect();
        let ours = signal_map(m, f);
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
        if m.kind().is_protected() {
            assert_eq!(
                dec["crc_ok"],
                json!(true),
                "{what}: cantools' E2E check fails our CRC"
            );
        } else {
            assert!(dec["crc_ok"].is_null());
        }
        // cantools' frame, our decoding.
        assert!(
            enc.get("error").is_none(),
            "{what}: cantools refused to encode: {enc}"
        );
        let data: Vec<u8> = (0..enc["data"].as_str().unwrap().len() / 2)
            .map(|i| {
                u8::from_str_radix(&enc["data"].as_str().unwrap()[2 * i..2 * i + 2], 16).unwrap()
            })
            .collect();
        assert_eq!(data, f.data(), "{what}: cantools' bytes differ from ours");
        let back = Message::decode(Id::Standard(f.id()), &data);
        assert_eq!(back, Ok((*node, *m)), "{what}");
    }
    // Every message of the database was exercised.
    assert_eq!(names.len(), 6 * 16);
    eprintln!(
        "{} frames checked both ways against cantools, {} messages",
        cases.len(),
        names.len()
    );
}

#[test]
fn values_outside_the_ranges_are_refused_by_both() {
    let Some(py) = python() else { return };
    let node = NodeId::new(3).unwrap();
    let id = |k: MessageKind| k.raw_id(node);
    // (message, signals with one value out of range, our codec's raw counterpart)
    let context = |x: f64| json!({"Crc": 0, "Counter": 1, "VelDesX": x, "VelDesY": 0, "AccDesX": 0, "AccDesY": 0});
    let invalid = vec![
        (id(MessageKind::Context), context(-0.4096)),
        (id(MessageKind::Context), context(0.4096)),
        (
            id(MessageKind::Context),
            json!({"Crc": 0, "Counter": 1, "VelDesX": 0, "VelDesY": 0, "AccDesX": 8.192, "AccDesY": 0}),
        ),
        (
            id(MessageKind::TipState),
            json!({"Crc": 0, "Counter": 1, "PosErrX": -0.032768, "PosErrY": 0}),
        ),
        (
            id(MessageKind::Phase),
            json!({"Crc": 0, "Counter": 1, "PhaseId": 8, "PhaseSeq": 0}),
        ),
        (
            id(MessageKind::Event),
            json!({"Crc": 0, "Counter": 1, "EventId": 0, "Level": 0, "Confidence": 1.0000305, "Tick": 0, "OnsetAge": 0}),
        ),
        (id(MessageKind::Confidence), json!({"Seq": 0, "Page": 3})),
        (
            id(MessageKind::Status),
            json!({"Page": 0, "ResetReason": 9, "FaultContextStale": 0, "FaultTipStateStale": 0, "FaultPhaseStale": 0, "FaultOverrun": 0, "FaultBusError": 0, "FaultTxDropped": 0, "FaultConfigFallback": 0, "FaultSensor": 0, "Uptime": 0, "Phase": 0, "PhaseSeq": 0}),
        ),
        (id(MessageKind::Status), json!({"Page": 6})),
    ];
    let request = json!({
        "dbc": dbc_path(),
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
    // Our codec refuses the same values.
    assert!(
        ContextMsg {
            counter: c(1),
            vel_des: [-4096, 0],
            acc_des: [0, 0]
        }
        .encode(node)
        .is_err()
    );
    assert!(
        TipStateMsg {
            counter: c(1),
            pos_err: [-32768, 0]
        }
        .encode(node)
        .is_err()
    );
    assert!(
        PhaseMsg {
            counter: c(1),
            phase: 8,
            sequence: 0
        }
        .encode(node)
        .is_err()
    );
    assert!(Confidence::from_bits(32769).is_none());
    assert!(ResetReason::from_raw(9).is_none());
    let status_page6 = [6u8, 0, 0, 0, 0, 0, 0, 0];
    assert!(Message::decode(Id::Standard(MessageKind::Status.id(node)), &status_page6).is_err());
    let stream_page3 = [0u8, 3, 0, 0, 0, 0, 0, 0];
    assert!(
        Message::decode(
            Id::Standard(MessageKind::Confidence.id(node)),
            &stream_page3
        )
        .is_err()
    );
}

#[test]
fn cantools_reads_the_database_as_specified() {
    let Some(py) = python() else { return };
    let answer = run_python(&py, &json!({"dbc": dbc_path()}));
    let messages = answer["messages"].as_array().expect("messages");
    assert_eq!(messages.len(), 6 * 16);
    let defs = dbc::messages();
    for msg in messages {
        let raw = msg["id"].as_u64().expect("id") as u16;
        let (kind, node) = MessageKind::from_raw_id(raw).expect("an identifier of the protocol");
        let def = defs
            .iter()
            .find(|d| d.kind == kind)
            .expect("kind in the table");
        let what = dbc::message_name(kind, node);
        assert_eq!(msg["name"], json!(what));
        assert_eq!(msg["length"], json!(kind.dlc()), "{what}");
        assert_eq!(msg["extended"], json!(false), "{what}");
        let sender = match kind.direction() {
            fingertip_can::Direction::FromFingertip => format!("Fingertip{}", node.get()),
            fingertip_can::Direction::ToFingertip => "Controller".to_string(),
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
