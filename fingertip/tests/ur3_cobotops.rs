//! `scripts/ur3_cobotops.py`, the converter of the public UR3 CobotOps dataset, on a small
//! log written here in the dataset's own layout (`;` separated, decimal commas, ISO times,
//! a logged sample a second): its recordings read as traces, hold each logged sample until
//! the next, label each event once from its first flagged sample, and run through
//! `fingertip evaluate` with `configs/ur3_cobotops.toml`. Bad input is refused naming what
//! is wrong, with nothing written.
//!
//! The script needs `python3`. Without it the tests print a skip notice and pass, unless
//! `FINGERTIP_REQUIRE_PYTHON=1`, when they fail.

use fingertip::trace::Trace;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A fresh directory of its own for each call (tests run in parallel), removed with
/// everything in it when the returned guard is dropped.
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("fingertip-ur3-{name}-"))
        .tempdir()
        .expect("scratch dir")
}

fn python_available() -> bool {
    let ok = Command::new("python3")
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !ok {
        let msg = "no python3 on PATH to run scripts/ur3_cobotops.py";
        if std::env::var("FINGERTIP_REQUIRE_PYTHON").as_deref() == Ok("1") {
            panic!("FINGERTIP_REQUIRE_PYTHON=1 but {msg}");
        }
        eprintln!("SKIPPED: {msg}");
    }
    ok
}

fn convert(input: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new("python3")
        .arg(root().join("scripts/ur3_cobotops.py"))
        .arg(input)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("python3 runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// One logged row: seconds after 08:00:00 UTC, the program's cycle, the two flags, and
/// whether the robot's values are missing (as in 54 of the dataset's rows).
struct Logged {
    t: f64,
    cycle: u32,
    stop: bool,
    lost: bool,
    missing: bool,
}

/// The value of channel `k` (0-5 currents, 6-11 speeds, 12 the gripper) on row `i`.
fn value(i: usize, k: usize) -> f64 {
    match k {
        12 => 0.08 + 0.001 * i as f64,
        _ => (k as f64 + 1.0) * 0.25 - 0.01 * i as f64,
    }
}

/// The dataset's header and rows, `;` separated with decimal commas.
fn dataset(rows: &[Logged]) -> String {
    let mut out = String::from(
        "Num;Timestamp;Current_J0;Temperature_T0;Current_J1;Temperature_J1;Current_J2;\
         Temperature_J2;Current_J3;Temperature_J3;Current_J4;Temperature_J4;Current_J5;\
         Temperature_J5;Speed_J0;Speed_J1;Speed_J2;Speed_J3;Speed_J4;Speed_J5;Tool_current;\
         cycle ;Robot_ProtectiveStop;grip_lost;;;\n",
    );
    for (i, r) in rows.iter().enumerate() {
        let ms = (r.t * 1000.0).round() as u64;
        let stamp = format!(
            "2022-10-26T08:{:02}:{:02}.{:03}Z",
            ms / 60_000,
            ms / 1000 % 60,
            ms % 1000
        );
        let num = |x: f64| format!("{x}").replace('.', ",");
        let mut cells = vec![(i + 1).to_string(), stamp];
        for j in 0..6 {
            cells.push(if r.missing {
                String::new()
            } else {
                num(value(i, j))
            });
            cells.push(if r.missing {
                String::new()
            } else {
                "30,5".into()
            });
        }
        for k in 6..13 {
            cells.push(if r.missing {
                String::new()
            } else {
                num(value(i, k))
            });
        }
        cells.push(r.cycle.to_string());
        let flag = |b: bool| if b { "True" } else { "False" };
        cells.push(if r.missing {
            String::new()
        } else {
            flag(r.stop).into()
        });
        cells.push(flag(r.lost).into());
        out.push_str(&cells.join(";"));
        out.push_str(";;;\n");
    }
    out
}

/// Two sessions a minute apart: the first over three program cycles, with a protective
/// stop, a sample the logger dropped, a row without robot values and a lost grip; the
/// second with another protective stop.
fn log() -> Vec<Logged> {
    let mut rows = Vec::new();
    let mut t = 0.0;
    for i in 0..16 {
        let cycle = match i {
            0..=3 => 1,
            4..=7 => 2,
            8..=11 => 3,
            _ => 4,
        };
        rows.push(Logged {
            t,
            cycle,
            stop: matches!(i, 2 | 3 | 14),
            lost: matches!(i, 9 | 10),
            missing: i == 8,
        });
        t += match i {
            6 => 2.010, // a dropped sample
            11 => 60.0, // the logging paused
            _ => 1.005,
        };
    }
    rows
}

/// Every event of a trace as (label, first row, last row).
fn events(trace: &Trace) -> Vec<(String, usize, usize)> {
    let truth = trace.truth().expect("a truth column");
    let mut out: Vec<(String, usize, usize)> = Vec::new();
    for row in 0..trace.len() {
        let label = truth.get(row).expect("a label per row");
        if label.is_empty() {
            continue;
        }
        match out.last_mut() {
            Some((name, _, last)) if name == label && *last + 1 == row => *last = row,
            _ => out.push((label.to_string(), row, row)),
        }
    }
    out
}

#[test]
fn the_converted_log_reads_as_traces_and_evaluates() {
    if !python_available() {
        return;
    }
    let tmp = scratch("convert");
    let dir = tmp.path();
    let input = dir.join("dataset.csv");
    std::fs::write(&input, dataset(&log())).expect("write the log");
    let out = dir.join("traces");
    let run = convert(&input, &out, &["--cycles", "2"]);
    assert!(run.status.success(), "{}", text(&run.stderr));
    assert!(
        text(&run.stdout).contains("3 recordings")
            && text(&run.stdout).contains("protective_stop 2, grip_lost 1"),
        "{}",
        text(&run.stdout)
    );

    // The first session is cut where its third cycle starts (two cycles a recording), the
    // second session is a recording of its own.
    let read = |n: u32| {
        Trace::read(out.join(format!("ur3_cobotops_{n:02}.csv"))).unwrap_or_else(|e| panic!("{e}"))
    };
    let (first, second, third) = (read(1), read(2), read(3));
    assert!(!out.join("ur3_cobotops_04.csv").exists());
    let channels: Vec<String> = (0..6)
        .map(|j| format!("current_j{j}"))
        .chain((0..6).map(|j| format!("speed_j{j}")))
        .chain(["tool_current".to_string()])
        .collect();
    for trace in [&first, &second, &third] {
        assert!((trace.rate_hz() - 10.0).abs() < 1e-6, "{}", trace.rate_hz());
        assert_eq!(trace.channel_names(), channels.as_slice());
        assert!(
            trace
                .meta("licence")
                .expect("licence")
                .contains("CC BY 4.0")
        );
        assert_eq!(trace.meta("unit.speed_j3"), Some("rad/s"));
    }

    // Rows 0-7, logged at 0 to 8.04 s, held on ticks of 0.1 s until the last has arrived.
    assert_eq!(first.len(), 82);
    let held =
        |trace: &Trace, tick: usize, k: usize| trace.column(&channels[k]).expect("column")[tick];
    // Row 2 (2.01 s) is first seen on the tick at 2.1 s and held until row 4 arrives.
    assert_eq!(held(&first, 20, 1), value(1, 1));
    assert_eq!(held(&first, 21, 1), value(2, 1));
    assert_eq!(held(&first, 40, 7), value(3, 7));
    assert_eq!(
        events(&first),
        vec![("protective_stop".to_string(), 21, 40)]
    );
    // The dropped sample: row 6 (6.03 s) held for two seconds, until row 7 (8.04 s).
    assert_eq!(held(&first, 80, 12), value(6, 12));
    assert_eq!(held(&first, 81, 12), value(7, 12));

    // Row 8 has no robot values: it holds row 7's. The lost grip (rows 9-10, from 1.005 s
    // into the recording) is one event.
    assert_eq!(held(&second, 0, 4), value(7, 4));
    assert_eq!(held(&second, 10, 4), value(7, 4));
    assert_eq!(held(&second, 11, 4), value(9, 4));
    assert_eq!(events(&second), vec![("grip_lost".to_string(), 11, 30)]);
    assert_eq!(
        events(&third),
        vec![("protective_stop".to_string(), 21, 30)]
    );

    // The hand-written configuration reads these channels and names these events.
    let json = dir.join("report.json");
    let config = root().join("configs/ur3_cobotops.toml");
    let eval = Command::new(env!("CARGO_BIN_EXE_fingertip"))
        .args(["evaluate", "--traces"])
        .arg(&out)
        .arg("--config")
        .arg(&config)
        .args(["--after-ms", "1000", "--json"])
        .arg(&json)
        .output()
        .expect("fingertip runs");
    assert!(eval.status.success(), "{}", text(&eval.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    assert_eq!(report["recordings"], 3);
    let runs = |name: &str| {
        report["events"]
            .as_array()
            .expect("events")
            .iter()
            .find(|e| e["name"] == name)
            .map(|e| e["runs"].clone())
    };
    assert_eq!(runs("protective_stop"), Some(2.into()));
    assert_eq!(runs("grip_lost"), Some(1.into()));
}

/// Converts `text_in` and expects a refusal whose message holds `expected`.
fn refused(dir: &Path, name: &str, text_in: &str, out: &Path, expected: &str) {
    let input = dir.join(name);
    std::fs::write(&input, text_in).expect("write the input");
    let run = convert(&input, out, &[]);
    assert!(!run.status.success(), "{name} accepted");
    assert!(
        text(&run.stderr).contains(expected),
        "{name}: {}",
        text(&run.stderr)
    );
}

#[test]
fn bad_input_is_refused_naming_it_and_nothing_is_written() {
    if !python_available() {
        return;
    }
    let tmp = scratch("bad");
    let dir = tmp.path();
    let good = dataset(&log());
    let out = dir.join("out");

    let no_flag = good.replacen(";grip_lost", ";grip", 1);
    refused(dir, "no_flag.csv", &no_flag, &out, "no column `grip_lost`");
    assert!(!out.exists(), "nothing written");

    // A number that is not one, named by its line and column.
    let bad_number: Vec<String> = good
        .lines()
        .enumerate()
        .map(|(n, l)| {
            let mut cells: Vec<&str> = l.split(';').collect();
            if n == 5 {
                cells[20] = "0,0x8"; // Tool_current
            }
            cells.join(";")
        })
        .collect();
    let expected = "line 6, column `Tool_current`: `0.0x8` is not a number";
    refused(
        dir,
        "bad_number.csv",
        &bad_number.join("\n"),
        &out,
        expected,
    );
    assert!(!out.exists(), "nothing written");

    let mut backwards: Vec<&str> = good.lines().collect();
    backwards.swap(3, 4);
    let expected = "line 5, column `Timestamp`: time does not increase";
    refused(dir, "backwards.csv", &backwards.join("\n"), &out, expected);
    assert!(!out.exists(), "nothing written");

    // An output directory holding something already is left as it is.
    std::fs::create_dir_all(&out).expect("mkdir");
    std::fs::write(out.join("keep.csv"), "t,x\n0,1\n").expect("write");
    refused(dir, "good.csv", &good, &out, "not an empty directory");
    let left: Vec<_> = std::fs::read_dir(&out).expect("dir").collect();
    assert_eq!(left.len(), 1, "only what was there");
}
