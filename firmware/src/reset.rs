//! The reset reason, from the STM32G4's RCC control/status register (RCC_CSR).
//!
//! RM0440 (RCC chapter, RCC_CSR): bit 31 LPWRRSTF (illegal low-power entry), 30 WWDGRSTF, 29 IWDGRSTF,
//! 28 SFTRSTF (software reset: `SCB::sys_reset`), 27 BORRSTF (brown-out, which the G4
//! also raises at every power-on), 26 PINRSTF (the NRST pin), 25 OBLRSTF (option-byte
//! load); writing 1 to RMVF (bit 23) clears them all. Every internal reset also pulses
//! NRST, so PINRSTF is set along with the real cause: the pin is the cause only when no
//! other flag is set. The flags accumulate until cleared, so the firmware reads them
//! once at boot and clears them.

use fingertip_can::ResetReason;

/// LPWRRSTF.
pub const LPWRRSTF: u32 = 1 << 31;
/// WWDGRSTF.
pub const WWDGRSTF: u32 = 1 << 30;
/// IWDGRSTF.
pub const IWDGRSTF: u32 = 1 << 29;
/// SFTRSTF.
pub const SFTRSTF: u32 = 1 << 28;
/// BORRSTF.
pub const BORRSTF: u32 = 1 << 27;
/// PINRSTF.
pub const PINRSTF: u32 = 1 << 26;
/// OBLRSTF.
pub const OBLRSTF: u32 = 1 << 25;
/// RMVF: write 1 to clear the reset flags.
pub const RMVF: u32 = 1 << 23;

/// The reason for the last reset from the RCC_CSR value: the most specific flag set.
/// BORRSTF reads as [`ResetReason::PowerOn`]: on the G4 a power-on and a brown-out set the
/// same flag, and a power-on is by far the commoner.
pub const fn reset_reason(csr: u32) -> ResetReason {
    // Most specific first: a watchdog or software reset also sets PINRSTF, and a
    // power-on may leave other flags set from before.
    if csr & LPWRRSTF != 0 {
        ResetReason::LowPower
    } else if csr & IWDGRSTF != 0 {
        ResetReason::IndependentWatchdog
    } else if csr & WWDGRSTF != 0 {
        ResetReason::WindowWatchdog
    } else if csr & SFTRSTF != 0 {
        ResetReason::Software
    } else if csr & OBLRSTF != 0 {
        ResetReason::OptionBytes
    } else if csr & BORRSTF != 0 {
        ResetReason::PowerOn
    } else if csr & PINRSTF != 0 {
        ResetReason::Pin
    } else {
        ResetReason::Unknown
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_flag_decodes_to_its_reason() {
        assert_eq!(reset_reason(PINRSTF), ResetReason::Pin);
        assert_eq!(reset_reason(BORRSTF | PINRSTF), ResetReason::PowerOn);
        assert_eq!(
            reset_reason(IWDGRSTF | PINRSTF),
            ResetReason::IndependentWatchdog
        );
        assert_eq!(
            reset_reason(WWDGRSTF | PINRSTF),
            ResetReason::WindowWatchdog
        );
        assert_eq!(reset_reason(SFTRSTF | PINRSTF), ResetReason::Software);
        assert_eq!(reset_reason(LPWRRSTF | PINRSTF), ResetReason::LowPower);
        assert_eq!(reset_reason(OBLRSTF | PINRSTF), ResetReason::OptionBytes);
        assert_eq!(reset_reason(0), ResetReason::Unknown);
        // Other bits of the register (LSI, RMVF) do not matter.
        assert_eq!(reset_reason(RMVF | 0x3), ResetReason::Unknown);
    }

    #[test]
    fn a_watchdog_reset_after_power_on_reads_as_the_watchdog() {
        // Flags accumulate until cleared: the specific cause wins over power-on.
        assert_eq!(
            reset_reason(BORRSTF | IWDGRSTF | PINRSTF),
            ResetReason::IndependentWatchdog
        );
    }
}
