//! Generates, on the PC, the detector the chip runs: `configs/approach.toml`, or the file
//! named by `FINGERTIP_CONFIG` (relative to the workspace root), parsed and validated by
//! `detector_build::Generator` (a bad configuration fails the build with its message), as
//! its image (`detector.image`, which the chip loads in place at boot) and its tick
//! (`detector_tick.rs`, the unit struct `GeneratedTick`, its tables written in as
//! constants).
//!
//! The crates that embed it read, in their own build scripts, which configuration it was
//! (`DEP_FINGERTIP_TICK_CONFIG`: its absolute path; `DEP_FINGERTIP_TICK_CONFIG_SOURCE`: as
//! given; `DEP_FINGERTIP_TICK_IMAGE_CRC`: the image's CRC-32), so that one variable chooses
//! it for the firmware and the QEMU program alike.

use std::env;
use std::error::Error;
use std::path::PathBuf;

use detector_build::Generator;

const DEFAULT_CONFIG: &str = "configs/approach.toml";

fn main() -> Result<(), Box<dyn Error>> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let root = manifest.join("../..");
    let out = PathBuf::from(env::var("OUT_DIR")?);

    println!("cargo::rerun-if-env-changed=FINGERTIP_CONFIG");
    let source = env::var("FINGERTIP_CONFIG").unwrap_or_else(|_| DEFAULT_CONFIG.into());
    let path = root.join(&source);
    let generated = Generator::new(&path)
        .tick_type("GeneratedTick")
        .file_stem("detector")
        .generate(&out)?;
    let path = path.canonicalize()?;
    println!("cargo::rustc-env=FINGERTIP_TICK_CONFIG_SOURCE={source}");
    println!("cargo::metadata=config={}", path.display());
    println!("cargo::metadata=config_source={source}");
    println!("cargo::metadata=image_crc={:#010x}", generated.image_crc);
    Ok(())
}
