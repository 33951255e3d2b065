//! The `fingertip` command end to end: the Table 1 reproduction, the JSON outputs, the CAN
//! log round trip, and bad input rejected with one clear line and no output file.

use fingertip::sim::Scenario;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fingertip(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fingertip"))
        .args(args)
        .output()
        .expect("the fingertip binary runs")
}

/// A fresh directory of its own for each call (tests run in parallel), removed with
/// everything in it when the returned guard is dropped.
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("fingertip-cli-{name}-"))
        .tempdir()
        .expect("scratch dir")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn simulate(dir: &Path, scenario: &str) -> PathBuf {
    let path = dir.join(format!("{scenario}.csv"));
    let out = fingertip(&[
        "simulate",
        scenario,
        "--out",
        path.to_str().expect("utf-8 path"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    path
}

/// The first failure line of an `evaluate` report, and the trace `simulate` writes for the
/// run it names, given the options the line gives (`NAME --seed SEED [OPTION VALUE]...:`).
fn rerun_first_failure(stdout: &str, dir: &Path) -> (String, String) {
    let line = stdout
        .lines()
        .find(|l| l.starts_with("  ") && l.contains(" --seed "))
        .expect("a failure line");
    let (run, _) = line.split_once(':').expect("the outcome after a colon");
    let words: Vec<&str> = run.split_whitespace().collect();
    let trace = dir.join("run.csv");
    let mut args = vec!["simulate", words[0], "--randomize"];
    args.extend(&words[1..]);
    args.extend(["--out", trace.to_str().expect("utf-8")]);
    let sim = fingertip(&args);
    assert!(sim.status.success(), "{}", text(&sim.stderr));
    (
        line.to_string(),
        std::fs::read_to_string(&trace).expect("trace"),
    )
}

/// Every nominal Table 1 run confirms its expected event first (and the sudden
/// accelerations nothing), within the paper's 20 ms.
#[test]
fn nominal_table1_runs_detect_the_right_event() {
    let tmp = scratch("table1");
    let dir = tmp.path();
    let list = text(&fingertip(&["scenarios"]).stdout);
    let runs: Vec<(String, String)> = list
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            Some((w.next()?.to_string(), w.next()?.to_string()))
        })
        .filter(|(name, _)| name != "free_motion")
        .collect();
    assert_eq!(runs.len(), Scenario::single_event().len(), "{list}");
    // The list starts with the 13 Table 1 runs.
    let table1: Vec<&str> = Scenario::table1().iter().map(|s| s.name()).collect();
    let runs: Vec<(String, String)> = runs.into_iter().take(table1.len()).collect();
    assert_eq!(
        runs.iter().map(|r| r.0.as_str()).collect::<Vec<_>>(),
        table1
    );
    for (scenario, expected) in runs {
        let trace = simulate(dir, &scenario);
        let out = fingertip(&["replay", trace.to_str().expect("utf-8"), "--json"]);
        assert!(out.status.success(), "{scenario}: {}", text(&out.stderr));
        let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
        let confirms: Vec<&serde_json::Value> = report["events"]
            .as_array()
            .expect("events")
            .iter()
            .filter(|e| e["level"] == "confirm")
            .collect();
        if expected == "none" {
            assert!(confirms.is_empty(), "{scenario}: {confirms:?}");
            continue;
        }
        let first = confirms
            .first()
            .unwrap_or_else(|| panic!("{scenario}: nothing confirmed"));
        assert_eq!(first["event"], expected.as_str(), "{scenario}");
        let onset = report["truth"]["onset_s"].as_f64().expect("truth onset");
        let t = first["t_s"].as_f64().expect("t_s");
        assert!(first["onset_s"].as_f64().expect("onset_s") <= t);
        assert!(
            t >= onset && t - onset <= 0.020,
            "{scenario}: confirmed {:.1} ms after onset",
            (t - onset) * 1e3
        );
    }
}

#[test]
fn evaluate_writes_the_documented_report() {
    let tmp = scratch("evaluate");
    let dir = tmp.path();
    let json = dir.join("report.json");
    let figure = dir.join("bins.png");
    let out = fingertip(&[
        "evaluate",
        "--runs",
        "2",
        "--free-hours",
        "0.005",
        "--json",
        json.to_str().expect("utf-8"),
        "--plot-bins",
        figure.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("false alarms"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    let scenarios = report["scenarios"].as_array().expect("scenarios");
    assert_eq!(scenarios.len(), Scenario::single_event().len());
    for s in scenarios {
        for key in [
            "name", "expected", "runs", "correct", "wrong", "missed", "repeated",
        ] {
            assert!(!s[key].is_null(), "{key} missing in {s}");
        }
        for key in ["median", "p95", "p99", "max"] {
            assert!(
                s["latency_ms"][key].is_number(),
                "latency_ms.{key} missing in {s}"
            );
        }
        assert_eq!(s["runs"], 2);
        // Per bin of the parameter that matters most: every run in one bin, tallied alike.
        assert!(
            s["binned_by"].as_str().is_some_and(|b| !b.is_empty()),
            "{s}"
        );
        let bins = s["bins"].as_array().expect("bins");
        assert!(bins.len() >= 2, "{s}");
        let sum = |key: &str| {
            bins.iter()
                .map(|b| b[key].as_u64().expect(key))
                .sum::<u64>()
        };
        for key in ["runs", "correct", "wrong", "missed", "repeated"] {
            assert_eq!(sum(key), s[key].as_u64().expect(key), "{key} in {s}");
        }
        let first = bins[0]["name"].as_str().expect("bin name");
        assert!(
            stdout.contains(&format!("  {first} ")),
            "{first} in {stdout}"
        );
    }
    let png = std::fs::read(&figure).expect("the figure is written");
    assert!(png.starts_with(b"\x89PNG"), "a PNG");
    assert!(report["false_alarms_per_hour"].is_number());
    assert!(report["free_motion_hours"].as_f64().expect("hours") >= 0.005);
}

/// `--config` twice compares detectors on the very same runs: the same configuration given
/// twice tallies identically, and the paper's reference sits beside it in one report; a
/// fifth configuration is refused before any run.
#[test]
fn evaluate_compares_configurations_on_the_same_runs() {
    let tmp = scratch("compare");
    let dir = tmp.path();
    let json = dir.join("compare.json");
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");
    let approach = format!("{root}approach.toml");
    let paper = format!("{root}paper.toml");
    fn args<'a>(configs: &[&'a str]) -> Vec<&'a str> {
        let mut a = vec!["evaluate", "--runs", "3", "--free-hours", "0.005"];
        for c in configs {
            a.extend(["--config", c]);
        }
        a
    }
    let mut with_json = args(&[&approach, &paper, &approach]);
    with_json.extend(["--json", json.to_str().expect("utf-8")]);
    let out = fingertip(&with_json);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("[2] ") && stdout.contains("paper.toml"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    let configs = report["configs"].as_array().expect("configs");
    assert_eq!(configs.len(), 3);
    assert_eq!(configs[0]["scenarios"], configs[2]["scenarios"]);
    assert!(
        configs[1]["config"]
            .as_str()
            .expect("name")
            .ends_with("paper.toml")
    );
    for c in configs {
        assert_eq!(
            c["scenarios"].as_array().expect("scenarios").len(),
            Scenario::single_event().len()
        );
    }
    let five = fingertip(&args(&[&approach, &approach, &approach, &approach, &paper]));
    assert!(!five.status.success());
    assert!(
        text(&five.stderr).contains("at most 4"),
        "{}",
        text(&five.stderr)
    );
}

/// One line of a CSV file's fields, a quoted field's doubled quotes read as one.
fn csv_fields(line: &str) -> Vec<String> {
    let (mut fields, mut field, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(std::mem::take(&mut field)),
            _ => field.push(c),
        }
    }
    fields.push(field);
    fields
}

/// `--runs-csv` writes one row per run, which tallies per scenario as the report does for
/// each detector, and whose seed and drawn parameters are those `simulate` draws again.
#[test]
fn evaluate_writes_one_row_per_run() {
    let tmp = scratch("runs-csv");
    let dir = tmp.path();
    let json = dir.join("report.json");
    let table = dir.join("runs.csv");
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/");
    let (approach, paper) = (format!("{root}approach.toml"), format!("{root}paper.toml"));
    let out = fingertip(&[
        "evaluate",
        "--runs",
        "3",
        "--free-hours",
        "0.005",
        "--config",
        &approach,
        "--config",
        &paper,
        "--json",
        json.to_str().expect("utf-8"),
        "--runs-csv",
        table.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    let written = std::fs::read_to_string(&table).expect("the table is written");
    // Some bins' labels hold a comma (`link1, < 50 %`), quoted; no field holds a line break.
    assert!(written.contains("\"link1, "), "quoted labels in {written}");
    let mut lines = written.lines().map(csv_fields);
    let header = lines.next().expect("a header");
    let rows: Vec<Vec<String>> = lines.collect();
    assert!(rows.iter().all(|r| r.len() == header.len()));
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let singles = Scenario::single_event().len() * 3;
    assert_eq!(
        rows[..singles]
            .iter()
            .filter(|r| r[0] != "free_motion")
            .count(),
        singles
    );
    assert!(rows[singles..].iter().all(|r| r[0] == "free_motion"));
    assert!(rows.len() > singles, "free-motion runs have rows too");
    for d in 0..2 {
        let suffix = format!("_{}", d + 1);
        let (outcome, latency) = (
            col(&format!("outcome{suffix}")),
            col(&format!("latency_ms{suffix}")),
        );
        let tallied = &report["configs"][d];
        for s in tallied["scenarios"].as_array().expect("scenarios") {
            let name = s["name"].as_str().expect("name");
            // A run where nothing is expected is right when quiet.
            let count = |o: &[&str]| {
                rows.iter()
                    .filter(|r| r[0] == name && o.contains(&r[outcome].as_str()))
                    .count() as u64
            };
            for (o, key) in [
                (&["right", "quiet"][..], "correct"),
                (&["wrong"], "wrong"),
                (&["missed"], "missed"),
                (&["repeated"], "repeated"),
            ] {
                assert_eq!(
                    count(o),
                    s[key].as_u64().expect(key),
                    "{name} {key}, detector {d}"
                );
            }
        }
        let alarms = rows[singles..]
            .iter()
            .filter(|r| r[outcome] == "wrong")
            .count() as u64;
        assert_eq!(
            alarms,
            tallied["false_alarms"].as_u64().expect("false alarms")
        );
        for r in &rows {
            let timed = matches!(r[outcome].as_str(), "right" | "repeated");
            assert_eq!(r[latency].parse::<f64>().is_ok(), timed, "{r:?}");
        }
    }
    // A row's seed simulates the run it describes: the same parameters are drawn again.
    let param = col("param.plant.control_bandwidth");
    let row = &rows[singles - 1];
    let trace = dir.join("again.csv");
    let sim = fingertip(&[
        "simulate",
        &row[0],
        "--randomize",
        "--seed",
        &row[col("seed")],
        "--out",
        trace.to_str().expect("utf-8"),
    ]);
    assert!(sim.status.success(), "{}", text(&sim.stderr));
    let again = std::fs::read_to_string(&trace).expect("trace");
    let line = format!("# param.plant.control_bandwidth: {}", row[param]);
    assert!(
        again.lines().any(|l| l == line),
        "{line} not in the simulated run"
    );
}

/// `identify` finds, in simulated free motion, the fingertip's inertia on the force sensor:
/// a gain of about minus its mass (20-45 g plus the skin) in the approach configuration's
/// units (cN per m/s^2, i.e. tens of grams), printed as a `cancel` stage ready to paste; a
/// channel the trace does not have is named.
#[test]
fn identify_finds_the_fingertip_inertia_in_free_motion() {
    let tmp = scratch("identify");
    let dir = tmp.path();
    let trace = dir.join("free.csv");
    let out = fingertip(&[
        "simulate",
        "free_motion",
        "--duration",
        "5",
        "--out",
        trace.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let path = trace.to_str().expect("utf-8");
    let out = fingertip(&[
        "identify",
        path,
        "--input",
        "force_x",
        "--motion",
        "acc_des_x",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let gain: f64 = stdout
        .split("gain = ")
        .nth(1)
        .and_then(|rest| rest.split(',').next())
        .and_then(|g| g.trim().parse().ok())
        .unwrap_or_else(|| panic!("no cancel stage in {stdout}"));
    assert!((-6.0..=-2.0).contains(&gain), "gain {gain} in {stdout}");
    assert!(
        stdout.contains("input = \"force_x\", motion = \"acc_des_x\""),
        "{stdout}"
    );
    let bad = fingertip(&[
        "identify",
        path,
        "--input",
        "force_z",
        "--motion",
        "acc_des_x",
    ]);
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("force_z"),
        "{}",
        text(&bad.stderr)
    );
}

/// No output may destroy an input or another output, and a bad output is found before any
/// work, with nothing written: each case of the class, for every command with outputs.
#[test]
fn outputs_never_destroy_inputs_and_are_all_or_none() {
    let tmp = scratch("outputs");
    let dir = tmp.path();
    let trace = simulate(dir, "contact_hard_8");
    let original = std::fs::read(&trace).expect("trace");
    let t = trace.to_str().expect("utf-8");
    let d = |name: &str| dir.join(name).to_str().expect("utf-8").to_owned();
    let link = dir.join("link.csv");
    std::os::unix::fs::symlink(&trace, &link).expect("symlink");
    let spelled = format!("{}/./contact_hard_8.csv", dir.display());
    let config = format!("{}/../configs/approach.toml", env!("CARGO_MANIFEST_DIR"));
    let config_before = std::fs::read(&config).expect("config");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["replay".into(), t.into(), "--out".into(), t.into()],
            "input",
        ),
        (
            vec!["replay".into(), t.into(), "--candump".into(), t.into()],
            "input",
        ),
        (
            vec!["replay".into(), t.into(), "--out".into(), spelled.clone()],
            "input",
        ),
        (
            vec![
                "replay".into(),
                t.into(),
                "--out".into(),
                link.to_str().expect("utf-8").into(),
            ],
            "input",
        ),
        (
            vec![
                "replay".into(),
                t.into(),
                "--config".into(),
                config.clone(),
                "--out".into(),
                config.clone(),
            ],
            "input",
        ),
        (
            vec![
                "replay".into(),
                t.into(),
                "--out".into(),
                d("a.csv"),
                "--candump".into(),
                d("a.csv"),
            ],
            "two outputs",
        ),
        (
            vec![
                "replay".into(),
                t.into(),
                "--out".into(),
                d("b.csv"),
                "--plot".into(),
                d("b.jpg"),
            ],
            ".png or .svg",
        ),
        (
            vec![
                "replay".into(),
                t.into(),
                "--out".into(),
                d("c.csv"),
                "--plot".into(),
                d("none/c.png"),
            ],
            "does not exist",
        ),
        (
            vec![
                "simulate".into(),
                "contact_hard_8".into(),
                "--out".into(),
                d(""),
            ],
            "directory",
        ),
        (
            vec![
                "evaluate".into(),
                "--runs".into(),
                "1".into(),
                "--config".into(),
                config.clone(),
                "--json".into(),
                config.clone(),
            ],
            "input",
        ),
    ];
    for (args, words) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let out = fingertip(&args);
        let err = text(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(err.contains(words), "{args:?}: {err}");
    }
    assert_eq!(
        std::fs::read(&trace).expect("trace"),
        original,
        "the input is intact"
    );
    assert_eq!(std::fs::read(&config).expect("config"), config_before);
    let mut left: Vec<String> = std::fs::read_dir(dir)
        .expect("dir")
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(
        left,
        ["contact_hard_8.csv", "link.csv"],
        "nothing else written"
    );
    // Outputs written together; a special file is written through and stays what it is.
    let out = fingertip(&[
        "replay",
        t,
        "--out",
        &d("conf.csv"),
        "--plot",
        &d("conf.svg"),
        "--candump",
        "/dev/null",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(dir.join("conf.csv").is_file() && dir.join("conf.svg").is_file());
    assert!(!std::fs::metadata("/dev/null").expect("null").is_file());
}

/// The frames the firmware would send decode back to the same confirmation.
/// Ctrl-C in the middle of a replay, every output staged: the command exits with 130 and
/// leaves neither an output nor a staging file behind. The recording comes through a pipe
/// that stays open, so the replay is surely mid-way when the signal comes.
#[test]
fn ctrl_c_leaves_no_output_and_no_staging_file() {
    use std::io::Write;
    let tmp = scratch("ctrl-c");
    let dir = tmp.path();
    let path = |name: &str| dir.join(name).to_str().expect("utf-8").to_owned();
    let mut child = Command::new(env!("CARGO_BIN_EXE_fingertip"))
        .args(["replay", "/dev/stdin", "--out", &path("conf.csv")])
        .args(["--candump", &path("frames.log"), "--plot", &path("run.png")])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the fingertip binary runs");
    let mut recording = Vec::new();
    fingertip::sim::long::write_long_recording(&mut recording, 2000).expect("in memory");
    let mut stdin = child.stdin.take().expect("piped");
    stdin.write_all(&recording).expect("the replay reads");
    stdin.flush().expect("the replay reads");
    let entries = || -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .expect("scratch dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    // The staging files exist before the first row is read.
    let start = std::time::Instant::now();
    while entries().len() < 2 && start.elapsed() < std::time::Duration::from_secs(20) {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let staged = entries();
    assert!(
        staged.len() == 2
            && staged
                .iter()
                .all(|n| n.starts_with('.') && n.contains(".tmp-")),
        "{staged:?}"
    );
    let interrupted = Command::new("sh")
        .args(["-c", &format!("kill -INT {}", child.id())])
        .status()
        .expect("sh runs");
    assert!(interrupted.success());
    let out = child.wait_with_output().expect("the replay ends");
    drop(stdin);
    assert_eq!(out.status.code(), Some(130), "{}", text(&out.stderr));
    assert_eq!(entries(), Vec::<String>::new());
}

#[test]
fn replay_candump_decodes_to_the_same_events() {
    let tmp = scratch("candump");
    let dir = tmp.path();
    let trace = simulate(dir, "contact_hard_8");
    let log = dir.join("run.log");
    let out = fingertip(&[
        "replay",
        trace.to_str().expect("utf-8"),
        "--candump",
        log.to_str().expect("utf-8"),
        "--node",
        "3",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let first = text(&std::fs::read(&log).expect("log"));
    assert!(
        first
            .lines()
            .all(|l| l.starts_with('(') && l.contains(" can0 ")),
        "{first}"
    );
    let out = fingertip(&["decode", log.to_str().expect("utf-8"), "--quiet"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let decoded = text(&out.stdout);
    assert!(
        decoded.contains("node  3  EVENT     contact CONFIRM"),
        "{decoded}"
    );
    assert!(decoded.contains("0 problems"), "{decoded}");
}

/// One line naming the file, row and column; non-zero exit; no output file left behind.
fn rejects(trace_text: &str, config: Option<&str>, expect: &[&str]) {
    let tmp = scratch("bad");
    let dir = tmp.path();
    let trace = dir.join("bad.csv");
    std::fs::write(&trace, trace_text).expect("write");
    let out_csv = dir.join("out.csv");
    let mut args = vec![
        "replay",
        trace.to_str().expect("utf-8"),
        "--out",
        out_csv.to_str().expect("utf-8"),
    ];
    let config_path = dir.join("config.toml");
    if let Some(c) = config {
        std::fs::write(&config_path, c).expect("write");
        args.extend(["--config", config_path.to_str().expect("utf-8")]);
    }
    let out = fingertip(&args);
    let stderr = text(&out.stderr);
    assert!(!out.status.success(), "accepted: {stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    for e in expect {
        assert!(stderr.contains(e), "'{e}' not in: {stderr}");
    }
    assert!(!out_csv.exists(), "an output file was left behind");
}

const HEADER: &str = "t,force_x,force_y,skin_accel,stress_rate,pos_err_x,pos_err_y,vel_des_x,vel_des_y,acc_des_x,acc_des_y";

#[test]
fn bad_traces_are_rejected_clearly() {
    rejects("", None, &["bad.csv", "empty"]);
    rejects(
        &format!("{HEADER}\n0,0,0,0,0,0,0,0,0,0,0\n0.0002,0,x,0,0,0,0,0,0,0,0\n"),
        None,
        &["bad.csv", "3", "force_y"],
    );
    rejects(
        &format!(
            "{HEADER}\n0,0,0,0,0,0,0,0,0,0,0\n0.0002,0,0,0,0,0,0,0,0,0,0\n0.0009,0,0,0,0,0,0,0,0,0,0\n"
        ),
        None,
        &["bad.csv", "4", "t"],
    );
    rejects(
        &format!("{HEADER}\n0.0002,0,0,0,0,0,0,0,0,0,0\n0,0,0,0,0,0,0,0,0,0,0\n"),
        None,
        &["bad.csv", "t"],
    );
    let missing = HEADER.replace(",stress_rate", "");
    rejects(
        &format!("{missing}\n0,0,0,0,0,0,0,0,0,0\n0.0002,0,0,0,0,0,0,0,0,0\n"),
        None,
        &["bad.csv", "stress_rate"],
    );
}

#[test]
fn bad_configurations_are_rejected_clearly() {
    let good = fingertip::APPROACH_TOML;
    let trace = format!("{HEADER}\n0,0,0,0,0,0,0,0,0,0,0\n0.0002,0,0,0,0,0,0,0,0,0,0\n");
    // The default's first sensor term (the contact's) given a weight above 1.
    let at = good.find("weight = ").expect("a sensor weight");
    let end = at + good[at..].find(',').expect("the weight's end");
    let heavy = format!("{}weight = 1.5{}", &good[..at], &good[end..]);
    rejects(
        &trace,
        Some(&heavy),
        &["config.toml", "event 'contact'", "1.5"],
    );
    let unknown = good.replacen("input = \"force_x\"", "input = \"force_z\"", 1);
    assert_ne!(unknown, good);
    rejects(
        &trace,
        Some(&unknown),
        &["config.toml", "feature 'force_ext'", "force_z"],
    );
    rejects(
        &trace,
        Some("rate_hz = 5000\n[[channel]]\nname = 1\n"),
        &["config.toml", "line 3"],
    );
}

/// A legal configuration with an event in no phase and a phase without events runs, with
/// one warning line each on standard error naming the file and the item.
#[test]
fn configuration_warnings_are_printed_and_the_run_goes_on() {
    let tmp = scratch("warn");
    let dir = tmp.path();
    let trace = dir.join("quiet.csv");
    std::fs::write(
        &trace,
        format!("{HEADER}\n0,0,0,0,0,0,0,0,0,0,0\n0.0002,0,0,0,0,0,0,0,0,0,0\n"),
    )
    .expect("write");
    let config = dir.join("idle.toml");
    let idle = format!(
        "{}\n[[phase]]\nname = \"idle\"\nevents = []\n",
        fingertip::APPROACH_TOML
    );
    std::fs::write(&config, idle).expect("write");
    let out = fingertip(&[
        "replay",
        trace.to_str().expect("utf-8"),
        "--config",
        config.to_str().expect("utf-8"),
    ]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let warnings: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("warning:"))
        .collect();
    assert_eq!(warnings.len(), 1, "{stderr}");
    assert!(
        warnings[0].contains("idle.toml") && warnings[0].contains("phase 'idle'"),
        "{stderr}"
    );
}

/// Counts no run could reach are refused at once with the limit, before any work and any
/// allocation in proportion to them.
#[test]
fn evaluate_bounds_its_counts() {
    for (args, expect) in [
        (["--runs", "18446744073709551615"], "--runs"),
        (["--runs", "0"], "--runs"),
        (["--free-hours", "1e300"], "--free-hours = 1e300"),
        (["--free-hours=-1", "--runs=1"], "--free-hours"),
        (["--lead-in-ms=-1", "--runs=1"], "--lead-in-ms = -1"),
        (["--lead-in-ms", "1e9"], "--lead-in-ms = 1e9"),
        (["--noise-factor=-1", "--runs=1"], "--noise-factor = -1"),
        (["--noise-factor", "11"], "--noise-factor = 11"),
        (["--encoder-um", "0.01"], "--encoder-um = 0.01"),
        (["--encoder-um=200", "--runs=1"], "--encoder-um = 200"),
        (
            ["--film-highpass-hz=-1", "--runs=1"],
            "--film-highpass-hz = -1",
        ),
        (["--film-highpass-hz", "20"], "--film-highpass-hz = 20"),
        (
            ["--context-turned-deg=-95", "--runs=1"],
            "--context-turned-deg = -95",
        ),
        (
            ["--range", "plant.arm_mass=1..50"],
            "--range plant.arm_mass=1..50: the bounds must stay",
        ),
    ] {
        let mut all = vec!["evaluate"];
        all.extend(args);
        let out = fingertip(&all);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{args:?} accepted");
        assert!(
            stderr.contains(expect) && stderr.contains("within"),
            "{stderr}"
        );
        assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    }
}

/// `--lead-in-ms` delays every run's event after the same drawn parameters: the report
/// says so, its JSON carries it, and each failure line reproduces its run with it, the
/// trace `simulate` writes then recording it. Recordings have their own timing.
#[test]
fn evaluate_gives_runs_a_lead_in() {
    let tmp = scratch("lead_in");
    let dir = tmp.path();
    let json = dir.join("report.json");
    let out = fingertip(&[
        "evaluate",
        "--runs",
        "3",
        "--free-hours",
        "0",
        "--lead-in-ms",
        "200",
        "--config",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/paper.toml"),
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("after a lead-in of 200 ms"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    assert_eq!(report["lead_in_ms"], 200.0);
    // The paper's detector gets some of these wrong; its first failure's line is run again.
    let (line, csv) = rerun_first_failure(&stdout, dir);
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(words[1], "--seed", "{line}");
    assert_eq!(words[3..5], ["--lead-in-ms", "200:"], "{line}");
    assert!(csv.contains("# lead_in_s: 0.2\n"), "{}", &csv[..400]);
    let clash = fingertip(&["evaluate", "--traces", ".", "--lead-in-ms", "5"]);
    assert!(!clash.status.success());
    assert!(
        text(&clash.stderr).contains("--lead-in-ms"),
        "{}",
        text(&clash.stderr)
    );
}

/// `--noise-factor` scales every sensor's white noise, `--encoder-um` sets the encoders'
/// resolution and `--range` a parameter's range in every run: the report says so, its
/// JSON carries them, and each failure line reproduces its run with them (after the
/// free-motion run's length), the trace `simulate` writes then recording them.
#[test]
fn evaluate_runs_beyond_the_envelope() {
    let tmp = scratch("beyond");
    let dir = tmp.path();
    let json = dir.join("report.json");
    let out = fingertip(&[
        "evaluate",
        "--runs",
        "2",
        "--free-hours",
        "0.02",
        "--noise-factor",
        "3",
        "--encoder-um",
        "5",
        "--film-highpass-hz",
        "1.5",
        "--context-turned-deg",
        "-10",
        "--range",
        "plant.control_bandwidth=10..12",
        "--range",
        "plant.arm_mass=0.6..0.7",
        "--config",
        concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/paper.toml"),
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("sensor noise 3 times the drawn, encoders resolving 5 um at the tip, the film AC-coupled at 1.5 Hz, the context in a frame turned -10 degrees from the pad's, plant.control_bandwidth drawn from 10 .. 12, plant.arm_mass drawn from 0.6 .. 0.7"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("report")).expect("JSON");
    assert_eq!(report["noise_factor"], 3.0);
    assert_eq!(report["encoder_um"], 5.0);
    assert_eq!(report["film_highpass_hz"], 1.5);
    assert_eq!(report["context_turned_deg"], -10.0);
    assert_eq!(report["ranges"][0]["parameter"], "plant.control_bandwidth");
    assert_eq!(report["ranges"][1]["min"], 0.6);
    // The paper's detector gets some of these wrong; its first failure's line is run again.
    let (line, csv) = rerun_first_failure(&stdout, dir);
    assert!(
        line.contains(" --noise-factor 3 --encoder-um 5 --film-highpass-hz 1.5 --context-turned-deg=-10 --range plant.control_bandwidth=10..12 --range plant.arm_mass=0.6..0.7:"),
        "{line}"
    );
    assert!(
        csv.contains("# range.plant.control_bandwidth: 10..12\n"),
        "{}",
        &csv[..600]
    );
    let drawn = |name: &str| -> f64 {
        let key = format!("# param.{name}: ");
        let at = csv.find(&key).expect("the parameter") + key.len();
        csv[at..]
            .lines()
            .next()
            .expect("a value")
            .parse()
            .expect("a number")
    };
    assert!((10.0..=12.0).contains(&drawn("plant.control_bandwidth")));
    assert!((0.6..=0.7).contains(&drawn("plant.arm_mass")));
    assert!(csv.contains("# noise_factor: 3\n"), "{}", &csv[..400]);
    assert!(
        csv.contains("# encoder_resolution_um: 5\n"),
        "{}",
        &csv[..400]
    );
    assert!(csv.contains("# film_highpass_hz: 1.5\n"), "{}", &csv[..400]);
    assert!(
        csv.contains("# context_turned_deg: -10\n"),
        "{}",
        &csv[..400]
    );
}

/// `evaluate --traces` on a directory of recordings: every `*.csv` under it (hidden files
/// and other files left out), each run of a `truth` label one event. A simulated contact
/// relabelled with a second, invented contact later on scores one right and one missed;
/// the JSON has the simulated evaluation's fields.
#[test]
fn evaluate_scores_labelled_recordings() {
    let tmp = scratch("corpus");
    let dir = tmp.path();
    let sub = dir.join("day1");
    std::fs::create_dir_all(&sub).expect("sub dir");
    simulate(&sub, "link_collision_8");
    let contact = simulate(dir, "contact_hard_8");
    // The real contact labelled for its first 10 ms only, then an invented one in the
    // last 10 ms, where nothing new happens.
    let text_in = std::fs::read_to_string(&contact).expect("trace");
    let rows = text_in.lines().filter(|l| !l.starts_with('#')).count() - 1;
    let mut seen = 0;
    let mut labelled = 0;
    let relabelled: String = text_in
        .lines()
        .map(|l| {
            if l.starts_with('#') || l.starts_with("t,") {
                return format!("{l}\n");
            }
            seen += 1;
            let (head, label) = l.rsplit_once(',').expect("cells");
            let keep = label == "contact" && labelled < 50;
            labelled += usize::from(keep);
            let invented = seen > rows - 50;
            let label = if keep || invented { "contact" } else { "" };
            format!("{head},{label}\n")
        })
        .collect();
    std::fs::write(&contact, relabelled).expect("written");
    std::fs::write(dir.join(".staging.csv"), "not a trace").expect("written");
    std::fs::write(dir.join("notes.txt"), "not a trace").expect("written");
    let json = dir.join("out").join("report.json");
    std::fs::create_dir_all(json.parent().expect("parent")).expect("out dir");
    let d = dir.to_str().expect("utf-8");
    let out = fingertip(&[
        "evaluate",
        "--traces",
        d,
        "--after-ms",
        "5",
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}{stdout}", text(&out.stderr));
    assert!(
        stdout.contains("2 recordings") && stdout.contains("5 ms after"),
        "{stdout}"
    );
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parses");
    let event = |name: &str| {
        report["events"]
            .as_array()
            .and_then(|e| e.iter().find(|e| e["name"] == name))
            .cloned()
            .unwrap_or_default()
    };
    assert_eq!(
        (
            event("contact")["runs"].as_u64(),
            event("contact")["correct"].as_u64()
        ),
        (Some(2), Some(1)),
        "{report}"
    );
    assert_eq!(event("contact")["missed"].as_u64(), Some(1));
    assert_eq!(event("link_collision")["correct"].as_u64(), Some(1));
    // Each event binned by the `scenario` its recordings name, as the simulator writes it.
    assert!(
        stdout.contains("  by the recordings' scenario:"),
        "{stdout}"
    );
    assert_eq!(event("contact")["binned_by"], "the recordings' scenario");
    let bin = &event("contact")["bins"][0];
    assert_eq!(
        (
            bin["name"].as_str(),
            bin["runs"].as_u64(),
            bin["correct"].as_u64()
        ),
        (Some("contact_hard_8"), Some(2), Some(1)),
        "{report}"
    );
    assert_eq!(
        event("link_collision")["bins"][0]["name"].as_str(),
        Some("link_collision_8")
    );
    let by_scenario: Vec<_> = report["false_alarms_by_scenario"]
        .as_array()
        .expect("a list")
        .iter()
        .map(|s| (s["scenario"].as_str(), s["false_alarms"].as_u64()))
        .collect();
    assert_eq!(
        by_scenario,
        [
            (Some("contact_hard_8"), Some(0)),
            (Some("link_collision_8"), Some(0))
        ]
    );
    assert_eq!(report["false_alarms"].as_u64(), Some(0));
    assert!(report["false_alarms_per_hour"].is_number() && report["config"].is_string());

    // Bad input: one line naming what was wrong, nothing written.
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).expect("empty dir");
    std::fs::write(dir.join("out").join("bad.csv"), "t,x\n0,1\n").expect("written");
    for (args, expect) in [
        (
            vec!["--traces", "/nonexistent/day"],
            "/nonexistent/day: cannot read",
        ),
        (
            vec!["--traces", empty.to_str().expect("utf-8")],
            "no recording",
        ),
        (vec!["--traces", d], "bad.csv"),
        (vec!["--traces", d, "--after-ms=-1"], "--after-ms"),
        (vec!["--traces", d, "--runs", "5"], "cannot be used with"),
    ] {
        let mut all = vec!["evaluate"];
        all.extend(args.iter().copied());
        let out = fingertip(&all);
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{args:?} accepted");
        assert!(stderr.contains(expect), "{args:?}: {stderr}");
    }
}

/// `features` on a corpus of a contact and event-free motion: the stress-rate energy
/// separates the contact almost perfectly, the figure and the JSON are written, and bad
/// windows are refused before any work.
#[test]
fn features_show_what_separates_each_event() {
    let tmp = scratch("features");
    let dir = tmp.path();
    simulate(dir, "contact_hard_8");
    let free = dir.join("free.csv");
    let out = fingertip(&[
        "simulate",
        "free_motion",
        "--duration",
        "2",
        "--out",
        free.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let d = dir.to_str().expect("utf-8");
    let figure = dir.join("figures").join("features.png");
    std::fs::create_dir_all(figure.parent().expect("parent")).expect("dir");
    let json = dir.join("figures").join("features.json");
    let out = fingertip(&[
        "features",
        "--traces",
        d,
        "--window-ms",
        "20",
        "--plot",
        figure.to_str().expect("utf-8"),
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}{stdout}", text(&out.stderr));
    assert!(std::fs::metadata(&figure).expect("figure").len() > 10_000);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parses");
    let separations = report["separations"].as_array().expect("a list");
    let stress = separations
        .iter()
        .find(|s| s["feature"] == "press" && s["event"] == "contact")
        .expect("press judged against the contact");
    assert!(stress["balanced_accuracy"].as_f64() > Some(0.9), "{stress}");
    assert_eq!(stress["above"], true);
    // 20 ms at 5 kHz after the contact's onset (both ends counted).
    assert_eq!(stress["n_event"].as_u64(), Some(101));
    // Only the contact is labelled: no other event is judged.
    assert!(separations.iter().all(|s| s["event"] == "contact"));
    for (args, expect) in [
        (
            vec!["features", "--traces", d, "--window-ms=-5"],
            "--window-ms",
        ),
        (
            vec!["features", "--traces", d, "--plot", "x.jpg"],
            ".png or .svg",
        ),
    ] {
        let out = fingertip(&args);
        assert!(!out.status.success(), "{args:?} accepted");
        assert!(text(&out.stderr).contains(expect), "{}", text(&out.stderr));
    }
}

/// `fit` keeps the base's structure and writes a configuration that loads, replays and
/// scores at least as the base on its corpus; every fitted item says what set it; a
/// feature that cannot tell its event from the rest stops the fit with the figures, and
/// nothing is written.
#[test]
fn fit_writes_a_configuration_that_runs() {
    let tmp = scratch("fit");
    let dir = tmp.path();
    let corpus = dir.join("corpus");
    std::fs::create_dir_all(&corpus).expect("corpus dir");
    for scenario in ["contact_hard_8", "disturbance_large_5"] {
        for seed in 1..=4 {
            let path = corpus.join(format!("{scenario}_{seed}.csv"));
            let out = fingertip(&[
                "simulate",
                scenario,
                "--randomize",
                "--seed",
                &seed.to_string(),
                "--out",
                path.to_str().expect("utf-8"),
            ]);
            assert!(out.status.success(), "{}", text(&out.stderr));
        }
    }
    let c = corpus.to_str().expect("utf-8");
    let fitted = dir.join("fitted.toml");
    let f = fitted.to_str().expect("utf-8");
    let out = fingertip(&["fit", "--traces", c, "--out", f, "--folds", "2"]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}{stdout}", text(&out.stderr));
    assert!(
        stdout.contains("fold 2") && stdout.contains("held out"),
        "{stdout}"
    );
    let toml = std::fs::read_to_string(&fitted).expect("written");
    assert!(toml.starts_with("# Fitted by `fingertip fit`"), "{toml}");
    assert!(toml.contains("# fitted sensor:") && toml.contains("# fitted confirm:"));
    // Hard contacts never push the force sensor while the structure is quiet: that path
    // keeps the base's numbers, the film's paths are fitted.
    assert!(
        toml.contains("force_push_still: kept the base's (weight 1)"),
        "{toml}"
    );
    // The link collision is not labelled: its numbers are the base's.
    let base = std::fs::read_to_string(format!(
        "{}/../configs/approach.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .expect("base");
    let block = |t: &str| {
        let start = t.find("name = \"link_collision\"").expect("the event");
        t[start..start + 300].to_string()
    };
    assert_eq!(block(&toml), block(&base));
    let json = dir.join("scores.json");
    let out = fingertip(&[
        "evaluate",
        "--traces",
        c,
        "--config",
        f,
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parses");
    let right: u64 = report["events"]
        .as_array()
        .expect("events")
        .iter()
        .filter_map(|e| e["correct"].as_u64())
        .sum();
    assert!(right >= 7, "{report}");
    // The fit's own figures (its levels stepped on the fitted terms' confidences) are the
    // detector's: the same events right as its replay.
    let trained = stdout
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("fitted: "))
        .expect("training figures");
    for event in report["events"].as_array().expect("events") {
        let figure = format!(
            "{} {}/{}",
            event["name"].as_str().expect("name"),
            event["correct"],
            event["runs"]
        );
        assert!(trained.contains(&figure), "{figure} in {trained}");
    }

    // A contact judged by the commanded acceleration alone, on every path: it cannot tell
    // contacts apart.
    let bad = dir.join("bad.toml");
    let mut replaced = base.clone();
    for path in ["press_fast_free", "press_clear", "force_push_still"] {
        let term = format!("{{ feature = \"{path}\", weight = 1.0");
        assert!(replaced.contains(&term), "{term}");
        replaced = replaced.replacen(&term, "{ feature = \"acc_step\", weight = 1.0", 1);
    }
    std::fs::write(&bad, replaced).expect("written");
    let refused = dir.join("refused.toml");
    let out = fingertip(&[
        "fit",
        "--traces",
        c,
        "--config",
        bad.to_str().expect("utf-8"),
        "--out",
        refused.to_str().expect("utf-8"),
        "--folds",
        "0",
    ]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("`acc_step` does not separate event `contact`"),
        "{stderr}"
    );
    assert!(!refused.exists());
}

/// A one-channel detector whose base misplaces its sigmoid (10..20 N for bumps of 5 N).
const BUMP_TOML: &str = r#"
rate_hz = 1000.0
[[channel]]
name = "x"
unit = "N"
[[feature]]
name = "level"
stage = { low_pass = { input = "x", cutoff_hz = 100.0 } }
[[event]]
name = "bump"
# The bump's level, low-passed.
sensor = [{ feature = "level", weight = 1.0, cdf = { sigmoid = { low = 10.0, high = 20.0 } } }]
alert = { on = 0.55, off = 0.35, hold_ms = 50.0 }
# Confirmed once sure.
confirm = { on = 0.75, off = 0.5, hold_ms = 50.0 }
[[phase]]
name = "main"
events = ["bump"]
"#;

/// Two seconds at 1 kHz: noise of ±0.1 N, and three bumps of `height` for 100 ms,
/// labelled, at seeds-dependent places.
fn bumps(seed: u64, height: f64) -> String {
    bumps_with_unlabelled(seed, height, false)
}

/// [`bumps`], and with `unlabelled` a fourth bump like the others, not labelled.
fn bumps_with_unlabelled(seed: u64, height: f64, unlabelled: bool) -> String {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let starts = [300 + seed as usize * 10, 900, 1500 - seed as usize * 10];
    let mut text = String::from("t,x,truth\n");
    for k in 0..2000 {
        let on = starts.iter().any(|s| (*s..s + 100).contains(&k));
        let hidden = unlabelled && (1800..1900).contains(&k);
        let x = 0.2 * noise() + if on || hidden { height } else { 0.0 };
        let label = if on { "bump" } else { "" };
        text.push_str(&format!("{},{x:.4},{label}\n", k as f64 / 1000.0));
    }
    text
}

/// A corpus separable by construction is fitted to every event found and nothing false,
/// the same file twice over, the user's comments kept and the held-out folds summed; a
/// refit of the fitted file replaces the earlier fit's comments; a corpus where every
/// level confirms falsely is fitted with a warning; one that no feature separates, an
/// unlabelled one, one whose channels or rate do not match are refused, the file named.
#[test]
fn fit_finds_what_is_separable_and_refuses_what_is_not() {
    let tmp = scratch("fit-bumps");
    let dir = tmp.path();
    let config = dir.join("bump.toml");
    std::fs::write(&config, BUMP_TOML).expect("written");
    let cfg = config.to_str().expect("utf-8");
    let corpus = |name: &str, height: f64, edit: &dyn Fn(String) -> String| {
        let d = dir.join(name);
        std::fs::create_dir_all(&d).expect("dir");
        for seed in 1..=6 {
            std::fs::write(d.join(format!("r{seed}.csv")), edit(bumps(seed, height)))
                .expect("written");
        }
        d.to_str().expect("utf-8").to_owned()
    };
    let good = corpus("good", 5.0, &|t| t);
    let fit = |traces: &str, out: &str| {
        fingertip(&[
            "fit", "--traces", traces, "--config", cfg, "--out", out, "--folds", "3",
        ])
    };
    let (a, b) = (dir.join("a.toml"), dir.join("b.toml"));
    for p in [&a, &b] {
        let out = fit(&good, p.to_str().expect("utf-8"));
        assert!(out.status.success(), "{}", text(&out.stderr));
        let stdout = text(&out.stdout);
        let summed = stdout
            .split("every fold's held-out recordings together:")
            .nth(1)
            .and_then(|rest| rest.lines().nth(1))
            .unwrap_or_default();
        assert!(summed.contains("fitted, held out:  bump 18/18"), "{stdout}");
    }
    assert_eq!(
        std::fs::read(&a).expect("a"),
        std::fs::read(&b).expect("b"),
        "fitting is deterministic"
    );
    let fitted = std::fs::read_to_string(&a).expect("a");
    for comment in ["# The bump's level, low-passed.", "# Confirmed once sure."] {
        assert_eq!(fitted.matches(comment).count(), 1, "{fitted}");
    }
    // Refitted from the fitted file: one header, one note per item, the user's comments.
    let again = dir.join("again.toml");
    let out = fingertip(&[
        "fit",
        "--traces",
        &good,
        "--config",
        a.to_str().expect("utf-8"),
        "--out",
        again.to_str().expect("utf-8"),
        "--folds",
        "0",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let refitted = std::fs::read_to_string(&again).expect("again");
    for once in [
        "# Fitted by `fingertip fit`",
        "# fitted sensor:",
        "# fitted confirm:",
        "# The bump's level, low-passed.",
        "# Confirmed once sure.",
    ] {
        assert_eq!(refitted.matches(once).count(), 1, "{once}: {refitted}");
    }
    // A bump the labels leave out in every recording: no level avoids it; the fit says so.
    let hidden = dir.join("hidden");
    std::fs::create_dir_all(&hidden).expect("dir");
    for seed in 1..=6 {
        std::fs::write(
            hidden.join(format!("r{seed}.csv")),
            bumps_with_unlabelled(seed, 5.0, true),
        )
        .expect("written");
    }
    let over = dir.join("over.toml");
    let out = fingertip(&[
        "fit",
        "--traces",
        hidden.to_str().expect("utf-8"),
        "--config",
        cfg,
        "--out",
        over.to_str().expect("utf-8"),
        "--folds",
        "0",
        "--window-ms",
        "1",
    ]);
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("no confirm level keeps `bump` within its share of --budget 1"),
        "{stderr}"
    );
    assert!(
        stderr.contains("--window-ms 1 holds 1 tick(s) at the detector's 1000 Hz"),
        "{stderr}"
    );
    let over = std::fs::read_to_string(&over).expect("written");
    assert!(over.contains("OVER the budget"), "{over}");
    let json = dir.join("scores.json");
    let out = fingertip(&[
        "evaluate",
        "--traces",
        &good,
        "--config",
        a.to_str().expect("utf-8"),
        "--json",
        json.to_str().expect("utf-8"),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("json")).expect("parses");
    assert_eq!(report["events"][0]["runs"].as_u64(), Some(18), "{report}");
    assert_eq!(
        report["events"][0]["correct"].as_u64(),
        Some(18),
        "{report}"
    );
    assert_eq!(report["false_alarms"].as_u64(), Some(0), "{report}");

    let flat = corpus("flat", 0.0, &|t| t);
    let unlabelled = corpus("unlabelled", 5.0, &|t| t.replace(",bump", ","));
    let renamed = corpus("renamed", 5.0, &|t| t.replacen("t,x,", "t,y,", 1));
    let fast = corpus("fast", 5.0, &|t| {
        t.lines()
            .enumerate()
            .map(|(k, l)| match (k, l.split_once(',')) {
                (0, _) | (_, None) => format!("{l}\n"),
                (_, Some((_, rest))) => format!("{},{rest}\n", (k - 1) as f64 / 2000.0),
            })
            .collect()
    });
    for (traces, expect) in [
        (&flat, "`level` does not separate event `bump`"),
        (&unlabelled, "nothing to fit"),
        (&renamed, "r1.csv: the configuration reads channel 'x'"),
        (&fast, "r1.csv: line 3, column `t`: time step 5e-4 s"),
    ] {
        let out_path = dir.join("refused.toml");
        let out = fit(traces, out_path.to_str().expect("utf-8"));
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{traces} accepted");
        assert!(stderr.contains(expect), "{traces}: {stderr}");
        assert!(!out_path.exists());
    }
}

/// `load`, `info` and `calibrate` refuse bad input with one line naming it, before
/// touching the bus; a missing interface is named too.
#[test]
fn load_and_info_name_what_is_wrong() {
    let tmp = scratch("load");
    let dir = tmp.path();
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "rate_hz = -1.0\n").expect("write");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let approach = root.join("configs/approach.toml");
    let approach = approach.to_str().expect("utf-8 path");
    for (args, want) in [
        (
            vec!["load", approach, "--node", "15"],
            "--node 15 must be within 0..=14",
        ),
        (vec!["load", "missing.toml", "--node", "3"], "missing.toml"),
        (
            vec!["load", bad.to_str().expect("utf-8"), "--node", "3"],
            "bad.toml",
        ),
        (
            vec!["load", approach, "--node", "3", "--iface", "nosuch0"],
            "CAN interface nosuch0",
        ),
        (
            vec!["info", "--node", "3", "--iface", "nosuch0"],
            "CAN interface nosuch0",
        ),
        (
            vec![
                "fetch-recording",
                "--config",
                approach,
                "--node",
                "3",
                "--out",
                "rec.csv",
                "--iface",
                "nosuch0",
            ],
            "CAN interface nosuch0",
        ),
        (
            vec![
                "fetch-recording",
                "--config",
                approach,
                "--node",
                "3",
                "--follow",
                "no/such/dir",
            ],
            "no/such/dir: not a directory",
        ),
        (
            vec!["calibrate", "--node", "3", "force_z.gain"],
            "unknown key `force_z.gain`",
        ),
        (
            vec!["calibrate", "--node", "3", "force_x.gain=abc"],
            "force_x.gain: `abc` is not a number",
        ),
        (
            vec!["calibrate", "--node", "3", "node_id=-1"],
            "node_id: `-1` is not a whole number",
        ),
        (
            vec![
                "calibrate",
                "--node",
                "3",
                "node_id=4",
                "--iface",
                "nosuch0",
            ],
            "CAN interface nosuch0",
        ),
    ] {
        let out = fingertip(&args);
        assert!(!out.status.success(), "{args:?}");
        let err = text(&out.stderr);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}

/// A flight recording, as `fetch-recording` writes it, replays from the state it saved:
/// `fingertip replay` on the rows from the alert on confirms at the tick the whole run
/// does, with the onset before the recording's first row; a state that is not the
/// detector's is refused in one line naming it.
#[test]
fn a_flight_recording_replays_from_its_saved_state() {
    use fingertip::can_tools::recording::{RecordedRow, Recording};
    use fingertip_can::service::{RecordingCause, RecordingInfo};

    let tmp = scratch("recording");
    let dir = tmp.path();
    let run = fingertip::trace::Trace::read(simulate(dir, "contact_hard_8")).expect("reads");
    let config = detector_build::Config::from_toml(fingertip::APPROACH_TOML).expect("parses");
    let d = detector_build::build(&config).expect("builds");
    let crc =
        fingertip_can::service::crc32(&detector_build::compile(&config).expect("compiles").image());
    // The whole run: the state after each row, and the contact's confirmation.
    let mut states = Vec::new();
    let whole =
        fingertip::replay::replay(&d, &run, |_, s, _| states.push(s.clone())).expect("replays");
    let confirm = whole
        .iter()
        .find(|r| r.is_confirm())
        .expect("confirmed")
        .clone();
    let alert = whole
        .iter()
        .find(|r| !r.is_confirm())
        .expect("alerted")
        .clone();
    // The recording starts after the alert, one tick before the confirmation.
    let first = (confirm.t_s * 5000.0).round() as usize;
    assert!(first > (alert.t_s * 5000.0).round() as usize);
    let mut saved = vec![0u8; detector_core::State::SAVED_BYTES];
    states[first - 1].save((&mut saved[..]).try_into().expect("length"));
    let columns: Vec<&[f64]> = d
        .channels()
        .iter()
        .map(|c| run.column(c).expect("column"))
        .collect();
    let rows: Vec<RecordedRow> = (first..run.len())
        .map(|k| RecordedRow {
            phase: 0,
            withheld: 0,
            samples: (0..columns.len())
                .map(|c| d.sample_from_si(c, columns[c][k]).to_bits())
                .collect(),
        })
        .collect();
    let event = d
        .events()
        .iter()
        .position(|e| e.as_str() == "contact")
        .expect("an event") as u8;
    let rec = Recording {
        info: RecordingInfo {
            frozen: true,
            cause: Some(RecordingCause::Confirmed(event)),
            trigger_tick: first as u32,
            first_tick: first as u32,
            rows: rows.len() as u32,
            channels: columns.len() as u8,
            rate_hz: 5000,
            detector_crc: crc,
            bytes: 0,
        },
        saved,
        rows,
    };
    let trace = rec.to_trace(&d, crc, "recording").expect("a trace");
    rec.check_replay(&d, &trace)
        .expect("confirms at the trigger");
    let path = dir.join("recording.csv");
    trace.write(&path).expect("written");

    let out = fingertip(&["replay", path.to_str().expect("utf-8"), "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    let events = json["events"].as_array().expect("events");
    let replayed = events
        .iter()
        .find(|e| e["level"] == "confirm")
        .expect("the recording confirms");
    assert_eq!(replayed["event"], "contact");
    assert!(
        (replayed["t_s"].as_f64().expect("t") - confirm.t_s).abs() < 1e-9,
        "{replayed}"
    );
    assert!(
        (replayed["onset_s"].as_f64().expect("onset") - confirm.onset_s).abs() < 1e-9,
        "the onset, before the first row: {replayed}"
    );

    // From a fresh state instead, the same rows confirm later, or not at all.
    let fresh = text(&std::fs::read(&path).expect("read"))
        .lines()
        .filter(|l| !l.starts_with("# state:"))
        .collect::<Vec<_>>()
        .join("\n");
    let fresh_path = dir.join("fresh.csv");
    std::fs::write(&fresh_path, fresh).expect("write");
    let out = fingertip(&["replay", fresh_path.to_str().expect("utf-8"), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).expect("json");
    assert!(
        json["events"]
            .as_array()
            .expect("events")
            .iter()
            .all(|e| e["level"] != "confirm" || e["t_s"].as_f64() > Some(confirm.t_s)),
        "the saved state matters: {json}"
    );

    // Another detector's state (a shorter one) is refused, naming the metadata.
    let magic: String = detector_core::SAVED_MAGIC
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    let recording = text(&std::fs::read(&path).expect("read"));
    let state_bytes = recording
        .lines()
        .find_map(|l| l.strip_prefix("# state: "))
        .expect("the recording carries its state")
        .trim()
        .len()
        / 2;
    let bad = recording.replacen(
        &format!("# state: {magic}"),
        &format!("# state: {magic}00"),
        1,
    );
    std::fs::write(&path, bad).expect("write");
    let out = fingertip(&["replay", path.to_str().expect("utf-8")]);
    let stderr = text(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("metadata 'state'")
            && stderr.contains(&format!("{state_bytes} bytes, not {}", state_bytes + 1)),
        "{stderr}"
    );
}

/// `simulate --gives-way-ms` writes a link collision's twin (a blow of the collision's own
/// force that reads as the collision until it lets go) or a contact's (a blow on the pad),
/// says so in the trace, and refuses a time outside 0 to 1,000 ms naming the option,
/// writing nothing.
#[test]
fn simulate_writes_an_events_twin() {
    let tmp = scratch("twin");
    let dir = tmp.path();
    let trace = dir.join("twin.csv");
    let path = trace.to_str().expect("utf-8");
    let twin = |scenario: &str, ms: &str| {
        fingertip(&["simulate", scenario, "--gives-way-ms", ms, "--out", path])
    };
    for (scenario, ms, meta) in [
        ("link_collision_8", "2", "# gives_way_s: 0.002\n"),
        ("contact_hard_5", "1", "# gives_way_s: 0.001\n"),
    ] {
        let ok = twin(scenario, ms);
        assert!(ok.status.success(), "{scenario}: {}", text(&ok.stderr));
        let written = std::fs::read_to_string(&trace).expect("trace");
        assert!(written.contains(meta), "{scenario}");
        assert!(written.contains("# gives_way_peak_force_n: "), "{scenario}");
        std::fs::remove_file(&trace).expect("removed");
    }
    let bad = twin("link_collision_8", "2000");
    assert!(!bad.status.success());
    assert!(
        text(&bad.stderr).contains("gives_way_s"),
        "{}",
        text(&bad.stderr)
    );
    assert!(!trace.exists());
}
