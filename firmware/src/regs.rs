//! The board binary's raw register accesses, the few the HAL does not offer, in one
//! place: the reset flags, the watchdog's debug freeze, the sample timer's trigger
//! output, and the FDCAN's error state, last error code and bus-off recovery.

use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM6;
use embassy_stm32::timer::low_level::Timer;
use firmware::supervise::BusState;

/// The reset flags (RCC_CSR), cleared so the next boot reports its own. Read before the
/// HAL touches the RCC.
pub fn take_reset_flags() -> u32 {
    let csr = pac::RCC.csr().read().0;
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    csr
}

/// Keeps the independent watchdog from firing while a debugger holds the core.
pub fn freeze_watchdog_when_halted() {
    pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
}

/// TRGO on every update event of the sample timer: one ADC trigger per period.
pub fn trigger_on_update(timer: &Timer<'static, TIM6>) {
    timer
        .regs_basic()
        .cr2()
        .modify(|w| w.set_mms(pac::timer::vals::Mms::UPDATE));
}

/// The FDCAN's error state, from its protocol status register.
pub struct FdcanStatus {
    /// Error-active, error-passive or bus-off.
    pub state: BusState,
    /// A protocol error happened since the last read (the last error code, which reading
    /// resets: 1..=6 an error, 0 none, 7 no change).
    pub protocol_error: bool,
}

/// Reads FDCAN1's protocol status (and so resets its last error code).
pub fn fdcan_status() -> FdcanStatus {
    let psr = pac::FDCAN1.psr().read();
    let state = if psr.bo() {
        BusState::BusOff
    } else if psr.ep() {
        BusState::ErrorPassive
    } else {
        BusState::ErrorActive
    };
    FdcanStatus {
        state,
        protocol_error: (1..=6).contains(&psr.lec().to_bits()),
    }
}

/// Starts the bus-off recovery: FDCAN1 leaves the initialization state and rejoins after
/// 128 × 11 recessive bits.
pub fn fdcan_recover() {
    pac::FDCAN1.cccr().modify(|w| w.set_init(false));
}
