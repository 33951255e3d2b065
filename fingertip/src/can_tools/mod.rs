//! PC-side tools for the fingertip's CAN protocol, behind the `fingertip decode`,
//! `fingertip monitor` and `fingertip busload` subcommands and `fingertip replay
//! --candump`.
//!
//! - [`candump`]: read candump logs (log and screen formats, classic and CAN FD frames),
//!   write the log format (`ID##1DATA` for CAN FD).
//! - [`decode`]: decode a log into confidences, events and status, reporting malformed
//!   lines, invalid frames (wrong length, bad CRC, out of range) and counter gaps by line.
//! - [`monitor`]: the same, live, from a SocketCAN interface (Linux).
//! - [`busload`]: worst-case bus load (CAN FD with bit stuffing in both phases, or classic
//!   CAN) and event-frame latency.
//! - [`service`]: the tool's end of the service channel (load a detector, read and write
//!   the store's keys), retried over a lossy bus.
//! - [`recording`]: a fingertip's flight recording read out and written as a trace that
//!   replays as the chip ran.
//! - [`dbc`]: the published databases `fingertip-can/fingertip.dbc` (CAN FD) and
//!   `fingertip-classic.dbc`, and their specification.
//!
//! The codec itself is `fingertip_can`, shared with the firmware.

use std::path::{Path, PathBuf};

pub mod busload;
pub mod candump;
pub mod dbc;
pub mod decode;
#[cfg(target_os = "linux")]
pub mod monitor;
pub mod recording;
pub mod service;

pub use busload::{BusConfig, BusReport, analyse, write_report};
pub use candump::{LogFrame, parse_line, write_log_line};
pub use decode::{
    DecodeOptions, DecodedLog, Decoder, Item, LineProblem, Problem, Record, StreamValue,
};
pub use decode::{decode_file, decode_reader, write_confidences_csv, write_events_csv};

/// A CAN tool failed (problems inside a log are not failures: they are reported).
#[derive(Debug, thiserror::Error)]
pub enum CanToolError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Opening or reading a CAN interface failed.
    #[error("CAN interface {iface}: {source}")]
    Socket {
        /// The interface.
        iface: String,
        /// The error.
        source: std::io::Error,
    },
    /// A bus-load parameter is invalid.
    #[error(transparent)]
    Bus(#[from] busload::BusError),
}

impl CanToolError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> CanToolError {
        CanToolError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
