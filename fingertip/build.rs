//! Generates, on the PC, the tick of the default detector `configs/approach.toml`
//! (`ApproachTick`), the firmware's way of running it: the tool runs it whenever the
//! detector it loaded is that one, bit for bit the interpreter's and about three times
//! faster.

use std::env;
use std::error::Error;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn Error>> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let out = PathBuf::from(env::var("OUT_DIR")?);
    detector_build::Generator::new(manifest.join("../configs/approach.toml"))
        .tick_type("ApproachTick")
        .generate(&out)?;
    Ok(())
}
