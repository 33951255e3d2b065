//! The detector image: what the firmware embeds and loads in place
//! ([`detector_core::Detector::load_image`]), written from a [`Compiled`] configuration in
//! the layout [`detector_core::image`] describes and reads.

use detector_core::image::{MAGIC, Section};
use detector_core::{Detector, Sink};

use crate::compile::{Compiled, Event};
use crate::config::{ConfigError, Item, Problem};

/// The bytes of an image being written.
struct Bytes(Vec<u8>);

impl Sink for Bytes {
    fn put(&mut self, bytes: &[u8]) {
        self.0.extend_from_slice(bytes);
    }
}

/// The image's CRC-32 (ISO-HDLC, as zlib's): what the firmware reports in status and what
/// a generated tick records of the image it was generated with.
pub fn image_crc(image: &[u8]) -> u32 {
    crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(image)
}

impl Compiled {
    /// The detector image.
    pub fn image(&self) -> Vec<u8> {
        let mut w = Bytes(Vec::new());
        w.put(&MAGIC);
        for section in Section::ORDER {
            w.section(section);
            match section {
                Section::Rate => w.f32(self.rate_hz),
                Section::Channels => {
                    w.count(self.channels.len());
                    for (name, scale) in &self.channels {
                        w.name(name);
                        w.f32(*scale);
                    }
                }
                Section::Features => {
                    w.count(self.features.len());
                    for (name, stage) in &self.features {
                        w.name(name);
                        stage.write_image(&mut w);
                    }
                }
                Section::SlotChannels => self
                    .slot_channels
                    .iter()
                    .take(Section::slots_in_use(self.features.len()))
                    .for_each(|&m| w.u32(m)),
                Section::Taps => self.taps.iter().for_each(|&t| w.u32(t)),
                Section::Terms => {
                    w.count(self.psis.len());
                    for p in &self.psis {
                        w.u8(p.slot);
                        p.cdf.write_image(&mut w);
                    }
                }
                Section::Events => {
                    w.count(self.events.len());
                    self.events.iter().for_each(|e| write_event(&mut w, e));
                }
                Section::Phases => {
                    w.count(self.phases.len());
                    for (name, mask) in &self.phases {
                        w.name(name);
                        w.u8(*mask);
                    }
                }
            }
        }
        w.0
    }

    /// The detector itself, loaded from [`Compiled::image`] as the firmware loads it.
    /// The loader accepts every image the compiler writes (the tests hold the two to each
    /// other); were it ever to refuse one, the error says why.
    pub fn detector(&self) -> Result<Detector, ConfigError> {
        let mut d = Detector::empty();
        d.load_image(&self.image()).map_err(|e| ConfigError {
            item: Item::Config,
            problem: Problem::Image(e),
        })?;
        Ok(d)
    }
}

/// One event: name, terms, levels, onset level, the events that exclude it.
fn write_event(w: &mut Bytes, e: &Event) {
    w.name(&e.name);
    w.count(e.context.len());
    e.context.iter().for_each(|&k| w.u8(k));
    w.count(e.sensor.len());
    for t in &e.sensor {
        w.u8(t.psi);
        w.u16(t.weight);
    }
    e.levels.iter().for_each(|l| l.write_image(w));
    w.u16(e.onset_level);
    w.u8(e.excluded_by);
}
