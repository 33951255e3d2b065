//! A detector as bytes: written on the PC by `detector-build` (`Compiled::image`), loaded
//! on the chip in place ([`crate::Detector::load_image`]) with a small stack frame, no
//! serde and no configuration parsing. The firmware embeds the image its build script
//! made, so the chip never holds a configuration.
//!
//! # Layout
//!
//! Little-endian. The magic [`MAGIC`] (`FTDA`, its last character is the layout's version,
//! 1-9 then A-Z), then
//! each [`Section`] in [`Section::ORDER`], each opened by its tag byte:
//!
//! | section | tag | contents |
//! |---|---|---|
//! | [`Section::Rate`] | 1 | the detector rate in Hz (`f32`) |
//! | [`Section::Channels`] | 2 | a count, then per channel: name, scale (`f32`) |
//! | [`Section::Features`] | 3 | a count, then per feature: name, stage (its kind's tag, then its values) |
//! | [`Section::SlotChannels`] | 4 | per slot in use ([`Section::slots_in_use`]: the channels' slots, then one per feature): the channels it depends on (`u32` mask) |
//! | [`Section::Taps`] | 5 | the STE window taps (`u32`, Q24), [`crate::feature::WINDOW_POOL`] of them |
//! | [`Section::Terms`] | 6 | a count, then per distinct (feature, CDF) pair: the slot, the CDF (its shape's tag, then its values) |
//! | [`Section::Events`] | 7 | a count, then per event: name, context terms (count, pair indices), sensor terms (count, pair index and Q15 weight each), alert and confirm levels (on, off, dwell, hold: `u16`; an early dwell's flag `u8`, and if 1 its slot `u8`, level `i32` and dwell `u16`), onset level (`u16`) |
//! | [`Section::Phases`] | 8 | a count, then per phase: name, event mask (`u8`) |
//!
//! A name is its length (`u8`) and its UTF-8 bytes; a count is one byte. Each compiled item
//! (stage, CDF, decision level) writes and reads itself next to the checks it must pass.
//! Loading checks every tag, count, index, shift and level, so a corrupt image is
//! rejected rather than run.

use crate::Name;

/// The first four bytes of every image (the last character is the layout's version).
pub const MAGIC: [u8; 4] = *b"FTDA";

/// An image's sections, each opened by its tag byte (the discriminant), in
/// [`Section::ORDER`]: the one statement of the layout that the writer and the loader both
/// walk.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Section {
    /// The detector rate.
    Rate = 1,
    /// The input channels and their scales.
    Channels = 2,
    /// The features' names and compiled stages.
    Features = 3,
    /// The channels each slot depends on.
    SlotChannels = 4,
    /// The tapered STE windows' taps.
    Taps = 5,
    /// The distinct (feature, CDF) pairs the events' terms judge.
    Terms = 6,
    /// The events: terms, weights, decision levels.
    Events = 7,
    /// The phases and their events.
    Phases = 8,
}

impl Section {
    /// The sections in the order an image holds them.
    pub const ORDER: [Section; 8] = [
        Section::Rate,
        Section::Channels,
        Section::Features,
        Section::SlotChannels,
        Section::Taps,
        Section::Terms,
        Section::Events,
        Section::Phases,
    ];

    /// How many slots [`Section::SlotChannels`] holds for a detector of `features`
    /// features: the channels' slots, then one per feature (the slots in use, so that an
    /// image does not grow with the capacity).
    pub const fn slots_in_use(features: usize) -> usize {
        crate::MAX_CHANNELS + features
    }

    /// The section's name, for errors.
    pub const fn name(self) -> &'static str {
        match self {
            Section::Rate => "rate",
            Section::Channels => "channels",
            Section::Features => "features",
            Section::SlotChannels => "slot channels",
            Section::Taps => "STE taps",
            Section::Terms => "terms",
            Section::Events => "events",
            Section::Phases => "phases",
        }
    }
}

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
    /// The tag of this section is missing where the layout puts it.
    Section(&'static str),
}

impl core::fmt::Display for ImageError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ImageError::Magic => write!(f, "not a detector image of this version"),
            ImageError::Truncated => write!(f, "the image is truncated"),
            ImageError::TrailingBytes => write!(f, "bytes follow the image's end"),
            ImageError::Invalid(what) => write!(f, "the image's {what} is out of range"),
            ImageError::Section(what) => {
                write!(f, "the image's {what} section is missing or out of place")
            }
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

    /// The tag that opens `section`.
    pub(crate) fn section(&mut self, section: Section) -> Result<(), ImageError> {
        if self.u8()? == section as u8 {
            Ok(())
        } else {
            Err(ImageError::Section(section.name()))
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

/// Where an image is written, a value at a time, in the layout the loader reads: the
/// build side gives a byte buffer. Each compiled item (stage, CDF, ramp) writes itself
/// through it, next to the code that reads it back.
pub trait Sink {
    /// Appends raw bytes.
    fn put(&mut self, bytes: &[u8]);

    /// Appends a byte.
    fn u8(&mut self, v: u8) {
        self.put(&[v]);
    }

    /// Appends a little-endian `u16`.
    fn u16(&mut self, v: u16) {
        self.put(&v.to_le_bytes());
    }

    /// Appends a little-endian `u32`.
    fn u32(&mut self, v: u32) {
        self.put(&v.to_le_bytes());
    }

    /// Appends a little-endian `i32`.
    fn i32(&mut self, v: i32) {
        self.put(&v.to_le_bytes());
    }

    /// Appends a little-endian `f32`.
    fn f32(&mut self, v: f32) {
        self.put(&v.to_le_bytes());
    }

    /// Appends a list's length: lists are bounded by the crate's capacities, all below 256.
    fn count(&mut self, n: usize) {
        self.u8(n as u8);
    }

    /// Appends the tag that opens `section`.
    fn section(&mut self, section: Section) {
        self.u8(section as u8);
    }

    /// Appends a name: its length, then its bytes.
    fn name(&mut self, n: &Name) {
        self.count(n.len());
        self.put(n.as_bytes());
    }
}

/// An image written in memory, for tests of the items that write and read themselves.
#[cfg(test)]
pub(crate) struct Bytes(pub(crate) std::vec::Vec<u8>);

#[cfg(test)]
impl Sink for Bytes {
    fn put(&mut self, bytes: &[u8]) {
        self.0.extend_from_slice(bytes);
    }
}
