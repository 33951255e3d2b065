//! The configuration checksum: CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG), so a
//! PC tool can check the value in the status heartbeat with `zlib.crc32(image)` of the
//! detector image `detector-build` writes (`detector_build::image_crc` is the same).
//!
//! The board computes it over the image it loads at boot, and the engine checks it
//! against the image the generated tick was made from.

/// Without a lookup table: it runs once per boot, never in the tick, and the table would
/// cost 1 KiB of flash.
const CRC32: crc::Crc<u32, crc::NoTable> =
    crc::Crc::<u32, crc::NoTable>::new(&crc::CRC_32_ISO_HDLC);

/// CRC-32/ISO-HDLC of `bytes` (check value: `crc32(b"123456789") == 0xCBF4_3926`).
pub const fn crc32(bytes: &[u8]) -> u32 {
    CRC32.checksum(bytes)
}
