//! Prepares what the QEMU program embeds, on the PC:
//!
//! - `trace.ftrc`: the inputs to replay, in the format of `src/trace.rs`: the file named by
//!   `FINGERTIP_QEMU_TRACE` if set (the host test writes the simulator's golden runs there),
//!   else a deterministic synthetic trace generated here for the detector `fingertip-tick`
//!   was generated from (`configs/approach.toml`, or the file `FINGERTIP_CONFIG` names;
//!   the crate's `links` metadata says which);
//! - for the target only, the linker script `mps2-an386.x` (QEMU's Cortex-M4 board, for
//!   cortex-m-rt's runtime), by absolute path.

use std::env;
use std::error::Error;
use std::f64::consts::PI;
use std::fs;
use std::path::{Path, PathBuf};

use detector_build::Config;
use detector_core::Detector;

#[allow(dead_code)]
#[path = "src/trace.rs"]
mod trace;

type Result<T> = std::result::Result<T, Box<dyn Error>>;

fn main() -> Result<()> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let out = PathBuf::from(env::var("OUT_DIR")?);

    if env::var("CARGO_CFG_TARGET_OS")? == "none" {
        link_script(&manifest);
    }

    // The detector the firmware's tick crate was generated from (another configuration's
    // cost on the chip: FINGERTIP_CONFIG; the host test always builds the default's).
    let config_path = env::var("DEP_FINGERTIP_TICK_CONFIG")
        .map_err(|_| "fingertip-tick did not report its configuration")?;
    println!("cargo:rerun-if-env-changed=FINGERTIP_CONFIG");
    println!("cargo:rerun-if-changed={config_path}");
    let config = detector_build::load(Path::new(&config_path))?;

    println!("cargo:rerun-if-env-changed=FINGERTIP_QEMU_TRACE");
    let (trace, source) = match env::var_os("FINGERTIP_QEMU_TRACE") {
        Some(p) => {
            let p = PathBuf::from(p);
            println!("cargo:rerun-if-changed={}", p.display());
            let bytes = fs::read(&p).map_err(|e| format!("reading {}: {e}", p.display()))?;
            (bytes, p.display().to_string())
        }
        None => (synthetic(&config)?, "synthetic".into()),
    };
    let parsed = trace::Trace::parse(&trace).map_err(|e| format!("trace {source}: {e}"))?;
    if parsed.channels() != config.channels.len() {
        return Err(format!(
            "trace {source} has {} channels per record, the configuration {}",
            parsed.channels(),
            config.channels.len()
        )
        .into());
    }
    fs::write(out.join("trace.ftrc"), &trace)?;
    println!("cargo:rustc-env=FINGERTIP_QEMU_TRACE_SOURCE={source}");
    Ok(())
}

/// Links with this crate's own script, by absolute path, instead of cortex-m-rt's
/// `link.x`: that one says `INCLUDE memory.x`, which the linker resolves in its working
/// directory (the workspace root, home of the firmware's STM32 `memory.x`) before any
/// search path. See `mps2-an386.x`.
fn link_script(manifest: &Path) {
    let script = manifest.join("mps2-an386.x");
    println!("cargo:rerun-if-changed={}", script.display());
    println!("cargo:rustc-link-arg-bins=-T{}", script.display());
}

/// A deterministic stand-in for the simulator's golden traces: the approach runs of the
/// paper's Table 1 (contact, link collision, disturbance, sudden acceleration) plus one
/// run with faulty channels, 200 ms each at the configured rate, the event at 20 ms.
fn synthetic(config: &Config) -> Result<Vec<u8>> {
    let detector: Detector = detector_build::build(config)?;
    let names: Vec<&str> = config.channels.iter().map(|c| c.name.as_str()).collect();
    let idx = |n: &str| -> Result<usize> {
        names
            .iter()
            .position(|c| *c == n)
            .ok_or_else(|| format!("the synthetic trace needs channel {n}").into())
    };
    let ch = Channels {
        force_x: idx("force_x")?,
        force_y: idx("force_y")?,
        skin_accel: idx("skin_accel")?,
        stress_rate: idx("stress_rate")?,
        pos_err_x: idx("pos_err_x")?,
        pos_err_y: idx("pos_err_y")?,
        vel_des_x: idx("vel_des_x")?,
        vel_des_y: idx("vel_des_y")?,
        acc_des_x: idx("acc_des_x")?,
        acc_des_y: idx("acc_des_y")?,
    };
    let rate = f64::from(config.rate_hz);
    let ticks = (0.2 * rate).round() as u32;
    // (name, scenario, first tick): one run starts just before the tick counter wraps.
    let runs: [(&str, Scenario, u32); 6] = [
        (
            "contact_hard_5cm_s",
            Scenario::Contact {
                speed: 0.05,
                stiffness: 2000.0,
            },
            0,
        ),
        (
            "contact_soft_2cm_s",
            Scenario::Contact {
                speed: 0.02,
                stiffness: 300.0,
            },
            1_000_000,
        ),
        (
            "link_collision_8cm_s",
            Scenario::Collision { speed: 0.08 },
            0,
        ),
        (
            "disturbance_large",
            Scenario::Disturbance { amplitude: 1.5 },
            u32::MAX - 300,
        ),
        ("sudden_acceleration", Scenario::SuddenAcceleration, 0),
        ("contact_with_faults", Scenario::ContactWithFaults, 0),
    ];
    let mut bytes = Vec::new();
    // The encoder borrows `bytes` until the end of this block.
    {
        let mut enc = trace::Encoder::new(
            |b: &[u8]| bytes.extend_from_slice(b),
            names.len(),
            runs.len() as u32,
        )
        .map_err(|e| format!("{e}"))?;
        let mut rng = XorShift(0x2545_F491);
        for (i, (name, scenario, start)) in runs.iter().enumerate() {
            enc.segment(i as u32, name, *start, ticks)
                .map_err(|e| format!("{e}"))?;
            for k in 0..ticks {
                let t = f64::from(k) / rate;
                let (values, faults) = scenario.sample(t, &mut rng);
                let mut samples = vec![0i32; names.len()];
                // SI values, in each channel's working unit (its `scale`).
                let put = |s: &mut Vec<i32>, i: usize, v: f64| {
                    s[i] = detector.sample_from_si(i, v).to_bits();
                };
                put(&mut samples, ch.force_x, values.force[0]);
                put(&mut samples, ch.force_y, values.force[1]);
                put(&mut samples, ch.skin_accel, values.skin_accel);
                put(&mut samples, ch.stress_rate, values.stress_rate);
                put(&mut samples, ch.pos_err_x, values.pos_err[0]);
                put(&mut samples, ch.pos_err_y, values.pos_err[1]);
                put(&mut samples, ch.vel_des_x, values.vel_des[0]);
                put(&mut samples, ch.vel_des_y, values.vel_des[1]);
                put(&mut samples, ch.acc_des_x, values.acc_des[0]);
                put(&mut samples, ch.acc_des_y, values.acc_des[1]);
                let mask = faults
                    .iter()
                    .map(|n| idx(n).map(|i| 1u32 << i))
                    .sum::<Result<u32>>()?;
                enc.record(mask, &samples).map_err(|e| format!("{e}"))?;
            }
        }
    }
    Ok(bytes)
}

struct Channels {
    force_x: usize,
    force_y: usize,
    skin_accel: usize,
    stress_rate: usize,
    pos_err_x: usize,
    pos_err_y: usize,
    vel_des_x: usize,
    vel_des_y: usize,
    acc_des_x: usize,
    acc_des_y: usize,
}

#[derive(Default)]
struct Values {
    force: [f64; 2],
    skin_accel: f64,
    stress_rate: f64,
    pos_err: [f64; 2],
    vel_des: [f64; 2],
    acc_des: [f64; 2],
}

#[derive(Clone, Copy)]
enum Scenario {
    Contact { speed: f64, stiffness: f64 },
    Collision { speed: f64 },
    Disturbance { amplitude: f64 },
    SuddenAcceleration,
    ContactWithFaults,
}

/// The event happens at 20 ms, as in the paper's runs.
const T_EVENT: f64 = 0.020;

/// A decaying ring: a second-order system's impulse response.
fn ring(dt: f64, freq_hz: f64, tau: f64) -> f64 {
    if dt < 0.0 {
        0.0
    } else {
        (-dt / tau).exp() * (2.0 * PI * freq_hz * dt).sin()
    }
}

impl Scenario {
    fn sample(self, t: f64, rng: &mut XorShift) -> (Values, &'static [&'static str]) {
        let mut v = Values::default();
        let dt = t - T_EVENT;
        let after = dt >= 0.0;
        // Sensor noise, always present.
        v.force = [0.01 * rng.uniform(), 0.01 * rng.uniform()];
        v.skin_accel = 0.3 * rng.uniform();
        v.stress_rate = 0.1 * rng.uniform();
        v.pos_err = [0.00002 * rng.uniform(), 0.00002 * rng.uniform()];
        let mut faults: &'static [&'static str] = &[];
        match self {
            Scenario::Contact { speed, stiffness } => contact(&mut v, speed, stiffness, dt),
            Scenario::ContactWithFaults => {
                contact(&mut v, 0.05, 2000.0, dt);
                let ms = t * 1000.0;
                faults = if (10.0..40.0).contains(&ms) {
                    // The skin accelerometer drops out across the contact: degraded.
                    &["skin_accel"]
                } else if (120.0..140.0).contains(&ms) {
                    // The controller's context goes stale: unjudgeable.
                    &["vel_des_x", "vel_des_y"]
                } else if (160.0..170.0).contains(&ms) {
                    &[
                        "skin_accel",
                        "stress_rate",
                        "pos_err_x",
                        "pos_err_y",
                        "force_x",
                    ]
                } else {
                    &[]
                };
            }
            Scenario::Collision { speed } => {
                v.vel_des[0] = speed;
                if after {
                    // A link hits something: the tip stops short of its target and rings.
                    v.pos_err[0] += (speed * dt).min(0.004);
                    v.force[0] += 0.3 * ring(dt, 80.0, 0.02);
                    v.force[1] += 0.2 * ring(dt, 95.0, 0.02);
                    v.skin_accel += 60.0 * ring(dt, 220.0, 0.04);
                }
            }
            Scenario::Disturbance { amplitude } => {
                v.vel_des[0] = 0.05;
                if after {
                    // Something taps the tip: it rings, the position barely moves.
                    v.force[0] += 0.4 * amplitude * ring(dt, 90.0, 0.015);
                    v.force[1] += 0.3 * amplitude * ring(dt, 70.0, 0.015);
                    v.skin_accel += 60.0 * amplitude * ring(dt, 300.0, 0.008);
                    v.pos_err[0] += 0.00005 * amplitude * ring(dt, 90.0, 0.015);
                }
            }
            Scenario::SuddenAcceleration => {
                // From standstill: 20 m/s^2 commanded for 5 ms; the tip's own mass
                // (20 g) loads the force sensor against the motion.
                if after {
                    let a = if dt < 0.005 { 20.0 } else { 0.0 };
                    v.acc_des[0] = a;
                    v.vel_des[0] = 20.0 * dt.min(0.005);
                    v.force[0] -= 0.02 * a;
                    v.skin_accel += 8.0 * ring(dt, 150.0, 0.004);
                    v.pos_err[0] += 0.0004 * (1.0 - (-dt / 0.004).exp()) * (-dt / 0.02).exp();
                }
            }
        }
        (v, faults)
    }
}

/// A contact at `speed` with an object of `stiffness` (N/m), `dt` after it.
fn contact(v: &mut Values, speed: f64, stiffness: f64, dt: f64) {
    v.vel_des[0] = speed;
    if dt >= 0.0 {
        // The tip is pushed back as it presses into the object.
        let depth = (speed * dt).min(0.003);
        v.force[0] -= stiffness * depth;
        v.stress_rate += 25.0 * (-dt / 0.004).exp() * (speed / 0.05).sqrt();
        v.skin_accel += 25.0 * ring(dt, 350.0, 0.003);
        v.pos_err[0] += depth;
    }
}

/// xorshift32: a tiny deterministic noise source.
struct XorShift(u32);

impl XorShift {
    /// Uniform in [-1, 1).
    fn uniform(&mut self) -> f64 {
        let mut x = self.0;
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        self.0 = x;
        f64::from(x) / f64::from(u32::MAX) * 2.0 - 1.0
    }
}
