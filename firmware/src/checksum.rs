//! The configuration checksum: CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG:
//! reflected polynomial 0xEDB88320, initial value and final XOR all ones), so a PC tool
//! can check the value in the status heartbeat with `zlib.crc32(postcard_bytes)`.
//!
//! Shared, as source, by the lib and by `build.rs`, which computes it at build time.

/// CRC-32/ISO-HDLC of `bytes` (check value: `crc32(b"123456789") == 0xCBF4_3926`).
/// Bitwise, no table: it runs once per build and once in a test, never in the tick.
pub const fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = u32::MAX;
    let mut i = 0;
    while i < bytes.len() {
        crc ^= bytes[i] as u32;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
            bit += 1;
        }
        i += 1;
    }
    !crc
}
