//! Where things live in flash: the application, the two detector slots and the key-value
//! store, within the first 128 KiB of the chip (`memory.x` states the same map for the
//! linker; a test holds the two together). Offsets are from the start of flash
//! (0x0800_0000), as the HAL's flash driver counts them.

use core::ops::Range;

/// The start of flash in the address space.
pub const FLASH_BASE: u32 = 0x0800_0000;
/// The erase unit, bytes (a page of the G4's single-bank flash).
pub const PAGE: u32 = 2048;
/// The write unit, bytes (a double word).
pub const WRITE: u32 = 8;

/// The application: code and constant data, the embedded detector's image among them.
pub const APPLICATION: Range<u32> = 0..104 * 1024;
/// Detector slot A: a detector image loaded at run time, kept across power cycles.
pub const SLOT_A: Range<u32> = APPLICATION.end..APPLICATION.end + 8 * 1024;
/// Detector slot B.
pub const SLOT_B: Range<u32> = SLOT_A.end..SLOT_A.end + 8 * 1024;
/// The key-value store: calibration, node id, the active slot.
pub const STORE: Range<u32> = SLOT_B.end..SLOT_B.end + 8 * 1024;

const _: () = assert!(STORE.end == 128 * 1024);
const _: () = assert!(
    SLOT_A.start.is_multiple_of(PAGE)
        && SLOT_B.start.is_multiple_of(PAGE)
        && STORE.start.is_multiple_of(PAGE)
        && STORE.end.is_multiple_of(PAGE)
        // The NUCLEO-G474RE's single-bank pages are 4 KiB.
        && SLOT_A.start.is_multiple_of(4096)
        && STORE.start.is_multiple_of(4096)
);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_x_gives_the_application_what_the_map_says() {
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../memory.x"))
            .expect("memory.x");
        let flash = text
            .lines()
            .find(|l| l.trim_start().starts_with("FLASH :"))
            .expect("a FLASH region");
        assert!(flash.contains("ORIGIN = 0x08000000"), "{flash}");
        let kib = APPLICATION.end / 1024;
        assert!(flash.contains(&format!("LENGTH = {kib}K")), "{flash}");
        for (name, r) in [("slot A", &SLOT_A), ("slot B", &SLOT_B), ("store", &STORE)] {
            let addr = format!(
                "0x{:04X}_{:04X}",
                (FLASH_BASE + r.start) >> 16,
                (FLASH_BASE + r.start) & 0xFFFF
            );
            assert!(
                text.lines().any(|l| l.contains(&addr) && l.contains(name)),
                "memory.x does not place {name} at {addr}"
            );
        }
    }
}
