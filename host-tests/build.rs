//! Generates, on the PC, the tick of the test detector `tests/data/every_kind.toml`
//! (`Detector::to_rust`, as the firmware's `build.rs` does for its configuration), for
//! `tests/core_generated.rs` to hold against the interpreter. A configuration that does not
//! build fails the build with the core's message.

use std::env;
use std::error::Error;
use std::fs;
use std::path::PathBuf;

use detector_core::{Config, Detector};

fn main() -> Result<(), Box<dyn Error>> {
    let manifest = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let out = PathBuf::from(env::var("OUT_DIR")?);
    let path = manifest.join("tests/data/every_kind.toml");
    println!("cargo:rerun-if-changed={}", path.display());
    let text = fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let config = Config::from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let detector = Detector::build(&config).map_err(|e| format!("{}: {e}", path.display()))?;
    fs::write(out.join("every_kind_tick.rs"), detector.to_rust())?;
    Ok(())
}
