//! The configuration checksum: CRC-32/ISO-HDLC (the CRC of zlib, Ethernet and PNG), so a
//! PC tool can check the value in the status heartbeat with `zlib.crc32(image)` of the
//! detector image `detector-build` writes (`detector_build::image_crc` is the same).
//!
//! The board computes it over every image it loads (the embedded one at boot, one received
//! over the bus), and the engine checks it against the image the generated tick was made
//! from. It is the service channel's checksum ([`fingertip_can::service::crc32`]).

pub use fingertip_can::service::crc32;
