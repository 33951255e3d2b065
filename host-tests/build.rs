//! Generates, on the PC, the image and the tick of the test detector
//! `tests/data/every_kind.toml` (`EveryKindTick`), with the same helper as the firmware's
//! build script, for `tests/core_generated.rs` to hold against the interpreter. A
//! configuration that does not build fails the build naming the item.

use std::env;
use std::error::Error;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn Error>> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let out = PathBuf::from(env::var("OUT_DIR")?);
    detector_build::Generator::new(manifest.join("tests/data/every_kind.toml"))
        .tick_type("EveryKindTick")
        // Its phase without events is one of the kinds it exists to cover.
        .report_warnings(false)
        .generate(&out)?;
    Ok(())
}
