//! Prepares what the firmware embeds, on the PC:
//!
//! - the detector configuration `configs/approach.toml` (or the file named by
//!   `FINGERTIP_CONFIG`, relative to the workspace root), parsed and validated by
//!   `detector_build::Generator` (a bad configuration fails the build with its message),
//!   which writes the detector's image (`detector.image`), which the chip loads in place
//!   at boot, and its tick with the tables written in as constants (`detector_tick.rs`,
//!   the unit struct `ApproachTick`), which the firmware runs; the configuration is then
//!   checked against the channels the board can feed and the sample timer's clock;
//! - `build_hash.rs`: the first 32 bits of the commit the firmware is built from
//!   (`git rev-parse HEAD` in the workspace, or `FINGERTIP_BUILD_HASH`; 0 when neither
//!   tells), reported in the status heartbeat;
//! - `build_consts.rs`: the detector image's CRC-32 (reported in the status heartbeat),
//!   its source path and the sample timer's period for its rate (the CAN node id is found
//!   at boot, not built in);
//! - for the chip only: `memory.x` on the linker path and the link arguments of the
//!   board binary (`-Tlink.x`, `-Tdefmt.x`, `--nmagic`), for the binary alone so that no
//!   other crate built for the target is made to link defmt.

use std::env;
use std::error::Error;
use std::fmt::Write as _;
use std::fs;
use std::path::PathBuf;

use detector_build::{Config, Generator};

#[allow(dead_code)]
#[path = "src/wiring.rs"]
mod wiring;

#[allow(dead_code)]
#[path = "src/trigger.rs"]
mod trigger;

type Result<T> = std::result::Result<T, Box<dyn Error>>;

const DEFAULT_CONFIG: &str = "configs/approach.toml";

fn main() -> Result<()> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let root = manifest.join("..");
    let out = PathBuf::from(env::var("OUT_DIR")?);

    println!("cargo:rerun-if-env-changed=FINGERTIP_CONFIG");
    println!("cargo:rerun-if-changed=src/wiring.rs");
    println!("cargo:rerun-if-changed=src/trigger.rs");

    let config_rel = env::var("FINGERTIP_CONFIG").unwrap_or_else(|_| DEFAULT_CONFIG.into());
    // Validated, and written as the image the chip loads in place at boot (no
    // configuration, no serde and no build on the chip: they would need far more stack
    // than it has) and as the tick generated for it.
    let generated = Generator::new(root.join(&config_rel))
        .tick_type("ApproachTick")
        .file_stem("detector")
        .generate(&out)?;
    let config = &generated.config;
    check_channels(config).map_err(|e| format!("{config_rel}: {e}"))?;
    let period = trigger::TriggerPeriod::new(
        wiring::SAMPLE_TIMER_CLOCK_HZ,
        config.rate_hz,
        wiring::MAX_RATE_ERROR_PPM,
    )
    .map_err(|e| {
        format!(
            "{config_rel}: rate_hz = {}: the {} Hz sample timer cannot make it within {} ppm ({e:?})",
            config.rate_hz,
            wiring::SAMPLE_TIMER_CLOCK_HZ,
            wiring::MAX_RATE_ERROR_PPM
        )
    })?;

    let mut consts = String::new();
    writeln!(
        consts,
        "/// CRC-32 (ISO-HDLC, as zlib's) of the embedded detector image."
    )?;
    writeln!(
        consts,
        "pub const CONFIG_CHECKSUM: u32 = {:#010x};",
        generated.image_crc
    )?;
    writeln!(
        consts,
        "/// The configuration file the firmware was built with, from the workspace root."
    )?;
    writeln!(consts, "pub const CONFIG_SOURCE: &str = {config_rel:?};")?;
    writeln!(
        consts,
        "/// The embedded detector's name: the configuration file's stem, at most 16 bytes."
    )?;
    writeln!(
        consts,
        "pub const CONFIG_NAME: &str = {:?};",
        config_name(&config_rel)
    )?;
    writeln!(
        consts,
        "/// Sample-timer clocks per detector tick, for the configuration's rate."
    )?;
    writeln!(consts, "pub const TRIGGER_CLOCKS: u32 = {};", period.clocks)?;
    writeln!(consts, "/// The rate those clocks make, mHz.")?;
    writeln!(
        consts,
        "pub const TRIGGER_RATE_MHZ: u64 = {};",
        period.actual_mhz
    )?;
    fs::write(out.join("build_consts.rs"), consts)?;
    fs::write(
        out.join("build_hash.rs"),
        format!(
            "/// The first 32 bits of the commit the firmware was built from (0 unknown).\npub const BUILD_HASH: u32 = {:#010x};\n",
            build_hash(&root)
        ),
    )?;

    if env::var("CARGO_CFG_TARGET_OS")? == "none" {
        // cortex-m-rt's link.x includes `memory.x`; the workspace root holds the STM32's.
        let memory = root.join("memory.x");
        println!("cargo:rerun-if-changed={}", memory.display());
        let dir = out.join("link");
        fs::create_dir_all(&dir)?;
        fs::copy(&memory, dir.join("memory.x"))?;
        println!("cargo:rustc-link-search={}", dir.display());
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
    Ok(())
}

/// The configuration file's stem, cut to the 16 bytes a detector name has on the bus.
fn config_name(path: &str) -> String {
    let stem = std::path::Path::new(path)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut name = String::new();
    for c in stem.chars() {
        if name.len() + c.len_utf8() > 16 {
            break;
        }
        name.push(c);
    }
    name
}

/// The first 32 bits of the commit being built: `FINGERTIP_BUILD_HASH` (hex), else git's
/// HEAD in the workspace, else 0. Rebuilds when HEAD moves.
fn build_hash(root: &std::path::Path) -> u32 {
    println!("cargo:rerun-if-env-changed=FINGERTIP_BUILD_HASH");
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .current_dir(root)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
        println!("cargo:rerun-if-changed={dir}/HEAD");
        println!("cargo:rerun-if-changed={dir}/logs/HEAD");
    }
    let hex = env::var("FINGERTIP_BUILD_HASH")
        .ok()
        .or_else(|| git(&["rev-parse", "HEAD"]))
        .unwrap_or_default();
    hex.get(..8)
        .and_then(|h| u32::from_str_radix(h, 16).ok())
        .unwrap_or(0)
}

/// Every configured channel must be one the board feeds; a channel nobody writes would
/// sit at zero and look like a real measurement.
fn check_channels(config: &Config) -> Result<()> {
    for c in &config.channels {
        if !wiring::ALL_CHANNELS.contains(&c.name.as_str()) {
            return Err(format!(
                "channel '{}' has no source on the board (it can feed {})",
                c.name,
                wiring::ALL_CHANNELS.join(", ")
            )
            .into());
        }
    }
    Ok(())
}
