//! End-to-end protection of the safety-relevant frames (event, phase, context, tip state),
//! laid out as AUTOSAR E2E profile 2:
//!
//! - byte 0 is a CRC-8/AUTOSAR (polynomial 0x2F, initial value 0xFF, final XOR 0xFF, no
//!   reflection) over bytes 1..DLC of the payload followed by one *data id* byte;
//! - bits 3..0 of byte 1 are a rolling [`Counter`], 0..=15, advanced by one per frame sent;
//! - the data id is never sent: it is [`data_id`]`(identifier, counter)`, so a payload sent
//!   under another identifier (another message, another node) fails the check, and a
//!   receiver tells lost, repeated and corrupted frames apart.
//!
//! Standard tools verify it: cantools' `compute_profile2_crc(payload, data_id)` gives the
//! same byte.

use super::StandardId;

/// The CRC: CRC-8/AUTOSAR, table-driven (a 256-byte table in flash).
const CRC8: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_AUTOSAR);

/// A rolling counter, `0..=15`, in bits 3..0 of byte 1 of a protected frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counter(u8);

impl Counter {
    /// The largest value; the next after it is 0.
    pub const MAX: u8 = 15;

    /// A counter; `None` above [`Counter::MAX`].
    pub const fn new(raw: u8) -> Option<Counter> {
        if raw <= Counter::MAX {
            Some(Counter(raw))
        } else {
            None
        }
    }

    /// The counter in the low four bits of `byte`.
    pub const fn from_low_bits(byte: u8) -> Counter {
        Counter(byte & 0x0F)
    }

    /// The raw value, `0..=15`.
    pub const fn get(self) -> u8 {
        self.0
    }

    /// The value after this one (15 wraps to 0).
    pub const fn next(self) -> Counter {
        Counter((self.0 + 1) & 0x0F)
    }

    /// How far `later` is ahead of `self`, modulo 16: 1 for the next frame, 0 for a
    /// repetition, 2..=15 when frames were lost (or arrived out of order).
    pub const fn delta_to(self, later: Counter) -> u8 {
        later.0.wrapping_sub(self.0) & 0x0F
    }
}

/// The data id of a protected frame with identifier `id` and counter `counter`: the low
/// byte of the identifier XOR `0x11 · counter`.
///
/// For a given counter value it is distinct for every identifier of the protocol
/// (0x080..=0x0DF), and it changes with the counter as profile 2's data id list does.
pub fn data_id(id: StandardId, counter: Counter) -> u8 {
    (id.as_raw() as u8) ^ counter.0.wrapping_mul(0x11)
}

/// The CRC byte a protected payload must carry in byte 0, computed over `payload[1..]`
/// and the data id for `id` and the counter in byte 1. Byte 0 itself is not read.
/// `None` for payloads shorter than 2 bytes (they cannot hold the header).
pub fn crc(id: StandardId, payload: &[u8]) -> Option<u8> {
    let body = payload.get(1..)?;
    let counter = Counter::from_low_bits(*body.first()?);
    let mut digest = CRC8.digest();
    digest.update(body);
    digest.update(&[data_id(id, counter)]);
    Some(digest.finalize())
}

/// Whether byte 0 of `payload` is its correct CRC for `id`.
pub fn check(id: StandardId, payload: &[u8]) -> bool {
    match (crc(id, payload), payload.first()) {
        (Some(c), Some(&b)) => c == b,
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_is_crc8_autosar() {
        // The catalogue check value of CRC-8/AUTOSAR over "123456789".
        assert_eq!(CRC8.checksum(b"123456789"), 0xDF);
    }

    #[test]
    fn data_ids_are_distinct_per_counter() {
        for c in 0..=15 {
            let c = Counter::new(c).unwrap();
            let mut seen = [false; 256];
            for raw in 0x080..=0x0DF {
                let d = data_id(StandardId::new(raw).unwrap(), c);
                assert!(!seen[usize::from(d)]);
                seen[usize::from(d)] = true;
            }
        }
    }

    #[test]
    fn a_payload_under_another_identifier_fails() {
        let a = StandardId::new(0x0A3).unwrap();
        let b = StandardId::new(0x0A4).unwrap();
        let mut p = [0u8, 0x05, 1, 2, 3, 4, 5, 6];
        p[0] = crc(a, &p).unwrap();
        assert!(check(a, &p));
        assert!(!check(b, &p));
        p[4] ^= 0x10;
        assert!(!check(a, &p));
        assert_eq!(crc(a, &[0]), None);
        assert!(!check(a, &[]));
    }

    #[test]
    fn counter_wraps_and_measures_distance() {
        let c = Counter::new(15).unwrap();
        assert_eq!(c.next().get(), 0);
        assert_eq!(c.delta_to(Counter::new(0).unwrap()), 1);
        assert_eq!(c.delta_to(c), 0);
        assert_eq!(
            Counter::new(3).unwrap().delta_to(Counter::new(1).unwrap()),
            14
        );
        assert_eq!(Counter::new(16), None);
    }
}
