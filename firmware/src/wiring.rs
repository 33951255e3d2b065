//! What the board can feed the detector: the channels it has a source for and the clock
//! the sample timer runs from.
//!
//! Shared, as source, by the lib and by `build.rs`, which checks the detector
//! configuration against it (a configuration naming a channel nothing feeds fails the
//! build) and embeds it. Plain constants only, so both can include it.

/// Channels sampled by the ADC, in the ADC's scan order (ranks 1..=4), with the ADC1
/// input each is wired to. The detector configuration names them; the sampler delivers
/// each scan in this order.
pub const ADC_CHANNELS: [&str; 4] = ["force_x", "force_y", "skin_accel", "stress_rate"];

/// Channels fed by the controller's context frame (desired velocity, desired
/// acceleration), in the order of the protocol's `ControllerInputs`.
pub const CONTEXT_CHANNELS: [&str; 4] = ["vel_des_x", "vel_des_y", "acc_des_x", "acc_des_y"];

/// Channels fed by the controller's tip state frame (tip position error x, y).
pub const TIP_STATE_CHANNELS: [&str; 2] = ["pos_err_x", "pos_err_y"];

/// Every channel the firmware can feed, for the build-time check.
pub const ALL_CHANNELS: [&str; 10] = [
    ADC_CHANNELS[0],
    ADC_CHANNELS[1],
    ADC_CHANNELS[2],
    ADC_CHANNELS[3],
    CONTEXT_CHANNELS[0],
    CONTEXT_CHANNELS[1],
    CONTEXT_CHANNELS[2],
    CONTEXT_CHANNELS[3],
    TIP_STATE_CHANNELS[0],
    TIP_STATE_CHANNELS[1],
];

/// The clock of the timer that triggers the ADC (TIM6 on APB1, whose timer clock equals
/// SYSCLK = 170 MHz with the APB1 prescaler at 1), in Hz.
pub const SAMPLE_TIMER_CLOCK_HZ: u32 = 170_000_000;

/// The core clock (SYSCLK, HCLK), in Hz: the unit of the cycle counter.
pub const CORE_CLOCK_HZ: u32 = 170_000_000;

/// The largest sample-rate error accepted at build time, in parts per million: the timer
/// period is a whole number of timer clocks, and the detector's ticks must keep time
/// with the controller's clock.
pub const MAX_RATE_ERROR_PPM: u32 = 100;
