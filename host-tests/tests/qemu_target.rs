//! The detector core on an emulated Cortex-M4 (issue 6): bit-exact with the PC, and its cost
//! per tick.
//!
//! The inputs are golden traces from the simulator (`fingertip::sim`): the 13 runs of the
//! paper's Table 1 (contacts, link collisions, disturbances, sudden accelerations, nominal
//! parameters, seed 0) and one second of event-free motion, at the configured rate, followed
//! by the synthetic runs `fingertip-qemu`'s build script generates (one with faulty channels,
//! one across the tick counter's wrap). They are written as a compact binary of raw 16.16
//! samples (`qemu-golden.ftrc` in the test's temporary directory, format in
//! `fingertip_qemu::trace`), which the program embeds.
//!
//! The test builds the `fingertip-qemu` program (`host-tests/qemu`) for
//! `thumbv7em-none-eabihf` with the firmware's profile (`firmware` in the workspace's
//! `Cargo.toml`: fat LTO, opt-level "z", the generated tick's crate `fingertip-tick` at 3,
//! the target's flags of `.cargo/config.toml`) by running `cargo build -p fingertip-qemu
//! --profile firmware --target thumbv7em-none-eabihf` itself, with `FINGERTIP_QEMU_TRACE` pointing at that file (same
//! target directory as the outer `cargo test`), runs it on QEMU's `mps2-an386` with
//! `-icount shift=10,align=off,sleep=off`, and checks that
//!
//! - its digests of every input, feature, term confidence, event confidence and decision
//!   equal the PC's over the same configuration (parsed here from `configs/approach.toml`)
//!   and trace;
//! - the instructions per tick of the tick the firmware runs (the one generated for the
//!   configuration at build time) stay within issue 6's [`BUDGET`], deterministically; the
//!   table shows them by stage, and the interpreter's for comparison;
//! - no 64-bit division or soft-float helper is reachable from the tick functions
//!   (disassembly call graph, `arm-none-eabi-objdump` or `llvm-objdump`).
//!
//! Needs `qemu-system-arm`, the `thumbv7em-none-eabihf` Rust target and an ARM objdump.
//! With `FINGERTIP_REQUIRE_QEMU=1` (the test command sets it) a missing tool fails the
//! tests; otherwise they print why they skip. `cargo test -p host-tests --test qemu_target
//! -- --nocapture` prints the performance table of `docs/performance.md`.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use detector_build::Config;
use fingertip::replay::channel_columns;
use fingertip::sim::golden_runs;
use fingertip_qemu::replay::{SegmentLine, plain_tick, replay, staged_tick};
use fingertip_qemu::trace::{Encoder, Trace};

/// Most instructions one tick may take (issue 6), enforced.
const BUDGET: u32 = 1_500;
/// What the tick should take.
const AIM: u32 = 800;
/// `-icount shift`: each instruction advances the virtual clock by 2^10 ns, 25.6 SysTick
/// counts at 25 MHz, so rounding recovers exact instruction counts.
const ICOUNT_SHIFT: u32 = 10;
const TARGET: &str = "thumbv7em-none-eabihf";
const PACKAGE: &str = "fingertip-qemu";
/// The firmware's build profile (`Cargo.toml`): opt-level "z", the tick crate at 3.
const PROFILE: &str = "firmware";
/// The program's `#[no_mangle] #[inline(never)]` tick and stage functions.
const ROOTS: [&str; 6] = [
    "fingertip_tick",
    "fingertip_tick_interpreted",
    "fingertip_update_features",
    "fingertip_term_confidences",
    "fingertip_combine",
    "fingertip_decide",
];
/// Wall-clock limit for one QEMU run (it takes well under a second).
const QEMU_TIMEOUT: Duration = Duration::from_secs(120);

// ---- Environment ----------------------------------------------------------------------------

fn required() -> bool {
    std::env::var("FINGERTIP_REQUIRE_QEMU").is_ok_and(|v| v == "1")
}

/// A missing tool: a failure when required, else a skip message.
fn unavailable(what: &str) {
    if required() {
        panic!("{what}, and FINGERTIP_REQUIRE_QEMU=1");
    }
    eprintln!("skipped: {what} (set FINGERTIP_REQUIRE_QEMU=1 to make this a failure)");
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
}

fn qemu_binary() -> Option<PathBuf> {
    match std::env::var_os("FINGERTIP_QEMU").filter(|p| !p.is_empty()) {
        Some(p) => Some(PathBuf::from(p)).filter(|p| p.is_file()),
        None => on_path("qemu-system-arm"),
    }
}

/// `arm-none-eabi-objdump`, else `llvm-objdump` (on the path or from rustup's llvm-tools).
fn objdump_binary() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("FINGERTIP_OBJDUMP").filter(|p| !p.is_empty()) {
        return Some(PathBuf::from(p));
    }
    if let Some(p) = on_path("arm-none-eabi-objdump").or_else(|| on_path("llvm-objdump")) {
        return Some(p);
    }
    let sysroot = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .ok()?;
    let sysroot = PathBuf::from(String::from_utf8(sysroot.stdout).ok()?.trim());
    let lib = sysroot.join("lib/rustlib");
    std::fs::read_dir(&lib)
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("bin/llvm-objdump"))
        .find(|p| p.is_file())
}

fn target_installed() -> bool {
    let Ok(out) = Command::new("rustc").args(["--print", "sysroot"]).output() else {
        return false;
    };
    let sysroot = String::from_utf8_lossy(&out.stdout).trim().to_owned();
    Path::new(&sysroot)
        .join("lib/rustlib")
        .join(TARGET)
        .is_dir()
}

// ---- Building and running the program ---------------------------------------------------

/// The inputs: the simulator's golden runs, then `fingertip-qemu`'s synthetic ones.
fn golden_trace() -> Result<Vec<u8>, String> {
    let config = Config::from_toml(fingertip::APPROACH_TOML).map_err(|e| e.to_string())?;
    let detector = detector_build::build(&config).map_err(|e| e.to_string())?;
    let names: Vec<&str> = config.channels.iter().map(|c| c.name.as_str()).collect();
    let synthetic = Trace::parse(fingertip_qemu::TRACE).map_err(|e| e.to_string())?;
    if synthetic.channels() != names.len() {
        return Err("the synthetic trace does not have the configuration's channels".into());
    }
    let mut runs = Vec::new();
    for (scenario, t) in golden_runs(f64::from(config.rate_hz)).map_err(|e| e.to_string())? {
        let columns = channel_columns(&detector, &t).map_err(|e| e.to_string())?;
        let records: Vec<(u32, Vec<i32>)> = (0..t.len())
            .map(|row| {
                let samples = columns
                    .iter()
                    .enumerate()
                    .map(|(k, c)| {
                        let si = c.get(row).copied().unwrap_or(0.0);
                        detector.sample_from_si(k, si).to_bits()
                    })
                    .collect();
                (0, samples)
            })
            .collect();
        runs.push((scenario.name().to_owned(), 0u32, records));
    }
    for seg in synthetic.segments() {
        let records = seg
            .records()
            .map(|r| (r.faults, r.samples[..names.len()].to_vec()))
            .collect();
        runs.push((
            format!("synthetic_{}", seg.name()),
            seg.start_tick(),
            records,
        ));
    }
    let mut bytes = Vec::new();
    {
        let mut enc = Encoder::new(
            |b: &[u8]| bytes.extend_from_slice(b),
            names.len(),
            runs.len() as u32,
        )
        .map_err(|e| e.to_string())?;
        for (i, (name, start, records)) in runs.iter().enumerate() {
            enc.segment(i as u32, name, *start, records.len() as u32)
                .map_err(|e| e.to_string())?;
            for (faults, samples) in records {
                enc.record(*faults, samples).map_err(|e| e.to_string())?;
            }
        }
    }
    Trace::parse(&bytes).map_err(|e| format!("the golden trace does not parse: {e}"))?;
    Ok(bytes)
}

/// Writes `bytes` unless the file already holds them, so an unchanged trace does not make
/// cargo rebuild the program.
fn write_if_changed(path: &Path, bytes: &[u8]) -> Result<(), String> {
    if std::fs::read(path).is_ok_and(|old| old == bytes) {
        return Ok(());
    }
    std::fs::write(path, bytes).map_err(|e| format!("writing {}: {e}", path.display()))
}

/// Builds the QEMU program around `trace` and returns the ELF's path.
fn build_program(trace: &Path) -> Result<PathBuf, String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(workspace_root())
        // Set by the outer cargo for this test binary; not meant for the inner build.
        .env_remove("OUT_DIR")
        .env_remove("CARGO_PRIMARY_PACKAGE")
        .env("FINGERTIP_QEMU_TRACE", trace)
        .args([
            "build",
            "-p",
            PACKAGE,
            "--profile",
            PROFILE,
            "--target",
            TARGET,
            "--message-format=json-render-diagnostics",
        ])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("running cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "cargo build -p {PACKAGE} --profile {PROFILE} --target {TARGET} failed:\n{}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    // The bin artifact's message names the executable.
    let stdout = String::from_utf8_lossy(&out.stdout);
    stdout
        .lines()
        .filter(|l| l.contains("\"reason\":\"compiler-artifact\"") && l.contains(PACKAGE))
        .find_map(|l| {
            let start = l.find("\"executable\":\"")? + "\"executable\":\"".len();
            let len = l.get(start..)?.find('"')?;
            Some(PathBuf::from(l.get(start..start + len)?))
        })
        .ok_or_else(|| format!("cargo built {PACKAGE} but reported no executable"))
}

/// Runs the program under QEMU; its semihosting output, or why it failed.
fn run_qemu(qemu: &Path, elf: &Path) -> Result<String, String> {
    let icount = format!("shift={ICOUNT_SHIFT},align=off,sleep=off");
    let mut child = Command::new(qemu)
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4", "-nographic"])
        .args(["-monitor", "none", "-serial", "none"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-icount", &icount])
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("starting {}: {e}", qemu.display()))?;
    let mut stdout = child.stdout.take().ok_or("no stdout pipe")?;
    let mut stderr = child.stderr.take().ok_or("no stderr pipe")?;
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > QEMU_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("QEMU did not finish within {QEMU_TIMEOUT:?}"));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(format!("waiting for QEMU: {e}")),
        }
    };
    let out = reader.join().unwrap_or_default();
    let err = err_reader.join().unwrap_or_default();
    if !status.success() || !out.lines().any(|l| l == "done") {
        return Err(format!(
            "QEMU exited with {status}; output:\n{out}\nstderr:\n{err}"
        ));
    }
    Ok(out)
}

/// The trace, the program's ELF and two runs of it (the second checks that the counts are
/// deterministic).
struct Run {
    trace: Vec<u8>,
    elf: PathBuf,
    first: String,
    second: String,
}

/// Builds and runs once per test process; `None` when skipped.
fn run() -> Option<&'static Run> {
    static RUN: OnceLock<Result<Option<Run>, String>> = OnceLock::new();
    let result = RUN.get_or_init(|| {
        let Some(qemu) = qemu_binary() else {
            unavailable("qemu-system-arm is not installed");
            return Ok(None);
        };
        if !target_installed() {
            unavailable(&format!(
                "the Rust target {TARGET} is not installed (rustup target add {TARGET})"
            ));
            return Ok(None);
        }
        let trace = golden_trace()?;
        let path = Path::new(env!("CARGO_TARGET_TMPDIR")).join("qemu-golden.ftrc");
        write_if_changed(&path, &trace)?;
        let elf = build_program(&path)?;
        let first = run_qemu(&qemu, &elf)?;
        let second = run_qemu(&qemu, &elf)?;
        Ok(Some(Run {
            trace,
            elf,
            first,
            second,
        }))
    });
    match result {
        Ok(run) => run.as_ref(),
        Err(e) => panic!("{e}"),
    }
}

// ---- The program's report --------------------------------------------------------------------

/// Instruction counts of one part of the tick, as the program prints them.
#[derive(Clone, Debug, PartialEq)]
struct Insns {
    mean: f64,
    min: u32,
    max: u32,
    max_at: String,
    n: u32,
}

#[derive(Debug, Default)]
struct Report {
    header: String,
    calibration: BTreeMap<String, String>,
    segments: Vec<String>,
    digest_tick: String,
    digest_stages: String,
    digest_interpreted: String,
    insns: BTreeMap<String, Insns>,
}

fn fields(s: &str) -> BTreeMap<String, String> {
    s.split_whitespace()
        .filter_map(|kv| kv.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
}

fn parse_report(text: &str) -> Result<Report, String> {
    let mut r = Report::default();
    for line in text.lines() {
        if line.starts_with("fingertip-qemu ") {
            r.header = line.to_owned();
        } else if let Some(rest) = line.strip_prefix("calibration ") {
            r.calibration = fields(rest);
        } else if line.starts_with("segment ") {
            r.segments.push(line.to_owned());
        } else if let Some(rest) = line.strip_prefix("digest tick: ") {
            r.digest_tick = rest.to_owned();
        } else if let Some(rest) = line.strip_prefix("digest stages: ") {
            r.digest_stages = rest.to_owned();
        } else if let Some(rest) = line.strip_prefix("digest interpreted: ") {
            r.digest_interpreted = rest.to_owned();
        } else if let Some(rest) = line.strip_prefix("insns ") {
            let (name, rest) = rest
                .split_once(": ")
                .ok_or_else(|| format!("bad line: {line}"))?;
            let f = fields(rest);
            let get = |k: &str| f.get(k).ok_or_else(|| format!("no {k} in: {line}"));
            let num = |k: &str| -> Result<u32, String> {
                get(k)?.parse().map_err(|e| format!("{k} in {line}: {e}"))
            };
            r.insns.insert(
                name.to_owned(),
                Insns {
                    mean: get("mean")?
                        .parse()
                        .map_err(|e| format!("mean in {line}: {e}"))?,
                    min: num("min")?,
                    max: num("max")?,
                    max_at: get("max_at")?.clone(),
                    n: num("n")?,
                },
            );
        } else if line.starts_with("error") {
            return Err(format!("the program reported: {line}"));
        }
    }
    if r.digest_tick.is_empty() || r.digest_stages.is_empty() || r.digest_interpreted.is_empty() {
        return Err(format!("no digest lines in the output:\n{text}"));
    }
    for part in [
        "tick",
        "interpreted",
        "features",
        "confidences",
        "combine",
        "decide",
    ] {
        if !r.insns.contains_key(part) {
            return Err(format!(
                "no instruction counts for {part} in the output:\n{text}"
            ));
        }
    }
    Ok(r)
}

/// The counting method works: `-icount` is on with the expected shift (SysTick counts per
/// 4096 `nop`s) and a 256-`nop` block counts as 256 instructions.
fn check_calibration(r: &Report) -> Result<(), String> {
    let get = |k: &str| -> Result<u64, String> {
        r.calibration
            .get(k)
            .ok_or_else(|| format!("no calibration {k}"))?
            .parse()
            .map_err(|e| format!("calibration {k}: {e}"))
    };
    let expected = 4096u64 * (1 << ICOUNT_SHIFT) / 40; // SysTick at 25 MHz: 40 ns per count
    let counts = get("counts")?;
    if counts.abs_diff(expected) > 2 {
        return Err(format!(
            "4096 nops took {counts} SysTick counts, not {expected}: QEMU's -icount shift={ICOUNT_SHIFT} is not in effect"
        ));
    }
    match get("check256")? {
        256 => Ok(()),
        n => Err(format!("a block of 256 nops counted as {n} instructions")),
    }
}

/// The worst tick within the budget.
fn check_budget(r: &Report) -> Result<(), String> {
    let tick = r.insns.get("tick").ok_or("no tick counts")?;
    if tick.max > BUDGET {
        let part = |k: &str| r.insns.get(k).map_or(0.0, |i| i.mean);
        return Err(format!(
            "the worst tick takes {} instructions (mean {:.0}; at segment:record {}), over the budget of {BUDGET}. \
             Means by stage: features {:.0}, confidences {:.0}, combine {:.0}, decide {:.0}; \
             the rest ({:.0}) is the tick's own frame (clearing the Output)",
            tick.max,
            tick.mean,
            tick.max_at,
            part("features"),
            part("confidences"),
            part("combine"),
            part("decide"),
            tick.mean - part("stages_sum"),
        ));
    }
    Ok(())
}

fn table(r: &Report) -> String {
    let mut s = String::from(
        "| part of the tick | mean | min | max | max share of the 1,500 budget |\n|---|---:|---:|---:|---:|\n",
    );
    for (key, label) in [
        ("features", "features (update_features)"),
        ("confidences", "confidences (term_confidences: the CDFs)"),
        ("combine", "combine (eq. 14)"),
        ("decide", "decide (levels, onsets)"),
        ("stages_sum", "sum of the four stages, called one by one"),
        ("tick", "whole tick, generated (the firmware's)"),
        (
            "interpreted",
            "whole tick, interpreted (Detector::tick_into)",
        ),
    ] {
        if let Some(i) = r.insns.get(key) {
            s += &format!(
                "| {label} | {:.1} | {} | {} | {:.0} % |\n",
                i.mean,
                i.min,
                i.max,
                100.0 * f64::from(i.max) / f64::from(BUDGET)
            );
        }
    }
    s
}

// ---- Call graph from the disassembly -----------------------------------------------------

#[derive(Debug, Default)]
struct Function {
    /// Functions it branches to (calls and tail calls).
    calls: BTreeSet<String>,
    /// Branches through a register, which the walk cannot follow.
    indirect: Vec<String>,
    /// Floating-point (VFP) instructions.
    vfp: usize,
}

const CONDITIONS: [&str; 16] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
];

/// Branch mnemonics: b, bl, blx, bx, with an optional condition and `.n`/`.w` width.
fn branch_kind(mnemonic: &str) -> Option<&'static str> {
    let m = mnemonic.trim_end_matches(".n").trim_end_matches(".w");
    for base in ["blx", "bl", "bx", "b"] {
        if let Some(cond) = m.strip_prefix(base)
            && (cond.is_empty() || CONDITIONS.contains(&cond))
        {
            return Some(base);
        }
    }
    None
}

/// `00006daa <fingertip_tick>:` as (address, name).
fn symbol_header(line: &str) -> Option<(u64, &str)> {
    let (addr, name) = line.strip_suffix(">:")?.split_once(" <")?;
    Some((u64::from_str_radix(addr, 16).ok()?, name))
}

/// ARM mapping symbols (`$t`, `$d`, `$a`, `$t.1`, ...) mark code and data inside functions;
/// LLVM's objdump prints them as labels, GNU's hides them.
fn is_mapping_symbol(name: &str) -> bool {
    name.starts_with('$')
}

/// Parses `objdump -d` output (GNU or LLVM) into functions and their branch targets. A
/// branch into the function it is in is not a call; a target labelled with a mapping symbol
/// is resolved by address to the function that holds it.
fn parse_disassembly(text: &str) -> BTreeMap<String, Function> {
    let starts: BTreeMap<u64, &str> = text
        .lines()
        .filter_map(symbol_header)
        .filter(|(_, name)| !is_mapping_symbol(name))
        .collect();
    let containing = |addr: u64| starts.range(..=addr).next_back().map(|(_, n)| *n);
    let mut funcs: BTreeMap<String, Function> = BTreeMap::new();
    let mut current: Option<&str> = None;
    for line in text.lines() {
        if let Some((_, name)) = symbol_header(line) {
            if !is_mapping_symbol(name) {
                funcs.entry(name.to_owned()).or_default();
                current = Some(name);
            }
            continue;
        }
        let Some(cur) = current else { continue };
        // `    6dd8:\tbl\ta7f4 <sym>` (GNU) or `    6dd8: <bytes> \tbl\t0xa7f4 <sym> @ imm = #..` (LLVM)
        let mut parts = line.split('\t').map(str::trim).filter(|p| !p.is_empty());
        let Some(first) = parts.next() else { continue };
        if !first.ends_with(':') && !first.contains(": ") {
            continue;
        }
        let Some(mnemonic) = parts.next() else {
            continue;
        };
        let operands = parts.collect::<Vec<_>>().join(" ");
        let Some(f) = funcs.get_mut(cur) else {
            continue;
        };
        if mnemonic.starts_with('v') {
            f.vfp += 1;
        }
        let Some(kind) = branch_kind(mnemonic) else {
            continue;
        };
        // A direct branch names its target address first, then the symbol in brackets.
        let address = operands
            .split_whitespace()
            .next()
            .and_then(|a| u64::from_str_radix(a.trim_start_matches("0x"), 16).ok());
        let symbol = operands
            .split_once('<')
            .and_then(|(_, rest)| rest.split_once('>'))
            .map(|(t, _)| t.split('+').next().unwrap_or(t));
        // objdump names the symbol before the target; when that is a mapping symbol (LLVM),
        // the function is the one whose range holds the address.
        let target = match symbol {
            Some(name) if !is_mapping_symbol(name) => Some(name),
            _ => address.and_then(containing),
        };
        match target {
            Some(name) => {
                if name != cur {
                    f.calls.insert(name.to_owned());
                }
            }
            // `bx lr` returns; any other branch through a register goes who knows where.
            None if kind == "bx" && operands == "lr" => {}
            None if symbol.is_none() && (kind == "blx" || kind == "bx") => {
                f.indirect.push(line.trim().to_owned())
            }
            // A target outside every function: reported as a callee the walk cannot find.
            None => {
                f.calls.insert(format!("the target of `{}`", line.trim()));
            }
        }
    }
    funcs
}

/// 64-bit division and soft-float helpers (ARM EABI and libgcc names).
fn forbidden(name: &str) -> bool {
    const EXACT: [&str; 8] = [
        "__aeabi_ldivmod",
        "__aeabi_uldivmod",
        "__divdi3",
        "__udivdi3",
        "__moddi3",
        "__umoddi3",
        "__divmoddi4",
        "__udivmoddi4",
    ];
    if EXACT.contains(&name) || name.starts_with("__aeabi_d") || name.starts_with("__aeabi_f") {
        return true;
    }
    // libgcc/compiler-rt soft float: __adddf3, __mulsf3, __fixdfsi, __floatsidf, __eqdf2, ...
    name.strip_prefix("__").is_some_and(|rest| {
        !rest.starts_with("aeabi_") && (rest.contains("df") || rest.contains("sf"))
    })
}

/// What the walk from the tick found.
#[derive(Debug)]
struct Reach {
    /// Every function reachable from the roots, with the path that reaches it.
    paths: BTreeMap<String, Vec<String>>,
    vfp: usize,
}

/// Walks the call graph from `roots`; fails on a forbidden helper or an indirect branch.
fn check_tick_path(funcs: &BTreeMap<String, Function>, roots: &[&str]) -> Result<Reach, String> {
    let mut paths: BTreeMap<String, Vec<String>> = BTreeMap::new();
    let mut queue = VecDeque::new();
    for r in roots {
        if !funcs.contains_key(*r) {
            return Err(format!("no function {r} in the disassembly"));
        }
        paths.insert((*r).to_owned(), vec![(*r).to_owned()]);
        queue.push_back((*r).to_owned());
    }
    let mut problems = Vec::new();
    let mut vfp = 0;
    while let Some(name) = queue.pop_front() {
        let path = paths.get(&name).cloned().unwrap_or_default();
        if forbidden(&name) {
            problems.push(format!("{name} is reachable: {}", path.join(" -> ")));
            continue;
        }
        let Some(f) = funcs.get(&name) else {
            problems.push(format!(
                "{name} (reached by {}) is not in the disassembly, so its body cannot be checked",
                path.join(" -> ")
            ));
            continue;
        };
        vfp += f.vfp;
        for i in &f.indirect {
            problems.push(format!(
                "indirect branch in {} (reached by {}): `{i}` cannot be followed",
                name,
                path.join(" -> ")
            ));
        }
        for callee in &f.calls {
            if !paths.contains_key(callee) {
                let mut p = path.clone();
                p.push(callee.clone());
                paths.insert(callee.clone(), p);
                queue.push_back(callee.clone());
            }
        }
    }
    if problems.is_empty() {
        Ok(Reach { paths, vfp })
    } else {
        Err(problems.join("\n"))
    }
}

// ---- The tests ----------------------------------------------------------------------------

/// On the PC already, the tick generated at build time for the approach configuration (the
/// firmware's) computes what the interpreter computes, tick for tick, over the golden runs
/// (faulty channels included), whole and stage by stage.
#[test]
fn generated_tick_matches_the_interpreter() {
    use detector_core::{DetectorTick, Output};
    use fingertip_qemu::ApproachTick;
    let bytes = golden_trace().expect("the golden trace");
    let trace = Trace::parse(&bytes).expect("parses");
    let detector = fingertip_qemu::detector().expect("the embedded configuration");
    let interpreted = replay(&detector, &trace, plain_tick(&detector), |_| {});
    let mut out = Output::default();
    let whole = replay(
        &detector,
        &trace,
        |s, now, inputs, _| {
            ApproachTick.tick_into(s, now, inputs, &mut out);
            out.clone()
        },
        |_| {},
    );
    let staged = replay(
        &detector,
        &trace,
        |s, now, inputs, _| staged_tick(&ApproachTick, s, now, inputs),
        |_| {},
    );
    assert!(interpreted.ticks > 0 && interpreted.confirms > 0);
    assert_eq!(whole, interpreted, "the generated tick differs");
    assert_eq!(staged, interpreted, "the generated stages differ");
}

#[test]
fn qemu_digest_matches_the_host() {
    let Some(run) = run() else { return };
    let report = parse_report(&run.first).expect("the program's report");

    let path = workspace_root().join("configs/approach.toml");
    let text = std::fs::read_to_string(&path).expect("configs/approach.toml");
    let config = Config::from_toml(&text).expect("approach.toml is valid");
    let image = detector_build::compile(&config)
        .expect("approach.toml compiles")
        .image();
    assert_eq!(
        fingertip_qemu::IMAGE,
        &image[..],
        "the detector image the program embeds is not configs/approach.toml's"
    );
    let crc = detector_build::image_crc(&image);
    let header = fields(&report.header);
    assert_eq!(
        header.get("image_crc"),
        Some(&format!("{crc:08x}")),
        "the program runs another detector image than the host's: {}",
        report.header
    );
    assert_eq!(
        detector_core::DetectorTick::image_crc(&fingertip_qemu::ApproachTick),
        Some(crc),
        "the generated tick was generated from another image"
    );
    let detector = detector_build::build(&config).expect("approach.toml builds");
    let trace = Trace::parse(&run.trace).expect("the golden trace");
    let mut segments = Vec::new();
    let host = replay(&detector, &trace, plain_tick(&detector), |r| {
        segments.push(
            SegmentLine {
                report: r,
                detector: &detector,
            }
            .to_string(),
        )
    });
    let host_staged = replay(
        &detector,
        &trace,
        |s, n, i, _| staged_tick(&detector, s, n, i),
        |_| {},
    );
    println!("{}", report.header);
    for line in &report.segments {
        println!("{line}");
    }
    println!("host digest: {host}");
    println!("QEMU digest: {}", report.digest_tick);
    assert!(host.ticks > 0, "the trace has no ticks");
    assert_eq!(
        host, host_staged,
        "on the host, the four stages differ from tick()"
    );
    assert_eq!(
        report.digest_tick,
        host.to_string(),
        "the Cortex-M4 and the PC computed different results (the first CRC that differs names the stage)"
    );
    assert_eq!(
        report.digest_stages, report.digest_tick,
        "on the Cortex-M4, the four stages called one by one differ from tick()"
    );
    assert_eq!(
        report.digest_interpreted, report.digest_tick,
        "on the Cortex-M4, the interpreter differs from the generated tick"
    );
    assert_eq!(report.segments, segments, "per-segment decisions differ");
}

#[test]
fn qemu_instructions_per_tick_within_the_budget() {
    let Some(run) = run() else { return };
    let first = parse_report(&run.first).expect("the program's report");
    let second = parse_report(&run.second).expect("the second run's report");
    check_calibration(&first).expect("instruction counting");
    assert_eq!(
        first.insns, second.insns,
        "two runs of the same program counted different instructions"
    );
    println!(
        "instructions per tick on QEMU mps2-an386 (Cortex-M4), approach configuration, {} ticks:\n{}",
        first.insns.get("tick").map_or(0, |i| i.n),
        table(&first)
    );
    if let Some(save) = first.insns.get("state_save") {
        println!(
            "the flight recorder's saved state (State::save, once per 50 ms segment): {} instructions",
            save.max
        );
    }
    let tick = first.insns.get("tick").expect("tick counts");
    if tick.max > AIM {
        println!(
            "note: the worst tick ({}, at segment:record {}) is above the aim of {AIM}",
            tick.max, tick.max_at
        );
    }
    check_budget(&first).expect("instruction budget");
}

#[test]
fn qemu_tick_calls_no_64_bit_division_or_soft_float() {
    let Some(run) = run() else { return };
    let Some(objdump) = objdump_binary() else {
        unavailable("no ARM objdump (arm-none-eabi-objdump or llvm-objdump)");
        return;
    };
    let out = Command::new(&objdump)
        .args(["-d", "--no-show-raw-insn"])
        .arg(&run.elf)
        .output()
        .expect("running objdump");
    assert!(
        out.status.success(),
        "{} failed: {}",
        objdump.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let funcs = parse_disassembly(&String::from_utf8_lossy(&out.stdout));
    let reach = check_tick_path(&funcs, &ROOTS)
        .unwrap_or_else(|e| panic!("the tick path is not clean ({}):\n{e}", objdump.display()));
    println!(
        "{} functions reachable from the tick, {} VFP instructions among them:",
        reach.paths.len(),
        reach.vfp
    );
    for (name, path) in &reach.paths {
        if name.contains("panicking") {
            println!("  {name} (a panic path: {})", path.join(" -> "));
        } else {
            println!("  {name}");
        }
    }
}

// ---- The checks themselves can fail ----------------------------------------------------

const FAKE_DISASSEMBLY: &str = "
00001000 <fingertip_tick>:
    1000:\tpush\t{r7, lr}
    1002:\tbl\t2000 <helper>
    1006:\tbne.n\t1002 <fingertip_tick+0x2>
    1008:\tb.w\t3000 <tail>

00002000 <helper>:
    2000:\tbl\t4000 <__aeabi_ldivmod>
    2004:\tbx\tlr

00003000 <tail>:
    3000:\tvmul.f32\ts0, s0, s1
    3004:\tbx\tlr

00004000 <__aeabi_ldivmod>:
    4000:\tbx\tlr

00005000 <unrelated>:
    5000:\tbl\t6000 <__aeabi_dmul>
    5004:\tblx\tr3

00006000 <__aeabi_dmul>:
    6000:\tbx\tlr
";

#[test]
fn call_graph_finds_a_helper_behind_a_call() {
    let funcs = parse_disassembly(FAKE_DISASSEMBLY);
    assert_eq!(
        funcs["fingertip_tick"].calls,
        BTreeSet::from(["helper".to_owned(), "tail".to_owned()])
    );
    let err = check_tick_path(&funcs, &["fingertip_tick"]).expect_err("ldivmod is reachable");
    assert!(
        err.contains("__aeabi_ldivmod is reachable: fingertip_tick -> helper -> __aeabi_ldivmod"),
        "{err}"
    );
    // What only unreachable code calls does not count.
    assert!(!err.contains("dmul"), "{err}");
    let clean = check_tick_path(&funcs, &["tail"]).expect("tail calls nothing");
    assert_eq!(clean.vfp, 1);
    assert!(check_tick_path(&funcs, &["missing"]).is_err());
}

const FAKE_LLVM_DISASSEMBLY: &str = "
00001000 <fingertip_tick>:
    1000:      \tpush\t{r7, lr}
    1002:      \tbl\t0x2000 <helper> @ imm = #4092
    1006:      \tb.w\t0x800 <missing> @ imm = #-2054
    100a:      \tbne.w\t0x1002 <$t+0x2> @ imm = #-12
    100e:      \tbeq.w\t0x2004 <$t+0x1004> @ imm = #4082

00001010 <$d>:
    1010:\t00 00 00 00\t.word\t0x00000000

00002000 <helper>:
    2000:      \tbl\t0x4000 <__aeabi_uldivmod> @ imm = #8188
    2004:      \tbx\tlr
";

#[test]
fn call_graph_reads_llvm_objdump_and_flags_unknown_targets() {
    let funcs = parse_disassembly(FAKE_LLVM_DISASSEMBLY);
    assert_eq!(
        funcs["fingertip_tick"].calls,
        BTreeSet::from(["helper".to_owned(), "missing".to_owned()])
    );
    let err = check_tick_path(&funcs, &["fingertip_tick"]).expect_err("uldivmod is reachable");
    assert!(
        err.contains("__aeabi_uldivmod is reachable: fingertip_tick -> helper -> __aeabi_uldivmod"),
        "{err}"
    );
    assert!(
        err.contains("missing (reached by fingertip_tick -> missing)"),
        "{err}"
    );
}

#[test]
fn call_graph_rejects_indirect_branches() {
    let funcs = parse_disassembly(FAKE_DISASSEMBLY);
    let err = check_tick_path(&funcs, &["unrelated"]).expect_err("blx r3 and dmul");
    assert!(err.contains("blx\tr3"), "{err}");
    assert!(err.contains("__aeabi_dmul is reachable"), "{err}");
}

#[test]
fn forbidden_names() {
    for n in [
        "__aeabi_ldivmod",
        "__aeabi_uldivmod",
        "__aeabi_dadd",
        "__aeabi_f2d",
        "__aeabi_fmul",
        "__adddf3",
        "__fixdfsi",
        "__floatsisf",
        "__udivmoddi4",
    ] {
        assert!(forbidden(n), "{n}");
    }
    for n in [
        "__aeabi_memcpy4",
        "__aeabi_memclr4",
        "__aeabi_uidiv",
        "fingertip_tick",
        "_ZN13detector_core8detector4eval17h789152b4ad058b9bE",
    ] {
        assert!(!forbidden(n), "{n}");
    }
}

const FAKE_REPORT: &str = "\
fingertip-qemu config=configs/approach.toml image_crc=00000000 trace=synthetic segments=1 ticks=2
calibration nops=4096 counts=104858 overhead=1 check256=256
segment 0 a start=0 ticks=2 contact=alert@-,confirm@-
digest tick: inputs=00000000 features=00000000 terms=00000000 outputs=00000000 ticks=2
digest stages: inputs=00000000 features=00000000 terms=00000000 outputs=00000000 ticks=2
digest interpreted: inputs=00000000 features=00000000 terms=00000000 outputs=00000000 ticks=2
insns tick: mean=1400.50 min=1300 max=2501 max_at=0:1 n=2
insns interpreted: mean=1500.50 min=1400 max=1600 max_at=0:1 n=2
insns features: mean=400.00 min=400 max=400 max_at=0:0 n=2
insns confidences: mean=600.00 min=600 max=600 max_at=0:0 n=2
insns combine: mean=200.00 min=200 max=200 max_at=0:0 n=2
insns decide: mean=100.00 min=100 max=100 max_at=0:0 n=2
insns stages_sum: mean=1300.00 min=1300 max=1300 max_at=0:0 n=2
done
";

#[test]
fn budget_and_calibration_checks_can_fail() {
    let over = FAKE_REPORT.replace("max=2501", &format!("max={}", BUDGET + 1));
    let r = parse_report(&over).expect("fake report parses");
    assert_eq!(r.insns["tick"].max, BUDGET + 1);
    let err = check_budget(&r).expect_err("one over the budget");
    assert!(
        err.contains(&(BUDGET + 1).to_string()) && err.contains("0:1"),
        "{err}"
    );
    check_calibration(&r).expect("fake calibration is right");

    let slow_clock = FAKE_REPORT.replace("counts=104858", "counts=4096");
    let r = parse_report(&slow_clock).expect("parses");
    assert!(check_calibration(&r).is_err(), "no -icount must be noticed");
    let off_by_one = FAKE_REPORT.replace("check256=256", "check256=255");
    assert!(check_calibration(&parse_report(&off_by_one).expect("parses")).is_err());

    let within = FAKE_REPORT.replace("max=2501", &format!("max={BUDGET}"));
    check_budget(&parse_report(&within).expect("parses")).expect("the budget is within");

    assert!(parse_report("fingertip-qemu\nerror: panic at x.rs:1\n").is_err());
    let no_counts: String = FAKE_REPORT
        .lines()
        .filter(|l| !l.starts_with("insns decide"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(parse_report(&no_counts).is_err());
}

// ---- The shared pieces -----------------------------------------------------------------------

#[test]
fn crc32_matches_its_check_value() {
    use fingertip_qemu::digest::Crc32;
    let mut c = Crc32::new();
    c.update(b"123456789");
    assert_eq!(c.value(), 0xCBF4_3926, "CRC-32/ISO-HDLC check value");
    let mut split = Crc32::new();
    split.update(b"1234");
    split.update(b"56789");
    assert_eq!(split.value(), c.value());
    c.update(&[0]);
    assert_ne!(c.value(), 0xCBF4_3926);
}

#[test]
fn trace_format_round_trips_and_rejects_damage() {
    use fingertip_qemu::trace::TraceError;
    let mut bytes = Vec::new();
    {
        let mut enc = Encoder::new(|b: &[u8]| bytes.extend_from_slice(b), 3, 2).expect("header");
        enc.segment(0, "first", 7, 2).expect("segment");
        enc.record(0b010, &[1, -2, 3]).expect("record");
        enc.record(0, &[i32::MIN, i32::MAX, 0]).expect("record");
        enc.segment(1, "second", u32::MAX, 1).expect("segment");
        enc.record(0, &[4, 5, 6]).expect("record");
        assert!(
            enc.record(0, &[1, 2]).is_err(),
            "a record of the wrong width"
        );
        assert!(
            enc.segment(2, &"x".repeat(33), 0, 0).is_err(),
            "a name too long"
        );
    }
    let t = Trace::parse(&bytes).expect("round trip");
    assert_eq!((t.channels(), t.segment_count(), t.ticks()), (3, 2, 3));
    let segs: Vec<_> = t.segments().collect();
    assert_eq!(segs[0].name(), "first");
    assert_eq!(segs[1].start_tick(), u32::MAX);
    let first: Vec<_> = segs[0].records().collect();
    assert_eq!(first[0].faults, 0b010);
    assert_eq!(first[0].samples[..3], [1, -2, 3]);
    assert_eq!(first[1].samples[..4], [i32::MIN, i32::MAX, 0, 0]);

    assert_eq!(
        Trace::parse(&bytes[..bytes.len() - 1]).err(),
        Some(TraceError::Truncated { segment: Some(1) })
    );
    assert_eq!(
        Trace::parse(&bytes[..5]).err(),
        Some(TraceError::Truncated { segment: None })
    );
    let mut trailing = bytes.clone();
    trailing.push(0);
    assert_eq!(
        Trace::parse(&trailing).err(),
        Some(TraceError::Trailing { bytes: 1 })
    );
    let mut magic = bytes.clone();
    magic[0] = b'X';
    assert_eq!(Trace::parse(&magic).err(), Some(TraceError::Magic));
    let mut version = bytes.clone();
    version[4] = 9;
    assert_eq!(Trace::parse(&version).err(), Some(TraceError::Version(9)));
    let mut channels = bytes;
    channels[6] = 17;
    assert_eq!(
        Trace::parse(&channels).err(),
        Some(TraceError::Channels(17))
    );
}
