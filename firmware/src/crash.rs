//! The crash record: what the firmware knew when it stopped (a panic's message and place,
//! a hard fault's program counter), kept in RAM that a reset leaves alone (`.uninit`),
//! read and cleared at the next boot, logged and answered to the service channel's
//! LastCrash request. The reset reason in the heartbeat says that a reset happened; this
//! says why, when the firmware could tell.
//!
//! The record is words with a magic and a CRC-32 over them, so RAM that held something
//! else (a power-on's contents, another firmware's data) is never taken for one.

use fingertip_can::service::{CrashKind, CrashReport, MESSAGE_MAX};

use crate::checksum::crc32;

/// The record's first word.
const MAGIC: u32 = 0x4853_5243; // "CRSH", little-endian
/// Words of the record: magic, kind, program counter, message length, message, CRC.
pub const RECORD_WORDS: usize = 4 + MESSAGE_MAX / 4 + 1;

/// The record as it lies in RAM.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub struct CrashRecord {
    words: [u32; RECORD_WORDS],
}

impl Default for CrashRecord {
    fn default() -> Self {
        CrashRecord::empty()
    }
}

impl CrashRecord {
    /// No crash.
    pub const fn empty() -> CrashRecord {
        CrashRecord {
            words: [0; RECORD_WORDS],
        }
    }

    fn bytes(words: &[u32]) -> ([u8; RECORD_WORDS * 4], usize) {
        let mut b = [0u8; RECORD_WORDS * 4];
        for (chunk, w) in b.chunks_mut(4).zip(words) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        (b, words.len() * 4)
    }

    /// Keeps `crash` for the next boot.
    pub fn write(&mut self, crash: &CrashReport) {
        let mut w = [0u32; RECORD_WORDS];
        w[0] = MAGIC;
        w[1] = crash.kind as u32;
        w[2] = crash.pc;
        w[3] = crash.message.len() as u32;
        let text = crash.message.as_bytes();
        for (k, word) in w[4..RECORD_WORDS - 1].iter_mut().enumerate() {
            let mut b = [0u8; 4];
            for (i, byte) in b.iter_mut().enumerate() {
                *byte = text.get(4 * k + i).copied().unwrap_or(0);
            }
            *word = u32::from_le_bytes(b);
        }
        let (bytes, n) = CrashRecord::bytes(&w[..RECORD_WORDS - 1]);
        w[RECORD_WORDS - 1] = crc32(&bytes[..n]);
        self.words = w;
    }

    /// The crash kept, if the record is one (its magic and CRC).
    pub fn read(&self) -> Option<CrashReport> {
        let w = &self.words;
        let (bytes, n) = CrashRecord::bytes(&w[..RECORD_WORDS - 1]);
        if w[0] != MAGIC || crc32(&bytes[..n]) != w[RECORD_WORDS - 1] {
            return None;
        }
        let kind = CrashKind::from_raw(u8::try_from(w[1]).ok()?)?;
        let len = usize::try_from(w[3]).ok().filter(|&l| l <= MESSAGE_MAX)?;
        let text = core::str::from_utf8(bytes.get(16..16 + len)?).ok()?;
        let mut report = CrashReport::new(kind, w[2]);
        report.message.push_str(text).ok()?;
        Some(report)
    }

    /// Forgets the crash (read once, at boot).
    pub fn clear(&mut self) {
        self.words = [0; RECORD_WORDS];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::fmt::Write;

    #[test]
    fn a_crash_kept_is_read_back_once() {
        let mut record = CrashRecord::empty();
        assert_eq!(record.read(), None);
        let mut c = CrashReport::new(CrashKind::Panic, 0);
        write!(c, "src/engine.rs:42: index out of bounds").unwrap();
        record.write(&c);
        assert_eq!(record.read(), Some(c));
        record.clear();
        assert_eq!(record.read(), None);
        let f = CrashReport::new(CrashKind::HardFault, 0x0800_4321);
        record.write(&f);
        assert_eq!(record.read(), Some(f));
    }

    #[test]
    fn ram_that_holds_anything_else_is_no_crash() {
        let mut c = CrashReport::new(CrashKind::Panic, 0);
        write!(c, "{}", "x".repeat(100)).unwrap();
        assert_eq!(c.message.len(), MESSAGE_MAX);
        let mut record = CrashRecord::empty();
        record.write(&c);
        // Every single bit flipped: refused (magic, CRC, kind or length).
        for word in 0..RECORD_WORDS {
            for bit in 0..32 {
                let mut r = record;
                r.words[word] ^= 1 << bit;
                assert_eq!(r.read(), None, "word {word} bit {bit}");
            }
        }
        // A power-on's pattern.
        let noise = CrashRecord {
            words: core::array::from_fn(|i| (i as u32).wrapping_mul(0x9E37_79B9)),
        };
        assert_eq!(noise.read(), None);
    }
}
