#![doc = include_str!("../README.md")]
#![forbid(unsafe_code)]

mod codegen;
mod compile;
mod config;
mod image;
mod load;

use std::fmt;
use std::fs;
use std::path::{Path, PathBuf};

use detector_core::Detector;

pub use compile::{Compiled, Event, Psi, Weighted, compile};
pub use config::{
    ChannelSpec, Config, ConfigError, ContextTerm, EarlySpec, EventSpec, FeatureSpec, Item,
    LevelSpec, PhaseSpec, Problem, SensorTerm, Warning,
};
pub use image::image_crc;
pub use load::LoadError;

/// Validates a configuration and loads the detector it describes, through its image, as
/// the firmware does.
pub fn build(config: &Config) -> Result<Detector, ConfigError> {
    compile(config)?.detector()
}

/// A configuration file could not be used.
#[derive(Debug)]
pub enum Error {
    /// Reading or writing a file failed.
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The configuration file does not parse or is invalid.
    Config {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the item named.
        source: Box<LoadError>,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {source}", path.display()),
            Error::Config { path, source } => write!(f, "{}: {source}", path.display()),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            Error::Config { source, .. } => Some(source.as_ref()),
        }
    }
}

/// Reads and validates a TOML configuration file.
pub fn load(path: &Path) -> Result<Config, Error> {
    let text = fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.to_owned(),
        source,
    })?;
    Config::from_toml(&text).map_err(|source| Error::Config {
        path: path.to_owned(),
        source: Box::new(source),
    })
}

/// Generates, from a build script, what a crate embeds for one detector configuration:
/// its image (`<stem>.image`) and its tick (`<stem>_tick.rs`, a unit struct implementing
/// `detector_core::DetectorTick`), in the given directory (normally `OUT_DIR`).
///
/// ```no_run
/// // build.rs
/// let out = std::path::PathBuf::from(std::env::var("OUT_DIR").unwrap());
/// let generated = detector_build::Generator::new("../configs/approach.toml")
///     .tick_type("ApproachTick")
///     .generate(&out)
///     .unwrap();
/// println!("image CRC {:#010x}", generated.image_crc);
/// ```
/// and in the crate:
/// ```ignore
/// include!(concat!(env!("OUT_DIR"), "/approach_tick.rs"));
/// static IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/approach.image"));
/// ```
#[derive(Clone, Debug)]
pub struct Generator {
    config: PathBuf,
    tick_type: String,
    stem: Option<String>,
    report_warnings: bool,
}

/// What [`Generator::generate`] made.
#[derive(Clone, Debug)]
pub struct Generated {
    /// The configuration, validated.
    pub config: Config,
    /// Its compiled tables.
    pub compiled: Compiled,
    /// Its image's bytes.
    pub image: Vec<u8>,
    /// The image's CRC-32, which the generated tick also records.
    pub image_crc: u32,
    /// Where the image was written.
    pub image_path: PathBuf,
    /// Where the tick's source was written.
    pub tick_path: PathBuf,
}

impl Generator {
    /// A generator for the configuration file at `config`.
    pub fn new(config: impl Into<PathBuf>) -> Generator {
        Generator {
            config: config.into(),
            tick_type: String::from("GeneratedTick"),
            stem: None,
            report_warnings: true,
        }
    }

    /// The name of the generated tick's type (default `GeneratedTick`).
    pub fn tick_type(mut self, name: &str) -> Generator {
        self.tick_type = name.to_owned();
        self
    }

    /// The stem of the output files (default: the configuration file's stem).
    pub fn file_stem(mut self, stem: &str) -> Generator {
        self.stem = Some(stem.to_owned());
        self
    }

    /// Whether the configuration's warnings become Cargo warnings (default: yes). Turn it
    /// off for a test detector whose oddities (a phase without events, say) are intended.
    pub fn report_warnings(mut self, report: bool) -> Generator {
        self.report_warnings = report;
        self
    }

    /// Reads and validates the configuration, writes its image and its tick into
    /// `out_dir`, reports the configuration's warnings as Cargo warnings, and tells Cargo
    /// to rerun the build script when the configuration changes.
    pub fn generate(&self, out_dir: &Path) -> Result<Generated, Error> {
        println!("cargo:rerun-if-changed={}", self.config.display());
        let config = load(&self.config)?;
        let invalid = |source| Error::Config {
            path: self.config.clone(),
            source: Box::new(LoadError::Invalid(source)),
        };
        let compiled = compile(&config).map_err(invalid)?;
        for w in compiled.warnings.iter().filter(|_| self.report_warnings) {
            println!("cargo:warning={}: {w}", self.config.display());
        }
        let image = compiled.image();
        // What the chip will run must load: the loader's checks, at build time.
        compiled.detector().map_err(invalid)?;
        let stem = self.stem.clone().unwrap_or_else(|| {
            self.config
                .file_stem()
                .map_or_else(|| "detector".into(), |s| s.to_string_lossy().into_owned())
        });
        let image_path = out_dir.join(format!("{stem}.image"));
        let tick_path = out_dir.join(format!("{stem}_tick.rs"));
        let write = |path: &Path, bytes: &[u8]| {
            fs::write(path, bytes).map_err(|source| Error::Io {
                path: path.to_owned(),
                source,
            })
        };
        write(&image_path, &image)?;
        write(&tick_path, compiled.to_rust(&self.tick_type).as_bytes())?;
        Ok(Generated {
            config,
            image_crc: image_crc(&image),
            compiled,
            image,
            image_path,
            tick_path,
        })
    }
}
