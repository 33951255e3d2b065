//! End-to-end protection of every frame, laid out as AUTOSAR E2E profile 5:
//!
//! - bytes 0..2 are a CRC-16/CCITT-FALSE (polynomial 0x1021, initial value 0xFFFF, no
//!   reflection, no final XOR; check value 0x29B1), little-endian, over bytes 2..len of the
//!   payload followed by the two bytes of the *data id*, low byte first;
//! - byte 2 is a rolling [`Counter`], 0..=255, advanced by one per frame sent;
//! - the data id is never sent: it is the frame's 11-bit identifier ([`data_id`]), so a
//!   payload sent under another identifier (another message, node or group) fails the
//!   check.
//!
//! At 1 kHz the counter wraps after 256 ms, far longer than any timeout of the protocol,
//! so a receiver counts every frame lost in a gap of up to 255.
//!
//! Standard tools verify it: cantools' `compute_profile5_crc(payload, data_id)` gives the
//! same value.

use super::StandardId;

/// The CRC: CRC-16/CCITT-FALSE (the catalogue's CRC-16/IBM-3740), table-driven (512 bytes
/// in flash).
const CRC16: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740);

/// Bytes of the header: the CRC (2) and the counter (1).
pub const HEADER_LEN: usize = 3;

/// A rolling counter, `0..=255`, in byte 2 of every frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counter(pub u8);

impl Counter {
    /// The raw value, `0..=255`.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// The value after this one (255 wraps to 0).
    pub const fn next(self) -> Counter {
        Counter(self.0.wrapping_add(1))
    }

    /// How far `later` is ahead of `self`, modulo 256: 1 for the next frame, 0 for a
    /// repetition, `k + 1` when `k` frames were lost in between.
    pub const fn delta_to(self, later: Counter) -> u8 {
        later.0.wrapping_sub(self.0)
    }
}

/// The data id of a frame with identifier `id`: the identifier itself, `0..=0x7FF`.
pub fn data_id(id: StandardId) -> u16 {
    id.as_raw()
}

/// The CRC a payload must carry in bytes 0..2, computed over `payload[2..]` and the data
/// id for `id`. Bytes 0 and 1 are not read. `None` for payloads shorter than the header.
pub fn crc(id: StandardId, payload: &[u8]) -> Option<u16> {
    let body = payload.get(2..)?;
    if body.is_empty() {
        return None;
    }
    let mut digest = CRC16.digest();
    digest.update(body);
    digest.update(&data_id(id).to_le_bytes());
    Some(digest.finalize())
}

/// The CRC `payload` carries in bytes 0..2, if it is long enough.
pub fn carried(payload: &[u8]) -> Option<u16> {
    match payload {
        [lo, hi, ..] => Some(u16::from_le_bytes([*lo, *hi])),
        _ => None,
    }
}

/// Writes the CRC for `id` into bytes 0..2 of `payload`; does nothing to a payload shorter
/// than the header.
pub fn seal(id: StandardId, payload: &mut [u8]) {
    if let (Some(c), Some(head)) = (crc(id, payload), payload.get_mut(..2)) {
        head.copy_from_slice(&c.to_le_bytes());
    }
}

/// Whether bytes 0..2 of `payload` are its correct CRC for `id`.
pub fn check(id: StandardId, payload: &[u8]) -> bool {
    matches!((crc(id, payload), carried(payload)), (Some(a), Some(b)) if a == b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_is_crc16_ccitt_false() {
        assert_eq!(CRC16.checksum(b"123456789"), 0x29B1);
    }

    #[test]
    fn a_payload_under_another_identifier_fails() {
        let a = StandardId::new(0x143).unwrap();
        let b = StandardId::new(0x144).unwrap();
        let mut p = [0u8, 0, 0x05, 1, 2];
        seal(a, &mut p);
        assert!(check(a, &p));
        assert!(!check(b, &p));
        p[4] ^= 0x10;
        assert!(!check(a, &p));
        assert_eq!(crc(a, &[0, 0]), None);
        assert!(!check(a, &[]));
        let mut short = [9u8];
        seal(a, &mut short);
        assert_eq!(short, [9]);
    }

    #[test]
    fn counter_wraps_and_measures_distance() {
        let c = Counter(255);
        assert_eq!(c.next().get(), 0);
        assert_eq!(c.delta_to(Counter(0)), 1);
        assert_eq!(c.delta_to(c), 0);
        assert_eq!(Counter(3).delta_to(Counter(1)), 254);
    }
}
