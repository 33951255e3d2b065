//! The compact binary trace (`.ftrc`) the QEMU program embeds: raw 16.16 samples, no
//! parsing work on the target.
//!
//! This file is also compiled into the crate's `build.rs` (with `#[path]`), which writes
//! the trace the program embeds; so it uses nothing but `core`.
//!
//! # Layout (all integers little-endian)
//!
//! | bytes | field |
//! |---|---|
//! | 4 | magic `FTRC` |
//! | 2 | format version, [`VERSION`] |
//! | 2 | channels per record, `1..=MAX_CHANNELS` (16), in the configuration's order |
//! | 4 | number of segments |
//!
//! then each segment (one run, e.g. one simulated scenario; the detector state is fresh at
//! the start of each):
//!
//! | bytes | field |
//! |---|---|
//! | 1 | name length, `0..=`[`NAME_MAX`] |
//! | n | name, UTF-8 |
//! | 4 | tick of the first record (ticks then count up by one, wrapping) |
//! | 4 | number of records |
//!
//! then each record (one tick): 4 bytes of channel fault mask (bit `i` for channel `i`),
//! then one `i32` per channel: the sample's raw 16.16 bits in the channel's SI unit.

/// The file's first four bytes.
pub const MAGIC: [u8; 4] = *b"FTRC";
/// The format version this code reads and writes.
pub const VERSION: u16 = 1;
/// Longest segment name, in bytes.
pub const NAME_MAX: usize = 32;
/// Most channels a record may hold (the detector core's `MAX_CHANNELS`).
pub const CHANNELS_MAX: usize = 16;

const HEADER_LEN: usize = 12;

/// Why bytes are not a valid trace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TraceError {
    /// The first four bytes are not `FTRC`.
    Magic,
    /// A format version this code does not read.
    Version(u16),
    /// The channel count is 0 or above [`CHANNELS_MAX`].
    Channels(u16),
    /// The data ends inside segment `segment` (0-based), or inside the header if `None`.
    Truncated {
        /// The segment being read.
        segment: Option<u32>,
    },
    /// Segment `segment`'s name is longer than [`NAME_MAX`] or not UTF-8.
    Name {
        /// The segment.
        segment: u32,
    },
    /// Bytes are left after the last segment.
    Trailing {
        /// How many.
        bytes: usize,
    },
}

impl core::fmt::Display for TraceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            TraceError::Magic => write!(f, "not a trace: the magic is not FTRC"),
            TraceError::Version(v) => {
                write!(f, "trace format version {v}; this code reads {VERSION}")
            }
            TraceError::Channels(n) => {
                write!(f, "{n} channels per record; must be 1..={CHANNELS_MAX}")
            }
            TraceError::Truncated { segment: None } => write!(f, "the trace header is truncated"),
            TraceError::Truncated { segment: Some(s) } => write!(f, "segment {s} is truncated"),
            TraceError::Name { segment } => write!(
                f,
                "segment {segment}: the name is longer than {NAME_MAX} bytes or not UTF-8"
            ),
            TraceError::Trailing { bytes } => {
                write!(f, "{bytes} bytes left after the last segment")
            }
        }
    }
}

/// Reads `N` bytes at `*at`, advancing it.
fn take<'a>(bytes: &'a [u8], at: &mut usize, n: usize) -> Option<&'a [u8]> {
    let end = at.checked_add(n)?;
    let s = bytes.get(*at..end)?;
    *at = end;
    Some(s)
}

fn u32_at(bytes: &[u8], at: &mut usize) -> Option<u32> {
    let b = take(bytes, at, 4)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// A validated trace, borrowing its bytes.
#[derive(Clone, Copy, Debug)]
pub struct Trace<'a> {
    body: &'a [u8],
    channels: usize,
    segments: u32,
}

impl<'a> Trace<'a> {
    /// Checks the whole layout once, so iterating never fails afterwards.
    pub fn parse(bytes: &'a [u8]) -> Result<Trace<'a>, TraceError> {
        let header = bytes
            .get(..HEADER_LEN)
            .ok_or(TraceError::Truncated { segment: None })?;
        if header[..4] != MAGIC {
            return Err(TraceError::Magic);
        }
        let version = u16::from_le_bytes([header[4], header[5]]);
        if version != VERSION {
            return Err(TraceError::Version(version));
        }
        let channels = u16::from_le_bytes([header[6], header[7]]);
        if channels == 0 || usize::from(channels) > CHANNELS_MAX {
            return Err(TraceError::Channels(channels));
        }
        let segments = u32::from_le_bytes([header[8], header[9], header[10], header[11]]);
        let trace = Trace {
            body: &bytes[HEADER_LEN..],
            channels: usize::from(channels),
            segments,
        };
        let mut at = 0;
        for s in 0..segments {
            trace.segment_at(&mut at, s)?;
        }
        if at != trace.body.len() {
            return Err(TraceError::Trailing {
                bytes: trace.body.len() - at,
            });
        }
        Ok(trace)
    }

    fn segment_at(&self, at: &mut usize, index: u32) -> Result<Segment<'a>, TraceError> {
        let truncated = TraceError::Truncated {
            segment: Some(index),
        };
        let len = take(self.body, at, 1).ok_or(truncated)?[0];
        if usize::from(len) > NAME_MAX {
            return Err(TraceError::Name { segment: index });
        }
        let name = take(self.body, at, usize::from(len)).ok_or(truncated)?;
        let name = core::str::from_utf8(name).map_err(|_| TraceError::Name { segment: index })?;
        let start_tick = u32_at(self.body, at).ok_or(truncated)?;
        let ticks = u32_at(self.body, at).ok_or(truncated)?;
        let record = record_len(self.channels);
        let size = (ticks as usize).checked_mul(record).ok_or(truncated)?;
        let records = take(self.body, at, size).ok_or(truncated)?;
        Ok(Segment {
            name,
            start_tick,
            ticks,
            channels: self.channels,
            records,
        })
    }

    /// Channels per record.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Number of segments.
    pub fn segment_count(&self) -> u32 {
        self.segments
    }

    /// The segments, in order.
    pub fn segments(&self) -> Segments<'a> {
        Segments {
            trace: *self,
            at: 0,
            next: 0,
        }
    }

    /// Total records (ticks) over all segments.
    pub fn ticks(&self) -> u64 {
        self.segments().map(|s| u64::from(s.ticks())).sum()
    }
}

/// Iterator over a trace's segments.
#[derive(Clone, Debug)]
pub struct Segments<'a> {
    trace: Trace<'a>,
    at: usize,
    next: u32,
}

impl<'a> Iterator for Segments<'a> {
    type Item = Segment<'a>;

    fn next(&mut self) -> Option<Segment<'a>> {
        if self.next >= self.trace.segments {
            return None;
        }
        let index = self.next;
        self.next += 1;
        // The layout was validated by `Trace::parse`.
        self.trace.segment_at(&mut self.at, index).ok()
    }
}

/// One run: a name, the first tick, and its records.
#[derive(Clone, Copy, Debug)]
pub struct Segment<'a> {
    name: &'a str,
    start_tick: u32,
    ticks: u32,
    channels: usize,
    records: &'a [u8],
}

impl<'a> Segment<'a> {
    /// The segment's name (e.g. the simulated scenario).
    pub fn name(&self) -> &'a str {
        self.name
    }

    /// The tick of the first record.
    pub fn start_tick(&self) -> u32 {
        self.start_tick
    }

    /// Number of records.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// The records, in order.
    pub fn records(&self) -> Records<'a> {
        Records {
            chunks: self.records.chunks_exact(record_len(self.channels)),
        }
    }
}

/// One tick of a trace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// Channels flagged faulty, bit `i` for channel `i`.
    pub faults: u32,
    /// Raw 16.16 samples; entries past the trace's channel count are 0.
    pub samples: [i32; CHANNELS_MAX],
}

/// Iterator over a segment's records.
#[derive(Clone, Debug)]
pub struct Records<'a> {
    chunks: core::slice::ChunksExact<'a, u8>,
}

impl Iterator for Records<'_> {
    type Item = Record;

    fn next(&mut self) -> Option<Record> {
        let chunk = self.chunks.next()?;
        let (faults, samples_bytes) = chunk.split_at(4);
        let mut samples = [0i32; CHANNELS_MAX];
        for (s, b) in samples.iter_mut().zip(samples_bytes.chunks_exact(4)) {
            *s = i32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        }
        Some(Record {
            faults: u32::from_le_bytes([faults[0], faults[1], faults[2], faults[3]]),
            samples,
        })
    }
}

fn record_len(channels: usize) -> usize {
    4 + 4 * channels
}

/// Writes a trace piece by piece into a byte sink (no allocation): the header, then for
/// each segment its header and exactly as many records as it declares. A converter from
/// the simulator's traces calls these in order; [`Trace::parse`] checks the result.
pub struct Encoder<W: FnMut(&[u8])> {
    sink: W,
    channels: usize,
}

impl<W: FnMut(&[u8])> Encoder<W> {
    /// Writes the header. `channels` must be `1..=CHANNELS_MAX`.
    pub fn new(mut sink: W, channels: usize, segments: u32) -> Result<Self, TraceError> {
        let n = u16::try_from(channels)
            .ok()
            .filter(|&n| n != 0 && usize::from(n) <= CHANNELS_MAX)
            .ok_or(TraceError::Channels(channels.min(u16::MAX as usize) as u16))?;
        sink(&MAGIC);
        sink(&VERSION.to_le_bytes());
        sink(&n.to_le_bytes());
        sink(&segments.to_le_bytes());
        Ok(Encoder { sink, channels })
    }

    /// Starts a segment of `ticks` records beginning at `start_tick`.
    pub fn segment(
        &mut self,
        index: u32,
        name: &str,
        start_tick: u32,
        ticks: u32,
    ) -> Result<(), TraceError> {
        let len = u8::try_from(name.len())
            .ok()
            .filter(|&l| usize::from(l) <= NAME_MAX)
            .ok_or(TraceError::Name { segment: index })?;
        (self.sink)(&[len]);
        (self.sink)(name.as_bytes());
        (self.sink)(&start_tick.to_le_bytes());
        (self.sink)(&ticks.to_le_bytes());
        Ok(())
    }

    /// Writes one record; `samples` must hold exactly the trace's channel count.
    pub fn record(&mut self, faults: u32, samples: &[i32]) -> Result<(), TraceError> {
        if samples.len() != self.channels {
            return Err(TraceError::Channels(
                samples.len().min(u16::MAX as usize) as u16
            ));
        }
        (self.sink)(&faults.to_le_bytes());
        for s in samples {
            (self.sink)(&s.to_le_bytes());
        }
        Ok(())
    }
}
