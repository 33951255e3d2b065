//! The detector task's timing, in core cycles (from the Cortex-M DWT cycle counter on the
//! chip): each tick's computation time and the worst seen ([`TickTiming`]), and each tick's
//! **lateness**, from its sample's conversion to the end of the tick, the worst seen and
//! the ticks over a deadline ([`Lateness`]).
//!
//! The budget of a tick is its period: at 170 MHz and 5 kHz, 34 000 cycles. A tick that
//! ends more than a period after its sample was converted is late: the next sample was
//! already waiting. Late ticks are counted and flagged, and the detector goes on; if it
//! falls a whole scan behind, the scans it can no longer read are counted lost.

/// Cycles available per tick: the core clock over the detector rate (at least 1).
pub const fn budget_cycles(core_hz: u32, rate_hz: u32) -> u32 {
    let b = core_hz / if rate_hz == 0 { 1 } else { rate_hz };
    if b == 0 { 1 } else { b }
}

/// Tick-time statistics.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickTiming {
    budget: u32,
    worst: u32,
    last: u32,
    overruns: u32,
}

impl TickTiming {
    /// Statistics against a budget of `budget_cycles` per tick.
    pub const fn new(budget_cycles: u32) -> TickTiming {
        TickTiming {
            budget: budget_cycles,
            worst: 0,
            last: 0,
            overruns: 0,
        }
    }

    /// One tick took `cycles`; returns whether it overran its budget.
    #[inline]
    pub fn record(&mut self, cycles: u32) -> bool {
        self.last = cycles;
        self.worst = self.worst.max(cycles);
        let over = cycles > self.budget;
        if over {
            self.overruns = self.overruns.saturating_add(1);
        }
        over
    }

    /// The budget, cycles per tick.
    pub const fn budget(&self) -> u32 {
        self.budget
    }

    /// The longest tick so far, cycles.
    pub const fn worst(&self) -> u32 {
        self.worst
    }

    /// The last tick, cycles.
    pub const fn last(&self) -> u32 {
        self.last
    }

    /// Ticks that overran (saturating).
    pub const fn overruns(&self) -> u32 {
        self.overruns
    }
}

/// How late the ticks end: from each sample's conversion to the end of its tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lateness {
    deadline: u32,
    worst: u32,
    late: u32,
}

impl Lateness {
    /// Lateness against a deadline of `deadline_cycles` (a tick period by default).
    pub const fn new(deadline_cycles: u32) -> Lateness {
        Lateness {
            deadline: deadline_cycles,
            worst: 0,
            late: 0,
        }
    }

    /// A tick ended `cycles` after its sample's conversion; returns whether it was late.
    #[inline]
    pub fn record(&mut self, cycles: u32) -> bool {
        self.worst = self.worst.max(cycles);
        let late = cycles > self.deadline;
        if late {
            self.late = self.late.saturating_add(1);
        }
        late
    }

    /// The deadline, cycles.
    pub const fn deadline(&self) -> u32 {
        self.deadline
    }

    /// The latest a tick ended after its sample's conversion, cycles.
    pub const fn worst(&self) -> u32 {
        self.worst
    }

    /// Ticks that ended after their deadline (saturating).
    pub const fn late(&self) -> u32 {
        self.late
    }
}

/// Cycles at `core_hz` (a whole number of MHz, at least 1) to tenths of a microsecond (the
/// status frame's unit), rounded down, saturating at 65535 (6.5535 ms). 32-bit arithmetic
/// only.
pub fn cycles_to_tenths_us(cycles: u32, core_hz: u32) -> u16 {
    let tenths = cycles.saturating_mul(10) / (core_hz / 1_000_000).max(1);
    tenths.min(u32::from(u16::MAX)) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_budget_is_34000_cycles() {
        assert_eq!(budget_cycles(170_000_000, 5000), 34_000);
        assert_eq!(budget_cycles(170_000_000, 0), 170_000_000);
        assert_eq!(budget_cycles(10, 50_000), 1);
    }

    #[test]
    fn worst_and_overruns_are_kept() {
        let mut t = TickTiming::new(34_000);
        assert!(!t.record(12_000));
        assert!(!t.record(34_000));
        assert!(t.record(34_001));
        assert!(!t.record(9_000));
        assert_eq!(
            (t.worst(), t.last(), t.overruns(), t.budget()),
            (34_001, 9_000, 1, 34_000)
        );
    }

    #[test]
    fn cycles_convert_to_tenths_of_microseconds() {
        assert_eq!(cycles_to_tenths_us(34_000, 170_000_000), 2_000);
        assert_eq!(cycles_to_tenths_us(16, 170_000_000), 0);
        assert_eq!(cycles_to_tenths_us(17, 170_000_000), 1);
        assert_eq!(cycles_to_tenths_us(u32::MAX, 170_000_000), u16::MAX);
        assert_eq!(cycles_to_tenths_us(16_000, 16_000_000), 10_000);
        assert_eq!(cycles_to_tenths_us(1_000, 0), 10_000);
    }

    #[test]
    fn lateness_keeps_the_worst_and_counts_the_late() {
        let mut l = Lateness::new(34_000);
        assert!(!l.record(3_000));
        assert!(l.record(34_001));
        assert!(!l.record(34_000));
        assert_eq!((l.worst(), l.late(), l.deadline()), (34_001, 1, 34_000));
    }
}
