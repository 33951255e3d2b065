//! The state the tasks share, each part with an owner: the detector's tick, the CAN
//! receive state, the board temperature, fault flags latched for the next heartbeat,
//! counters, and the watchdog's check-ins.
//!
//! [`Shared`] holds it all, with nothing public; [`Shared::split`] hands out one handle
//! per task ([`Handles`]), once, and each handle can write only what its task owns:
//!
//! | handle | writes | reads |
//! |---|---|---|
//! | [`SamplerHandle`] | its counters (lost scans, rail and stuck-value episodes), its check-in | the temperature |
//! | [`DetectorHandle`] | the detector's tick, the late and frame-dropped flags, its check-in | every counter, the latched flags (it takes them), the sensor fault |
//!
//! The sampler's and the detector's handles belong to one task on the board (the detector
//! reads each scan itself), kept apart for what each part owns.
//! | [`TemperatureHandle`] | the temperature ([`Watch`]), its counters (sensor errors, timeouts) | — |
//! | [`CanRxHandle`] | its counters (frames, protocol errors) | the detector's tick |
//! | [`BusHandle`] | its counters (bus-off, bus state events), the bus-error flag | — |
//! | [`WatchdogHandle`] | starts the check-in rounds | the check-ins |
//!
//! Each handle is made once, by [`Shared::split`]. Counters have one writer each (the
//! handle of the task that owns the thing counted), so atomics are enough; to everyone
//! else a [`Counter`] is read-only. The CAN receive state ([`RxShared`]) is written by the
//! CAN receive task and read-modified by the detector task once per tick, under a
//! critical-section mutex held only for the few instructions of the receiver's
//! `receive` / `poll` calls.
//!
//! Latched flags are handed over, not read and cleared in two steps: the detector task
//! takes them all at once (an atomic swap) into its handle, where they wait until a
//! heartbeat has reported them. A flag raised after the take, even one already waiting
//! in the handle, stays latched in the shared state for the next heartbeat, whatever
//! the interleaving.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU16, AtomicU32, Ordering};

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::watch::Watch;

use detector_core::{Signal, Tick};
use fingertip_can::{FaultFlags, RxState};

use crate::supervise::{Liveness, Task};
use crate::tmp117::SensorHealth;

/// The mutex flavour shared between tasks (and, for the HAL, interrupts).
pub type RawMutex = CriticalSectionRawMutex;

/// Fault flags raised by any task for the next heartbeat (the flags that mean "since the
/// last heartbeat": overrun, bus error, frame dropped), until the detector task takes
/// them.
#[derive(Debug, Default)]
struct Latch(AtomicU16);

impl Latch {
    const fn new() -> Latch {
        Latch(AtomicU16::new(0))
    }

    fn raise(&self, flags: FaultFlags) {
        self.0.fetch_or(flags.0, Ordering::Relaxed);
    }

    /// Every flag raised since the last take, cleared in the same atomic step: a raise
    /// lands either in this take or in the next.
    fn take(&self) -> FaultFlags {
        FaultFlags(self.0.swap(0, Ordering::Relaxed))
    }
}

/// A counter: read by anyone, written only through the handle of the task that owns the
/// thing counted.
#[derive(Debug, Default)]
pub struct Counter(AtomicU32);

impl Counter {
    const fn new() -> Counter {
        Counter(AtomicU32::new(0))
    }

    /// The value.
    #[inline]
    pub fn get(&self) -> u32 {
        self.0.load(Ordering::Relaxed)
    }

    /// Adds `n`, saturating at `u32::MAX`.
    fn add(&self, n: u32) {
        // One writer, so load + store cannot lose an update.
        self.0
            .store(self.get().saturating_add(n), Ordering::Relaxed);
    }

    /// Sets the value (for counts kept elsewhere and published).
    fn set(&self, v: u32) {
        self.0.store(v, Ordering::Relaxed);
    }
}

/// Everything counted since boot (read-only: each counter's writer is its task's).
#[derive(Debug, Default)]
pub struct Counters {
    /// Scans lost: overwritten in the DMA's ring before the detector read them (sampler).
    pub lost_samples: Counter,
    /// Stuck-at-rail episodes, all channels (sampler).
    pub rail_episodes: Counter,
    /// Stuck-value episodes (a channel frozen mid-scale), all channels (sampler).
    pub stuck_episodes: Counter,
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
    /// Received frames handed to the receiver (CAN receive).
    pub rx_frames: Counter,
}

impl Counters {
    /// CAN error events for the status heartbeat (saturating).
    pub fn bus_errors(&self) -> u32 {
        self.bus_state_events
            .get()
            .saturating_add(self.rx_protocol_errors.get())
    }

    const fn new() -> Counters {
        Counters {
            lost_samples: Counter::new(),
            rail_episodes: Counter::new(),
            stuck_episodes: Counter::new(),
            sensor_errors: Counter::new(),
            sensor_timeouts: Counter::new(),
            bus_off: Counter::new(),
            bus_state_events: Counter::new(),
            rx_protocol_errors: Counter::new(),
            rx_frames: Counter::new(),
        }
    }
}

/// The board temperature as the temperature task last published it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Temperature {
    /// °C; `None` until the first reading and while the sensor is faulty.
    pub celsius: Option<Signal>,
    /// The sensor is faulty.
    pub sensor_fault: bool,
}

/// The temperature: one sender (the temperature task); readers take the newest value
/// without waiting (`None` before the first).
type TemperatureWatch = Watch<RawMutex, Temperature, 1>;

/// The CAN receive state, under a critical-section mutex: the receive task writes it,
/// the detector task polls it once per tick.
pub struct RxShared(Mutex<RawMutex, RefCell<RxState>>);

impl Default for RxShared {
    fn default() -> Self {
        RxShared::new()
    }
}

impl RxShared {
    /// Nothing received.
    pub fn new() -> RxShared {
        RxShared(Mutex::new(RefCell::new(RxState::new())))
    }

    /// Runs `f` on the receive state, under the mutex (keep `f` short).
    pub fn with<R>(&self, f: impl FnOnce(&mut RxState) -> R) -> R {
        self.0.lock(|rx| f(&mut rx.borrow_mut()))
    }
}

/// The shared state, created once at boot (the receive state has no `const`
/// constructor) and [split](Shared::split) into the tasks' handles.
pub struct Shared {
    /// The tick the detector is at: the clock the CAN receive task stamps frames with.
    /// Not the newest tick sampled, which runs up to a queue's length ahead: a frame
    /// stamped after the tick being judged has a negative age, which the receiver reads
    /// as stale.
    now: AtomicU32,
    rx: RxShared,
    temperature: TemperatureWatch,
    latched: Latch,
    counters: Counters,
    liveness: Liveness,
}

impl Default for Shared {
    fn default() -> Self {
        Shared::new()
    }
}

/// Every task's handle on the [`Shared`] state.
pub struct Handles<'a> {
    /// The sampler's.
    pub sampler: SamplerHandle<'a>,
    /// The detector task's.
    pub detector: DetectorHandle<'a>,
    /// The temperature task's.
    pub temperature: TemperatureHandle<'a>,
    /// The CAN receive task's.
    pub can_rx: CanRxHandle<'a>,
    /// The CAN supervisor's.
    pub bus: BusHandle<'a>,
    /// The watchdog task's.
    pub watchdog: WatchdogHandle<'a>,
}

impl Shared {
    /// The state at boot.
    pub fn new() -> Shared {
        Shared {
            now: AtomicU32::new(0),
            rx: RxShared::new(),
            temperature: Watch::new(),
            latched: Latch::new(),
            counters: Counters::new(),
            liveness: Liveness::new(),
        }
    }

    /// The tasks' handles. Borrowing the state mutably for as long as the handles live,
    /// it can be split only once: every counter gets one writer.
    pub fn split(&mut self) -> Handles<'_> {
        let s: &Shared = self;
        Handles {
            sampler: SamplerHandle(s),
            detector: DetectorHandle {
                shared: s,
                unreported: FaultFlags(0),
            },
            temperature: TemperatureHandle(s),
            can_rx: CanRxHandle(s),
            bus: BusHandle(s),
            watchdog: WatchdogHandle(s),
        }
    }
}

/// The sampler's handle: the reading of the scans.
pub struct SamplerHandle<'a>(&'a Shared);

impl SamplerHandle<'_> {
    /// The board temperature, °C; `None` before the first reading and while the sensor
    /// is faulty.
    pub fn temperature(&self) -> Option<Signal> {
        self.0.temperature.try_get().and_then(|t| t.celsius)
    }

    /// Publishes the scans lost so far (the sampler's count).
    pub fn set_lost_samples(&mut self, n: u32) {
        self.0.counters.lost_samples.set(n);
    }

    /// Publishes the stuck-at-rail episodes so far (the front end's count).
    pub fn set_rail_episodes(&mut self, n: u32) {
        self.0.counters.rail_episodes.set(n);
    }

    /// Publishes the stuck-value episodes so far (the front end's count).
    pub fn set_stuck_episodes(&mut self, n: u32) {
        self.0.counters.stuck_episodes.set(n);
    }

    /// The sampler is alive.
    pub fn check_in(&self) {
        self.0.liveness.check_in(Task::Sampler);
    }
}

/// The detector task's handle. It holds the latched flags it has taken and no heartbeat
/// has reported yet.
pub struct DetectorHandle<'a> {
    shared: &'a Shared,
    unreported: FaultFlags,
}

impl<'a> DetectorHandle<'a> {
    /// Publishes the tick the detector is at (the CAN receive task's clock).
    pub fn set_now(&mut self, now: Tick) {
        self.shared.now.store(now, Ordering::Relaxed);
    }

    /// The CAN receive state.
    pub fn rx(&self) -> &'a RxShared {
        &self.shared.rx
    }

    /// Every counter, read-only.
    pub fn counters(&self) -> &'a Counters {
        &self.shared.counters
    }

    /// Whether the temperature sensor is faulty (not before its first report).
    pub fn sensor_fault(&self) -> bool {
        self.shared
            .temperature
            .try_get()
            .is_some_and(|t| t.sensor_fault)
    }

    /// The flags latched and not yet reported, for the heartbeat about to be built:
    /// takes the flags raised since the last call out of the shared state and adds them
    /// to those still unreported. Call it once per heartbeat built, and
    /// [`clear_reported`](DetectorHandle::clear_reported) with what that heartbeat
    /// reported before calling it again.
    pub fn latched(&mut self) -> FaultFlags {
        self.unreported = self.unreported | self.shared.latched.take();
        self.unreported
    }

    /// Latches `flags` for the next heartbeat.
    pub fn raise(&self, flags: FaultFlags) {
        self.shared.latched.raise(flags);
    }

    /// A heartbeat reported `flags` (as [`latched`](DetectorHandle::latched) returned
    /// them): they are no longer unreported. A flag raised since that call is still in
    /// the shared state, untouched, for the next heartbeat.
    pub fn clear_reported(&mut self, flags: FaultFlags) {
        self.unreported.0 &= !flags.0;
    }

    /// The detector is alive.
    pub fn check_in(&self) {
        self.shared.liveness.check_in(Task::Detector);
    }
}

/// The temperature task's handle.
pub struct TemperatureHandle<'a>(&'a Shared);

impl TemperatureHandle<'_> {
    /// Publishes the sensor's state: the temperature to use (none while faulty), the
    /// fault, and the error counts.
    pub fn publish(&mut self, health: &SensorHealth) {
        self.0.temperature.sender().send(Temperature {
            celsius: health.temperature(),
            sensor_fault: health.is_faulty(),
        });
        let c = &self.0.counters;
        c.sensor_errors.set(health.errors().total());
        c.sensor_timeouts.set(health.errors().timeout);
    }
}

/// The CAN receive task's handle.
pub struct CanRxHandle<'a>(&'a Shared);

impl<'a> CanRxHandle<'a> {
    /// The tick the detector is at: the stamp for a received frame.
    pub fn now(&self) -> Tick {
        self.0.now.load(Ordering::Relaxed)
    }

    /// The CAN receive state.
    pub fn rx(&self) -> &'a RxShared {
        &self.0.rx
    }

    /// A frame was handed to the receiver.
    pub fn frame_received(&mut self) {
        self.0.counters.rx_frames.add(1);
    }

    /// The receive path saw a protocol error.
    pub fn protocol_error(&mut self) {
        self.0.counters.rx_protocol_errors.add(1);
    }
}

/// The CAN supervisor's handle.
pub struct BusHandle<'a>(&'a Shared);

impl BusHandle<'_> {
    /// Publishes the bus-off entries so far (the supervisor's count).
    pub fn set_bus_off(&mut self, n: u32) {
        self.0.counters.bus_off.set(n);
    }

    /// Publishes the error-passive and bus-off entries and protocol errors so far.
    pub fn set_state_events(&mut self, n: u32) {
        self.0.counters.bus_state_events.set(n);
    }

    /// Latches a bus error for the next heartbeat.
    pub fn bus_error(&self) {
        self.0.latched.raise(FaultFlags::BUS_ERROR);
    }
}

/// The watchdog task's handle.
pub struct WatchdogHandle<'a>(&'a Shared);

impl WatchdogHandle<'_> {
    /// Whether every task of `required` checked in since the last round; starts a new
    /// round either way.
    pub fn round(&mut self, required: u8) -> bool {
        self.0.liveness.round(required)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latched_flags_survive_until_reported() {
        let mut s = Shared::new();
        let mut h = s.split();
        h.detector.raise(FaultFlags::LATE);
        let seen = h.detector.latched();
        assert_eq!(seen, FaultFlags::LATE);
        // Raised after the heartbeat read the flags: kept for the next one.
        h.bus.bus_error();
        h.detector.clear_reported(seen);
        assert_eq!(h.detector.latched(), FaultFlags::BUS_ERROR);
        h.detector.clear_reported(FaultFlags::BUS_ERROR);
        h.bus.bus_error();
        assert_eq!(h.detector.latched(), FaultFlags::BUS_ERROR);
        // Not reported yet (no heartbeat cleared it): still there at the next look.
        assert_eq!(h.detector.latched(), FaultFlags::BUS_ERROR);
    }

    #[test]
    fn a_flag_raised_again_between_the_read_and_the_clear_is_kept() {
        let mut s = Shared::new();
        let mut h = s.split();
        h.bus.bus_error();
        // A heartbeat is built with the bus-error flag ...
        let reported = h.detector.latched();
        assert_eq!(reported, FaultFlags::BUS_ERROR);
        // ... the bus errs again before the clear: the same flag, raised again ...
        h.bus.bus_error();
        h.detector.clear_reported(reported);
        // ... and the next heartbeat reports it.
        assert_eq!(h.detector.latched(), FaultFlags::BUS_ERROR);
        h.detector.clear_reported(FaultFlags::BUS_ERROR);
        assert_eq!(h.detector.latched(), FaultFlags(0));
    }

    #[test]
    fn counters_saturate_and_each_task_writes_its_own() {
        let mut s = Shared::new();
        let mut h = s.split();
        h.can_rx.frame_received();
        h.sampler.set_lost_samples(u32::MAX);
        h.sampler.set_lost_samples(u32::MAX);
        h.bus.set_state_events(u32::MAX - 1);
        h.can_rx.protocol_error();
        h.can_rx.protocol_error();
        let c = h.detector.counters();
        assert_eq!(c.rx_frames.get(), 1);
        assert_eq!(c.lost_samples.get(), u32::MAX);
        assert_eq!(c.rx_protocol_errors.get(), 2);
        assert_eq!(c.bus_errors(), u32::MAX, "the sum saturates");
        assert_eq!(c.rail_episodes.get(), 0);
        h.sampler.set_stuck_episodes(2);
        h.sampler.set_rail_episodes(1);
        assert_eq!((c.stuck_episodes.get(), c.rail_episodes.get()), (2, 1));
    }

    #[test]
    fn the_temperature_reaches_its_readers() {
        let mut s = Shared::new();
        let mut h = s.split();
        assert_eq!(h.sampler.temperature(), None);
        assert!(!h.detector.sensor_fault());
        let mut health = SensorHealth::new(1);
        health.record::<embedded_hal::i2c::ErrorKind>(Ok(Some(Signal::from_f64(21.5))));
        h.temperature.publish(&health);
        assert_eq!(h.sampler.temperature(), Some(Signal::from_f64(21.5)));
        // Read again: still the newest value.
        assert_eq!(h.sampler.temperature(), Some(Signal::from_f64(21.5)));
        health.record::<embedded_hal::i2c::ErrorKind>(Err(&crate::tmp117::Error::Timeout));
        h.temperature.publish(&health);
        assert_eq!(h.sampler.temperature(), None);
        assert!(h.detector.sensor_fault());
        assert_eq!(h.detector.counters().sensor_timeouts.get(), 1);
    }

    #[test]
    fn the_detectors_tick_is_the_receive_tasks_clock() {
        let mut s = Shared::new();
        let mut h = s.split();
        h.detector.set_now(42);
        assert_eq!(h.can_rx.now(), 42);
        assert!(
            h.can_rx
                .rx()
                .with(|rx| rx.link().controller_time().is_none())
        );
        h.sampler.check_in();
        h.detector.check_in();
        assert!(h.watchdog.round(Task::CRITICAL));
        assert!(!h.watchdog.round(Task::CRITICAL));
    }
}
