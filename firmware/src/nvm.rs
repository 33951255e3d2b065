//! What the board keeps across power cycles ([`crate::flash_map`]): two detector slots and
//! a key-value store, over any flash with embedded-storage's (async) traits, so the PC
//! tests drive it on a simulated flash that loses power at every step.
//!
//! **The store** is `sequential-storage`'s map (items with CRCs, written append-only and
//! wear-levelled over its pages): `u16` keys ([`fingertip_can::service::Key`]'s, and
//! [`ACTIVE_SLOT`]), 4-byte values. After a power cut at any step of a write it reads back
//! the old value or the new one.
//!
//! **A slot** holds one detector image behind a header:
//!
//! | bytes | content |
//! |---|---|
//! | 0..4 | magic `FTS1` |
//! | 4..8 | sequence number (`u32`): one more than any slot's before it |
//! | 8..12 | image length, bytes |
//! | 12..16 | the image's CRC-32 |
//! | 16..33 | the detector's name: length, 16 bytes |
//! | 36..40 | CRC-32 of bytes 0..36 |
//! | 40.. | the image |
//!
//! A slot is written in three steps: its pages erased, the image written, the header
//! written last (until then the slot reads as empty). The store's [`ACTIVE_SLOT`] key is
//! written after that: the commit. At boot ([`Nvm::boot_image`]) the slot the key names is
//! taken if it is whole (both CRCs), else the other slot if it is, else nothing: the
//! built-in detector, with `FaultConfigFallback` when a slot had been chosen. A power cut
//! anywhere in a save leaves the old detector or the new one, never a part of either.
//!
//! **The stall.** The STM32G4's flash is single-bank: while a page is erased or a double
//! word programmed, the CPU cannot fetch from flash, interrupts included. The datasheet
//! (STM32G431/G491, *Flash memory characteristics*) gives a page erase 22.0 ms typical,
//! 24.5 ms at most, and a double word 81.7 µs, 90.8 µs at most; [`stall_us`] computes a
//! write's worst case from those.

use core::ops::Range;

use embedded_storage_async::nor_flash::NorFlash;
use fingertip_can::service::{CalibrationParameter, DetectorName, Key, NAME_MAX};
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

use crate::calib::Calibration;
use crate::channel_set::ChannelSet;
use crate::checksum::crc32;
use crate::flash_map::{PAGE, SLOT_A, SLOT_B, STORE, WRITE};
use crate::wiring::ADC_CHANNELS;

/// The store's key of the slot chosen at the last save: 0 none (the built-in detector),
/// 1 slot A, 2 slot B (`u32`).
pub const ACTIVE_SLOT: u16 = 0x0002;

/// A page erase at most, µs (datasheet).
pub const ERASE_US: u32 = 24_470;
/// A double word's programming at most, µs (datasheet).
pub const PROGRAM_US: u32 = 91;

/// The worst-case time the CPU stalls to erase `pages` pages and program `bytes` bytes, µs.
pub const fn stall_us(pages: u32, bytes: u32) -> u32 {
    pages * ERASE_US + bytes.div_ceil(WRITE) * PROGRAM_US
}

/// Bytes of a slot's header.
pub const HEADER: usize = 40;
/// The largest image a slot holds, bytes.
pub const SLOT_IMAGE_MAX: usize = 8 * 1024 - HEADER;
const MAGIC: [u8; 4] = *b"FTS1";

/// One of the two detector slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Slot {
    /// Slot A.
    A,
    /// Slot B.
    B,
}

impl Slot {
    /// Its flash range.
    pub const fn range(self) -> Range<u32> {
        match self {
            Slot::A => SLOT_A,
            Slot::B => SLOT_B,
        }
    }

    /// The other one.
    pub const fn other(self) -> Slot {
        match self {
            Slot::A => Slot::B,
            Slot::B => Slot::A,
        }
    }

    /// Its value in [`ACTIVE_SLOT`].
    pub const fn raw(self) -> u32 {
        match self {
            Slot::A => 1,
            Slot::B => 2,
        }
    }

    fn from_raw(raw: u32) -> Option<Slot> {
        match raw {
            1 => Some(Slot::A),
            2 => Some(Slot::B),
            _ => None,
        }
    }
}

/// What a whole slot holds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SlotHeader {
    /// One more than any slot's before it.
    pub sequence: u32,
    /// Image bytes.
    pub len: u32,
    /// The image's CRC-32.
    pub crc: u32,
    /// The detector's name.
    pub name: DetectorName,
}

impl SlotHeader {
    fn bytes(&self) -> [u8; HEADER] {
        let mut h = [0u8; HEADER];
        h[0..4].copy_from_slice(&MAGIC);
        h[4..8].copy_from_slice(&self.sequence.to_le_bytes());
        h[8..12].copy_from_slice(&self.len.to_le_bytes());
        h[12..16].copy_from_slice(&self.crc.to_le_bytes());
        h[16] = self.name.len() as u8;
        h[17..17 + self.name.len()].copy_from_slice(self.name.as_bytes());
        let crc = crc32(&h[..36]);
        h[36..40].copy_from_slice(&crc.to_le_bytes());
        h
    }

    /// The header in `h`, if it is one (magic, CRC, sizes).
    fn parse(h: &[u8; HEADER]) -> Option<SlotHeader> {
        let word = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        if h[0..4] != MAGIC || crc32(&h[..36]) != word(36) {
            return None;
        }
        let n = usize::from(h[16]);
        let len = word(8);
        if n > NAME_MAX || len as usize > SLOT_IMAGE_MAX {
            return None;
        }
        let mut name = DetectorName::new();
        name.push_str(core::str::from_utf8(&h[17..17 + n]).ok()?)
            .ok()?;
        Some(SlotHeader {
            sequence: word(4),
            len,
            crc: word(12),
            name,
        })
    }
}

/// A flash operation failed, or what it read cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum NvmError {
    /// The flash refused an operation (or lost power during it).
    Flash,
    /// The store found data it could not repair.
    Corrupted,
    /// The store is full of live items (it never is with this firmware's few keys).
    Full,
    /// An image longer than a slot holds.
    TooLong(u32),
}

impl core::fmt::Display for NvmError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            NvmError::Flash => write!(f, "the flash refused an operation"),
            NvmError::Corrupted => write!(f, "the store holds data it cannot repair"),
            NvmError::Full => write!(f, "the store is full"),
            NvmError::TooLong(n) => {
                write!(
                    f,
                    "an image of {n} bytes does not fit a slot ({SLOT_IMAGE_MAX})"
                )
            }
        }
    }
}

impl<E> From<sequential_storage::Error<E>> for NvmError {
    fn from(e: sequential_storage::Error<E>) -> NvmError {
        match e {
            sequential_storage::Error::Storage { .. } => NvmError::Flash,
            sequential_storage::Error::FullStorage => NvmError::Full,
            _ => NvmError::Corrupted,
        }
    }
}

/// What boot found in the slots.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BootImage {
    /// No slot chosen: the built-in detector.
    BuiltIn,
    /// A whole slot: its header; the image is in the caller's buffer.
    Slot(Slot, SlotHeader),
    /// A slot was chosen but neither is whole: the built-in detector, with
    /// `FaultConfigFallback`.
    Fallback,
}

type StoreCache = Cache<Uncached, Uncached, Uncached, u16>;

/// The board's flash: slots and store.
pub struct Nvm<F> {
    flash: F,
}

impl<F: NorFlash> Nvm<F> {
    /// Over `flash` (offsets from the start of flash, as [`crate::flash_map`] counts).
    pub const fn new(flash: F) -> Nvm<F> {
        Nvm { flash }
    }

    /// The flash.
    pub fn into_inner(self) -> F {
        self.flash
    }

    /// The store's map, made for each operation: uncached, so it scans its pages (a few
    /// milliseconds for 8 KiB, on a request, never in a tick) and holds nothing between
    /// operations.
    fn map(&mut self) -> MapStorage<u16, &mut F, StoreCache> {
        MapStorage::new(
            &mut self.flash,
            const { MapConfig::new(STORE.start..STORE.end) },
            Cache::new_uncached(),
        )
    }

    /// The value of `key`, `None` if never written.
    pub async fn read_key(&mut self, key: u16) -> Result<Option<[u8; 4]>, NvmError> {
        let mut buf = [0u8; 16];
        Ok(self.map().fetch_item::<[u8; 4]>(&mut buf, &key).await?)
    }

    /// Writes `key`: a few double words, and a page erase when the store moves on to a
    /// fresh page.
    pub async fn write_key(&mut self, key: u16, value: [u8; 4]) -> Result<(), NvmError> {
        let mut buf = [0u8; 16];
        self.map().store_item(&mut buf, &key, &value).await?;
        Ok(())
    }

    /// The node id the store holds, if any (as written: [`crate::node_id::resolve`]
    /// checks its range).
    pub async fn node_id(&mut self) -> Result<Option<u8>, NvmError> {
        Ok(self
            .read_key(Key::NodeId.raw())
            .await?
            .map(|v| u8::try_from(u32::from_le_bytes(v)).unwrap_or(u8::MAX)))
    }

    /// Each analog channel's calibration: `nominal`'s, with the parameters the store
    /// holds in their place. A channel whose parameters together are not a calibration
    /// keeps its nominal one and is named in the set returned.
    pub async fn calibration(
        &mut self,
        nominal: &[Calibration; ADC_CHANNELS.len()],
    ) -> Result<([Calibration; ADC_CHANNELS.len()], ChannelSet), NvmError> {
        let mut out = *nominal;
        let mut refused = ChannelSet::EMPTY;
        for (c, (cal, nom)) in out.iter_mut().zip(nominal).enumerate() {
            let mut p = [nom.gain(), nom.zero(), nom.drift(), nom.t_ref()];
            let mut stored = false;
            for parameter in CalibrationParameter::ALL {
                let key = Key::Calibration {
                    channel: c as u8,
                    parameter,
                };
                if let Some(v) = self.read_key(key.raw()).await? {
                    p[parameter as usize] = f32::from_le_bytes(v);
                    stored = true;
                }
            }
            if stored {
                match Calibration::new(p[0], p[1], p[2], p[3]) {
                    Ok(k) => *cal = k,
                    Err(_) => refused.insert(c),
                }
            }
        }
        Ok((out, refused))
    }

    /// The slot chosen at the last save, if any.
    pub async fn active_slot(&mut self) -> Result<Option<Slot>, NvmError> {
        Ok(self
            .read_key(ACTIVE_SLOT)
            .await?
            .and_then(|v| Slot::from_raw(u32::from_le_bytes(v))))
    }

    /// `slot`'s header if the slot is whole: a good header and an image of its CRC,
    /// read into `buf`.
    pub async fn read_slot(
        &mut self,
        slot: Slot,
        buf: &mut [u8],
    ) -> Result<Option<SlotHeader>, NvmError> {
        let r = slot.range();
        let Some(header) = self.read_header(slot).await? else {
            return Ok(None);
        };
        let Some(image) = buf.get_mut(..header.len as usize) else {
            return Ok(None);
        };
        self.flash
            .read(r.start + HEADER as u32, image)
            .await
            .map_err(|_| NvmError::Flash)?;
        Ok((crc32(image) == header.crc).then_some(header))
    }

    /// `slot`'s header, if it is one (its image not checked).
    async fn read_header(&mut self, slot: Slot) -> Result<Option<SlotHeader>, NvmError> {
        let mut h = [0u8; HEADER];
        self.flash
            .read(slot.range().start, &mut h)
            .await
            .map_err(|_| NvmError::Flash)?;
        Ok(SlotHeader::parse(&h))
    }

    /// Saves `image`, named `name`, into the slot not chosen now and chooses it: the slot's
    /// pages erased, the image, its header, then the store's [`ACTIVE_SLOT`]. Returns the
    /// slot and the worst-case stall of the whole save (µs).
    pub async fn save(
        &mut self,
        name: &DetectorName,
        image: &[u8],
    ) -> Result<(Slot, u32), NvmError> {
        if image.len() > SLOT_IMAGE_MAX {
            return Err(NvmError::TooLong(image.len() as u32));
        }
        let active = self.active_slot().await?;
        let slot = active.map_or(Slot::A, Slot::other);
        // One more than any slot's sequence.
        let mut sequence = 1;
        for s in [Slot::A, Slot::B] {
            if let Some(h) = self.read_header(s).await? {
                sequence = sequence.max(h.sequence.wrapping_add(1));
            }
        }
        let r = slot.range();
        // A page at a time, and the image a few milliseconds at a time, letting the
        // other tasks run in between (the watchdog's among them): a blocking flash driver
        // holds the CPU for the whole of one call.
        for page in (r.start..r.end).step_by(PAGE as usize) {
            self.flash
                .erase(page, page + PAGE)
                .await
                .map_err(|_| NvmError::Flash)?;
            embassy_futures::yield_now().await;
        }
        // The image in whole double words (the last padded as erased flash reads).
        let mut at = r.start + HEADER as u32;
        for (k, chunk) in image.chunks(WRITE as usize).enumerate() {
            let mut word = [0xFF; WRITE as usize];
            word[..chunk.len()].copy_from_slice(chunk);
            self.flash
                .write(at, &word)
                .await
                .map_err(|_| NvmError::Flash)?;
            at += WRITE;
            if k % 64 == 63 {
                embassy_futures::yield_now().await;
            }
        }
        let header = SlotHeader {
            sequence,
            len: image.len() as u32,
            crc: crc32(image),
            name: name.clone(),
        };
        self.flash
            .write(r.start, &header.bytes())
            .await
            .map_err(|_| NvmError::Flash)?;
        self.write_key(ACTIVE_SLOT, slot.raw().to_le_bytes())
            .await?;
        let pages = (r.end - r.start) / PAGE;
        // The key: two double words, and a page erase if the store moves on.
        let stall = stall_us(pages + 1, (image.len() + HEADER + 16) as u32);
        Ok((slot, stall))
    }

    /// Forgets the chosen slot: the next boot runs the built-in detector.
    pub async fn choose_built_in(&mut self) -> Result<(), NvmError> {
        self.write_key(ACTIVE_SLOT, 0u32.to_le_bytes()).await
    }

    /// The detector to boot: the chosen slot if whole, else the other if whole (its image
    /// read into `buf`), else the built-in one.
    pub async fn boot_image(&mut self, buf: &mut [u8]) -> Result<BootImage, NvmError> {
        let Some(chosen) = self.active_slot().await? else {
            return Ok(BootImage::BuiltIn);
        };
        for slot in [chosen, chosen.other()] {
            if let Some(h) = self.read_slot(slot, buf).await? {
                return Ok(BootImage::Slot(slot, h));
            }
        }
        Ok(BootImage::Fallback)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flash_sim::SimFlash;
    use embassy_futures::block_on;

    fn name(s: &str) -> DetectorName {
        DetectorName::try_from(s).unwrap()
    }

    fn image(seed: u8, len: usize) -> Vec<u8> {
        (0..len)
            .map(|i| (i as u8).wrapping_mul(31) ^ seed)
            .collect()
    }

    #[test]
    fn keys_read_back_and_overwrite() {
        let mut nvm = Nvm::new(SimFlash::new());
        block_on(async {
            assert_eq!(nvm.read_key(7).await, Ok(None));
            nvm.write_key(7, [1, 2, 3, 4]).await.unwrap();
            nvm.write_key(8, [5, 6, 7, 8]).await.unwrap();
            nvm.write_key(7, [9, 9, 9, 9]).await.unwrap();
            assert_eq!(nvm.read_key(7).await, Ok(Some([9, 9, 9, 9])));
            assert_eq!(nvm.read_key(8).await, Ok(Some([5, 6, 7, 8])));
            // Many writes: the store moves over its pages and keeps the last values.
            for k in 0..2000u32 {
                nvm.write_key((k % 5) as u16, k.to_le_bytes())
                    .await
                    .unwrap();
            }
            for key in 0..5u16 {
                let last = 1995 + u32::from(key);
                assert_eq!(nvm.read_key(key).await, Ok(Some(last.to_le_bytes())));
            }
        });
    }

    #[test]
    fn the_stores_calibration_and_node_id_replace_the_nominal_ones() {
        use crate::calib::NOMINAL;
        let mut nvm = Nvm::new(SimFlash::new());
        block_on(async {
            assert_eq!(nvm.node_id().await, Ok(None));
            assert_eq!(
                nvm.calibration(&NOMINAL).await,
                Ok((NOMINAL, ChannelSet::EMPTY))
            );
            let key = |channel, parameter| Key::Calibration { channel, parameter }.raw();
            nvm.write_key(Key::NodeId.raw(), 9u32.to_le_bytes())
                .await
                .unwrap();
            nvm.write_key(key(1, CalibrationParameter::Gain), 0.005f32.to_le_bytes())
                .await
                .unwrap();
            nvm.write_key(key(1, CalibrationParameter::Zero), 2000.5f32.to_le_bytes())
                .await
                .unwrap();
            // Channel 3's gain made 0 behind the checks of the service channel.
            nvm.write_key(key(3, CalibrationParameter::Gain), 0f32.to_le_bytes())
                .await
                .unwrap();
            assert_eq!(nvm.node_id().await, Ok(Some(9)));
            let (cal, refused) = nvm.calibration(&NOMINAL).await.unwrap();
            assert_eq!(refused, ChannelSet::from_bits(0b1000));
            assert_eq!(
                [cal[0], cal[2], cal[3]],
                [NOMINAL[0], NOMINAL[2], NOMINAL[3]]
            );
            assert!((cal[1].gain() - 0.005).abs() < 1e-7);
            assert!((cal[1].zero() - 2000.5).abs() < 1e-3);
            assert_eq!(cal[1].drift(), NOMINAL[1].drift());
        });
    }

    #[test]
    fn saves_alternate_slots_and_boot_takes_the_chosen_one() {
        let mut nvm = Nvm::new(SimFlash::new());
        let mut buf = vec![0u8; SLOT_IMAGE_MAX];
        block_on(async {
            assert_eq!(nvm.boot_image(&mut buf).await, Ok(BootImage::BuiltIn));
            let a = image(1, 1785);
            let (slot, stall) = nvm.save(&name("first"), &a).await.unwrap();
            assert_eq!(slot, Slot::A);
            // 4 pages of the slot and one of the store, 1785 + 56 bytes.
            assert_eq!(stall, 5 * ERASE_US + 231 * PROGRAM_US);
            let b = image(2, 5000);
            assert_eq!(nvm.save(&name("second"), &b).await.unwrap().0, Slot::B);
            let Ok(BootImage::Slot(Slot::B, h)) = nvm.boot_image(&mut buf).await else {
                panic!()
            };
            assert_eq!((h.sequence, h.len, h.name.as_str()), (2, 5000, "second"));
            assert_eq!(&buf[..5000], &b[..]);
            // A third save goes back to A, newer than both.
            let c = image(3, 100);
            assert_eq!(nvm.save(&name("third"), &c).await.unwrap().0, Slot::A);
            let Ok(BootImage::Slot(Slot::A, h)) = nvm.boot_image(&mut buf).await else {
                panic!()
            };
            assert_eq!((h.sequence, h.crc), (3, crc32(&c)));
            nvm.choose_built_in().await.unwrap();
            assert_eq!(nvm.boot_image(&mut buf).await, Ok(BootImage::BuiltIn));
            assert_eq!(
                nvm.save(&name("huge"), &vec![0; SLOT_IMAGE_MAX + 1]).await,
                Err(NvmError::TooLong(SLOT_IMAGE_MAX as u32 + 1))
            );
        });
    }

    #[test]
    fn a_damaged_chosen_slot_falls_to_the_other_then_to_the_fallback() {
        let mut nvm = Nvm::new(SimFlash::new());
        let mut buf = vec![0u8; SLOT_IMAGE_MAX];
        block_on(async {
            let a = image(1, 300);
            let b = image(2, 400);
            nvm.save(&name("a"), &a).await.unwrap();
            nvm.save(&name("b"), &b).await.unwrap();
            let mut flash = nvm.into_inner();
            // A bit of slot B's image flips: B fails its CRC, A is taken.
            flash.bytes[(SLOT_B.start as usize) + HEADER + 10] ^= 4;
            let mut nvm = Nvm::new(flash);
            let Ok(BootImage::Slot(Slot::A, h)) = nvm.boot_image(&mut buf).await else {
                panic!()
            };
            assert_eq!(h.crc, crc32(&a));
            // And A's header too: nothing whole, a slot was chosen.
            let mut flash = nvm.into_inner();
            flash.bytes[SLOT_A.start as usize + 5] ^= 1;
            let mut nvm = Nvm::new(flash);
            assert_eq!(nvm.boot_image(&mut buf).await, Ok(BootImage::Fallback));
        });
    }

    /// Cuts the power at every step of `act` on a flash prepared by `prepare`; after each
    /// cut the board restarts on the same flash, and `check` sees what it reads.
    fn at_every_cut(
        prepare: impl Fn(&mut Nvm<SimFlash>),
        act: impl Fn(&mut Nvm<SimFlash>) -> bool,
        check: impl Fn(&mut Nvm<SimFlash>, usize),
    ) -> usize {
        // The steps the act takes with the power on.
        let mut nvm = Nvm::new(SimFlash::new());
        prepare(&mut nvm);
        let before = nvm.flash.steps;
        assert!(act(&mut nvm), "the act succeeds with the power on");
        let steps = nvm.flash.steps - before;
        for cut in 0..steps {
            let mut nvm = Nvm::new(SimFlash::new());
            prepare(&mut nvm);
            nvm.flash.power = Some(cut);
            assert!(!act(&mut nvm), "cut {cut} of {steps}: the act fails");
            nvm.flash.revive();
            check(&mut nvm, cut);
        }
        steps
    }

    #[test]
    fn a_key_written_as_the_power_fails_reads_back_old_or_new() {
        let steps = at_every_cut(
            |nvm| {
                block_on(async {
                    for k in 0..300u32 {
                        nvm.write_key((k % 3) as u16, k.to_le_bytes())
                            .await
                            .unwrap();
                    }
                })
            },
            |nvm| block_on(nvm.write_key(1, [0xAB; 4])).is_ok(),
            |nvm, cut| {
                block_on(async {
                    let v = nvm.read_key(1).await.unwrap();
                    assert!(
                        v == Some(298u32.to_le_bytes()) || v == Some([0xAB; 4]),
                        "cut {cut}: {v:?}"
                    );
                    // The other keys are untouched, and the store takes writes again.
                    assert_eq!(nvm.read_key(0).await.unwrap(), Some(297u32.to_le_bytes()));
                    assert_eq!(nvm.read_key(2).await.unwrap(), Some(299u32.to_le_bytes()));
                    nvm.write_key(1, [1; 4]).await.unwrap();
                    assert_eq!(nvm.read_key(1).await.unwrap(), Some([1; 4]));
                })
            },
        );
        assert!(steps >= 2, "{steps} steps");
        // And across a page change: the store full of its page, so the write erases one.
        let mut crossings = 0;
        for fill in 0..40u32 {
            let steps = at_every_cut(
                |nvm| {
                    block_on(async {
                        for k in 0..(250 + fill) {
                            nvm.write_key((k % 3) as u16, k.to_le_bytes())
                                .await
                                .unwrap();
                        }
                    })
                },
                |nvm| block_on(nvm.write_key(2, [0xCD; 4])).is_ok(),
                |nvm, cut| {
                    let v = block_on(nvm.read_key(2)).unwrap();
                    let last = (0..250 + fill).rev().find(|k| k % 3 == 2).unwrap();
                    assert!(
                        v == Some(last.to_le_bytes()) || v == Some([0xCD; 4]),
                        "fill {fill} cut {cut}: {v:?}"
                    );
                },
            );
            if steps > 2 {
                crossings += 1;
            }
        }
        assert!(
            crossings > 0,
            "no write erased a page: the test misses that case"
        );
    }

    #[test]
    fn a_save_cut_anywhere_boots_the_old_detector_or_the_new_one() {
        let old = crate::boot::DETECTOR_IMAGE.to_vec();
        let new = crate::load::tests::small_image();
        let steps = at_every_cut(
            |nvm| {
                block_on(nvm.save(&name("old"), &old)).unwrap();
            },
            |nvm| block_on(nvm.save(&name("new"), &new)).is_ok(),
            |nvm, cut| {
                let mut buf = vec![0u8; SLOT_IMAGE_MAX];
                let len = match block_on(nvm.boot_image(&mut buf)).unwrap() {
                    BootImage::Slot(Slot::A, h) => {
                        assert_eq!(h.name.as_str(), "old", "cut {cut}");
                        assert_eq!(&buf[..old.len()], &old[..]);
                        old.len()
                    }
                    BootImage::Slot(Slot::B, h) => {
                        assert_eq!(h.name.as_str(), "new", "cut {cut}");
                        assert_eq!(&buf[..new.len()], &new[..]);
                        new.len()
                    }
                    other => panic!("cut {cut}: {other:?}"),
                };
                // And it boots: the loader takes it, the engine runs it.
                let mut d = Box::new(detector_core::Detector::empty());
                let mut loader = crate::load::Loader::new(&mut d, 5000.0);
                let staged = loader.stage("boot", &buf[..len]).expect("loads");
                let board = crate::engine::BoardInfo {
                    node: fingertip_can::NodeId::new(1).unwrap(),
                    node_source: fingertip_can::NodeIdSource::Straps,
                    format: fingertip_can::BusFormat::Fd,
                    reset: fingertip_can::ResetReason::PowerOn,
                    clock_fallback: false,
                };
                let params = crate::engine::EngineParams::new(board, staged.crc);
                assert!(
                    crate::engine::Engine::<crate::boot::ApproachTick>::interpreted(
                        staged.detector,
                        params
                    )
                    .is_ok()
                );
            },
        );
        // Four page erases, the image's double words, the header's 5, the key's.
        assert!(steps > 4 + new.len() / 8 + 5, "{steps} steps");
    }
}
