//! Live decoding of SocketCAN traffic (Linux): `fingertip monitor --iface can0`.
//!
//! Frames are read from a raw CAN socket in CAN FD mode (so classic and CAN FD frames both
//! arrive), timestamped on arrival, decoded exactly as a log would be (frame numbers stand
//! for line numbers) and printed as they come.

use std::io::Write;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use socketcan::{CanAnyFrame, CanFdSocket, EmbeddedFrame, ShouldRetry, Socket};

use super::CanToolError;
use super::candump::{LogFrame, write_log_line};
use super::decode::{DecodeOptions, DecodedLog, Decoder, Item};

/// When to stop monitoring (besides the caller's stop flag).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MonitorLimits {
    /// Stop after this many frames.
    pub max_frames: Option<usize>,
    /// Stop after this long.
    pub duration: Option<Duration>,
}

/// Converts a SocketCAN frame into a log frame numbered `n`, timestamped `time` (s).
pub fn log_frame(frame: &CanAnyFrame, iface: &str, n: usize, time: f64) -> LogFrame {
    let mut f = LogFrame {
        line: n,
        time: Some(time),
        iface: iface.to_string(),
        id: frame.id(),
        remote: false,
        error: false,
        fd: false,
        brs: false,
        esi: false,
        data: Vec::new(),
    };
    match frame {
        CanAnyFrame::Normal(d) => f.data = d.data().to_vec(),
        CanAnyFrame::Remote(_) => f.remote = true,
        CanAnyFrame::Error(e) => {
            f.error = true;
            f.data = e.data().to_vec();
        }
        CanAnyFrame::Fd(d) => {
            f.fd = true;
            f.brs = d.is_brs();
            f.esi = d.is_esi();
            f.data = d.data().to_vec();
        }
    }
    f
}

/// Reads `iface` until `stop()` returns true or a limit is reached, printing every
/// decoded frame and problem to `out`. With `candump` set, every frame read is also
/// written there in candump log format (fingertip frames only; the log can be decoded
/// later with `fingertip decode`). Returns everything decoded.
pub fn monitor(
    iface: &str,
    opts: &DecodeOptions,
    limits: &MonitorLimits,
    out: &mut dyn Write,
    mut candump: Option<&mut dyn Write>,
    stop: &dyn Fn() -> bool,
) -> Result<DecodedLog, CanToolError> {
    let socket = CanFdSocket::open(iface).map_err(|e| CanToolError::Socket {
        iface: iface.to_string(),
        source: e,
    })?;
    let sock_err = |e: std::io::Error| CanToolError::Socket {
        iface: iface.to_string(),
        source: e,
    };
    let start = Instant::now();
    let mut dec = Decoder::new();
    let mut log = DecodedLog::default();
    let mut n = 0usize;
    while !stop()
        && limits.max_frames.is_none_or(|m| n < m)
        && limits.duration.is_none_or(|d| start.elapsed() < d)
    {
        let frame = match socket.read_frame_timeout(Duration::from_millis(100)) {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut || e.should_retry() => continue,
            Err(e) => return Err(sock_err(e)),
        };
        n += 1;
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default();
        let lf = log_frame(&frame, iface, n, now.as_secs_f64());
        if let (Some(w), socketcan::Id::Standard(id)) = (candump.as_deref_mut(), lf.id)
            && !lf.remote
            && !lf.error
            && let Some(cf) = if lf.fd {
                fingertip_can::CanFrame::new_fd(id, &lf.data)
            } else {
                fingertip_can::CanFrame::new(id, &lf.data)
            }
        {
            write_log_line(w, now, iface, &cf).map_err(sock_err)?;
        }
        for item in dec.push_frame(&lf, opts) {
            if let Some(text) = dec.describe(&item, opts) {
                writeln!(out, "{text}").map_err(sock_err)?;
            }
            log.items.push(item);
        }
        log.lines = n;
    }
    log.protocol_frames = dec.protocol_frames;
    log.foreign_frames = dec.foreign_frames;
    Ok(log)
}

/// Whether [`Item`] is a problem (for callers counting them live).
pub fn is_problem(item: &Item) -> bool {
    matches!(item, Item::Problem(_))
}
