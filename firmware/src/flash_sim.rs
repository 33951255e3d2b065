//! A simulated flash for the PC's tests of [`crate::nvm`] and the service channel: the
//! G4's rules (8-byte writes only to erased double words, 2 KiB pages) over the first
//! 128 KiB, and a power cut at a chosen step: a double word half programmed, a page half
//! erased, and nothing after it until the power comes back. Not used on the board.

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::flash_map::{PAGE, STORE, WRITE};

/// The flash it simulates, bytes.
pub const SIZE: usize = STORE.end as usize;

/// Why an operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimError {
    /// The power failed during it, or before.
    PowerCut,
    /// A double word written twice without an erase.
    NotErased,
    /// Not on a double word (write) or page (erase) boundary.
    Unaligned,
}

impl NorFlashError for SimError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            SimError::Unaligned => NorFlashErrorKind::NotAligned,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The simulated flash.
pub struct SimFlash {
    /// Its contents.
    pub bytes: [u8; SIZE],
    /// Steps (double words programmed, pages erased) left before the power fails; `None`
    /// for a power that never fails.
    pub power: Option<usize>,
    /// Whether the power has failed.
    pub dead: bool,
    /// Steps taken so far.
    pub steps: usize,
}

impl Default for SimFlash {
    fn default() -> Self {
        SimFlash::new()
    }
}

impl SimFlash {
    /// Erased throughout, the power on.
    pub const fn new() -> SimFlash {
        SimFlash {
            bytes: [0xFF; SIZE],
            power: None,
            dead: false,
            steps: 0,
        }
    }

    /// The power comes back (the board restarts on the same flash).
    pub fn revive(&mut self) {
        self.power = None;
        self.dead = false;
    }

    /// One step; whether the power fails during it.
    fn step(&mut self) -> Result<bool, SimError> {
        if self.dead {
            return Err(SimError::PowerCut);
        }
        self.steps += 1;
        match &mut self.power {
            Some(0) => {
                self.dead = true;
                Ok(true)
            }
            Some(n) => {
                *n -= 1;
                Ok(false)
            }
            None => Ok(false),
        }
    }

    fn range(offset: u32, len: usize) -> Result<core::ops::Range<usize>, SimError> {
        let start = offset as usize;
        let end = start.checked_add(len).filter(|&e| e <= SIZE);
        end.map(|e| start..e).ok_or(SimError::Unaligned)
    }
}

impl ErrorType for SimFlash {
    type Error = SimError;
}

impl ReadNorFlash for SimFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), SimError> {
        if self.dead {
            return Err(SimError::PowerCut);
        }
        let r = SimFlash::range(offset, bytes.len())?;
        bytes.copy_from_slice(&self.bytes[r]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl NorFlash for SimFlash {
    const WRITE_SIZE: usize = WRITE as usize;
    const ERASE_SIZE: usize = PAGE as usize;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), SimError> {
        if !from.is_multiple_of(PAGE) || !to.is_multiple_of(PAGE) || to as usize > SIZE {
            return Err(SimError::Unaligned);
        }
        for page in (from..to).step_by(PAGE as usize) {
            let p = page as usize;
            if self.step()? {
                // Half the page erased.
                self.bytes[p..p + PAGE as usize / 2].fill(0xFF);
                return Err(SimError::PowerCut);
            }
            self.bytes[p..p + PAGE as usize].fill(0xFF);
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SimError> {
        if !offset.is_multiple_of(WRITE) || !bytes.len().is_multiple_of(WRITE as usize) {
            return Err(SimError::Unaligned);
        }
        SimFlash::range(offset, bytes.len())?;
        for (k, word) in bytes.chunks(WRITE as usize).enumerate() {
            let o = offset as usize + k * WRITE as usize;
            if self.bytes[o..o + WRITE as usize].iter().any(|&b| b != 0xFF) {
                return Err(SimError::NotErased);
            }
            if self.step()? {
                // Half the double word programmed.
                self.bytes[o..o + 4].copy_from_slice(&word[..4]);
                return Err(SimError::PowerCut);
            }
            self.bytes[o..o + WRITE as usize].copy_from_slice(word);
        }
        Ok(())
    }
}
