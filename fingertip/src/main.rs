//! `fingertip`: design and prove a fingertip event detector on the PC.
//!
//! Simulate the paper's Table 1 runs, replay any trace through the same fixed-point core
//! that runs on the chip, evaluate many randomized runs, and plot confidences over time.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context as _, Result, anyhow, bail};
use clap::{Parser, Subcommand};
use detector_build::Config;
use detector_core::Detector;
use fingertip::can_tools::busload::{self, BusConfig};
use fingertip::can_tools::candump::write_log_line;
use fingertip::can_tools::decode::{self, DecodeOptions};
use fingertip::output::{Kind, OutputPlan};
use fingertip::plot::{self, RunPlot};
use fingertip::replay::{self, DecisionRecord};
use fingertip::score::{self, Outcome, ScenarioReport};
use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::{Trace, TraceReader};
use fingertip_can::{BusFormat, NodeId, Status, Transmitter, TxState};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

/// Runs' traces reuse the pages of the ones before (docs/simulator.md, Speed).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[derive(Parser)]
#[command(
    name = "fingertip",
    version,
    about = "Design and prove a fingertip event detector on the PC"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a scenario and write its trace (CSV; see docs/trace-format.md).
    Simulate {
        /// Scenario name; `fingertip scenarios` lists them.
        scenario: String,
        /// Seed of the noise (and of the parameters, with --randomize).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Draw speeds, stiffness, masses, onset, noise and gains from their ranges instead
        /// of the nominal Table 1 values.
        #[arg(long)]
        randomize: bool,
        /// Length of the run in seconds (default: lead-in + onset + 130 ms for single-event
        /// runs, 10 s for free motion).
        #[arg(long)]
        duration: Option<f64>,
        /// How long the motion runs before a single-event run's event window (ms, 0 to
        /// 10,000): the event comes this much later than its drawn onset, after a detector
        /// started with the run has learnt its sensors' usual readings.
        #[arg(long, default_value_t = 0.0)]
        lead_in_ms: f64,
        /// Multiplies every sensor's white noise beyond its drawn noise scale (0 to 10): a
        /// run on sensors noisier (or quieter) than the envelope's.
        #[arg(long, default_value_t = 1.0)]
        noise_factor: f64,
        /// The resolution of the tip position the controller reads from its joint encoders
        /// (µm, 0.1 to 100; the envelope's is 1): a run on an arm whose encoders are coarser.
        #[arg(long, default_value_t = sim::DEFAULT_ENCODER_RESOLUTION_UM)]
        encoder_um: f64,
        /// The corner of an AC coupling of the stress-rate film's amplifier (Hz, 0 to 10;
        /// the envelope's film has none): a run whose film reads a steady rate of loading
        /// as a rate that dies away.
        #[arg(long, default_value_t = 0.0)]
        film_highpass_hz: f64,
        /// The corner of the low-pass through which the joint loops take their velocity
        /// from the encoders' difference (Hz, 0 to 2,000; the envelope's loops read the
        /// true velocity): a run on an arm that shakes itself with its encoders' steps. Its
        /// trace starts 0.5 s into the run, the arm already shaking.
        #[arg(long, default_value_t = 0.0)]
        velocity_filter_hz: f64,
        /// The frame the controller reports its context in, turned by this angle from the
        /// pad's (degrees, -90 to 90; the protocol's and the envelope's is 0): a run from a
        /// controller whose pad frame is off, or that reports in a fixed task frame.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        context_turned_deg: f64,
        /// With --randomize: draw a parameter from another range than the envelope's,
        /// `group.name=min..max` as docs/simulator.md names it (e.g.
        /// `plant.control_bandwidth=10..15`); may be repeated.
        #[arg(
            long = "range",
            value_name = "GROUP.NAME=MIN..MAX",
            requires = "randomize"
        )]
        ranges: Vec<sim::ParamRange>,
        /// For a link collision or a contact: the obstacle or the object gives way this
        /// long after the first touch (ms, 0 to 1,000), and the run becomes a blow of the
        /// event's own force on the link or the pad, read the same bit for bit until then
        /// (its labels stay the event's; `--example twins`).
        #[arg(long)]
        gives_way_ms: Option<f64>,
        /// Output file; standard output when absent.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// List the scenarios and the event each should raise.
    Scenarios,
    /// Run the detector over a trace: confirmations with their latency, per-tick confidences,
    /// a plot.
    Replay {
        /// The trace (CSV).
        trace: PathBuf,
        /// Detector configuration (TOML); the approach configuration when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Write per-tick confidences here (CSV).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Write a plot here (.png or .svg).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Print one JSON object to standard output instead of text.
        #[arg(long)]
        json: bool,
        /// Also write the CAN frames the firmware would have sent, timestamped, in candump
        /// log format (`(sec.usec) can0 ID##1HEX` for CAN FD frames, `ID#HEX` classic).
        #[arg(long)]
        candump: Option<PathBuf>,
        /// The fingertip's CAN node id (0..=14) for --candump.
        #[arg(long, default_value_t = 0)]
        node: u8,
        /// With --candump: the frames of a classic CAN bus instead of CAN FD.
        #[arg(long, requires = "candump")]
        classic: bool,
    },
    /// Decode a candump log (log or screen format): confidences, events, status, and every
    /// malformed line, bad CRC and counter gap by line number.
    Decode {
        /// The log file.
        file: PathBuf,
        /// Configuration whose event names to show; the approach configuration when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Only this node's frames (0..=14), and the context frames of its group.
        #[arg(long)]
        node: Option<u8>,
        /// Print events, status and problems only, not every stream sample.
        #[arg(long)]
        quiet: bool,
        /// Plot the confidence stream and events here (.png or .svg).
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Decode live SocketCAN traffic (Linux) the way `decode` reads a log.
    Monitor {
        /// The CAN interface, e.g. can0 or vcan0.
        #[arg(long)]
        iface: String,
        /// Configuration whose event names to show; the approach configuration when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Only this node's frames (0..=14), and the context frames of its group.
        #[arg(long)]
        node: Option<u8>,
        /// Print events, status and problems only.
        #[arg(long)]
        quiet: bool,
        /// Stop after this many frames.
        #[arg(long)]
        frames: Option<usize>,
        /// Stop after this many seconds.
        #[arg(long)]
        seconds: Option<f64>,
        /// Also log the fingertips' frames here in candump log format.
        #[arg(long)]
        candump: Option<PathBuf>,
    },
    /// Load a detector into a running fingertip over its service channel (SocketCAN, CAN
    /// FD): builds the configuration's image, sends it, and reports the CRC-32 the
    /// fingertip checked. It takes over at the next phase entry, or at once with
    /// --activate.
    Load {
        /// Detector configuration (TOML).
        config: PathBuf,
        /// The fingertip's node id (0..=14).
        #[arg(long)]
        node: u8,
        /// The CAN interface, e.g. can0 or vcan0.
        #[arg(long, default_value = "can0")]
        iface: String,
        /// Put it in service at the fingertip's next tick instead of the next phase entry.
        #[arg(long)]
        activate: bool,
        /// Also save it to a flash slot, so the fingertip boots with it: the fingertip
        /// enters its service state for the write (its detector out of service for up to
        /// 0.2 s), then leaves it.
        #[arg(long)]
        save: bool,
    },
    /// Read or write a fingertip's calibration keys and node id (its flash store):
    /// `force_x.gain`, `force_x.zero`, `force_x.drift`, `force_x.t_ref` (and the same for
    /// force_y, skin_accel, stress_rate), `node_id`. `KEY` reads, `KEY=VALUE` writes
    /// (in the fingertip's service state, entered and left around the writes).
    Calibrate {
        /// The fingertip's node id (0..=14).
        #[arg(long)]
        node: u8,
        /// The CAN interface, e.g. can0 or vcan0.
        #[arg(long, default_value = "can0")]
        iface: String,
        /// Keys to read (`KEY`) or write (`KEY=VALUE`); every key when none is given.
        keys: Vec<String>,
    },
    /// Read a fingertip's flight recording out (the detector's inputs tick by tick, at
    /// least 50 ms before and 50 ms after the confirmation or fault that froze it) and
    /// write it as a trace that `fingertip replay` runs as the fingertip did: the same
    /// confirmations at the same ticks, checked here before it is written. Then re-arms
    /// the recorder (unless --keep). With --follow, collects every recording as it
    /// freezes, for a corpus to fit on (docs/recordings.md).
    FetchRecording {
        /// The configuration the fingertip runs (TOML): names the columns; its image's
        /// CRC-32 must be the recording's.
        #[arg(long)]
        config: PathBuf,
        /// The trace to write.
        #[arg(long, required_unless_present = "follow", conflicts_with = "follow")]
        out: Option<PathBuf>,
        /// Wait for each recording to freeze and write it into this directory
        /// (`node<N>-tick<first tick>.csv`), re-arming after each, until --count
        /// recordings or Ctrl-C. The fingertip records nothing while one waits to be
        /// read (about 0.15 s).
        #[arg(long, conflicts_with = "keep")]
        follow: Option<PathBuf>,
        /// With --follow: stop after this many recordings.
        #[arg(long, requires = "follow")]
        count: Option<usize>,
        /// The fingertip's node id (0..=14).
        #[arg(long)]
        node: u8,
        /// The CAN interface, e.g. can0 or vcan0.
        #[arg(long, default_value = "can0")]
        iface: String,
        /// Leave the recording frozen in the fingertip (to read it again).
        #[arg(long)]
        keep: bool,
    },
    /// What a fingertip runs: firmware version and build, the detector in service (its
    /// CRC-32 and name) and any waiting for its phase boundary.
    Info {
        /// The fingertip's node id (0..=14).
        #[arg(long)]
        node: u8,
        /// The CAN interface, e.g. can0 or vcan0.
        #[arg(long, default_value = "can0")]
        iface: String,
    },
    /// Worst-case CAN bus load (CAN FD, or classic CAN) and event-frame latency for N
    /// fingertips, both directions, bit stuffing in both phases.
    Busload {
        /// Fingertips on the bus (1..=15).
        #[arg(long, default_value_t = 1)]
        fingertips: u32,
        /// Ticks per confidence-stream sample (default 20 on CAN FD, 100 with --classic).
        #[arg(long)]
        decimation: Option<u32>,
        /// Control cycles per second: the controller's context to each fingertip.
        #[arg(long)]
        context_hz: Option<f64>,
        /// Arbitration (nominal) bit rate in bit/s.
        #[arg(long)]
        bitrate: Option<u32>,
        /// CAN FD data-phase bit rate in bit/s.
        #[arg(long, conflicts_with = "classic")]
        data_bitrate: Option<u32>,
        /// Classic CAN instead of CAN FD.
        #[arg(long)]
        classic: bool,
    },
    /// Randomized runs of every scenario, or labelled recordings (`--traces`): detections,
    /// errors, latency, false alarms.
    Evaluate {
        /// Randomized runs per scenario.
        #[arg(long, default_value_t = 1000)]
        runs: usize,
        /// Base seed; run k of a scenario uses a seed derived from it, so that two base
        /// seeds draw disjoint runs: tune a configuration on one (say 100) and report it on
        /// another (the default, 1).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Score labelled recordings instead of simulated runs: trace files, or directories
        /// searched (recursively) for `*.csv`. Each run of rows with the same `truth` label
        /// is one event.
        #[arg(long, num_args = 1.., conflicts_with_all = ["runs", "seed", "free_hours", "lead_in_ms", "noise_factor", "encoder_um", "film_highpass_hz", "velocity_filter_hz", "context_turned_deg", "ranges"])]
        traces: Vec<PathBuf>,
        /// With `--traces`: how long after a labelled event's end a confirmation still
        /// counts for it (ms).
        #[arg(long, default_value_t = fingertip::corpus::DEFAULT_AFTER_MS)]
        after_ms: f64,
        /// Detector configuration (TOML); the approach configuration when absent. Give it
        /// up to four times to compare detectors on the very same runs, side by side.
        #[arg(long)]
        config: Vec<PathBuf>,
        /// Hours of simulated event-free motion for the false-alarm rate.
        #[arg(long, default_value_t = 1.0)]
        free_hours: f64,
        /// How long each single-event run's motion runs before its event window (ms, 0 to
        /// 10,000): 0, the default, starts the detector cold 15-40 ms before the event, as
        /// the paper does; a lead-in shows which misses come from that cold start.
        #[arg(long, default_value_t = 0.0, conflicts_with = "traces")]
        lead_in_ms: f64,
        /// Multiplies every sensor's white noise beyond its drawn noise scale (0 to 10):
        /// how the detectors fare on sensors noisier (or quieter) than the envelope's, the
        /// false alarms in event-free motion included.
        #[arg(long, default_value_t = 1.0)]
        noise_factor: f64,
        /// The resolution of the tip position the controller reads from its joint encoders
        /// (µm, 0.1 to 100; the envelope's is 1): how the detectors fare on an arm whose
        /// encoders are coarser, its loops acting on them.
        #[arg(long, default_value_t = sim::DEFAULT_ENCODER_RESOLUTION_UM)]
        encoder_um: f64,
        /// The corner of an AC coupling of the stress-rate film's amplifier (Hz, 0 to 10;
        /// the envelope's film has none): how the detectors fare on a film that reads a
        /// steady rate of loading as a rate that dies away over 1 / (2 pi f) s.
        #[arg(long, default_value_t = 0.0)]
        film_highpass_hz: f64,
        /// The corner of the low-pass through which the joint loops take their velocity
        /// from the encoders' difference (Hz, 0 to 2,000; the envelope's loops read the
        /// true velocity): how the detectors fare on an arm that shakes itself with its
        /// encoders' steps, most where a joint is slow.
        #[arg(long, default_value_t = 0.0)]
        velocity_filter_hz: f64,
        /// The frame the controller reports its context in, turned by this angle from the
        /// pad's (degrees, -90 to 90; the protocol's and the envelope's is 0): how the
        /// detectors fare on a controller whose model of the pad's orientation is off, or
        /// that reports in a task frame the pad turns away from.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        context_turned_deg: f64,
        /// Draw a parameter from another range than the envelope's, `group.name=min..max`
        /// as docs/simulator.md names it: how the detectors fare on one arm's range (e.g.
        /// `plant.control_bandwidth=10..15`, the slow loops) or beyond the envelope; may be
        /// repeated.
        #[arg(long = "range", value_name = "GROUP.NAME=MIN..MAX")]
        ranges: Vec<sim::ParamRange>,
        /// Also write the report as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Also plot, per scenario, each run's peak confidence of its expected event (the
        /// highest of any event where none is expected) against the parameter its runs are
        /// binned by, coloured by outcome (.png or .svg; the first configuration's).
        #[arg(long, conflicts_with = "traces")]
        plot_bins: Option<PathBuf>,
        /// Also write one row per run here (.csv): its scenario, seed and bin, each
        /// detector's outcome, latency and peak confidence, and everything the run drew
        /// (its `param.*` and what was struck, as `fingertip simulate` records them), to
        /// look for a weak region along any parameter, not only the binned one.
        #[arg(long, conflicts_with = "traces")]
        runs_csv: Option<PathBuf>,
    },
    /// Each feature's values in labelled events and outside them, from recordings: how
    /// well one threshold on it tells each event from the rest, and a figure.
    Features {
        /// Labelled recordings: trace files, or directories searched (recursively) for
        /// `*.csv`.
        #[arg(long, num_args = 1.., required = true)]
        traces: Vec<PathBuf>,
        /// Detector configuration (TOML): its features are computed; the approach
        /// configuration when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// How long after each labelled onset a feature's values count for the event (ms).
        #[arg(long, default_value_t = 50.0)]
        window_ms: f64,
        /// How long after a labelled event's end the values are left out, neither the
        /// event's nor outside (ms).
        #[arg(long, default_value_t = fingertip::corpus::DEFAULT_AFTER_MS)]
        after_ms: f64,
        /// Write the distributions, one panel per feature (.png or .svg).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Also write the table as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Fit a configuration's numbers to labelled recordings, keeping its structure: every
    /// term's CDF, the sensor weights and the confirm levels (docs/recordings.md), with
    /// cross-validated figures by recording.
    Fit {
        /// Labelled recordings: trace files, or directories searched (recursively) for
        /// `*.csv`.
        #[arg(long, num_args = 1.., required = true)]
        traces: Vec<PathBuf>,
        /// The configuration whose structure is kept (TOML); the approach configuration
        /// when absent.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Where to write the fitted configuration (TOML).
        #[arg(long)]
        out: PathBuf,
        /// How long after each labelled onset a feature's values count for the event (ms):
        /// what the detector has to decide on.
        #[arg(long, default_value_t = 20.0)]
        window_ms: f64,
        /// How long after a labelled event's end a confirmation still counts for it (ms).
        #[arg(long, default_value_t = fingertip::corpus::DEFAULT_AFTER_MS)]
        after_ms: f64,
        /// False confirmations per hour outside events that the levels may cost, shared
        /// among the labelled events.
        #[arg(long, default_value_t = 1.0)]
        budget: f64,
        /// Folds of the cross-validation, by recording (0 or 1: none). Each fold is one
        /// more fit held in memory at once.
        #[arg(long, default_value_t = 5)]
        folds: usize,
    },
    /// Identify a self-motion cancellation (the `cancel` stage) from event-free motion: the
    /// gain and cut-off with which the low-passed commanded motion best explains a sensor.
    Identify {
        /// A trace of motion without events (rows with a `truth` label are left out).
        trace: PathBuf,
        /// The sensor channel to cancel, e.g. `force_x`.
        #[arg(long)]
        input: String,
        /// The commanded motion that explains it, e.g. `acc_des_x`.
        #[arg(long)]
        motion: String,
        /// The configuration whose channel scales give the gain in the detector's units
        /// (the approach configuration when absent).
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Simulate the four runs of the paper's figure 4 and a sudden acceleration, print who
    /// was detected when, and write the figures.
    Demo {
        /// Where to write the figures.
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {}", one_line(&error));
            ExitCode::FAILURE
        }
    }
}

/// The error and its causes on one line, outermost first, each joined by `: `. A cause
/// whose text is already shown is skipped: many errors print their source in their own
/// message, and a file name or reason is said once.
fn one_line(error: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate {
            scenario,
            seed,
            randomize,
            duration,
            lead_in_ms,
            noise_factor,
            encoder_um,
            film_highpass_hz,
            velocity_filter_hz,
            context_turned_deg,
            ranges,
            gives_way_ms,
            out,
        } => simulate(
            &scenario,
            &SimOptions {
                seed,
                randomize,
                duration_s: duration,
                lead_in_s: lead_in_ms / 1000.0,
                noise_factor,
                encoder_resolution_um: encoder_um,
                film_highpass_hz,
                velocity_filter_hz,
                context_turned_deg,
                ranges,
                gives_way_s: gives_way_ms.map(|ms| ms / 1000.0),
                ..SimOptions::default()
            },
            out.as_deref(),
        ),
        Command::Scenarios => {
            for s in Scenario::all() {
                println!("{:<26} {}", s.name(), s.expected().unwrap_or("none"));
            }
            Ok(())
        }
        Command::Replay {
            trace,
            config,
            out,
            plot,
            json,
            candump,
            node,
            classic,
        } => {
            let format = if classic {
                BusFormat::Classic
            } else {
                BusFormat::Fd
            };
            let can = match candump {
                Some(path) => Some((path, node_id(node)?, format)),
                None => None,
            };
            replay_cmd(
                &trace,
                config.as_deref(),
                out.as_deref(),
                plot.as_deref(),
                json,
                can,
            )
        }
        Command::Decode {
            file,
            config,
            node,
            quiet,
            plot,
        } => decode_cmd(&file, config.as_deref(), node, quiet, plot.as_deref()),
        Command::Monitor {
            iface,
            config,
            node,
            quiet,
            frames,
            seconds,
            candump,
        } => monitor_cmd(
            &iface,
            config.as_deref(),
            node,
            quiet,
            frames,
            seconds,
            candump.as_deref(),
        ),
        Command::Load {
            config,
            node,
            iface,
            activate,
            save,
        } => load_cmd(&config, node, &iface, activate, save),
        Command::Calibrate { node, iface, keys } => calibrate_cmd(node, &iface, &keys),
        Command::Info { node, iface } => info_cmd(node, &iface),
        Command::FetchRecording {
            config,
            out,
            follow,
            count,
            node,
            iface,
            keep,
        } => fetch_recording_cmd(
            &config,
            Fetch {
                out,
                follow,
                count,
                keep,
            },
            node,
            &iface,
        ),
        Command::Busload {
            fingertips,
            decimation,
            context_hz,
            bitrate,
            data_bitrate,
            classic,
        } => {
            let mut cfg = BusConfig::with_fingertips(fingertips);
            if classic {
                cfg.format = BusFormat::Classic;
                cfg.stream_decimation = u32::from(cfg.format.default_stream_decimation());
            }
            if let Some(d) = decimation {
                cfg.stream_decimation = d;
            }
            if let Some(h) = context_hz {
                cfg.context_hz = h;
            }
            if let Some(b) = bitrate {
                cfg.bitrate = b;
            }
            if let Some(b) = data_bitrate {
                cfg.data_bitrate = b;
            }
            let report = busload::analyse(&cfg)?;
            busload::write_report(&cfg, &report, &mut std::io::stdout().lock())?;
            Ok(())
        }
        Command::Evaluate {
            traces,
            after_ms,
            config,
            json,
            ..
        } if !traces.is_empty() => evaluate_traces(&traces, after_ms, &config, json.as_deref()),
        Command::Evaluate {
            runs,
            seed,
            config,
            free_hours,
            lead_in_ms,
            noise_factor,
            encoder_um,
            film_highpass_hz,
            velocity_filter_hz,
            context_turned_deg,
            ranges,
            json,
            plot_bins,
            runs_csv,
            ..
        } => evaluate(
            Plan {
                runs,
                seed,
                free_hours,
                lead_in_ms,
                noise_factor,
                encoder_um,
                film_highpass_hz,
                velocity_filter_hz,
                context_turned_deg,
                ranges,
            },
            &config,
            (json.as_deref(), plot_bins.as_deref(), runs_csv.as_deref()),
        ),
        Command::Features {
            traces,
            config,
            window_ms,
            after_ms,
            plot,
            json,
        } => features(
            &traces,
            config.as_deref(),
            (window_ms, after_ms),
            plot.as_deref(),
            json.as_deref(),
        ),
        Command::Fit {
            traces,
            config,
            out,
            window_ms,
            after_ms,
            budget,
            folds,
        } => fit(
            &traces,
            config.as_deref(),
            &out,
            fingertip::fit::FitOptions {
                window_s: window_ms / 1e3,
                after_s: after_ms / 1e3,
                budget_per_hour: budget,
            },
            folds,
        ),
        Command::Identify {
            trace,
            input,
            motion,
            config,
        } => identify(&trace, &input, &motion, config.as_deref()),
        Command::Demo { out } => demo(&out),
    }
}

/// The detector from `--config`, or the approach configuration, and the configuration's
/// name (its path). What is legal but probably unintended in it is printed as a warning.
fn load_detector(path: Option<&Path>) -> Result<(Detector, String)> {
    let (config, name) = match path {
        Some(p) => (detector_build::load(p)?, p.display().to_string()),
        None => {
            let name = "configs/approach.toml";
            let config = Config::from_toml(fingertip::APPROACH_TOML).context(name)?;
            (config, name.to_string())
        }
    };
    let compiled = detector_build::compile(&config).with_context(|| name.clone())?;
    for w in &compiled.warnings {
        eprintln!("warning: {name}: {w}");
    }
    let detector = compiled.detector().with_context(|| name.clone())?;
    Ok((detector, name))
}

/// The CAN node id of `--node`.
fn node_id(node: u8) -> Result<NodeId> {
    NodeId::new(node).ok_or_else(|| anyhow!("--node {node} must be within 0..=14"))
}

fn simulate(name: &str, opts: &SimOptions, out: Option<&Path>) -> Result<()> {
    let scenario: Scenario = name.parse()?;
    let trace = sim::simulate(&scenario, opts)?;
    match out {
        Some(path) => trace.write(path)?,
        None => print!("{}", trace.to_csv()),
    }
    Ok(())
}

/// A replay of a simulated run with every tick's confidences kept, for the demo's figures.
struct Recorded {
    decisions: Vec<DecisionRecord>,
    /// Per event of the configuration: name and confidence per tick.
    series: Series,
}

fn record(detector: &Detector, trace: &Trace) -> Result<Recorded> {
    let names: Vec<String> = detector.events().iter().map(|n| n.to_string()).collect();
    let mut values = vec![Vec::with_capacity(trace.len()); names.len()];
    let decisions = replay::replay(detector, trace, |_, _, out| {
        for (v, c) in values.iter_mut().zip(out.confidences.iter()) {
            v.push(c.to_f64());
        }
    })?;
    Ok(Recorded {
        decisions,
        series: names.into_iter().zip(values).collect(),
    })
}

fn truth_of(trace: &Trace) -> Option<(String, f64)> {
    trace
        .truth_onset()
        .and_then(|(row, event)| trace.time().get(row).map(|&t| (event.to_string(), t)))
}

/// The outputs of a command that has them, checked against each other and its inputs
/// before any work: `(path, kind)` where given.
fn plan_outputs(inputs: &[&Path], outputs: &[Option<(&Path, Kind)>]) -> Result<OutputPlan> {
    let given: Vec<(&Path, Kind)> = outputs.iter().flatten().copied().collect();
    Ok(OutputPlan::new(inputs, &given)?)
}

fn describe(d: &DecisionRecord, truth: Option<&(String, f64)>) -> String {
    let mut s = format!(
        "{:>9.2} ms  {:<15} {:<8} confidence {:.3}  onset {:.2} ms",
        d.t_s * 1e3,
        d.event,
        d.level,
        d.confidence,
        d.onset_s * 1e3
    );
    if let Some((event, onset)) = truth {
        let _ = write!(
            s,
            "  ({:+.2} ms after the true {event} onset)",
            (d.t_s - onset) * 1e3
        );
    }
    s
}

fn replay_cmd(
    path: &Path,
    config: Option<&Path>,
    out: Option<&Path>,
    plot_to: Option<&Path>,
    json: bool,
    candump: Option<(PathBuf, NodeId, BusFormat)>,
) -> Result<()> {
    let inputs: Vec<&Path> = std::iter::once(path).chain(config).collect();
    // Staged in this order: confidences, figure, CAN log; committed together at the end.
    let plan = plan_outputs(
        &inputs,
        &[
            out.map(|p| (p, Kind::File)),
            plot_to.map(|p| (p, Kind::Figure)),
            candump.as_ref().map(|(p, _, _)| (p.as_path(), Kind::File)),
        ],
    )?;
    let mut next = 0..;
    let mut staged = |given: bool| given.then(|| next.next().unwrap_or(0));
    let (out_k, plot_k, can_k) = (
        staged(out.is_some()),
        staged(plot_to.is_some()),
        staged(candump.is_some()),
    );
    let (detector, config_name) = load_detector(config)?;
    let reader = TraceReader::open(path)?;
    let name = reader.name().to_string();
    let writer = |k: usize| -> Result<std::io::BufWriter<std::fs::File>> {
        let p = plan.staging(k);
        let f = std::fs::File::create(p).with_context(|| p.display().to_string())?;
        Ok(std::io::BufWriter::with_capacity(1 << 16, f))
    };
    let mut csv = match out_k {
        Some(k) => Some(ConfidenceCsv::start(
            writer(k)?,
            &detector,
            &name,
            &config_name,
        )?),
        None => None,
    };
    let mut can = match (can_k, &candump) {
        (Some(k), Some((_, node, format))) => {
            Some(CanLog::start(writer(k)?, &detector, *node, *format)?)
        }
        _ => None,
    };
    let mut figure = plot_to.map(|_| Decimated::new(detector.events(), PLOT_POINTS));
    let mut failed: Option<std::io::Error> = None;
    let streamed = replay::replay_stream(&detector, reader, |tick| {
        if failed.is_some() {
            return;
        }
        let written = csv
            .as_mut()
            .map_or(Ok(()), |w| w.row(tick.t, tick.state, tick.output))
            .and_then(|()| {
                can.as_mut()
                    .map_or(Ok(()), |w| w.tick(tick.t, tick.row, tick.output))
            });
        if let Err(e) = written {
            failed = Some(e);
        }
        if let Some(f) = figure.as_mut() {
            f.push(tick.t, tick.output);
        }
    })?;
    if let Some(e) = failed {
        return Err(e).context("writing the outputs");
    }
    let csv = csv
        .map(ConfidenceCsv::finish)
        .transpose()
        .context("writing the outputs")?;
    for w in [csv, can.map(CanLog::into_inner)].into_iter().flatten() {
        w.into_inner()
            .map_err(|e| e.into_error())
            .context("writing the outputs")?;
    }
    let truth = streamed.first_truth();
    if let (Some(k), Some(f)) = (plot_k, figure) {
        let (t, series) = f.finish();
        let run = RunPlot {
            title: name.clone(),
            t: &t,
            series,
            truth: truth.clone(),
            decisions: &streamed.decisions,
        };
        plot::write_run(plan.staging(k), &run)?;
    }
    plan.commit()?;
    if json {
        let report = serde_json::json!({
            "trace": name,
            "config": config_name,
            "truth": truth.as_ref().map(|(e, t)| serde_json::json!({"event": e, "onset_s": t})),
            "labelled": streamed.labelled,
            "events": streamed.decisions,
        });
        println!("{report}");
        return Ok(());
    }
    println!(
        "{name} with {config_name}: {} ticks, sampled at {} Hz (the detector runs at {} Hz)",
        streamed.rows,
        (streamed.rate_hz * 1000.0).round() / 1000.0,
        detector.rate_hz()
    );
    for l in &streamed.labelled {
        println!(
            "true event: {} at {:.2} ms (labelled until {:.2} ms)",
            l.event,
            l.onset_s * 1e3,
            l.end_s * 1e3
        );
    }
    if streamed.decisions.is_empty() {
        println!("no level raised");
    }
    for d in &streamed.decisions {
        // Measured from the latest labelled onset before it.
        let before = streamed
            .labelled
            .iter()
            .rev()
            .find(|l| l.onset_s <= d.t_s)
            .map(|l| (l.event.clone(), l.onset_s));
        println!("{}", describe(d, before.as_ref()));
    }
    Ok(())
}

/// Points a replay's figure keeps per event, however long the trace.
const PLOT_POINTS: usize = 4000;

/// Per-tick event confidences and feature values as CSV, written row by row.
struct ConfidenceCsv<W: std::io::Write> {
    out: W,
    events: usize,
    features: usize,
    /// Rows not yet written, handed to `out` 64 KiB at a time.
    pending: Vec<u8>,
}

impl<W: std::io::Write> ConfidenceCsv<W> {
    fn start(mut out: W, detector: &Detector, trace: &str, config: &str) -> std::io::Result<Self> {
        writeln!(out, "# fingertip replay of {trace} with {config}")?;
        writeln!(
            out,
            "# event columns: confidence in [0, 1]; feature columns (feature:NAME): value in the feature's unit"
        )?;
        let header: Vec<String> = detector
            .events()
            .iter()
            .map(|n| n.to_string())
            .chain(detector.features().iter().map(|n| format!("feature:{n}")))
            .collect();
        writeln!(out, "t,{}", header.join(","))?;
        Ok(ConfidenceCsv {
            out,
            events: detector.events().len(),
            features: detector.features().len(),
            pending: Vec::with_capacity(1 << 17),
        })
    }

    /// Confidences with 5 decimals, features with 6, each exactly rounded from its fixed
    /// point (as `{:.5}` and `{:.6}` print the same value, at a fraction of the cost).
    fn row(
        &mut self,
        t: f64,
        state: &detector_core::State,
        output: &detector_core::Output,
    ) -> std::io::Result<()> {
        use std::io::Write as _;
        let line = &mut self.pending;
        write!(line, "{t:.6}")?;
        for c in output.confidences.iter().take(self.events) {
            line.push(b',');
            fingertip::write_binary_fraction(line, c.to_bits().into(), 15, 5);
        }
        for k in 0..self.features {
            line.push(b',');
            let bits = state.feature(k).map_or(0, |x| x.to_bits());
            fingertip::write_binary_fraction(line, bits, 16, 6);
        }
        line.push(b'\n');
        if line.len() >= 1 << 16 {
            self.out.write_all(line)?;
            line.clear();
        }
        Ok(())
    }

    /// Writes the rows still pending and hands the output back.
    fn finish(mut self) -> std::io::Result<W> {
        self.out.write_all(&self.pending)?;
        Ok(self.out)
    }
}

/// The frames the firmware's transmit logic would send, in candump log format, stamped
/// with the trace's time, written tick by tick.
struct CanLog<W: std::io::Write> {
    out: W,
    tx: Transmitter,
    state: TxState,
    status: Status,
}

impl<W: std::io::Write> CanLog<W> {
    fn start(out: W, detector: &Detector, node: NodeId, format: BusFormat) -> Result<Self> {
        Ok(CanLog {
            out,
            tx: Transmitter::with_defaults(node, format, detector.rate_hz().round() as u32)?,
            state: TxState::new(),
            status: Status {
                tick_rate_hz: detector.rate_hz().round() as u16,
                ..Status::default()
            },
        })
    }

    fn tick(&mut self, t: f64, row: usize, output: &detector_core::Output) -> std::io::Result<()> {
        let stamp = std::time::Duration::from_secs_f64(t.max(0.0));
        for frame in self
            .tx
            .tick(&mut self.state, row as u32, output, &self.status)
        {
            write_log_line(&mut self.out, stamp, "can0", &frame)?;
        }
        Ok(())
    }

    fn into_inner(self) -> W {
        self.out
    }
}

/// Event confidences kept for a figure of a trace of any length: at most about `points`
/// per event, each the highest confidence of the ticks it stands for (a short peak
/// stays visible), their time the first of those ticks.
struct Decimated {
    names: Vec<String>,
    points: usize,
    /// Ticks per kept point (a power of two).
    stride: usize,
    t: Vec<f64>,
    series: Vec<Vec<f64>>,
    /// The point being gathered: its time, ticks so far and running maxima.
    open: Option<(f64, usize)>,
    peak: Vec<f64>,
}

impl Decimated {
    fn new(names: &[detector_core::Name], points: usize) -> Decimated {
        Decimated {
            names: names.iter().map(|n| n.to_string()).collect(),
            points: points.max(2),
            stride: 1,
            t: Vec::new(),
            series: vec![Vec::new(); names.len()],
            open: None,
            peak: vec![0.0; names.len()],
        }
    }

    fn push(&mut self, t: f64, output: &detector_core::Output) {
        let (start, n) = self.open.get_or_insert((t, 0));
        let start = *start;
        *n += 1;
        let n = *n;
        for (p, c) in self.peak.iter_mut().zip(output.confidences.iter()) {
            *p = if n == 1 {
                c.to_f64()
            } else {
                p.max(c.to_f64())
            };
        }
        if n == self.stride {
            self.close(start);
        }
        if self.t.len() >= 2 * self.points {
            self.halve();
        }
    }

    fn close(&mut self, start: f64) {
        self.t.push(start);
        for (s, p) in self.series.iter_mut().zip(&self.peak) {
            s.push(*p);
        }
        self.open = None;
    }

    /// Merges neighbouring points pairwise: half the points, twice the stride.
    fn halve(&mut self) {
        let pairs = self.t.len() / 2;
        self.t = (0..pairs).map(|i| self.t[2 * i]).collect();
        for s in &mut self.series {
            *s = (0..pairs).map(|i| s[2 * i].max(s[2 * i + 1])).collect();
        }
        self.stride *= 2;
    }

    /// The kept times and each event's series.
    fn finish(mut self) -> (Vec<f64>, Series) {
        if let Some((start, _)) = self.open {
            self.close(start);
        }
        (self.t, self.names.into_iter().zip(self.series).collect())
    }
}

fn decode_options(config: Option<&Path>, node: Option<u8>, quiet: bool) -> Result<DecodeOptions> {
    let (detector, _) = load_detector(config)?;
    let node = node.map(node_id).transpose()?;
    Ok(DecodeOptions {
        tick_rate_hz: f64::from(detector.rate_hz()),
        event_names: detector.events().iter().map(|n| n.to_string()).collect(),
        node,
        print_confidences: !quiet,
    })
}

fn decode_cmd(
    file: &Path,
    config: Option<&Path>,
    node: Option<u8>,
    quiet: bool,
    plot_to: Option<&Path>,
) -> Result<()> {
    let inputs: Vec<&Path> = std::iter::once(file).chain(config).collect();
    let plan = plan_outputs(&inputs, &[plot_to.map(|p| (p, Kind::Figure))])?;
    let opts = decode_options(config, node, quiet)?;
    let log = decode::decode_file(file, &opts, &mut std::io::stdout().lock())?;
    if plot_to.is_some() {
        let (t, series, decisions) = stream_series(&log, &opts);
        let run = RunPlot {
            title: file.display().to_string(),
            t: &t,
            series,
            truth: None,
            decisions: &decisions,
        };
        plot::write_run(plan.staging(0), &run)?;
    }
    plan.commit()?;
    Ok(())
}

/// Named series of values, one per tick or stream sample.
type Series = Vec<(String, Vec<f64>)>;

/// The confidence stream of a decoded log as per-event series on the stream's own time
/// base (each event holds its last value between pages), and its event frames.
fn stream_series(
    log: &decode::DecodedLog,
    opts: &DecodeOptions,
) -> (Vec<f64>, Series, Vec<DecisionRecord>) {
    let mut t = Vec::new();
    let mut current: Vec<f64> = Vec::new();
    let mut series: Series = Vec::new();
    // The last streamed confidence of each event (by node), for the events' markers.
    let mut last: std::collections::HashMap<(u8, usize), f64> = Default::default();
    let mut decisions = Vec::new();
    let mut t0 = None;
    for r in log.records() {
        let Some(time) = r.time else { continue };
        if let fingertip_can::Message::Event(m) = &r.message {
            let event = usize::from(m.event.0);
            let at = time - *t0.get_or_insert(time);
            decisions.push(DecisionRecord {
                event: opts.event_name(event),
                level: m.level.name(),
                confidence: last
                    .get(&(r.address.index(), event))
                    .copied()
                    .unwrap_or(1.0),
                onset_s: at - f64::from(m.onset_age) / opts.tick_rate_hz,
                t_s: at,
            });
            continue;
        }
        let values = r.stream_values();
        if values.is_empty() {
            continue;
        }
        t0.get_or_insert(time);
        for v in &values {
            if current.len() <= v.event {
                current.resize(v.event + 1, 0.0);
            }
            current[v.event] = v.confidence;
            last.insert((r.address.index(), v.event), v.confidence);
        }
        t.push(time);
        for (index, value) in current.iter().enumerate() {
            if series.len() <= index {
                let filled = vec![0.0; t.len() - 1];
                series.push((opts.event_name(index), filled));
            }
            series[index].1.push(*value);
        }
    }
    let t0 = t0.unwrap_or(0.0);
    let t: Vec<f64> = t.iter().map(|x| x - t0).collect();
    (t, series, decisions)
}

/// The detector's name as a fingertip keeps it: the configuration file's stem, cut to
/// the protocol's 16 bytes at a character.
fn detector_name(config: &Path) -> String {
    let stem = config
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut name = String::new();
    for c in stem.chars() {
        if name.len() + c.len_utf8() > fingertip_can::service::NAME_MAX {
            break;
        }
        name.push(c);
    }
    name
}

/// A service-channel client for `node` on `iface`.
#[cfg(target_os = "linux")]
fn service_client(
    node: NodeId,
    iface: &str,
) -> Result<fingertip::can_tools::service::Client<fingertip::can_tools::service::SocketLink>> {
    use fingertip::can_tools::service::{Client, SocketLink};
    let link = SocketLink::open(iface, node).with_context(|| format!("CAN interface {iface}"))?;
    Ok(Client::new(link))
}

#[cfg(not(target_os = "linux"))]
fn service_client(
    _node: NodeId,
    iface: &str,
) -> Result<fingertip::can_tools::service::Client<NoLink>> {
    bail!("CAN interface {iface}: SocketCAN is Linux only")
}

/// Stands in for a link where SocketCAN does not exist.
#[cfg(not(target_os = "linux"))]
struct NoLink;

#[cfg(not(target_os = "linux"))]
impl fingertip::can_tools::service::Link for NoLink {
    fn send(&mut self, _: &[u8]) -> std::io::Result<()> {
        Err(std::io::Error::other("no SocketCAN"))
    }
    fn recv(&mut self, _: u64) -> std::io::Result<Option<Vec<u8>>> {
        Err(std::io::Error::other("no SocketCAN"))
    }
    fn now_us(&mut self) -> u64 {
        0
    }
}

/// An error response as one line.
fn refused(node: NodeId, code: fingertip_can::service::ErrorCode, text: &str) -> anyhow::Error {
    anyhow!("node {}: {}: {text}", node.get(), code.name())
}

/// Sends `request`; an error response becomes an error naming the node.
fn ask<L: fingertip::can_tools::service::Link>(
    client: &mut fingertip::can_tools::service::Client<L>,
    node: NodeId,
    request: &fingertip_can::service::Request<'_>,
) -> Result<fingertip_can::service::Response> {
    use fingertip::can_tools::service::ClientError;
    client.ask(request).map_err(|e| match e {
        ClientError::Refused { code, text } => refused(node, code, &text),
        e => e.into(),
    })
}

/// Runs `writes` in the fingertip's service state, and leaves it whatever they did.
fn in_service_state<L: fingertip::can_tools::service::Link, T>(
    client: &mut fingertip::can_tools::service::Client<L>,
    node: NodeId,
    writes: impl FnOnce(&mut fingertip::can_tools::service::Client<L>) -> Result<T>,
) -> Result<T> {
    use fingertip_can::service::Request;
    ask(client, node, &Request::EnterService)?;
    // The detector task takes the engine out of service at its next tick (200 µs).
    std::thread::sleep(std::time::Duration::from_millis(2));
    let result = writes(client);
    let left = ask(client, node, &Request::LeaveService);
    let value = result?;
    left?;
    Ok(value)
}

fn load_cmd(config: &Path, node: u8, iface: &str, activate: bool, save: bool) -> Result<()> {
    use fingertip_can::service::{Request, Response, crc32};
    let node = node_id(node)?;
    let parsed = detector_build::load(config)?;
    let image = detector_build::compile(&parsed)
        .with_context(|| config.display().to_string())?
        .image();
    let name = detector_name(config);
    let crc = crc32(&image);
    let mut client = service_client(node, iface)?;
    let checked = |c: u32| {
        if c == crc {
            Ok(())
        } else {
            Err(anyhow!(
                "node {}: the fingertip checked CRC-32 {c:#010x}, the image's is {crc:#010x}",
                node.get()
            ))
        }
    };
    let load = Request::Load {
        name: &name,
        image: &image,
    };
    match ask(&mut client, node, &load)? {
        Response::Staged(c) => checked(c)?,
        other => bail!("node {}: unexpected answer {other:?}", node.get()),
    }
    println!(
        "node {}: `{name}` loaded ({} bytes, CRC-32 {crc:#010x}), checked and staged",
        node.get(),
        image.len()
    );
    if save {
        let saved = in_service_state(&mut client, node, |client| {
            ask(
                client,
                node,
                &Request::Save {
                    name: &name,
                    image: &image,
                },
            )
        })?;
        match saved {
            Response::Saved {
                crc: c,
                slot,
                stall_ms,
            } => {
                checked(c)?;
                let slot = if slot == 1 { "A" } else { "B" };
                println!(
                    "node {}: saved to slot {slot}, the fingertip boots with it (its CPU stalled up to {stall_ms} ms)",
                    node.get()
                );
            }
            other => bail!("node {}: unexpected answer {other:?}", node.get()),
        }
    }
    if activate {
        match ask(&mut client, node, &Request::Activate)? {
            Response::Active(c) => println!("node {}: in service, CRC-32 {c:#010x}", node.get()),
            other => bail!("node {}: unexpected answer {other:?}", node.get()),
        }
    } else {
        println!("it takes over at the next phase entry (or run with --activate)");
    }
    Ok(())
}

/// A key to read, or to write with its value.
fn parse_key_arg(arg: &str) -> Result<(fingertip_can::service::Key, Option<[u8; 4]>)> {
    use fingertip_can::service::Key;
    let (name, value) = match arg.split_once('=') {
        Some((k, v)) => (k.trim(), Some(v.trim())),
        None => (arg.trim(), None),
    };
    let key = Key::parse(name).ok_or_else(|| {
        let all: Vec<String> = Key::all().map(|k| k.to_string()).collect();
        anyhow!("unknown key `{name}` (keys: {})", all.join(", "))
    })?;
    let value = match value {
        None => None,
        Some(v) if key.is_float() => {
            let x: f32 = v
                .parse()
                .map_err(|_| anyhow!("{key}: `{v}` is not a number"))?;
            if !x.is_finite() {
                bail!("{key}: `{v}` is not finite");
            }
            Some(x.to_le_bytes())
        }
        Some(v) => {
            let n: u32 = v
                .parse()
                .map_err(|_| anyhow!("{key}: `{v}` is not a whole number"))?;
            Some(n.to_le_bytes())
        }
    };
    Ok((key, value))
}

/// A key's value as text.
fn key_value(key: fingertip_can::service::Key, v: [u8; 4]) -> String {
    if key.is_float() {
        format!("{}", f32::from_le_bytes(v))
    } else {
        format!("{}", u32::from_le_bytes(v))
    }
}

fn calibrate_cmd(node: u8, iface: &str, keys: &[String]) -> Result<()> {
    use fingertip_can::service::{ErrorCode, Key, Request, Response};
    let node = node_id(node)?;
    // Every argument checked before anything goes on the bus.
    let args: Vec<(Key, Option<[u8; 4]>)> = if keys.is_empty() {
        Key::all().map(|k| (k, None)).collect()
    } else {
        keys.iter()
            .map(|a| parse_key_arg(a))
            .collect::<Result<_>>()?
    };
    let mut client = service_client(node, iface)?;
    let writes: Vec<(Key, [u8; 4])> = args
        .iter()
        .filter_map(|&(k, v)| v.map(|v| (k, v)))
        .collect();
    if !writes.is_empty() {
        in_service_state(&mut client, node, |client| {
            for &(k, v) in &writes {
                ask(client, node, &Request::WriteKey(k, v))?;
                println!("node {}: {k} = {} written", node.get(), key_value(k, v));
            }
            Ok(())
        })?;
    }
    for &(k, v) in &args {
        if v.is_some() {
            continue;
        }
        match client.request(&Request::ReadKey(k))? {
            Response::Value(v) => println!("node {}: {k} = {}", node.get(), key_value(k, v)),
            Response::Error(ErrorCode::Key, _) => {
                println!("node {}: {k} not set (the firmware's default)", node.get())
            }
            Response::Error(code, text) => return Err(refused(node, code, &text)),
            other => bail!("node {}: unexpected answer {other:?}", node.get()),
        }
    }
    Ok(())
}

/// What `fetch-recording` fetches, and where it writes it.
struct Fetch {
    out: Option<PathBuf>,
    follow: Option<PathBuf>,
    count: Option<usize>,
    keep: bool,
}

fn fetch_recording_cmd(config: &Path, fetch: Fetch, node: u8, iface: &str) -> Result<()> {
    use fingertip::can_tools::recording;
    use fingertip_can::service::{Request, crc32};
    let node = node_id(node)?;
    // Where it writes, before anything is read.
    let into = match (&fetch.out, &fetch.follow) {
        (Some(out), _) => out.parent().filter(|p| !p.as_os_str().is_empty()),
        (None, Some(dir)) => Some(dir.as_path()),
        (None, None) => bail!("give --out or --follow"),
    };
    if let Some(dir) = into.filter(|d| !d.is_dir()) {
        bail!("{}: not a directory", dir.display());
    }
    let parsed = detector_build::load(config)?;
    let crc = crc32(
        &detector_build::compile(&parsed)
            .with_context(|| config.display().to_string())?
            .image(),
    );
    let detector = detector_build::build(&parsed).with_context(|| config.display().to_string())?;
    let mut client = service_client(node, iface)?;
    let at_node = || format!("node {}", node.get());
    let one = |client: &mut _, out: &Path| -> Result<()> {
        let rec = recording::fetch(client).with_context(at_node)?;
        let name = out.display().to_string();
        let trace = rec.to_trace(&detector, crc, &name)?;
        let decisions = rec.check_replay(&detector, &trace)?;
        trace.write(out)?;
        let info = &rec.info;
        let rate = f64::from(info.rate_hz);
        let end = info.first_tick.wrapping_add(info.rows);
        println!(
            "node {}: {} ticks from tick {} ({:.1} ms), frozen {:.1} ms after tick {} ({}), written to {name}",
            node.get(),
            info.rows,
            info.first_tick,
            f64::from(info.rows) / rate * 1e3,
            f64::from(end.wrapping_sub(info.trigger_tick)) / rate * 1e3,
            info.trigger_tick,
            trace.meta("trigger").unwrap_or("?"),
        );
        let confirmed = decisions.iter().filter(|d| d.is_confirm()).count();
        let matched = match info.cause {
            Some(fingertip_can::service::RecordingCause::Confirmed(_)) => {
                ", the trigger's at its tick"
            }
            _ => "",
        };
        println!(
            "replayed on the PC from the fingertip's state: {confirmed} confirmation(s){matched}"
        );
        Ok(())
    };
    if let Some(out) = &fetch.out {
        one(&mut client, out)?;
        if !fetch.keep {
            ask(&mut client, node, &Request::RecordingRearm)?;
        }
    } else if let Some(dir) = &fetch.follow {
        let mut fetched = 0;
        while fetch.count.is_none_or(|n| fetched < n) {
            let Some(info) =
                recording::wait_frozen(&mut client, 20_000, None).with_context(at_node)?
            else {
                continue;
            };
            let out = dir.join(format!("node{}-tick{}.csv", node.get(), info.first_tick));
            one(&mut client, &out)?;
            ask(&mut client, node, &Request::RecordingRearm)?;
            fetched += 1;
        }
    }
    Ok(())
}

fn info_cmd(node: u8, iface: &str) -> Result<()> {
    use fingertip_can::service::{Request, Response};
    let node = node_id(node)?;
    let mut client = service_client(node, iface)?;
    match client.request(&Request::Identify)? {
        Response::Identity(i) => {
            let [major, minor, patch] = i.version;
            println!(
                "node {}: firmware {major}.{minor}.{patch} (build {:08x}); detector `{}` ({}), CRC-32 {:#010x}",
                node.get(),
                i.build,
                i.detector_name,
                i.mode.name(),
                i.detector_crc
            );
            if let Some(s) = i.staged_crc {
                println!("staged: CRC-32 {s:#010x}, waiting for the next phase entry");
            }
            match ask(&mut client, node, &Request::LastCrash)? {
                Response::Crash(Some(c)) => println!(
                    "the last run stopped: {} at {:#010x}: {}",
                    c.kind.name(),
                    c.pc,
                    c.message
                ),
                Response::Crash(None) => println!("no crash kept from the last run"),
                other => bail!("node {}: unexpected answer {other:?}", node.get()),
            }
            Ok(())
        }
        Response::Error(code, text) => Err(refused(node, code, &text)),
        other => bail!("node {}: unexpected answer {other:?}", node.get()),
    }
}

fn monitor_cmd(
    iface: &str,
    config: Option<&Path>,
    node: Option<u8>,
    quiet: bool,
    frames: Option<usize>,
    seconds: Option<f64>,
    candump: Option<&Path>,
) -> Result<()> {
    use fingertip::can_tools::monitor::{self, MonitorLimits};
    let opts = decode_options(config, node, quiet)?;
    let duration = match seconds {
        Some(s) if s.is_finite() && s > 0.0 => Some(std::time::Duration::from_secs_f64(s)),
        Some(s) => bail!("--seconds {s} must be a positive number"),
        None => None,
    };
    let limits = MonitorLimits {
        max_frames: frames,
        duration,
    };
    let mut log_file = match candump {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).with_context(|| p.display().to_string())?,
        )),
        None => None,
    };
    let copy = log_file.as_mut().map(|w| w as &mut dyn std::io::Write);
    let log = monitor::monitor(
        iface,
        &opts,
        &limits,
        &mut std::io::stdout().lock(),
        copy,
        &|| false,
    )?;
    decode::write_summary(&log, &mut std::io::stdout().lock())?;
    Ok(())
}

/// Failing runs listed per scenario by `evaluate`.
const SHOWN_FAILURES: usize = 3;

/// Length of each simulated stretch of event-free motion (s).
const FREE_RUN_S: f64 = 60.0;

/// The most randomized runs per scenario `evaluate` takes: 1.4 million runs in all, a day
/// of work on two cores, and its bookkeeping stays within tens of megabytes.
const MAX_RUNS: usize = 100_000;

/// The most hours of event-free motion `evaluate` simulates: about a day of work on two
/// cores.
const MAX_FREE_HOURS: f64 = 100.0;

/// What `evaluate` simulates.
#[derive(Clone, Debug)]
struct Plan {
    /// Randomized runs per single-event scenario.
    runs: usize,
    /// The base seed every run's seed derives from.
    seed: u64,
    /// Hours of event-free motion.
    free_hours: f64,
    /// How long each single-event run's motion runs before its event window (ms).
    lead_in_ms: f64,
    /// Multiplies every sensor's white noise ([`SimOptions::noise_factor`]).
    noise_factor: f64,
    /// The encoders' resolution at the tip, µm ([`SimOptions::encoder_resolution_um`]).
    encoder_um: f64,
    /// The film's AC coupling, Hz ([`SimOptions::film_highpass_hz`]).
    film_highpass_hz: f64,
    /// The loops' velocity low-pass, Hz ([`SimOptions::velocity_filter_hz`]).
    velocity_filter_hz: f64,
    /// The context's frame, turned from the pad's, degrees
    /// ([`SimOptions::context_turned_deg`]).
    context_turned_deg: f64,
    /// Parameters drawn from other ranges than the envelope's ([`SimOptions::ranges`]).
    ranges: Vec<sim::ParamRange>,
}

impl Plan {
    /// The `simulate` options every run of the plan shares beyond the envelope's defaults
    /// (the lead-in and a free-motion run's length aside), as a failure line gives them.
    fn run_flags(&self) -> String {
        let mut flags = String::new();
        if self.noise_factor != 1.0 {
            flags += &format!(" --noise-factor {}", self.noise_factor);
        }
        if self.encoder_um != sim::DEFAULT_ENCODER_RESOLUTION_UM {
            flags += &format!(" --encoder-um {}", self.encoder_um);
        }
        if self.film_highpass_hz > 0.0 {
            flags += &format!(" --film-highpass-hz {}", self.film_highpass_hz);
        }
        if self.velocity_filter_hz > 0.0 {
            flags += &format!(" --velocity-filter-hz {}", self.velocity_filter_hz);
        }
        if self.context_turned_deg != 0.0 {
            flags += &format!(" --context-turned-deg={}", self.context_turned_deg);
        }
        for r in &self.ranges {
            flags += &format!(" --range {r}");
        }
        flags
    }
}

/// One randomized run of `evaluate`.
#[derive(Clone, Copy, Debug)]
enum Job {
    /// Run `k` of the scenario at `index` in [`Scenario::single_event`].
    Single { index: usize, k: usize },
    /// Stretch `k` of event-free motion, [`FREE_RUN_S`] long.
    FreeMotion { k: usize },
}

impl Job {
    /// Job `i` of an evaluation of `runs` per single-event scenario, in order, then the
    /// stretches of free motion: jobs are made as they run, never listed up front.
    fn at(i: usize, runs: usize) -> Job {
        let single = Scenario::single_event().len() * runs;
        if i < single {
            Job::Single {
                index: i / runs,
                k: i % runs,
            }
        } else {
            Job::FreeMotion { k: i - single }
        }
    }

    fn scenario(self) -> Scenario {
        match self {
            Job::Single { index, .. } => Scenario::single_event()[index],
            Job::FreeMotion { .. } => Scenario::FreeMotion,
        }
    }

    /// The run's length: the scenario's default for single-event runs.
    fn duration_s(self) -> Option<f64> {
        match self {
            Job::Single { .. } => None,
            Job::FreeMotion { .. } => Some(FREE_RUN_S),
        }
    }

    /// The run's seed, derived from the base seed and spread so that no two runs share
    /// one; free motion draws from stream `u64::MAX`, beyond every scenario index.
    fn seed(self, base: u64) -> u64 {
        let (stream, k) = match self {
            Job::Single { index, k } => (index as u64, k),
            Job::FreeMotion { k } => (u64::MAX, k),
        };
        base.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (stream << 40) ^ k as u64
    }
}

/// What one job gave.
struct JobResult {
    job: Job,
    seed: u64,
    /// One per detector, in `--config` order.
    outcomes: Vec<Outcome>,
    /// Per detector, the run's peak confidence of its expected event from its onset on
    /// (of any event all run long where none is expected), in [0, 1].
    peaks: Vec<f64>,
    /// Where the run falls in its scenario's binning.
    bin: Option<sim::RunBin>,
    /// Simulated time (s).
    seconds: f64,
    /// What the run drew ([`drawn`]), when a table of the runs is asked for; else empty.
    drawn: Vec<(String, String)>,
}

/// The metadata of a simulated run that can differ from one run to the next: its drawn
/// parameters, what was struck and where, its onset. Left out: the scenario and seed (a
/// table's own columns) and what every run shares (units, full scales, the rates, the
/// description).
fn drawn(trace: &Trace) -> Vec<(String, String)> {
    const SHARED: [&str; 7] = [
        "scenario",
        "description",
        "expected",
        "seed",
        "randomized",
        "rate_hz",
        "internal_rate_hz",
    ];
    trace
        .metadata()
        .iter()
        .filter(|(k, _)| {
            !(SHARED.contains(&k.as_str())
                || k.starts_with("unit.")
                || k.starts_with("full_scale."))
        })
        .cloned()
        .collect()
}

/// Simulates one job and scores it with each detector.
fn run_job(detectors: &[Detector], job: Job, plan: &Plan, keep_drawn: bool) -> Result<JobResult> {
    let scenario = job.scenario();
    let seed = job.seed(plan.seed);
    let opts = SimOptions {
        seed,
        randomize: true,
        duration_s: job.duration_s(),
        lead_in_s: plan.lead_in_ms / 1000.0,
        noise_factor: plan.noise_factor,
        encoder_resolution_um: plan.encoder_um,
        film_highpass_hz: plan.film_highpass_hz,
        velocity_filter_hz: plan.velocity_filter_hz,
        context_turned_deg: plan.context_turned_deg,
        ranges: plan.ranges.clone(),
        ..SimOptions::default()
    };
    let trace = sim::simulate(&scenario, &opts)?;
    let truth = truth_of(&trace);
    let expected = scenario
        .expected()
        .map(|e| (e, truth.as_ref().map_or(0.0, |t| t.1)));
    let from_row = trace.truth_onset().map_or(0, |(row, _)| row);
    let (outcomes, peaks) = detectors
        .iter()
        .map(|d| {
            let watched = scenario.expected().and_then(|e| d.event(e));
            let mut peak: f64 = 0.0;
            let decisions = replay::replay(d, &trace, |row, _, out| {
                let c = match watched {
                    Some(id) if row >= from_row => out.confidences[usize::from(id.0)],
                    Some(_) => return,
                    None => out.confidences.iter().copied().max().unwrap_or_default(),
                };
                peak = peak.max(c.to_f64());
            })?;
            Ok((score::classify(expected, &decisions), peak))
        })
        .collect::<Result<Vec<(Outcome, f64)>>>()?
        .into_iter()
        .unzip();
    Ok(JobResult {
        job,
        seed,
        outcomes,
        peaks,
        bin: scenario.run_bin(&trace),
        seconds: trace.len() as f64 / trace.rate_hz(),
        drawn: if keep_drawn {
            drawn(&trace)
        } else {
            Vec::new()
        },
    })
}

/// Runs the plan's runs of every single-event scenario and `free_runs` stretches of free
/// motion on all cores behind a progress bar; the results in job order and the wall time
/// taken (s). With `keep_drawn`, each result keeps what its run drew.
fn run_jobs(
    detectors: &[Detector],
    plan: &Plan,
    free_runs: usize,
    keep_drawn: bool,
) -> Result<(Vec<JobResult>, f64)> {
    let runs = plan.runs;
    let jobs = Scenario::single_event().len() * runs + free_runs;
    let bar = progress(jobs, "runs")?;
    let started = Instant::now();
    // Jobs are split down to one each: a 60 s free-motion run costs hundreds of event runs,
    // and rayon's default splitting would leave a batch of them in one thread's share while
    // the other core idles.
    let results: Result<Vec<JobResult>> = (0..jobs)
        .into_par_iter()
        .with_max_len(1)
        .map(|i| {
            let result = run_job(detectors, Job::at(i, runs), plan, keep_drawn);
            bar.inc(1);
            result
        })
        .collect::<Vec<_>>()
        .into_iter()
        .collect();
    bar.finish_and_clear();
    Ok((results?, started.elapsed().as_secs_f64()))
}

/// A progress bar over `n` things called `what`, on standard error.
fn progress(n: usize, what: &str) -> Result<ProgressBar> {
    let template =
        format!("{{elapsed_precise}} [{{bar:40}}] {{pos}}/{{len}} {what} ({{eta}} left)");
    Ok(ProgressBar::new(n as u64)
        .with_style(ProgressStyle::with_template(&template)?.progress_chars("=> ")))
}

/// The results of `evaluate`, tallied.
struct Tally {
    /// One per single-event scenario.
    reports: Vec<ScenarioReport>,
    /// Free-motion runs with a confirmation.
    free_alarms: usize,
    /// Hours of free motion simulated.
    free_hours: f64,
    /// Every run that went wrong, in job order: scenario, seed, outcome.
    failures: Vec<(Scenario, u64, Outcome)>,
    /// The single-event runs' lead-in (ms), to reproduce them.
    lead_in_ms: f64,
    /// The options every run shares, to reproduce them ([`Plan::run_flags`]).
    run_flags: String,
}

impl Tally {
    /// The tally of detector `d`'s outcomes in the runs of `plan`.
    fn of(results: &[JobResult], d: usize, plan: &Plan) -> Tally {
        let scenarios = Scenario::single_event();
        let mut outcomes: Vec<Vec<Outcome>> = vec![Vec::new(); scenarios.len()];
        let mut bins: Vec<Vec<Option<usize>>> = vec![Vec::new(); scenarios.len()];
        let mut free_alarms = 0usize;
        let mut free_seconds = 0.0;
        let mut failures = Vec::new();
        for r in results {
            let Some(outcome) = r.outcomes.get(d) else {
                continue;
            };
            if !outcome.is_right() {
                failures.push((r.job.scenario(), r.seed, outcome.clone()));
            }
            match r.job {
                Job::Single { index, .. } => {
                    outcomes[index].push(outcome.clone());
                    bins[index].push(r.bin.map(|b| b.bin));
                }
                Job::FreeMotion { .. } => {
                    free_seconds += r.seconds;
                    free_alarms += usize::from(!outcome.is_right());
                }
            }
        }
        Tally {
            reports: scenarios
                .iter()
                .zip(&outcomes)
                .zip(&bins)
                .map(|((s, o), b)| match s.binning() {
                    Some(binning) => ScenarioReport::tally_binned(
                        s.name(),
                        s.expected(),
                        o,
                        (
                            &format!("{} [{}]", binning.parameter, binning.unit),
                            &binning.labels(),
                            b,
                        ),
                    ),
                    None => ScenarioReport::tally(s.name(), s.expected(), o),
                })
                .collect(),
            free_alarms,
            free_hours: free_seconds / 3600.0,
            failures,
            lead_in_ms: plan.lead_in_ms,
            run_flags: plan.run_flags(),
        }
    }

    fn alarms_per_hour(&self) -> f64 {
        if self.free_hours > 0.0 {
            self.free_alarms as f64 / self.free_hours
        } else {
            0.0
        }
    }

    /// The table per scenario, the false-alarm rate and the first failures of each
    /// scenario with the command that reproduces them.
    fn print(&self) {
        let mut table = Vec::new();
        // Writing to memory cannot fail.
        let _ = score::write_table(&mut table, ("scenario", "runs"), true, &self.reports);
        print!("{}", String::from_utf8_lossy(&table));
        self.print_false_alarms("");
        self.print_failures();
    }

    /// The false-alarm line, after `prefix`.
    fn print_false_alarms(&self, prefix: &str) {
        println!(
            "{prefix}false alarms: {} runs with a confirmation in {:.2} h of event-free motion = {:.2} per hour",
            self.free_alarms,
            self.free_hours,
            self.alarms_per_hour()
        );
    }

    /// The first failures of each scenario, with the command that reproduces them.
    fn print_failures(&self) {
        if self.failures.is_empty() {
            return;
        }
        println!(
            "runs that went wrong (at most {SHOWN_FAILURES} per scenario; `fingertip simulate NAME --randomize --seed SEED` reproduces one):"
        );
        let mut shown: std::collections::HashMap<Scenario, usize> = Default::default();
        for (scenario, seed, outcome) in &self.failures {
            let n = shown.entry(*scenario).or_default();
            *n += 1;
            if *n > SHOWN_FAILURES {
                continue;
            }
            // What `simulate` needs besides the seed to draw the same run.
            let length = if *scenario == Scenario::FreeMotion {
                format!(" --duration {FREE_RUN_S}")
            } else if self.lead_in_ms > 0.0 {
                format!(" --lead-in-ms {}", self.lead_in_ms)
            } else {
                String::new()
            };
            println!(
                "  {:<26} --seed {seed}{length}{}: {outcome}",
                scenario.name(),
                self.run_flags
            );
        }
    }

    /// The report as JSON, named by its configuration.
    fn json(&self, config: &str) -> serde_json::Value {
        serde_json::json!({
            "config": config,
            "scenarios": self.reports,
            "false_alarms": self.free_alarms,
            "false_alarms_per_hour": self.alarms_per_hour(),
            "free_motion_hours": self.free_hours,
            // Every run that went wrong, with the seed that reproduces it.
            "failures": self
                .failures
                .iter()
                .map(|(scenario, seed, outcome)| serde_json::json!({
                    "scenario": scenario.name(),
                    "seed": seed,
                    "outcome": outcome.to_string(),
                }))
                .collect::<Vec<_>>(),
        })
    }
}

/// Several detectors' tallies side by side: per scenario and detector, right / runs,
/// wrong, missed, repeated and the latency's median and p99; then each one's false alarms
/// and failures.
fn print_comparison(tallies: &[(String, Tally)]) {
    for (k, (name, _)) in tallies.iter().enumerate() {
        println!("[{}] {name}", k + 1);
    }
    let mut head = format!("{:<26} {:>6}", "scenario", "runs");
    for k in 1..=tallies.len() {
        head.push_str(&format!(
            " | [{k}] {:>6} {:>5} {:>5} {:>5} {:>6} {:>6}",
            "right", "wrong", "miss", "rep", "med", "p99"
        ));
    }
    println!("{head}");
    let Some((_, first)) = tallies.first() else {
        return;
    };
    let cells = |r: &ScenarioReport| {
        format!(
            " |     {:>6} {:>5} {:>5} {:>5} {:>6.2} {:>6.2}",
            r.correct, r.wrong, r.missed, r.repeated, r.latency_ms.median, r.latency_ms.p99
        )
    };
    for (i, r) in first.reports.iter().enumerate() {
        let mut line = format!("{:<26} {:>6}", r.name, r.runs);
        for (_, t) in tallies {
            if let Some(r) = t.reports.get(i) {
                line.push_str(&cells(r));
            }
        }
        println!("{line}");
        // Each bin under its scenario, indented, after a line naming what they bin.
        if !r.bins.is_empty() {
            println!("  by {}:", r.binned_by);
        }
        for (b, bin) in r.bins.iter().enumerate() {
            let mut line = format!("{:<26} {:>6}", format!("  {}", bin.name), bin.runs);
            for (_, t) in tallies {
                if let Some(bin) = t.reports.get(i).and_then(|r| r.bins.get(b)) {
                    line.push_str(&cells(bin));
                }
            }
            println!("{line}");
        }
    }
    for (k, (_, t)) in tallies.iter().enumerate() {
        t.print_false_alarms(&format!("[{}] ", k + 1));
    }
    for (k, (name, t)) in tallies.iter().enumerate() {
        if !t.failures.is_empty() {
            println!("[{}] {name}:", k + 1);
            t.print_failures();
        }
    }
}

/// At most this many `--config` in one evaluation (the comparison table's width).
const MAX_COMPARED: usize = 4;

/// The detectors of `--config` (at most [`MAX_COMPARED`]; the default one when none) and
/// their names.
fn load_detectors(configs: &[PathBuf]) -> Result<(Vec<Detector>, Vec<String>)> {
    if configs.len() > MAX_COMPARED {
        bail!(
            "--config is given {} times: at most {MAX_COMPARED} detectors are compared at once",
            configs.len()
        );
    }
    let loaded = if configs.is_empty() {
        vec![load_detector(None)?]
    } else {
        configs
            .iter()
            .map(|c| load_detector(Some(c)))
            .collect::<Result<Vec<_>>>()?
    };
    Ok(loaded.into_iter().unzip())
}

/// `evaluate` on simulated runs: the plan's randomized runs of every single-event
/// scenario and its hours of event-free motion, with each detector of `configs`; the
/// report as JSON and the figure of peak confidences per bin to `outputs`.
fn evaluate(
    plan: Plan,
    configs: &[PathBuf],
    (json, plot_bins, runs_csv): (Option<&Path>, Option<&Path>, Option<&Path>),
) -> Result<()> {
    let Plan {
        runs,
        seed,
        free_hours,
        lead_in_ms,
        noise_factor,
        encoder_um,
        film_highpass_hz,
        velocity_filter_hz,
        context_turned_deg,
        ref ranges,
    } = plan;
    let (detectors, names) = load_detectors(configs)?;
    let inputs: Vec<&Path> = configs.iter().map(PathBuf::as_path).collect();
    let outputs = plan_outputs(
        &inputs,
        &[
            json.map(|p| (p, Kind::File)),
            plot_bins.map(|p| (p, Kind::Figure)),
            runs_csv.map(|p| (p, Kind::File)),
        ],
    )?;
    if !(1..=MAX_RUNS).contains(&runs) {
        bail!("--runs = {runs} must be within 1..={MAX_RUNS} runs per scenario");
    }
    if !(free_hours.is_finite() && (0.0..=MAX_FREE_HOURS).contains(&free_hours)) {
        bail!(
            "--free-hours = {} must be within 0..={MAX_FREE_HOURS} hours",
            fingertip::readable(free_hours)
        );
    }
    let max_lead_in_ms = sim::MAX_LEAD_IN_S * 1000.0;
    if !(lead_in_ms.is_finite() && (0.0..=max_lead_in_ms).contains(&lead_in_ms)) {
        bail!(
            "--lead-in-ms = {} must be within 0..={max_lead_in_ms} ms",
            fingertip::readable(lead_in_ms)
        );
    }
    if !(noise_factor.is_finite() && (0.0..=sim::MAX_NOISE_FACTOR).contains(&noise_factor)) {
        bail!(
            "--noise-factor = {} must be within 0..={}",
            fingertip::readable(noise_factor),
            sim::MAX_NOISE_FACTOR
        );
    }
    let (finest, coarsest) = sim::ENCODER_RESOLUTION_RANGE_UM;
    if !(encoder_um.is_finite() && (finest..=coarsest).contains(&encoder_um)) {
        bail!(
            "--encoder-um = {} must be within {finest}..={coarsest} um",
            fingertip::readable(encoder_um)
        );
    }
    if !(film_highpass_hz.is_finite()
        && (0.0..=sim::MAX_FILM_HIGHPASS_HZ).contains(&film_highpass_hz))
    {
        bail!(
            "--film-highpass-hz = {} must be within 0..={} Hz",
            fingertip::readable(film_highpass_hz),
            sim::MAX_FILM_HIGHPASS_HZ
        );
    }
    if !(velocity_filter_hz.is_finite()
        && (0.0..=sim::MAX_VELOCITY_FILTER_HZ).contains(&velocity_filter_hz))
    {
        bail!(
            "--velocity-filter-hz = {} must be within 0..={} Hz",
            fingertip::readable(velocity_filter_hz),
            sim::MAX_VELOCITY_FILTER_HZ
        );
    }
    if !(context_turned_deg.is_finite() && context_turned_deg.abs() <= sim::MAX_CONTEXT_TURNED_DEG)
    {
        bail!(
            "--context-turned-deg = {} must be within -{max}..={max} degrees",
            fingertip::readable(context_turned_deg),
            max = sim::MAX_CONTEXT_TURNED_DEG
        );
    }
    for r in ranges {
        r.check().map_err(|e| anyhow!("--range {e}"))?;
    }
    let free_runs = (free_hours * 3600.0 / FREE_RUN_S).ceil() as usize;
    let (results, wall) = run_jobs(&detectors, &plan, free_runs, runs_csv.is_some())?;
    let tallies: Vec<(String, Tally)> = names
        .into_iter()
        .enumerate()
        .map(|(d, name)| (name, Tally::of(&results, d, &plan)))
        .collect();
    let simulated_s: f64 = results.iter().map(|r| r.seconds).sum();
    let speed = simulated_s / wall.max(1e-9);

    let mut conditions = if lead_in_ms > 0.0 {
        format!(", each event after a lead-in of {lead_in_ms} ms")
    } else {
        String::new()
    };
    if noise_factor != 1.0 {
        conditions += &format!(", sensor noise {noise_factor} times the drawn");
    }
    if encoder_um != sim::DEFAULT_ENCODER_RESOLUTION_UM {
        conditions += &format!(", encoders resolving {encoder_um} um at the tip");
    }
    if film_highpass_hz > 0.0 {
        conditions += &format!(", the film AC-coupled at {film_highpass_hz} Hz");
    }
    if velocity_filter_hz > 0.0 {
        conditions += &format!(
            ", the loops' velocity from the encoders' difference through {velocity_filter_hz} Hz"
        );
    }
    if context_turned_deg != 0.0 {
        conditions +=
            &format!(", the context in a frame turned {context_turned_deg} degrees from the pad's");
    }
    for r in ranges {
        conditions += &format!(", {} drawn from {} .. {}", r.name, r.min, r.max);
    }
    match tallies.as_slice() {
        [(name, tally)] => {
            println!("{name}: {runs} randomized runs per scenario, base seed {seed}{conditions}");
            tally.print();
        }
        _ => {
            println!(
                "{runs} randomized runs per scenario, base seed {seed}{conditions}, the same runs for each detector"
            );
            print_comparison(&tallies);
        }
    }
    println!(
        "throughput: {simulated_s:.0} simulated s in {wall:.1} wall s = {speed:.0} simulated s per wall s ({} threads, {} detector(s) per run)",
        rayon::current_num_threads(),
        tallies.len()
    );
    if json.is_some() {
        let mut report = serde_json::json!({
            "runs_per_scenario": runs,
            "seed": seed,
            "lead_in_ms": lead_in_ms,
            "noise_factor": noise_factor,
            "encoder_um": encoder_um,
            "film_highpass_hz": film_highpass_hz,
            "velocity_filter_hz": velocity_filter_hz,
            "context_turned_deg": context_turned_deg,
            "ranges": ranges
                .iter()
                .map(|r| serde_json::json!({ "parameter": r.name, "min": r.min, "max": r.max }))
                .collect::<Vec<_>>(),
            "simulated_s_per_wall_s": speed,
        });
        // One detector: its fields at the top level; several: a list of them.
        if let [(name, t)] = tallies.as_slice() {
            if let (Some(r), serde_json::Value::Object(one)) =
                (report.as_object_mut(), t.json(name))
            {
                r.extend(one);
            }
        } else {
            let per_config: Vec<serde_json::Value> =
                tallies.iter().map(|(name, t)| t.json(name)).collect();
            report["configs"] = serde_json::Value::from(per_config);
        }
        outputs.write(0, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    if plot_bins.is_some() {
        let slot = usize::from(json.is_some());
        plot::write_bins(outputs.staging(slot), &bin_panels(&results))?;
    }
    if runs_csv.is_some() {
        let slot = usize::from(json.is_some()) + usize::from(plot_bins.is_some());
        outputs.write(slot, runs_table(&results, tallies.len()).as_bytes())?;
    }
    outputs.commit()?;
    Ok(())
}

/// One panel per single-event scenario for `--plot-bins`: each run's binning value and its
/// peak confidence with the first detector, by outcome.
fn bin_panels(results: &[JobResult]) -> Vec<plot::BinPanel> {
    Scenario::single_event()
        .iter()
        .enumerate()
        .filter_map(|(index, s)| {
            let binning = s.binning()?;
            let mut points: [Vec<(f64, f64)>; 4] = Default::default();
            for r in results {
                let (Job::Single { index: i, .. }, Some(bin), Some(outcome), Some(peak)) =
                    (r.job, r.bin, r.outcomes.first(), r.peaks.first())
                else {
                    continue;
                };
                if i != index {
                    continue;
                }
                let k = match outcome {
                    Outcome::Correct { .. } | Outcome::QuietAsExpected => 0,
                    Outcome::Wrong { .. } => 1,
                    Outcome::Missed => 2,
                    Outcome::Repeated { .. } => 3,
                };
                points[k].push((bin.value, *peak));
            }
            Some(plot::BinPanel {
                title: s.name().to_string(),
                x_label: format!("{} [{}]", binning.parameter, binning.unit),
                y_label: match s.expected() {
                    Some(e) => format!("peak {e} confidence"),
                    None => "highest confidence".to_string(),
                },
                log_x: binning.log,
                points,
            })
        })
        .collect()
}

/// `--runs-csv`: one row per run in job order, with `detectors` detectors' columns (named
/// plainly for one detector, suffixed `_1`, `_2`... in `--config` order for several), then
/// one column per metadata entry any run drew, in the order first met, empty where a run
/// did not draw it. An outcome is `right`, `wrong`, `missed`, `repeated` or, where nothing
/// is expected, `quiet`; latencies are from the true onset, the wrong confirmation's time
/// from the run's start, both in ms.
fn runs_table(results: &[JobResult], detectors: usize) -> String {
    let mut keys: Vec<&str> = Vec::new();
    for r in results {
        for (k, _) in &r.drawn {
            if !keys.contains(&k.as_str()) {
                keys.push(k);
            }
        }
    }
    let suffix = |d: usize| {
        if detectors == 1 {
            String::new()
        } else {
            format!("_{}", d + 1)
        }
    };
    let mut header = vec![
        "scenario".to_string(),
        "run".into(),
        "seed".into(),
        "bin".into(),
    ];
    for d in 0..detectors {
        for col in [
            "outcome",
            "latency_ms",
            "wrong_event",
            "wrong_at_ms",
            "peak",
        ] {
            header.push(format!("{col}{}", suffix(d)));
        }
    }
    header.extend(keys.iter().map(|k| k.to_string()));
    let mut out = csv_row(&header);
    for r in results {
        let (k, bin) = match r.job {
            Job::Single { k, .. } => (k, r.bin),
            Job::FreeMotion { k } => (k, None),
        };
        let scenario = r.job.scenario();
        let label = bin
            .zip(scenario.binning())
            .and_then(|(b, binning)| binning.labels().get(b.bin).cloned());
        let mut row = vec![
            scenario.name().to_string(),
            k.to_string(),
            r.seed.to_string(),
            label.unwrap_or_default(),
        ];
        for d in 0..detectors {
            let ms = |s: f64| format!("{:.2}", s * 1e3);
            let (outcome, latency, event, at) = match r.outcomes.get(d) {
                Some(Outcome::Correct { latency_s }) => {
                    ("right", ms(*latency_s), "", String::new())
                }
                Some(Outcome::Repeated { latency_s, .. }) => {
                    ("repeated", ms(*latency_s), "", String::new())
                }
                Some(Outcome::Wrong { event, t_s }) => {
                    ("wrong", String::new(), event.as_str(), ms(*t_s))
                }
                Some(Outcome::Missed) => ("missed", String::new(), "", String::new()),
                Some(Outcome::QuietAsExpected) => ("quiet", String::new(), "", String::new()),
                None => ("", String::new(), "", String::new()),
            };
            let peak = r.peaks.get(d).map_or(String::new(), |p| format!("{p:.4}"));
            row.extend([outcome.to_string(), latency, event.to_string(), at, peak]);
        }
        row.extend(keys.iter().map(|key| {
            r.drawn
                .iter()
                .find(|(k, _)| k == key)
                .map_or(String::new(), |(_, v)| v.clone())
        }));
        out += &csv_row(&row);
    }
    out
}

/// One CSV line: each field quoted where it holds a comma, a quote or a line break.
fn csv_row(fields: &[String]) -> String {
    let quoted: Vec<String> = fields
        .iter()
        .map(|f| {
            if f.contains([',', '"', '\n', '\r']) {
                format!("\"{}\"", f.replace('"', "\"\""))
            } else {
                f.clone()
            }
        })
        .collect();
    quoted.join(",") + "\n"
}

/// The longest time `--after-ms` and `--window-ms` take: a minute.
const MAX_AFTER_MS: f64 = 60_000.0;

/// A time flag within 0..=[`MAX_AFTER_MS`].
fn check_ms(flag: &str, ms: f64) -> Result<()> {
    if !(ms.is_finite() && (0.0..=MAX_AFTER_MS).contains(&ms)) {
        bail!(
            "{flag} = {} must be within 0..={MAX_AFTER_MS} ms",
            fingertip::readable(ms)
        );
    }
    Ok(())
}

/// `evaluate --traces`: every recording replayed with every detector, in parallel behind a
/// progress bar, and scored per labelled event ([`fingertip::corpus`]).
fn evaluate_traces(
    paths: &[PathBuf],
    after_ms: f64,
    configs: &[PathBuf],
    json: Option<&Path>,
) -> Result<()> {
    check_ms("--after-ms", after_ms)?;
    let (detectors, names) = load_detectors(configs)?;
    let files = fingertip::corpus::find_recordings(paths)?;
    let inputs: Vec<&Path> = configs.iter().chain(&files).map(PathBuf::as_path).collect();
    let plan = plan_outputs(&inputs, &[json.map(|p| (p, Kind::File))])?;
    let jobs = files.len() * detectors.len();
    let bar = progress(jobs, "recordings")?;
    let started = Instant::now();
    // One recording per job, as in `run_jobs`: recordings differ in length by 1,000 times.
    let results: Vec<fingertip::corpus::RecordingResult> = (0..jobs)
        .into_par_iter()
        .with_max_len(1)
        .map(|i| {
            let (file, detector) = (&files[i / detectors.len()], &detectors[i % detectors.len()]);
            let reader = TraceReader::open(file)?;
            let name = reader.name().to_string();
            let streamed = replay::replay_stream(detector, reader, |_| {})?;
            bar.inc(1);
            Ok(fingertip::corpus::RecordingResult::new(
                &name,
                &streamed,
                after_ms / 1e3,
            ))
        })
        // In order, so that the error reported is the first one's.
        .collect::<Vec<_>>()
        .into_iter()
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let wall = started.elapsed().as_secs_f64();
    let reports: Vec<(String, fingertip::corpus::CorpusReport)> = names
        .into_iter()
        .enumerate()
        .map(|(d, name)| {
            let mine: Vec<_> = results
                .iter()
                .skip(d)
                .step_by(detectors.len())
                .cloned()
                .collect();
            let events: Vec<String> = detectors[d]
                .events()
                .iter()
                .map(|n| n.to_string())
                .collect();
            (
                name,
                fingertip::corpus::CorpusReport::tally(&events, &mine, after_ms),
            )
        })
        .collect();
    use std::io::Write as _;
    let mut stdout = std::io::stdout().lock();
    for (k, (name, report)) in reports.iter().enumerate() {
        if reports.len() > 1 {
            writeln!(stdout, "[{}] {name}", k + 1)?;
        } else {
            writeln!(stdout, "{name}")?;
        }
        report.write(&mut stdout)?;
    }
    let hours = reports.first().map_or(0.0, |(_, r)| r.hours);
    writeln!(
        stdout,
        "throughput: {:.0} recorded s in {wall:.1} wall s = {:.0} recorded s per wall s ({} threads, {} detector(s))",
        hours * 3600.0,
        hours * 3600.0 * detectors.len() as f64 / wall.max(1e-9),
        rayon::current_num_threads(),
        detectors.len()
    )?;
    if json.is_some() {
        let per_config: Vec<serde_json::Value> =
            reports.iter().map(|(name, r)| r.json(name)).collect();
        let report = match per_config.as_slice() {
            [one] => one.clone(),
            _ => serde_json::json!({ "configs": per_config }),
        };
        plan.write(0, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    plan.commit()?;
    Ok(())
}

/// `features`: every recording replayed in parallel, each feature's values sorted into the
/// events and the time outside them; the separability table, and the figure.
fn features(
    paths: &[PathBuf],
    config: Option<&Path>,
    (window_ms, after_ms): (f64, f64),
    plot_to: Option<&Path>,
    json: Option<&Path>,
) -> Result<()> {
    check_ms("--window-ms", window_ms)?;
    check_ms("--after-ms", after_ms)?;
    let (detector, config_name) = load_detector(config)?;
    warn_short_window(window_ms / 1e3, detector.rate_hz());
    let files = fingertip::corpus::find_recordings(paths)?;
    let inputs: Vec<&Path> = config
        .into_iter()
        .chain(files.iter().map(PathBuf::as_path))
        .collect();
    let plan = plan_outputs(
        &inputs,
        &[
            plot_to.map(|p| (p, Kind::Figure)),
            json.map(|p| (p, Kind::File)),
        ],
    )?;
    let bar = progress(files.len(), "recordings")?;
    let (mut groups, _) = fingertip::features::sample_sets(
        &detector,
        &files,
        window_ms / 1e3,
        after_ms / 1e3,
        1,
        |_, _| true,
        |_, _| bar.inc(1),
    )?;
    bar.finish_and_clear();
    let samples = groups
        .pop()
        .unwrap_or_else(|| fingertip::features::FeatureSamples::new(&detector));
    let table = fingertip::features::separations(&samples);
    println!(
        "{config_name} on {} recordings: each event's first {window_ms} ms against the time outside events ({} ticks, {} kept)",
        files.len(),
        samples.outside_ticks(),
        samples.outside.first().map_or(0, Vec::len)
    );
    println!(
        "{:<20} {:<16} {:>8} {:>13} {:>13}   {:<19} {:>9}",
        "feature", "event", "ticks", "event median", "outside med.", "event is", "separates"
    );
    for s in &table {
        println!(
            "{:<20} {:<16} {:>8} {:>13} {:>13}   {:<5} {:>13} {:>7.1} %",
            s.feature,
            s.event,
            s.n_event,
            four_digits(s.event_median),
            four_digits(s.outside_median),
            if s.above { "above" } else { "below" },
            four_digits(s.threshold),
            s.balanced_accuracy * 100.0
        );
    }
    println!(
        "separates: the balanced accuracy of the best single threshold ((event ticks beyond it + outside ticks not) / 2), 50 % = no better than chance"
    );
    if samples.inside.iter().flatten().all(Vec::is_empty) {
        println!("no labelled event in the recordings: only the outside distributions are drawn");
    }
    let mut k = 0..;
    if plot_to.is_some() {
        let slot = k.next().unwrap_or(0);
        let panels: Vec<plot::FeaturePanel<'_>> = samples
            .features
            .iter()
            .enumerate()
            .map(|(f, feature)| plot::FeaturePanel {
                feature,
                outside: &samples.outside[f],
                events: samples
                    .events
                    .iter()
                    .enumerate()
                    .filter(|(e, _)| !samples.inside[*e][f].is_empty())
                    .map(|(e, event)| {
                        let accuracy = table
                            .iter()
                            .find(|s| s.feature == *feature && s.event == *event)
                            .map_or(0.5, |s| s.balanced_accuracy);
                        (event.as_str(), samples.inside[e][f].as_slice(), accuracy)
                    })
                    .collect(),
            })
            .collect();
        plot::write_features(plan.staging(slot), &panels)?;
    }
    if json.is_some() {
        let slot = k.next().unwrap_or(0);
        let report = serde_json::json!({
            "config": config_name,
            "recordings": files.len(),
            "window_ms": window_ms,
            "after_ms": after_ms,
            "separations": table,
        });
        plan.write(slot, serde_json::to_string_pretty(&report)?.as_bytes())?;
    }
    plan.commit()?;
    Ok(())
}

/// The most folds `fit` cross-validates with.
const MAX_FOLDS: usize = 20;

/// One line of a fit's figures: events right of those labelled, per event, and the false
/// confirmations per hour.
fn fit_figures(report: &fingertip::corpus::CorpusReport) -> String {
    let mut line = String::new();
    for r in &report.events {
        let _ = write!(line, "{} {}/{}  ", r.name, r.correct, r.runs);
    }
    let _ = write!(
        line,
        "false {} in {:.3} h = {:.2}/h",
        report.false_confirmations,
        report.outside_hours,
        report.false_per_hour()
    );
    line
}

/// Warns when `--window-ms` holds fewer than two ticks at the detector's rate: each event
/// is then judged by its onset's value alone.
fn warn_short_window(window_s: f64, rate_hz: f32) {
    let ticks = window_s * f64::from(rate_hz);
    if ticks < 2.0 {
        eprintln!(
            "warning: --window-ms {} holds {} tick(s) at the detector's {rate_hz} Hz: each event is judged by its onset's value alone; give at least {} ms",
            window_s * 1e3,
            ticks.ceil().max(1.0),
            fingertip::readable(2e3 / f64::from(rate_hz))
        );
    }
}

/// Names the events no confirm level kept within their share of the budget.
fn warn_over_budget(events: &[String], options: &fingertip::fit::FitOptions) {
    for e in events {
        eprintln!(
            "warning: no confirm level keeps `{e}` within its share of --budget {} false confirmations per hour: it got the level with the fewest (see its comment in the file); a better feature, more labelled events, or a larger --budget",
            options.budget_per_hour
        );
    }
}

/// `fit`: cross-validated by recording, then fitted on every recording and written.
fn fit(
    paths: &[PathBuf],
    config: Option<&Path>,
    out: &Path,
    options: fingertip::fit::FitOptions,
    folds: usize,
) -> Result<()> {
    use fingertip::fit;
    check_ms("--window-ms", options.window_s * 1e3)?;
    check_ms("--after-ms", options.after_s * 1e3)?;
    if !(options.budget_per_hour.is_finite() && (0.0..=1e6).contains(&options.budget_per_hour)) {
        bail!(
            "--budget = {} must be within 0..=1e6 false confirmations per hour",
            fingertip::readable(options.budget_per_hour)
        );
    }
    if folds > MAX_FOLDS {
        bail!("--folds = {folds} must be within 0..={MAX_FOLDS}");
    }
    let (base_text, base_name) = match config {
        Some(p) => (
            std::fs::read_to_string(p).with_context(|| p.display().to_string())?,
            p.display().to_string(),
        ),
        None => (
            fingertip::APPROACH_TOML.to_string(),
            "configs/approach.toml".to_string(),
        ),
    };
    let base = Config::from_toml(&base_text).with_context(|| base_name.clone())?;
    let (detector, _) = load_detector(config)?;
    warn_short_window(options.window_s, detector.rate_hz());
    let files = fingertip::corpus::find_recordings(paths)?;
    let inputs: Vec<&Path> = config
        .into_iter()
        .chain(files.iter().map(PathBuf::as_path))
        .collect();
    let plan = plan_outputs(&inputs, &[Some((out, Kind::File))])?;
    println!("fitting {base_name} on {} recordings", files.len());
    let fitted = fit::fit_folds(&base, &detector, &files, folds, &options)?;
    let base_score = |keep: &dyn Fn(usize) -> bool| {
        let results: Vec<_> = fitted
            .base
            .iter()
            .enumerate()
            .filter(|(i, _)| keep(*i))
            .map(|(_, r)| r.clone())
            .collect();
        let events: Vec<String> = base.events.iter().map(|e| e.name.clone()).collect();
        fingertip::corpus::CorpusReport::tally(&events, &results, options.after_s * 1e3)
    };
    let events: Vec<String> = base.events.iter().map(|e| e.name.clone()).collect();
    let tally = |results: &[fingertip::corpus::RecordingResult]| {
        fingertip::corpus::CorpusReport::tally(&events, results, options.after_s * 1e3)
    };
    let k = fitted.folds.len();
    if k >= 2 {
        println!("cross-validation, {k} folds by recording (recording i in fold i mod {k}):");
        let mut all_held = Vec::new();
        for (fold, one) in fitted.folds.iter().enumerate() {
            let held = |i: usize| fitted.holds_out(fold, i);
            let test = (0..files.len()).filter(|&i| held(i)).count();
            println!(
                "  fold {}: {} training, {test} held out",
                fold + 1,
                files.len() - test
            );
            println!("    fitted, training:  {}", fit_figures(&one.trained));
            println!("    fitted, held out:  {}", fit_figures(&tally(&one.held)));
            println!("    base,   held out:  {}", fit_figures(&base_score(&held)));
            warn_over_budget(&one.over_budget, &options);
            all_held.extend(one.held.iter().cloned());
        }
        println!("  every fold's held-out recordings together:");
        println!("    fitted, held out:  {}", fit_figures(&tally(&all_held)));
        println!(
            "    base,   held out:  {}",
            fit_figures(&base_score(&|_| true))
        );
    }
    let fitted = fitted.whole;
    println!("on every recording (training figures):");
    println!("    fitted: {}", fit_figures(&fitted.trained));
    println!("    base:   {}", fit_figures(&base_score(&|_| true)));
    warn_over_budget(&fitted.over_budget, &options);
    let text = fit::write_toml(
        &base_text,
        &fitted.config,
        &fitted.notes,
        &fit::header(&base_name, files.len(), &options),
    )?;
    plan.write(0, text.as_bytes())?;
    plan.commit()?;
    println!("written: {}", out.display());
    Ok(())
}

/// The best cancellations of `input` by `motion` in a trace, and the best as a feature in
/// the configuration's working units.
fn identify(trace: &Path, input: &str, motion: &str, config: Option<&Path>) -> Result<()> {
    let (config, config_name) = match config {
        Some(p) => (detector_build::load(p)?, p.display().to_string()),
        None => (
            Config::from_toml(fingertip::APPROACH_TOML)?,
            "configs/approach.toml".to_string(),
        ),
    };
    let data = Trace::read(trace)?;
    let fits = fingertip::identify::identify(&data, input, motion)
        .with_context(|| trace.display().to_string())?;
    println!(
        "{}: {input} explained by {motion} low-passed, over {} rows (event rows left out)",
        trace.display(),
        data.len()
    );
    println!(
        "{:>10} {:>14} {:>10} {:>14}",
        "cutoff Hz", "gain", "explained", "residual RMS"
    );
    for f in fits.iter().take(5) {
        println!(
            "{:>10.1} {:>14} {:>9.1} % {:>14}",
            f.cutoff_hz,
            four_digits(f.gain),
            f.explained * 100.0,
            four_digits(f.residual_rms)
        );
    }
    let best = fits[0];
    let scale = |name: &str| {
        config
            .channels
            .iter()
            .find(|c| c.name == name)
            .map(|c| c.scale)
    };
    match (scale(input), scale(motion)) {
        (Some(si), Some(sm)) => println!(
            "in {config_name}'s units:\nstage = {{ cancel = {{ input = \"{input}\", motion = \"{motion}\", gain = {:.4}, cutoff_hz = {:.1} }} }}",
            best.gain * f64::from(si) / f64::from(sm),
            best.cutoff_hz
        ),
        _ => println!(
            "{config_name} has no channel `{input}` or `{motion}`: the gain above is in the trace's units"
        ),
    }
    Ok(())
}

/// Four significant digits in the everyday range, [`fingertip::readable`] outside it.
fn four_digits(v: f64) -> String {
    if v != 0.0 && (1e-3..1e7).contains(&v.abs()) {
        let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        fingertip::readable(v)
    }
}

fn demo(out: &Path) -> Result<()> {
    let (detector, config_name) = load_detector(None)?;
    std::fs::create_dir_all(out).with_context(|| out.display().to_string())?;
    let runs = [
        ("contact_hard_8", "Contact, hard object, 8 cm/s"),
        ("contact_soft_2", "Contact, soft object, 2 cm/s"),
        ("disturbance_large_5", "Disturbance (vibration), 5 cm/s"),
        ("link_collision_8", "Link collision, 8 cm/s"),
        (
            "sudden_accel_moving_5",
            "Sudden acceleration while moving, 5 cm/s",
        ),
    ];
    // Every figure, per run then the grid, each as PNG and SVG: staged, then committed
    // together.
    let names = runs.iter().map(|r| r.0).chain(["figure4"]);
    let files: Vec<PathBuf> = names
        .flat_map(|n| ["png", "svg"].map(|ext| out.join(format!("{n}.{ext}"))))
        .collect();
    let figures: Vec<Option<(&Path, Kind)>> = files
        .iter()
        .map(|f| Some((f.as_path(), Kind::Figure)))
        .collect();
    let plan = plan_outputs(&[], &figures)?;
    println!("fingertip demo: {config_name}, nominal Table 1 runs, event at t = 20 ms\n");
    let mut traces = Vec::new();
    let mut recs = Vec::new();
    for (name, _) in runs {
        let scenario: Scenario = name.parse()?;
        let trace = sim::simulate(
            &scenario,
            &SimOptions {
                seed: 1,
                randomize: false,
                ..SimOptions::default()
            },
        )?;
        recs.push(record(&detector, &trace)?);
        traces.push((scenario, trace));
    }
    let mut plots = Vec::new();
    let mut staged = (0..files.len()).map(|k| plan.staging(k));
    for (((scenario, trace), rec), (_, title)) in traces.iter().zip(&recs).zip(runs) {
        let truth = truth_of(trace);
        let expected = scenario
            .expected()
            .map(|e| (e, truth.as_ref().map_or(0.0, |t| t.1)));
        let verdict = score::classify(expected, &rec.decisions);
        println!("{title}: {verdict}");
        for d in &rec.decisions {
            println!("  {}", describe(d, truth.as_ref()));
        }
        let run = RunPlot {
            title: title.to_string(),
            t: trace.time(),
            series: rec.series.clone(),
            truth,
            decisions: &rec.decisions,
        };
        for p in staged.by_ref().take(2) {
            plot::write_run(p, &run)?;
        }
        plots.push(run);
    }
    let figure: Vec<RunPlot<'_>> = plots.iter().take(4).cloned().collect();
    for p in staged {
        plot::write_grid(p, &figure, 2, (800, 380))?;
    }
    plan.commit()?;
    println!(
        "\nfigures: {}/figure4.png (.svg) and one per run",
        out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Jobs made one by one are every scenario's runs in order, then free motion, each
    /// with its own seed: the order and seeds an evaluation reports.
    #[test]
    fn jobs_are_made_in_order_without_a_list() {
        let runs = 3;
        let singles = Scenario::single_event().len() * runs;
        let jobs: Vec<Job> = (0..singles + 2).map(|i| Job::at(i, runs)).collect();
        for (i, job) in jobs.iter().take(singles).enumerate() {
            assert!(
                matches!(*job, Job::Single { index, k } if index == i / runs && k == i % runs),
                "{i}: {job:?}"
            );
        }
        assert!(matches!(jobs[singles], Job::FreeMotion { k: 0 }));
        assert!(matches!(jobs[singles + 1], Job::FreeMotion { k: 1 }));
        let mut seeds: Vec<u64> = jobs.iter().map(|j| j.seed(1)).collect();
        seeds.sort_unstable();
        seeds.dedup();
        assert_eq!(seeds.len(), jobs.len(), "every run its own seed");
        // Tuning on one base seed and reporting on another uses disjoint runs.
        let runs = 1000;
        let n = Scenario::single_event().len() * runs + 60;
        let tuned: std::collections::HashSet<u64> =
            (0..n).map(|i| Job::at(i, runs).seed(100)).collect();
        assert!((0..n).all(|i| !tuned.contains(&Job::at(i, runs).seed(1))));
        // The largest evaluation allowed is made as it runs: its last job is reachable.
        let last = Scenario::single_event().len() * MAX_RUNS;
        assert!(matches!(Job::at(last, MAX_RUNS), Job::FreeMotion { k: 0 }));
    }
}
