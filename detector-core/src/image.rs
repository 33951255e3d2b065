//! A built detector as bytes: made on the PC (`Detector::to_image`, `std`), loaded
//! on the chip in place ([`crate::Detector::load_image`]) with a small stack frame, no
//! serde and no configuration parsing. The firmware embeds the image of
//! `configs/approach.toml` that its build script made, so the chip never holds a
//! [`crate::Config`].
//!
//! Layout, little-endian: the magic `FTD2`, the detector rate (f32), then each list as a
//! one-byte count followed by its items (channels: name, scale; features: name, stage;
//! the distinct (feature, CDF) pairs; events: name, terms as indices into those pairs,
//! levels; phases: name, event mask), and the slot dependency masks and STE window taps as
//! fixed arrays. Loading checks every count, index, shift and
//! level, so a corrupt image is rejected rather than run.

use crate::config::Name;

/// The first four bytes of every image (the digit is the layout's version).
pub(crate) const MAGIC: [u8; 4] = *b"FTD2";

/// Why an image was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ImageError {
    /// It does not start with the magic of this layout version.
    Magic,
    /// It ends in the middle of an item.
    Truncated,
    /// Bytes are left after the last item.
    TrailingBytes,
    /// A value is out of its range; names which.
    Invalid(&'static str),
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ImageError::Magic => write!(f, "not a detector image of this version"),
            ImageError::Truncated => write!(f, "the image is truncated"),
            ImageError::TrailingBytes => write!(f, "bytes follow the image's end"),
            ImageError::Invalid(what) => write!(f, "the image's {what} is out of range"),
        }
    }
}

impl core::error::Error for ImageError {}

/// Reads an image front to back.
pub(crate) struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Reader<'a> {
        Reader { bytes }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], ImageError> {
        let (head, rest) = self
            .bytes
            .split_first_chunk::<N>()
            .ok_or(ImageError::Truncated)?;
        self.bytes = rest;
        Ok(*head)
    }

    pub(crate) fn u8(&mut self) -> Result<u8, ImageError> {
        Ok(self.take::<1>()?[0])
    }

    pub(crate) fn u16(&mut self) -> Result<u16, ImageError> {
        Ok(u16::from_le_bytes(self.take()?))
    }

    pub(crate) fn u32(&mut self) -> Result<u32, ImageError> {
        Ok(u32::from_le_bytes(self.take()?))
    }

    pub(crate) fn i32(&mut self) -> Result<i32, ImageError> {
        Ok(i32::from_le_bytes(self.take()?))
    }

    pub(crate) fn f32(&mut self) -> Result<f32, ImageError> {
        Ok(f32::from_le_bytes(self.take()?))
    }

    /// A count of items, at most `max`.
    pub(crate) fn count(&mut self, max: usize, what: &'static str) -> Result<usize, ImageError> {
        let n = usize::from(self.u8()?);
        if n > max {
            return Err(ImageError::Invalid(what));
        }
        Ok(n)
    }

    /// A value below `limit`.
    pub(crate) fn below(&mut self, limit: usize, what: &'static str) -> Result<u8, ImageError> {
        let v = self.u8()?;
        if usize::from(v) >= limit {
            return Err(ImageError::Invalid(what));
        }
        Ok(v)
    }

    pub(crate) fn name(&mut self) -> Result<Name, ImageError> {
        let n = self.count(crate::NAME_LEN, "name length")?;
        let (text, rest) = self
            .bytes
            .split_at_checked(n)
            .ok_or(ImageError::Truncated)?;
        self.bytes = rest;
        let text = core::str::from_utf8(text).map_err(|_| ImageError::Invalid("name"))?;
        let mut name = Name::new();
        name.push_str(text)
            .map_err(|_| ImageError::Invalid("name"))?;
        Ok(name)
    }

    pub(crate) fn magic(&mut self) -> Result<(), ImageError> {
        if self.take::<4>().map_err(|_| ImageError::Magic)? == MAGIC {
            Ok(())
        } else {
            Err(ImageError::Magic)
        }
    }

    pub(crate) fn finish(&self) -> Result<(), ImageError> {
        if self.bytes.is_empty() {
            Ok(())
        } else {
            Err(ImageError::TrailingBytes)
        }
    }
}

/// Writes an image (PC side).
#[cfg(feature = "std")]
#[derive(Default)]
pub(crate) struct Writer(pub(crate) std::vec::Vec<u8>);

#[cfg(feature = "std")]
impl Writer {
    pub(crate) fn u8(&mut self, v: u8) {
        self.0.push(v);
    }

    pub(crate) fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn i32(&mut self, v: i32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    pub(crate) fn f32(&mut self, v: f32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }

    /// A list's length: lists are bounded by the crate's capacities, all below 256.
    pub(crate) fn count(&mut self, n: usize) {
        self.u8(n as u8);
    }

    pub(crate) fn name(&mut self, n: &Name) {
        self.count(n.len());
        self.0.extend_from_slice(n.as_bytes());
    }
}
