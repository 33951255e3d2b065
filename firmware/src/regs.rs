//! The board binary's raw register accesses, the few the HAL does not offer, in one
//! place: the reset flags, the crystal's probe and clock security, the watchdog's debug
//! freeze, the sample timer's trigger output, the ADC DMA's position, and the FDCAN's
//! transceiver delay compensation, error state, last error code, bus-off recovery and
//! transmit buffers (the HAL's transmit path neither keeps a buffer for events nor hands
//! back the CAN FD frames it cancels).

use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM6;
use embassy_stm32::timer::low_level::Timer;
use firmware::supervise::BusState;
use firmware::txqueue::{HW_BUFFERS, TxBuffers, TxFrame, dlc_code};

/// The reset flags (RCC_CSR), cleared so the next boot reports its own. Read before the
/// HAL touches the RCC.
pub fn take_reset_flags() -> u32 {
    let csr = pac::RCC.csr().read().0;
    pac::RCC.csr().modify(|w| w.set_rmvf(true));
    csr
}

/// The ADC's DMA channel (DMA1 channel 1): transfers left before it wraps (CNDTR).
pub fn adc_dma_remaining() -> u16 {
    pac::DMA1.ch(0).ndtr().read().ndt()
}

/// Starts the crystal oscillator and waits up to 10 ms for it (a crystal starts in 2 ms at
/// most); `false`, with the oscillator off again, if it does not. Run on the internal
/// oscillator at reset (16 MHz), before the HAL's clock set-up, which would wait forever.
pub fn hse_starts() -> bool {
    pac::RCC.cr().modify(|w| w.set_hseon(true));
    for _ in 0..100 {
        if pac::RCC.cr().read().hserdy() {
            return true;
        }
        // 100 µs at 16 MHz.
        cortex_m::asm::delay(1_600);
    }
    pac::RCC.cr().modify(|w| w.set_hseon(false));
    false
}

/// Watches the crystal from now on (the clock security system): if it stops, the
/// non-maskable interrupt fires.
pub fn enable_clock_security() {
    pac::RCC.cr().modify(|w| w.set_csson(true));
}

/// Acknowledges a clock failure.
pub fn clear_clock_failure() {
    pac::RCC.cicr().write(|w| w.set_cssc(true));
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

/// FDCAN1's three transmit buffers, run as the Tx queue (the HAL configures queue mode).
pub struct FdcanTx;

/// Words of one transmit buffer element in the G4's message RAM: two header words and
/// 64 data bytes.
const TX_ELEMENT_WORDS: usize = 18;

impl TxBuffers for FdcanTx {
    fn pending(&self) -> u8 {
        let r = pac::FDCAN1.txbrp().read();
        (0..HW_BUFFERS).fold(0, |m, i| m | (u8::from(r.trp(i)) << i))
    }

    fn put_index(&self) -> Option<usize> {
        let q = pac::FDCAN1.txfqs().read();
        (!q.tfqf()).then_some(usize::from(q.tfqpi()))
    }

    fn put(&mut self, index: usize, frame: &TxFrame) {
        let ram = pac::FDCANRAM1;
        let base = index * TX_ELEMENT_WORDS;
        let data = frame.data();
        // T0: standard identifier in bits 28..18, data frame, not extended, ESI 0.
        ram.txbuf(base).write_value(u32::from(frame.id()) << 18);
        // T1: DLC in 19..16, BRS (20) and FDF (21) for CAN FD, no Tx event.
        let fd = u32::from(frame.is_fd());
        let dlc = u32::from(dlc_code(data.len()).unwrap_or(0));
        ram.txbuf(base + 1)
            .write_value(dlc << 16 | fd << 20 | fd << 21);
        for (k, chunk) in data.chunks(4).enumerate() {
            let mut word = [0u8; 4];
            word[..chunk.len()].copy_from_slice(chunk);
            ram.txbuf(base + 2 + k)
                .write_value(u32::from_le_bytes(word));
        }
        pac::FDCAN1.txbar().write(|w| w.set_ar(index, true));
    }

    fn cancel(&mut self, index: usize) {
        pac::FDCAN1.txbcr().write(|w| w.set_cr(index, true));
    }

    fn transmitted(&self) -> u8 {
        let r = pac::FDCAN1.txbto().read();
        (0..HW_BUFFERS).fold(0, |m, i| m | (u8::from(r.to(i)) << i))
    }
}

/// Interrupts when a cancellation finishes (the HAL enables only transmission complete),
/// so the transmit path puts a cancelled frame back and the event that asked for its
/// buffer in at once.
pub fn enable_cancel_interrupt() {
    pac::FDCAN1.txbcie().write(|w| {
        for i in 0..HW_BUFFERS {
            w.set_cfie(i, true);
        }
    });
    pac::FDCAN1.ie().modify(|w| w.set_tcfe(true));
}

/// Acknowledges a finished cancellation (the HAL's interrupt handler does not).
pub fn clear_cancel_interrupt() {
    if pac::FDCAN1.ir().read().tcf() {
        pac::FDCAN1.ir().write(|w| w.set_tcf(true));
    }
}

/// Enables the transceiver delay compensation of FDCAN1's data phase with the secondary
/// sample point `offset` kernel clocks after the measured delay (TDCR.TDCO, filter off):
/// back to initialization with configuration change enabled (DBTP and TDCR are protected),
/// set, and out again. Returns whether the registers read back as set.
pub fn enable_tdc(offset: u8) -> bool {
    let r = pac::FDCAN1;
    r.cccr().modify(|w| w.set_init(true));
    while !r.cccr().read().init() {}
    r.cccr().modify(|w| w.set_cce(true));
    r.tdcr().write(|w| {
        w.set_tdco(offset);
        w.set_tdcf(0);
    });
    r.dbtp().modify(|w| w.set_tdc(true));
    let set = r.dbtp().read().tdc() && r.tdcr().read().tdco() == offset;
    r.cccr().modify(|w| w.set_cce(false));
    r.cccr().modify(|w| w.set_init(false));
    while r.cccr().read().init() {}
    set
}
