//! The state the tasks share: the newest tick, the CAN receive state, the board
//! temperature, fault flags latched for the next heartbeat, counters, and the watchdog's
//! check-ins.
//!
//! Each counter has one writer (the task that owns the thing counted) and is read by the
//! detector task when it fills the status heartbeat; atomics are enough for that. The
//! receive state is written by the CAN receive task and read-modified by the detector
//! task once per tick, under a critical-section mutex held only for the few
//! instructions of the core's `receive` / `poll` calls.

use core::cell::{Cell, RefCell};
use core::sync::atomic::{AtomicBool, AtomicU8, AtomicU32, Ordering};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;

use detector_core::can::{FaultFlags, RxState};
use detector_core::{Signal, Tick};

use crate::supervise::Liveness;

/// The mutex flavour shared between tasks (and, for the HAL, interrupts).
pub type RawMutex = CriticalSectionRawMutex;

/// Fault flags raised by any task and reported, then cleared, by the next heartbeat
/// (the core's flags that mean "since the last heartbeat": overrun, bus error, frame
/// dropped).
#[derive(Debug, Default)]
pub struct Latch(AtomicU8);

impl Latch {
    /// Nothing latched.
    pub const fn new() -> Latch {
        Latch(AtomicU8::new(0))
    }

    /// Raises `flags`.
    #[inline]
    pub fn raise(&self, flags: FaultFlags) {
        self.0.fetch_or(flags.0, Ordering::Relaxed);
    }

    /// The flags raised and not yet reported.
    pub fn peek(&self) -> FaultFlags {
        FaultFlags(self.0.load(Ordering::Relaxed))
    }

    /// Clears `reported` (and only those: a flag raised since the peek stays).
    pub fn clear(&self, reported: FaultFlags) {
        self.0.fetch_and(!reported.0, Ordering::Relaxed);
    }
}

/// A counter with one writer.
#[derive(Debug, Default)]
pub struct Counter(AtomicU32);

impl Counter {
    /// Zero.
    pub const fn new() -> Counter {
        Counter(AtomicU32::new(0))
    }

    /// Adds `n`, saturating at `u32::MAX`.
    #[inline]
    pub fn add(&self, n: u32) {
        // One writer, so load + store cannot lose an update.
        let v = self.0.load(Ordering::Relaxed);
        self.0.store(v.saturating_add(n), Ordering::Relaxed);
    }

    /// Sets the value (for counts kept elsewhere and published).
    #[inline]
    pub fn set(&self, v: u32) {
        self.0.store(v, Ordering::Relaxed);
    }

    /// The value.
    #[inline]
    pub fn get(&self) -> u32 {
        self.0.load(Ordering::Relaxed)
    }
}

/// Everything counted since boot.
#[derive(Debug, Default)]
pub struct Counters {
    /// Scans lost: DMA overruns and scans dropped because the detector's queue was full
    /// (sampler).
    pub lost_samples: Counter,
    /// DMA overruns of the ADC ring buffer (sampler).
    pub adc_overruns: Counter,
    /// Stuck-at-rail episodes, all channels (sampler).
    pub rail_episodes: Counter,
    /// Failed temperature readings (sensor task).
    pub sensor_errors: Counter,
    /// Of those, timeouts (sensor task).
    pub sensor_timeouts: Counter,
    /// Bus-off entries (CAN supervisor).
    pub bus_off: Counter,
    /// Error-passive and bus-off entries, and protocol errors the supervisor saw
    /// (CAN supervisor).
    pub bus_state_events: Counter,
    /// Protocol errors the receive path saw (CAN receive). The FDCAN keeps only the
    /// last protocol error code and clears it when read, so each error is seen by at
    /// most one of the two readers and the sum is a lower bound.
    pub rx_protocol_errors: Counter,
    /// Frames the CAN transmit task could not send (mailbox replaced) (CAN transmit).
    pub tx_lost: Counter,
    /// Received frames handed to the core's receiver (CAN receive).
    pub rx_frames: Counter,
}

impl Counters {
    /// CAN error events for the status heartbeat (saturating).
    pub fn bus_errors(&self) -> u32 {
        self.bus_state_events
            .get()
            .saturating_add(self.rx_protocol_errors.get())
    }

    /// All zero.
    pub const fn new() -> Counters {
        Counters {
            lost_samples: Counter::new(),
            adc_overruns: Counter::new(),
            rail_episodes: Counter::new(),
            sensor_errors: Counter::new(),
            sensor_timeouts: Counter::new(),
            bus_off: Counter::new(),
            bus_state_events: Counter::new(),
            rx_protocol_errors: Counter::new(),
            tx_lost: Counter::new(),
            rx_frames: Counter::new(),
        }
    }
}

/// The shared state. Created once at boot (the receive state has no `const`
/// constructor) and handed to every task as `&'static`.
pub struct Shared {
    /// The tick the detector is at: the clock the CAN receive task stamps frames with.
    /// Not the newest tick sampled, which runs up to a queue's length ahead: a frame
    /// stamped after the tick being judged has a negative age, which the core reads as
    /// stale.
    pub now: AtomicU32,
    /// The core's CAN receive state.
    pub rx: Mutex<RawMutex, RefCell<RxState>>,
    /// The board temperature, °C; `None` until the first reading and while the sensor is
    /// faulty.
    pub temperature: Mutex<RawMutex, Cell<Option<Signal>>>,
    /// The temperature sensor is faulty.
    pub sensor_fault: AtomicBool,
    /// Flags for the next heartbeat.
    pub latched: Latch,
    /// Counters.
    pub counters: Counters,
    /// Watchdog check-ins.
    pub liveness: Liveness,
}

impl Default for Shared {
    fn default() -> Self {
        Shared::new()
    }
}

impl Shared {
    /// The state at boot.
    pub fn new() -> Shared {
        Shared {
            now: AtomicU32::new(0),
            rx: Mutex::new(RefCell::new(RxState::new())),
            temperature: Mutex::new(Cell::new(None)),
            sensor_fault: AtomicBool::new(false),
            latched: Latch::new(),
            counters: Counters::new(),
            liveness: Liveness::new(),
        }
    }

    /// The tick the detector is at.
    pub fn now(&self) -> Tick {
        self.now.load(Ordering::Relaxed)
    }

    /// Runs `f` on the receive state, under the mutex (keep `f` short).
    pub fn with_rx<R>(&self, f: impl FnOnce(&mut RxState) -> R) -> R {
        self.rx.lock(|rx| f(&mut rx.borrow_mut()))
    }

    /// The board temperature.
    pub fn temperature(&self) -> Option<Signal> {
        self.temperature.lock(Cell::get)
    }

    /// Publishes the board temperature.
    pub fn set_temperature(&self, t: Option<Signal>) {
        self.temperature.lock(|c| c.set(t));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latched_flags_survive_until_reported() {
        let l = Latch::new();
        l.raise(FaultFlags::OVERRUN);
        let seen = l.peek();
        // Raised after the heartbeat read the flags: kept for the next one.
        l.raise(FaultFlags::BUS_ERROR);
        l.clear(seen);
        assert_eq!(l.peek(), FaultFlags::BUS_ERROR);
    }

    #[test]
    fn counters_saturate() {
        let c = Counter::new();
        c.add(3);
        c.add(u32::MAX);
        assert_eq!(c.get(), u32::MAX);
        c.set(7);
        assert_eq!(c.get(), 7);
    }

    #[test]
    fn shared_state_round_trips() {
        let s = Shared::new();
        assert_eq!(s.temperature(), None);
        s.set_temperature(Some(Signal::from_f64(21.5)));
        assert_eq!(s.temperature(), Some(Signal::from_f64(21.5)));
        s.now.store(42, Ordering::Relaxed);
        assert_eq!(s.now(), 42);
        assert!(s.with_rx(|rx| rx.link().context().is_none()));
    }
}
