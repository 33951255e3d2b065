//! Supervision: which tasks must prove they are alive before the independent watchdog is
//! refreshed, and when to let the CAN controller out of bus-off.

use core::sync::atomic::{AtomicU8, Ordering};

/// A task the watchdog waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Task {
    /// The reading of the ADC's scans (one per tick).
    Sampler = 1 << 0,
    /// The detector (a tick every 200 µs).
    Detector = 1 << 1,
}

impl Task {
    /// The tasks whose silence must end in a watchdog reset: without samples or ticks
    /// there is no detector. The CAN and sensor tasks may legitimately wait (bus-off, a
    /// dead sensor) and report those faults instead.
    pub const CRITICAL: u8 = Task::Sampler as u8 | Task::Detector as u8;
}

/// Check-ins since the watchdog task last looked.
#[derive(Debug, Default)]
pub struct Liveness(AtomicU8);

impl Liveness {
    /// No task checked in.
    pub const fn new() -> Liveness {
        Liveness(AtomicU8::new(0))
    }

    /// `task` is alive.
    #[inline]
    pub fn check_in(&self, task: Task) {
        self.0.fetch_or(task as u8, Ordering::Relaxed);
    }

    /// Whether every task of `required` checked in since the last call; starts a new
    /// round either way.
    pub fn round(&self, required: u8) -> bool {
        self.0.swap(0, Ordering::Relaxed) & required == required
    }
}

/// The CAN controller's error state (ISO 11898-1 fault confinement).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusState {
    /// Error counters below 128: normal.
    ErrorActive,
    /// An error counter at 128 or more: the node may only send passive error flags.
    ErrorPassive,
    /// The transmit error counter passed 255: the controller left the bus.
    BusOff,
}

/// What the CAN supervisor should do now.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusAction {
    /// Nothing.
    Wait,
    /// Start the bus-off recovery (on the FDCAN: clear CCCR.INIT; the controller then
    /// waits for 128 × 11 recessive bits before it rejoins).
    Recover,
}

/// Bus-off recovery with exponential back-off, and the error counts for the status.
///
/// The first recovery starts [`BusSupervisor::FIRST_BACKOFF_MS`] after bus-off; each
/// further bus-off before the bus has been good for [`BusSupervisor::GOOD_RESET_MS`]
/// doubles the wait, up to [`BusSupervisor::MAX_BACKOFF_MS`], so a node with a broken
/// transceiver does not keep disturbing the other fingertips' traffic.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BusSupervisor {
    state: BusState,
    backoff_ms: u32,
    next_attempt_ms: u64,
    good_since_ms: Option<u64>,
    bus_off: u32,
    error_passive: u32,
    recoveries: u32,
}

impl Default for BusSupervisor {
    fn default() -> Self {
        BusSupervisor::new()
    }
}

impl BusSupervisor {
    /// Wait before the first recovery attempt, ms.
    pub const FIRST_BACKOFF_MS: u32 = 10;
    /// Longest wait between attempts, ms.
    pub const MAX_BACKOFF_MS: u32 = 1000;
    /// Error-active time after which the back-off starts over, ms.
    pub const GOOD_RESET_MS: u64 = 1000;

    /// A controller that starts error-active.
    pub const fn new() -> BusSupervisor {
        BusSupervisor {
            state: BusState::ErrorActive,
            backoff_ms: BusSupervisor::FIRST_BACKOFF_MS,
            next_attempt_ms: 0,
            good_since_ms: Some(0),
            bus_off: 0,
            error_passive: 0,
            recoveries: 0,
        }
    }

    /// The controller is in `state` at `now_ms`: what to do.
    pub fn poll(&mut self, now_ms: u64, state: BusState) -> BusAction {
        let entered = state != self.state;
        self.state = state;
        match state {
            BusState::ErrorActive => {
                let since = *self.good_since_ms.get_or_insert(now_ms);
                if now_ms.saturating_sub(since) >= BusSupervisor::GOOD_RESET_MS {
                    self.backoff_ms = BusSupervisor::FIRST_BACKOFF_MS;
                }
                BusAction::Wait
            }
            BusState::ErrorPassive => {
                self.good_since_ms = None;
                if entered {
                    self.error_passive = self.error_passive.saturating_add(1);
                }
                BusAction::Wait
            }
            BusState::BusOff => {
                self.good_since_ms = None;
                if entered {
                    self.bus_off = self.bus_off.saturating_add(1);
                    self.next_attempt_ms = now_ms.saturating_add(u64::from(self.backoff_ms));
                    self.backoff_ms =
                        (self.backoff_ms.saturating_mul(2)).min(BusSupervisor::MAX_BACKOFF_MS);
                    BusAction::Wait
                } else if now_ms >= self.next_attempt_ms {
                    // Still off after an attempt (or waiting for the first): try again
                    // after the current back-off.
                    self.recoveries = self.recoveries.saturating_add(1);
                    self.next_attempt_ms = now_ms.saturating_add(u64::from(self.backoff_ms));
                    BusAction::Recover
                } else {
                    BusAction::Wait
                }
            }
        }
    }

    /// The last state seen.
    pub const fn state(&self) -> BusState {
        self.state
    }

    /// Bus-off entries since boot.
    pub const fn bus_off(&self) -> u32 {
        self.bus_off
    }

    /// Error-passive entries since boot.
    pub const fn error_passive(&self) -> u32 {
        self.error_passive
    }

    /// Recovery attempts since boot.
    pub const fn recoveries(&self) -> u32 {
        self.recoveries
    }

    /// CAN error events for the status frame: error-passive and bus-off entries.
    pub const fn error_events(&self) -> u32 {
        self.bus_off.saturating_add(self.error_passive)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use BusAction::*;
    use BusState::*;

    #[test]
    fn the_watchdog_waits_for_every_critical_task() {
        let l = Liveness::new();
        assert!(!l.round(Task::CRITICAL));
        l.check_in(Task::Sampler);
        assert!(!l.round(Task::CRITICAL));
        l.check_in(Task::Sampler);
        l.check_in(Task::Detector);
        assert!(l.round(Task::CRITICAL));
        // A new round starts empty.
        assert!(!l.round(Task::CRITICAL));
    }

    #[test]
    fn bus_off_recovers_after_the_backoff_which_doubles() {
        let mut s = BusSupervisor::new();
        assert_eq!(s.poll(0, ErrorActive), Wait);
        assert_eq!(s.poll(100, BusOff), Wait);
        assert_eq!(s.poll(105, BusOff), Wait);
        assert_eq!(s.poll(110, BusOff), Recover);
        assert_eq!(s.poll(111, BusOff), Wait);
        assert_eq!(s.poll(112, ErrorActive), Wait);
        // Off again soon after: the next wait is 20 ms.
        assert_eq!(s.poll(200, BusOff), Wait);
        assert_eq!(s.poll(219, BusOff), Wait);
        assert_eq!(s.poll(220, BusOff), Recover);
        // Still off after the attempt: retried after the current back-off (40 ms).
        assert_eq!(s.poll(259, BusOff), Wait);
        assert_eq!(s.poll(260, BusOff), Recover);
        assert_eq!((s.bus_off(), s.recoveries(), s.error_events()), (2, 3, 2));
    }

    #[test]
    fn the_backoff_is_capped_and_starts_over_after_a_good_second() {
        let mut s = BusSupervisor::new();
        let mut t = 0;
        for _ in 0..12 {
            s.poll(t, BusOff);
            t += 1;
            s.poll(t, ErrorActive);
            t += 1;
        }
        assert_eq!(s.backoff_ms, BusSupervisor::MAX_BACKOFF_MS);
        // Good since the last poll of the loop.
        let good = t - 1;
        s.poll(good + 999, ErrorActive);
        assert_eq!(s.backoff_ms, BusSupervisor::MAX_BACKOFF_MS);
        s.poll(good + 1000, ErrorActive);
        assert_eq!(s.backoff_ms, BusSupervisor::FIRST_BACKOFF_MS);
    }

    #[test]
    fn error_passive_entries_are_counted_once_each() {
        let mut s = BusSupervisor::new();
        for t in 0..5 {
            s.poll(t, ErrorPassive);
        }
        s.poll(5, ErrorActive);
        s.poll(6, ErrorPassive);
        assert_eq!(
            (s.error_passive(), s.bus_off(), s.state()),
            (2, 0, ErrorPassive)
        );
    }
}
