//! Reading and writing candump logs.
//!
//! Two formats are read, line by line:
//! - the log format of `candump -l` / `candump -L`: `(1436509052.249713) can0 123#DEADBEEF`
//!   (remote frames `123#R`, CAN FD `ID##<flags><data>` with one hex digit of flags, bit 0
//!   bit-rate switching and bit 1 the error state indicator, e.g. `123##1DEADBEEF`; an
//!   optional trailing `T`/`R` direction mark);
//! - the screen format of plain `candump`: `  can0  123   [8]  11 22 33 44 55 66 77 88`,
//!   optionally preceded by a timestamp in parentheses (`-t a`, `-t d`, `-t z`: seconds;
//!   `-t A`: a local date and time), with `-x` columns between interface and
//!   identifier, `remote request` for remote frames, and an ASCII column (`-a`) after
//!   the bytes.
//!
//! Blank lines and lines starting with `#` are skipped. Error frames (identifier flag
//! 0x20000000) are recognized and marked. The log format is written: classic frames as
//! `ID#DATA`, CAN FD frames as `ID##1DATA` (bit-rate switching, as the protocol sends them).

use std::fmt;
use std::io::{self, Write};
use std::time::Duration;

use fingertip_can::{CanFrame, ExtendedId, Id, StandardId};

/// The error-frame flag of a SocketCAN identifier.
const ERR_FLAG: u32 = 0x2000_0000;

/// One frame read from a log line.
#[derive(Clone, Debug, PartialEq)]
pub struct LogFrame {
    /// The 1-based line number in the file.
    pub line: usize,
    /// The timestamp in seconds, if the line had one (since the epoch for `-t a`/`-t A`
    /// and the log format, since the previous frame or the first for `-t d`/`-t z`).
    pub time: Option<f64>,
    /// The interface name (`can0`).
    pub iface: String,
    /// The identifier.
    pub id: Id,
    /// A remote frame (no data).
    pub remote: bool,
    /// An error frame (identifier flag 0x20000000; `id` holds the error class bits).
    pub error: bool,
    /// A CAN FD frame.
    pub fd: bool,
    /// A CAN FD frame sent with bit-rate switching (flag 0x1).
    pub brs: bool,
    /// A CAN FD frame whose sender was error-passive (flag 0x2).
    pub esi: bool,
    /// The data bytes (0..=8, or up to 64 for CAN FD).
    pub data: Vec<u8>,
}

/// Why a line could not be read as a frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LineError {
    /// What was wrong.
    pub reason: String,
}

impl fmt::Display for LineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.reason)
    }
}

impl std::error::Error for LineError {}

fn bad<T>(reason: impl Into<String>) -> Result<T, LineError> {
    Err(LineError {
        reason: reason.into(),
    })
}

/// Parses one line of either format. `Ok(None)` for blank and comment lines.
pub fn parse_line(line_no: usize, line: &str) -> Result<Option<LogFrame>, LineError> {
    let text = line.trim();
    if text.is_empty() || text.starts_with('#') {
        return Ok(None);
    }
    let (time, rest) = if let Some(after) = text.strip_prefix('(') {
        let Some(close) = after.find(')') else {
            return bad("timestamp has no closing parenthesis");
        };
        let stamp = after.get(..close).unwrap_or("");
        (
            Some(parse_time(stamp)?),
            after.get(close + 1..).unwrap_or(""),
        )
    } else {
        (None, text)
    };
    let tokens: Vec<&str> = rest.split_whitespace().collect();
    let Some((&iface, after_iface)) = tokens.split_first() else {
        return bad("no interface name");
    };
    let frame = match after_iface.first() {
        Some(tok) if tok.contains('#') => {
            if after_iface.len() > 2
                || (after_iface.len() == 2 && !matches!(after_iface.get(1), Some(&"T" | &"R")))
            {
                return bad(format!(
                    "unexpected text after the frame: {:?}",
                    &after_iface[1..]
                ));
            }
            parse_log_frame(tok)?
        }
        Some(_) => parse_screen_frame(after_iface)?,
        None => return bad("no frame after the interface name"),
    };
    Ok(Some(LogFrame {
        line: line_no,
        time,
        iface: iface.to_string(),
        ..frame
    }))
}

/// `sec.usec` (or plain seconds), or `YYYY-MM-DD HH:MM:SS.ffffff` as written by `-t A`
/// (read as UTC).
fn parse_time(stamp: &str) -> Result<f64, LineError> {
    let s = stamp.trim();
    if let Some((date, clock)) = s.split_once(' ') {
        let d: Vec<&str> = date.split('-').collect();
        let c: Vec<&str> = clock.split(':').collect();
        let (Some(y), Some(mo), Some(da)) = (d.first(), d.get(1), d.get(2)) else {
            return bad(format!("bad date in timestamp {s:?}"));
        };
        let (Some(h), Some(mi), Some(se)) = (c.first(), c.get(1), c.get(2)) else {
            return bad(format!("bad time in timestamp {s:?}"));
        };
        let num = |t: &str| t.parse::<i64>().ok();
        let (Some(y), Some(mo), Some(da), Some(h), Some(mi)) =
            (num(y), num(mo), num(da), num(h), num(mi))
        else {
            return bad(format!("bad timestamp {s:?}"));
        };
        let Ok(sec) = se.parse::<f64>() else {
            return bad(format!("bad seconds in timestamp {s:?}"));
        };
        let days = days_from_civil(y, mo, da);
        return Ok((days * 86_400 + h * 3600 + mi * 60) as f64 + sec);
    }
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 && s.chars().all(|c| c.is_ascii_digit() || c == '.') => {
            Ok(v)
        }
        _ => bad(format!("bad timestamp {s:?}")),
    }
}

/// Days from 1970-01-01 to a proleptic Gregorian date.
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

fn parse_id(text: &str) -> Result<(Id, bool), LineError> {
    if text.is_empty() || !text.chars().all(|c| c.is_ascii_hexdigit()) {
        return bad(format!("bad identifier {text:?}"));
    }
    let Ok(raw) = u32::from_str_radix(text, 16) else {
        return bad(format!("bad identifier {text:?}"));
    };
    match text.len() {
        3 => match StandardId::new(raw as u16).filter(|_| raw <= 0x7FF) {
            Some(id) => Ok((Id::Standard(id), false)),
            None => bad(format!("standard identifier {text} above 0x7FF")),
        },
        8 => {
            let error = raw & ERR_FLAG != 0;
            match ExtendedId::new(raw & !ERR_FLAG) {
                Some(id) => Ok((Id::Extended(id), error)),
                None => bad(format!("extended identifier {text} above 0x1FFFFFFF")),
            }
        }
        n => bad(format!(
            "identifier {text:?} has {n} digits (3 for standard, 8 for extended)"
        )),
    }
}

fn parse_hex_bytes(text: &str) -> Result<Vec<u8>, LineError> {
    let digits: String = text.chars().filter(|&c| c != '.').collect();
    if !digits.len().is_multiple_of(2) {
        return bad(format!("odd number of hex digits in data {text:?}"));
    }
    let bytes = digits.as_bytes();
    let mut out = Vec::with_capacity(bytes.len() / 2);
    for pair in bytes.chunks(2) {
        let s = std::str::from_utf8(pair).unwrap_or("");
        match u8::from_str_radix(s, 16) {
            Ok(b) if s.chars().all(|c| c.is_ascii_hexdigit()) => out.push(b),
            _ => return bad(format!("bad hex byte {s:?} in data")),
        }
    }
    Ok(out)
}

fn frame(id: Id, error: bool) -> LogFrame {
    LogFrame {
        line: 0,
        time: None,
        iface: String::new(),
        id,
        remote: false,
        error,
        fd: false,
        brs: false,
        esi: false,
        data: Vec::new(),
    }
}

/// The CAN FD flags digit of the log format: bit 0 bit-rate switching, bit 1 error state
/// indicator (bit 2, FD format, is implied by the `##`).
const FLAG_BRS: u32 = 0x1;
const FLAG_ESI: u32 = 0x2;

/// `123#DEADBEEF`, `123#R`, `123#R4`, `123##1DEADBEEF`.
fn parse_log_frame(tok: &str) -> Result<LogFrame, LineError> {
    let Some((id_text, payload)) = tok.split_once('#') else {
        return bad("no '#' in frame");
    };
    let (id, error) = parse_id(id_text)?;
    let mut f = frame(id, error);
    if let Some(fd) = payload.strip_prefix('#') {
        let mut chars = fd.chars();
        let Some(flags) = chars.next().and_then(|c| c.to_digit(16)) else {
            return bad("CAN FD frame without a flags digit");
        };
        f.fd = true;
        f.brs = flags & FLAG_BRS != 0;
        f.esi = flags & FLAG_ESI != 0;
        f.data = parse_hex_bytes(chars.as_str())?;
        if !fingertip_can::is_fd_length(f.data.len()) {
            return bad(format!(
                "CAN FD frame with {} bytes (0..=8, 12, 16, 20, 24, 32, 48 or 64)",
                f.data.len()
            ));
        }
    } else if let Some(len) = payload.strip_prefix('R') {
        if !(len.is_empty() || (len.len() == 1 && len.chars().all(|c| c.is_ascii_digit()))) {
            return bad(format!("bad remote frame length {len:?}"));
        }
        f.remote = true;
    } else {
        f.data = parse_hex_bytes(payload)?;
        if f.data.len() > 8 {
            return bad(format!("classic CAN frame with {} bytes", f.data.len()));
        }
    }
    Ok(f)
}

/// `[-x columns] 123 [8] 11 22 33 ... ['ascii']` or `123 [2] remote request`.
fn parse_screen_frame(tokens: &[&str]) -> Result<LogFrame, LineError> {
    // The identifier is the token before the first `[n]`.
    let Some(len_at) = tokens
        .iter()
        .position(|t| t.starts_with('[') && t.ends_with(']'))
    else {
        return bad("neither `ID#DATA` nor `ID [len] bytes`");
    };
    let Some(id_text) = len_at.checked_sub(1).and_then(|i| tokens.get(i)) else {
        return bad("no identifier before the length");
    };
    let (id, error) = parse_id(id_text)?;
    let len_text = tokens
        .get(len_at)
        .and_then(|t| t.get(1..t.len().saturating_sub(1)))
        .unwrap_or("");
    let Ok(len) = len_text.parse::<usize>() else {
        return bad(format!("bad length [{len_text}]"));
    };
    let mut f = frame(id, error);
    let rest = tokens.get(len_at + 1..).unwrap_or(&[]);
    if rest.first() == Some(&"remote") {
        f.remote = true;
        return Ok(f);
    }
    for t in rest {
        if t.starts_with('\'') || *t == "ERRORFRAME" {
            break;
        }
        if t.len() != 2 {
            return bad(format!("bad data byte {t:?}"));
        }
        f.data.extend(parse_hex_bytes(t)?);
    }
    if f.data.len() != len {
        return bad(format!(
            "length says {len} bytes, the line has {}",
            f.data.len()
        ));
    }
    if len > 8 {
        f.fd = true;
        if !fingertip_can::is_fd_length(len) {
            return bad(format!("frame with {len} bytes"));
        }
    }
    Ok(f)
}

/// Writes one frame in the candump log format, `(sec.usec) iface ID#HEX` for a classic
/// frame, `(sec.usec) iface ID##1HEX` for a CAN FD frame (with bit-rate switching).
pub fn write_log_line(
    w: &mut dyn Write,
    time: Duration,
    iface: &str,
    frame: &CanFrame,
) -> io::Result<()> {
    write!(
        w,
        "({:010}.{:06}) {} {:03X}#{}",
        time.as_secs(),
        time.subsec_micros(),
        iface,
        frame.id().as_raw(),
        if frame.is_fd() { "#1" } else { "" }
    )?;
    for b in frame.data() {
        write!(w, "{b:02X}")?;
    }
    writeln!(w)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sid(raw: u16) -> Id {
        Id::Standard(StandardId::new(raw).unwrap())
    }

    #[test]
    fn reads_the_log_format() {
        let f = parse_line(3, "(1436509052.249713) can0 0A3#0102030405060708")
            .unwrap()
            .unwrap();
        assert_eq!(f.line, 3);
        assert_eq!(f.time, Some(1436509052.249713));
        assert_eq!(f.iface, "can0");
        assert_eq!(f.id, sid(0x0A3));
        assert_eq!(f.data, [1, 2, 3, 4, 5, 6, 7, 8]);
        let r = parse_line(1, "(0.000001) vcan1 123#R T").unwrap().unwrap();
        assert!(r.remote);
        let e = parse_line(1, "(1.5) can0 12345678#").unwrap().unwrap();
        assert!(matches!(e.id, Id::Extended(_)));
        assert!(e.data.is_empty());
        let fd = parse_line(1, "(1.5) can0 123##1112233").unwrap().unwrap();
        assert!(fd.fd && fd.brs && !fd.esi);
        assert_eq!(fd.data, [0x11, 0x22, 0x33]);
        let esi = parse_line(1, "(1.5) can0 123##200").unwrap().unwrap();
        assert!(esi.fd && !esi.brs && esi.esi);
        let long = format!("(1.5) can0 123##1{}", "AB".repeat(64));
        assert_eq!(parse_line(1, &long).unwrap().unwrap().data.len(), 64);
        let err = parse_line(1, "(1.5) can0 20000080#0000000000000000")
            .unwrap()
            .unwrap();
        assert!(err.error);
    }

    #[test]
    fn reads_the_screen_format() {
        let f = parse_line(1, "  can0  0D1   [8]  00 01 02 03 04 05 06 07")
            .unwrap()
            .unwrap();
        assert_eq!(f.time, None);
        assert_eq!(f.id, sid(0x0D1));
        assert_eq!(f.data, [0, 1, 2, 3, 4, 5, 6, 7]);
        let t = parse_line(1, " (1436509052.249713)  can0  123   [2]  11 22   '.\"'")
            .unwrap()
            .unwrap();
        assert_eq!(t.time, Some(1436509052.249713));
        assert_eq!(t.data, [0x11, 0x22]);
        let x = parse_line(1, "  can0  RX - -  123   [1]  FF")
            .unwrap()
            .unwrap();
        assert_eq!(x.data, [0xFF]);
        let r = parse_line(1, "  can0  123   [2]  remote request")
            .unwrap()
            .unwrap();
        assert!(r.remote);
        let a = parse_line(1, "(2015-07-10 08:17:32.249713)  can0  123   [0] ")
            .unwrap()
            .unwrap();
        assert!((a.time.unwrap() - 1436516252.249713).abs() < 1e-6);
    }

    #[test]
    fn skips_comments_and_rejects_garbage() {
        assert_eq!(parse_line(1, "   "), Ok(None));
        assert_eq!(parse_line(1, "# recorded on the bench"), Ok(None));
        for bad in [
            "(12.5 can0 123#00",
            "(abc) can0 123#00",
            "can0",
            "(1.0) can0 12#00",
            "(1.0) can0 800#00",
            "(1.0) can0 123#0",
            "(1.0) can0 123#GG",
            "(1.0) can0 123#000102030405060708",
            "(1.0) can0 123##1000102030405060708",
            "(1.0) can0 123##G00",
            "(1.0) can0 123##",
            "  can0  123   [3]  11 22",
            "  can0  123   [x]  11",
            "(1.0) can0 123#00 extra words",
            "hello world",
        ] {
            assert!(parse_line(7, bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn writes_what_it_reads() {
        let frame = CanFrame::new(StandardId::new(0x0C2).unwrap(), &[0xAB, 0x01]).unwrap();
        let mut out = Vec::new();
        write_log_line(&mut out, Duration::new(12, 345_678_000), "can0", &frame).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(text, "(0000000012.345678) can0 0C2#AB01\n");
        let back = parse_line(1, &text).unwrap().unwrap();
        assert_eq!(back.data, [0xAB, 0x01]);
        assert_eq!(back.id, sid(0x0C2));
        let fd = CanFrame::new_fd(StandardId::new(0x152).unwrap(), &[7; 12]).unwrap();
        let mut out = Vec::new();
        write_log_line(&mut out, Duration::new(1, 0), "can1", &fd).unwrap();
        let text = String::from_utf8(out).unwrap();
        assert_eq!(
            text,
            format!("(0000000001.000000) can1 152##1{}\n", "07".repeat(12))
        );
        let back = parse_line(1, &text).unwrap().unwrap();
        assert!(back.fd && back.brs);
        assert_eq!(back.data, [7; 12]);
    }
}
