//! The detector task's work for one tick, free of hardware so it runs on the PC: merge
//! the newest analog sample with the controller's context (withheld and flagged faulty
//! when stale), follow the controller's phase, run the core, keep the status, and turn
//! the output into CAN frames (events at once, the decimated confidence stream, the
//! heartbeat) with the protocol's transmitter (`fingertip_can`).
//!
//! The engine is generic over the tick it runs ([`DetectorTick`]): on the board the tick
//! generated for the embedded detector ([`crate::boot::ApproachTick`]), in tests the
//! core's interpreter too. A generated tick belongs to one detector image, and
//! [`Engine::new`] refuses it for any other.
//!
//! A detector loaded at run time ([`crate::load`]) is [staged](Engine::stage) and put in
//! service at the next phase entry the controller commands, or at the next tick after
//! [`Engine::activate`]: within that tick, so no tick is skipped. From then on the
//! engine runs it through the interpreter, from a fresh state, and hands the detector it
//! replaced back ([`Engine::take_retired`]) to be loaded into next.
//!
//! When the detector cannot run (its image rejected, or an engine that cannot be set up
//! for it) the board runs a [`Fallback`] instead: the detector out of service, the
//! heartbeat on the bus with [`FaultFlags::CONFIG_FALLBACK`]. The detector task runs
//! either through one [`Service`].
//!
//! The board's detector task only adds the cycle counter and the queues around
//! [`TickRunner::step`].

use detector_core::{
    Detector, DetectorTick, EventMask, ImageError, Inputs, Level, MAX_CHANNELS, Output, Signal,
    State, Tick,
};
use fingertip_can::service::{DetectorName, Mode, NAME_MAX};
use fingertip_can::{
    BusFormat, CanFrame, ContextPart, FaultFlags, MessageKind, NodeId, NodeIdSource, Receiver,
    ResetReason, RxConfigError, Status, Transmitter, TxConfigError, TxFrames, TxState,
};

use crate::channel_set::ChannelSet;
use crate::load::Staged;
use crate::recorder::Ticked;
use crate::sampling::AdcSample;
use crate::shared::{DetectorHandle, RxShared};
use crate::timing::{Lateness, TickTiming, budget_cycles, cycles_to_tenths_us};
use crate::txqueue::Pushed;
use crate::wiring::{ADC_CHANNELS, CONTEXT_CHANNELS, TIP_STATE_CHANNELS};

/// Where the board's inputs go in the configuration's channel order (`None` for an
/// input the configuration does not use), and how each becomes a sample in its
/// channel's working unit (SI × the channel's `scale`, as
/// [`Detector::sample_from_si`] on the PC).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelMap {
    /// The [`ADC_CHANNELS`], in scan order.
    pub adc: [Option<u8>; ADC_CHANNELS.len()],
    /// The [`CONTEXT_CHANNELS`]: vel_des x, y, acc_des x, y.
    pub context: [Option<u8>; CONTEXT_CHANNELS.len()],
    /// The [`TIP_STATE_CHANNELS`]: pos_err x, y.
    pub tip_state: [Option<u8>; TIP_STATE_CHANNELS.len()],
    /// By configuration channel: steps of 2⁻¹⁶ working unit per step of what feeds it
    /// (a calibrated ADC sample's 2⁻¹⁶ SI unit, a context frame's raw step), Q16.
    pub factor: [i64; MAX_CHANNELS],
}

/// Working 2⁻¹⁶ steps per source step, Q16: `scale` × 2³² / `per_si` (a source counting
/// `per_si` steps per SI unit), rounded to nearest, halves away from zero, and saturated
/// at ±(2⁶³ − 1); NaN gives 0. Exact, in integers: the board has no double-precision unit, and the
/// soft-float routines a double would pull in cost flash.
fn factor(scale: f32, per_si: u32) -> i64 {
    let bits = scale.to_bits();
    let (exponent, fraction) = ((bits >> 23) & 0xff, bits & 0x7f_ffff);
    if exponent == 0xff && fraction != 0 {
        return 0;
    }
    // |scale| = m × 2^e with m below 2²⁴ (an infinity: the largest exponent, saturating).
    let (m, e) = match exponent {
        0 => (u64::from(fraction), -149),
        _ => (u64::from(fraction | 0x80_0000), exponent as i32 - 150),
    };
    let den = u64::from(per_si.max(1));
    // The quotient of n = m × 2^shift by den.
    let shift = e + 32;
    let magnitude = if shift >= 0 {
        // n = (m × 2^s1) × 2^s2, m × 2^s1 below 2⁶⁴. From s2 = 32 on, n / den is at least
        // 2²³ × 2⁷² / 2³²: saturated.
        let s1 = shift.min(40) as u32;
        let s2 = shift as u32 - s1;
        let (q, r) = ((m << s1) / den, (m << s1) % den);
        if s2 >= 32 || q > u64::MAX >> s2 {
            u64::MAX
        } else {
            // r × 2^s2 is below 2³² × 2³¹: the fraction's part, rounded, stays exact.
            (q << s2).saturating_add(((r << s2) + den / 2) / den)
        }
    } else {
        // n / den = m / (den × 2^k); from den × 2^k ≥ 2⁶², above 2m, it rounds to 0.
        let k = shift.unsigned_abs();
        if k + 1 >= den.leading_zeros() {
            0
        } else {
            let d = den << k;
            (m + d / 2) / d
        }
    };
    let magnitude = i64::try_from(magnitude).unwrap_or(i64::MAX);
    if bits >> 31 == 0 {
        magnitude
    } else {
        -magnitude
    }
}

impl ChannelMap {
    /// Looks the board's channels up in a detector's configuration by name, with the
    /// conversion of each into its working unit.
    pub fn resolve(detector: &Detector) -> ChannelMap {
        let find = |name: &&str| detector.channel(name).and_then(|i| u8::try_from(i).ok());
        let mut map = ChannelMap {
            adc: ADC_CHANNELS.each_ref().map(find),
            context: CONTEXT_CHANNELS.each_ref().map(find),
            tip_state: TIP_STATE_CHANNELS.each_ref().map(find),
            factor: [0; MAX_CHANNELS],
        };
        // Steps of each source per SI unit: 2¹⁶ for a calibrated sample, the protocol's
        // for the controller's values.
        let adc = map.adc.map(|slot| (slot, 1 << 16));
        let context = map.context.iter().enumerate().map(|(k, &slot)| {
            let part = if k < 2 {
                ContextPart::Velocity
            } else {
                ContextPart::Acceleration
            };
            (slot, part.per_si())
        });
        let tip = map
            .tip_state
            .map(|slot| (slot, ContextPart::PositionError.per_si()));
        for (slot, per_si) in adc.into_iter().chain(context).chain(tip) {
            let Some(i) = slot.map(usize::from) else {
                continue;
            };
            let scale = detector.channel_scales().get(i).copied().unwrap_or(1.0);
            if let Some(f) = map.factor.get_mut(i) {
                *f = factor(scale, per_si);
            }
        }
        map
    }

    /// A source value (a calibrated sample's bits, or a frame's raw value) as the sample
    /// of configuration channel `i`, rounded to nearest and saturated.
    pub fn convert(&self, i: usize, source: i64) -> Signal {
        let f = self.factor.get(i).copied().unwrap_or(0);
        let q = source.saturating_mul(f).saturating_add(1 << 15) >> 16;
        Signal::from_bits(q.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32)
    }

    fn set(slots: &[Option<u8>]) -> ChannelSet {
        slots.iter().flatten().map(|&i| usize::from(i)).collect()
    }

    /// The configuration channels fed by the context frame.
    pub fn context_channels(&self) -> ChannelSet {
        ChannelMap::set(&self.context)
    }

    /// The configuration channels fed by the tip state frame.
    pub fn tip_state_channels(&self) -> ChannelSet {
        ChannelMap::set(&self.tip_state)
    }
}

/// What the board knows of itself at boot, reported in its status.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BoardInfo {
    /// This fingertip's node id.
    pub node: NodeId,
    /// Where the node id came from ([`crate::node_id`]).
    pub node_source: NodeIdSource,
    /// The bus format the firmware was built for.
    pub format: BusFormat,
    /// Why the board last reset (reported in every heartbeat).
    pub reset: ResetReason,
    /// The crystal did not start: the board runs from its internal oscillator
    /// ([`FaultFlags::CLOCK_FALLBACK`] in every heartbeat).
    pub clock_fallback: bool,
}

impl BoardInfo {
    /// The status a service starts from: the board's identity, its permanent faults.
    fn status(&self, tick_rate_hz: u16, image_crc: u32, faults: FaultFlags) -> Status {
        let mut status = Status {
            reset: self.reset,
            node_source: self.node_source,
            faults,
            tick_rate_hz,
            config_checksum: image_crc,
            firmware: crate::version::VERSION,
            build: crate::version::BUILD_HASH,
            ..Status::default()
        };
        status
            .faults
            .set(FaultFlags::CLOCK_FALLBACK, self.clock_fallback);
        status
    }
}

/// The engine's fixed parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EngineParams {
    /// The board.
    pub board: BoardInfo,
    /// The CRC-32 of the image the detector was loaded from
    /// ([`crate::checksum::crc32`]): reported in the heartbeat as the configuration's
    /// checksum, and what a generated tick must have been generated for.
    pub image_crc: u32,
    /// Context and tip state go stale this long after their last good frame, ms.
    pub context_timeout_ms: u32,
    /// The phase goes stale this long after its last good frame, ms.
    pub phase_timeout_ms: u32,
}

impl EngineParams {
    /// Context stale after 20 ms (twenty missed frames at the controller's 1 kHz), phase
    /// after 100 ms.
    pub const fn new(board: BoardInfo, image_crc: u32) -> EngineParams {
        EngineParams {
            board,
            image_crc,
            context_timeout_ms: 20,
            phase_timeout_ms: 100,
        }
    }
}

/// The engine cannot be set up for this detector.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EngineError {
    /// The detector rate does not fit the CAN protocol (1..=65535 Hz).
    Rate(f32),
    /// The receiver refused its parameters.
    Receiver(RxConfigError),
    /// The transmitter refused its parameters.
    Transmitter(TxConfigError),
    /// The tick was generated for another detector image than the one loaded.
    TickImage {
        /// The CRC-32 of the image the tick was generated for.
        tick: u32,
        /// The CRC-32 of the image the detector was loaded from.
        loaded: u32,
    },
}

impl core::fmt::Display for EngineError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            EngineError::Rate(r) => write!(f, "detector rate {r} Hz is not within 1..=65535"),
            EngineError::Receiver(e) => write!(f, "CAN receiver: {e}"),
            EngineError::Transmitter(e) => write!(f, "CAN transmitter: {e}"),
            EngineError::TickImage { tick, loaded } => write!(
                f,
                "the tick was generated for image {tick:#010x}, the detector loaded {loaded:#010x}"
            ),
        }
    }
}

/// Why the detector is out of service.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FallbackReason {
    /// The detector image was rejected by the loader.
    Image(ImageError),
    /// The engine cannot be set up for the detector loaded (a tick generated for
    /// another image, a rate or a phase count outside the protocol's).
    Engine(EngineError),
}

impl core::fmt::Display for FallbackReason {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FallbackReason::Image(e) => write!(f, "the detector image was rejected: {e}"),
            FallbackReason::Engine(e) => write!(f, "the engine cannot run the detector: {e}"),
        }
    }
}

/// What the rest of the board reports into the heartbeat, gathered by the detector task.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// Longest time from a sample's conversion to the end of its tick so far, 0.1 µs.
    pub worst_lateness: u16,
    /// Ticks that ended after their deadline since boot.
    pub late_ticks: u32,
    /// Longest tick computation so far, 0.1 µs.
    pub worst_tick: u16,
    /// Scans lost since boot (overwritten before the detector read them).
    pub lost_scans: u32,
    /// CAN error events since boot.
    pub bus_errors: u32,
    /// Frames not sent since boot (refused, pushed out, flushed after bus-off).
    pub tx_dropped: u32,
    /// Flags latched and not yet reported (late, bus error, frame dropped).
    pub latched: FaultFlags,
    /// The temperature sensor is faulty.
    pub sensor_fault: bool,
}

/// The result of one tick.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TickResult {
    /// The core's output.
    pub output: Output,
    /// The frames to send, highest priority first.
    pub frames: TxFrames,
    /// A heartbeat is among the frames: once queued, the latched flags it reported can be
    /// cleared.
    pub heartbeat: bool,
}

/// The flags a heartbeat reports as "since the last heartbeat".
pub const LATCHED_FLAGS: FaultFlags =
    FaultFlags(FaultFlags::LATE.0 | FaultFlags::BUS_ERROR.0 | FaultFlags::TX_DROPPED.0);

/// A detector's name as the status carries it: its bytes, zero-padded.
fn name_bytes(name: &DetectorName) -> [u8; NAME_MAX] {
    let mut b = [0u8; NAME_MAX];
    for (d, s) in b.iter_mut().zip(name.as_bytes()) {
        *d = *s;
    }
    b
}

/// A tick with the detector out of service: the board's health into `status`, and the
/// heartbeat when due (nothing evaluated, nothing decided).
fn heartbeat_only(
    transmitter: &Transmitter,
    tx: &mut TxState,
    status: &mut Status,
    sample: &AdcSample,
    health: &Health,
) -> TickResult {
    report_health(status, health, sample, tx.dropped());
    let output = Output::default();
    let frames = transmitter.tick(tx, sample.tick, &output, status);
    let heartbeat = frames.iter().any(is_status);
    TickResult {
        output,
        frames,
        heartbeat,
    }
}

/// The receiver of a fingertip running `detector` at `rate_hz`: its phase count, the
/// timeouts of `params`.
fn receiver_for(
    detector: &Detector,
    params: &EngineParams,
    rate_hz: u32,
) -> Result<Receiver, EngineError> {
    let phases = u8::try_from(detector.phases().len()).unwrap_or(u8::MAX);
    Receiver::new(
        params.board.node,
        phases,
        ms_to_ticks(params.context_timeout_ms, rate_hz),
        ms_to_ticks(params.phase_timeout_ms, rate_hz),
    )
    .map_err(EngineError::Receiver)
}

fn ms_to_ticks(ms: u32, rate_hz: u32) -> Tick {
    ms.saturating_mul(rate_hz).div_ceil(1000).max(1)
}

/// Whether `frame` is a status heartbeat page.
fn is_status(frame: &CanFrame) -> bool {
    MessageKind::from_raw_id(frame.id().as_raw()).is_some_and(|(k, _)| k == MessageKind::Status)
}

/// Copies the board's health into `status`: counters, the latched flags, the sensor
/// fault (a faulty analog channel of `sample`, or the temperature sensor).
fn report_health(status: &mut Status, health: &Health, sample: &AdcSample, tx_dropped: u32) {
    status.worst_lateness = health.worst_lateness;
    status.late_ticks = health.late_ticks;
    status.worst_tick = health.worst_tick;
    status.lost_scans = health.lost_scans;
    status.bus_errors = health.bus_errors;
    status.tx_dropped = health.tx_dropped.saturating_add(tx_dropped);
    for flag in [
        FaultFlags::LATE,
        FaultFlags::BUS_ERROR,
        FaultFlags::TX_DROPPED,
    ] {
        status.faults.set(flag, health.latched.contains(flag));
    }
    status.faults.set(
        FaultFlags::SENSOR_FAULT,
        !sample.faults.is_empty() || health.sensor_fault,
    );
}

/// The detector task's state and logic, running the tick `T`.
pub struct Engine<'d, T: DetectorTick> {
    detector: &'d mut Detector,
    /// The tick it started with; `None` once a detector loaded at run time is in service
    /// (the interpreter runs it).
    tick: Option<T>,
    params: EngineParams,
    name: DetectorName,
    staged: Option<Staged<'d>>,
    activate: bool,
    retired: Option<&'d mut Detector>,
    /// In the service state: the detector out of service, heartbeats only.
    service: bool,
    state: State,
    map: ChannelMap,
    receiver: Receiver,
    transmitter: Transmitter,
    tx: TxState,
    status: Status,
    applied_phase: Option<(u8, u8)>,
    inputs: Inputs,
    /// Counts fresh starts of the detector's state (another detector, the service state
    /// left): a flight recording is one run of one state.
    generation: u32,
    /// The last tick the detector ran, and the events it confirmed; `None` when the last
    /// tick ran none (the service state).
    last: Option<(Tick, EventMask)>,
}

impl<'d, T: DetectorTick> Engine<'d, T> {
    /// An engine running `tick` for `detector`, with a fresh state (first phase active).
    /// `detector` gives the names, the phases and the rate; `tick` computes: the
    /// interpreter (a [`Detector`] runs any detector) or a tick generated for the image
    /// whose CRC-32 is `params.image_crc`, and for no other
    /// ([`EngineError::TickImage`]).
    pub fn new(
        detector: &'d mut Detector,
        tick: T,
        params: EngineParams,
    ) -> Result<Engine<'d, T>, EngineError> {
        if let Some(generated) = tick.image_crc()
            && generated != params.image_crc
        {
            return Err(EngineError::TickImage {
                tick: generated,
                loaded: params.image_crc,
            });
        }
        Engine::build(detector, Some(tick), params)
    }

    /// An engine running `detector` through the interpreter (a detector loaded at run
    /// time, from the bus or a flash slot), with a fresh state.
    pub fn interpreted(
        detector: &'d mut Detector,
        params: EngineParams,
    ) -> Result<Engine<'d, T>, EngineError> {
        let mut e = Engine::build(detector, None, params)?;
        e.status.mode = Mode::Loaded;
        Ok(e)
    }

    fn build(
        detector: &'d mut Detector,
        tick: Option<T>,
        params: EngineParams,
    ) -> Result<Engine<'d, T>, EngineError> {
        let rate = detector.rate_hz();
        if !(1.0..=65_535.0).contains(&rate) {
            return Err(EngineError::Rate(rate));
        }
        let rate_hz = (rate + 0.5) as u32;
        let board = params.board;
        let receiver = receiver_for(detector, &params, rate_hz)?;
        let transmitter = Transmitter::with_defaults(board.node, board.format, rate_hz)
            .map_err(EngineError::Transmitter)?;
        let status = board.status(rate_hz as u16, params.image_crc, FaultFlags(0));
        Ok(Engine {
            state: detector.new_state(),
            map: ChannelMap::resolve(detector),
            detector,
            receiver,
            transmitter,
            tx: TxState::new(),
            status,
            applied_phase: None,
            inputs: Inputs::default(),
            tick,
            params,
            name: DetectorName::new(),
            staged: None,
            activate: false,
            retired: None,
            service: false,
            generation: 0,
            last: None,
        })
    }

    /// Names the detector in service (reported in the status heartbeat and by the
    /// service channel's identify).
    pub fn with_name(mut self, name: DetectorName) -> Engine<'d, T> {
        self.status.detector_name = name_bytes(&name);
        self.name = name;
        self
    }

    /// Raises [`FaultFlags::CONFIG_FALLBACK`] in every heartbeat: a detector saved in
    /// flash was chosen but none is whole, and this one runs in its place.
    pub fn with_config_fallback(mut self) -> Engine<'d, T> {
        self.status.faults.set(FaultFlags::CONFIG_FALLBACK, true);
        self
    }

    /// The detector this engine runs.
    pub fn detector(&self) -> &Detector {
        self.detector
    }

    /// The detector in service: what runs it (the tick the engine was made with, or the
    /// interpreter for a detector loaded at run time), its image's CRC-32, its name.
    pub fn in_service(&self) -> (Mode, u32, &DetectorName) {
        let mode = if self.tick.is_some() {
            Mode::BuiltIn
        } else {
            Mode::Loaded
        };
        (mode, self.status.config_checksum, &self.name)
    }

    /// Stages a detector loaded at run time: it goes into service at the next phase
    /// entry, or at the next tick after [`Engine::activate`]. A detector staged before
    /// and not yet in service is handed back, replaced.
    pub fn stage(&mut self, staged: Staged<'d>) -> Option<Staged<'d>> {
        self.staged.replace(staged)
    }

    /// The CRC-32 of the staged detector's image, if one waits.
    pub fn staged_crc(&self) -> Option<u32> {
        self.staged.as_ref().map(|s| s.crc)
    }

    /// Puts the staged detector in service at the next tick, in the phase the
    /// controller last commanded. Returns whether one is staged.
    pub fn activate(&mut self) -> bool {
        self.activate = self.staged.is_some();
        self.activate
    }

    /// Enters (`true`) or leaves the service state. In it the detector is out of
    /// service: no confidence stream, no events, the heartbeat with
    /// [`FaultFlags::SERVICE`]; ticks go on (their frames are the heartbeat's) but the
    /// flash writes it is for stall the CPU, so the detector leaves it from a fresh state,
    /// entering the controller's phase anew.
    pub fn set_service(&mut self, on: bool) {
        if self.service && !on {
            self.state = self.detector.new_state();
            self.applied_phase = None;
            self.generation = self.generation.wrapping_add(1);
        }
        self.service = on;
        self.status.faults.set(FaultFlags::SERVICE, on);
    }

    /// Whether it is in the service state.
    pub fn in_service_state(&self) -> bool {
        self.service
    }

    /// The detector a staged one replaced, to load into next.
    pub fn take_retired(&mut self) -> Option<&'d mut Detector> {
        self.retired.take()
    }

    /// Puts the staged detector in service now, from a fresh state (first phase). The
    /// loader has checked its rate, so the transmitter stays; the receiver follows its
    /// phase count. Nothing happens when nothing is staged.
    fn put_in_service(&mut self) {
        let Some(s) = self.staged.take() else {
            return;
        };
        let rate_hz = u32::from(self.status.tick_rate_hz);
        // A receiver for the new phase count; one with the old count if the new one is
        // refused (it is not: an image holds 1..=8 phases, as the receiver takes).
        if let Ok(r) = receiver_for(s.detector, &self.params, rate_hz) {
            self.receiver = r;
        }
        let old = core::mem::replace(&mut self.detector, s.detector);
        self.retired = Some(old);
        self.tick = None;
        self.state = self.detector.new_state();
        self.generation = self.generation.wrapping_add(1);
        self.map = ChannelMap::resolve(self.detector);
        self.status.config_checksum = s.crc;
        self.status.mode = Mode::Loaded;
        self.status.detector_name = name_bytes(&s.name);
        self.name = s.name;
        // The controller's current phase is entered anew by the new detector.
        self.applied_phase = None;
    }

    /// The receiver (the CAN receive task uses a copy).
    pub fn receiver(&self) -> Receiver {
        self.receiver
    }

    /// Where the board's channels go.
    pub fn channel_map(&self) -> &ChannelMap {
        &self.map
    }

    /// The status as last reported.
    pub fn status(&self) -> &Status {
        &self.status
    }

    /// The detector's state.
    pub fn state(&self) -> &State {
        &self.state
    }

    /// What the last tick gave the flight recorder: its inputs and the state after it,
    /// or `None` when it ran no detector (the service state).
    pub fn ticked(&self) -> Option<Ticked<'_>> {
        let (now, confirmed) = self.last?;
        Some(Ticked {
            now,
            rate_hz: u32::from(self.status.tick_rate_hz),
            crc: self.status.config_checksum,
            generation: self.generation,
            channels: self.detector.channels().len(),
            inputs: &self.inputs,
            state: &self.state,
            confirmed,
        })
    }

    /// One tick on the newest analog sample: its tick is the detector's `now`.
    pub fn tick(&mut self, sample: &AdcSample, rx: &RxShared, health: &Health) -> TickResult {
        let now = sample.tick;
        self.last = None;
        let receiver = self.receiver;
        let status = &mut self.status;
        // Under the receive-state mutex: only the receiver's bookkeeping, no detector work.
        let (controller, phase) = rx.with(|rx| {
            receiver.poll(rx, now);
            status.update_from_rx(&receiver, rx, now);
            (receiver.inputs(rx, now), rx.link().phase())
        });

        if self.service {
            return heartbeat_only(
                &self.transmitter,
                &mut self.tx,
                &mut self.status,
                sample,
                health,
            );
        }
        // A staged detector takes over at a phase entry, or when asked to, in this tick.
        let entering = phase.is_some_and(|p| self.applied_phase != Some((p.phase, p.sequence)));
        if entering || self.activate {
            self.activate = false;
            self.put_in_service();
        }
        // Follow the controller's phase command (a new phase, or the same phase started
        // again under a new sequence number).
        if let Some(p) = phase {
            let key = (p.phase, p.sequence);
            if self.applied_phase != Some(key) {
                if let Some(id) = self.detector.phase_at(p.phase) {
                    self.detector.set_phase(&mut self.state, id);
                }
                self.applied_phase = Some(key);
            }
        }

        let map = &self.map;
        let samples = &mut self.inputs.samples;
        let mut faults = ChannelSet::EMPTY;
        let mut put = |slot: Option<u8>, value: Option<i64>| {
            if let Some(i) = slot {
                let i = usize::from(i);
                match (samples.get_mut(i), value) {
                    (Some(s), Some(v)) => *s = map.convert(i, v),
                    // Withheld: keep the last value (the core ignores it) and flag it.
                    _ => faults.insert(i),
                }
            }
        };
        for (k, (&slot, &value)) in map.adc.iter().zip(&sample.values).enumerate() {
            put(
                slot,
                (!sample.faults.contains(k)).then_some(i64::from(value.to_bits())),
            );
        }
        let vel = controller.vel_des;
        let acc = controller.acc_des;
        for (k, &slot) in map.context.iter().enumerate() {
            let v = match k {
                0 | 1 => vel.and_then(|v| v.get(k).copied()),
                _ => acc.and_then(|a| a.get(k - 2).copied()),
            };
            put(slot, v.map(i64::from));
        }
        for (k, &slot) in map.tip_state.iter().enumerate() {
            put(
                slot,
                controller
                    .pos_err
                    .and_then(|p| p.get(k).copied())
                    .map(i64::from),
            );
        }

        self.inputs.faults = faults.into();

        let mut output = Output::default();
        match &self.tick {
            Some(t) => t.tick_into(&mut self.state, now, &self.inputs, &mut output),
            None => self
                .detector
                .tick_into(&mut self.state, now, &self.inputs, &mut output),
        }
        let confirmed = output
            .decisions
            .iter()
            .filter(|d| d.level == Level::Confirm)
            .fold(0, |m: EventMask, d| m | 1 << (d.event.0 & 7));
        self.last = Some((now, confirmed));

        report_health(&mut self.status, health, sample, self.tx.dropped());
        let frames = self
            .transmitter
            .tick(&mut self.tx, now, &output, &self.status);
        let heartbeat = frames.iter().any(is_status);
        TickResult {
            output,
            frames,
            heartbeat,
        }
    }
}

/// The board with its detector out of service: no confidence stream, no events, and
/// nothing received (context, tip state and phase are not read); the heartbeat goes on
/// at its period with [`FaultFlags::CONFIG_FALLBACK`] set, the reset reason, the board's
/// own faults (sensors, overruns, bus errors, dropped frames), the sample rate as the
/// tick rate, no phase, and as the configuration checksum the CRC-32 of the image it
/// could not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fallback {
    transmitter: Transmitter,
    tx: TxState,
    status: Status,
}

impl Fallback {
    /// Heartbeats through `transmitter` (its heartbeat period is in samples), reporting
    /// `params`' reset reason and image CRC-32 and a tick rate of `rate_hz` (the sample
    /// rate, saturating at 65535).
    pub fn new(transmitter: Transmitter, params: &EngineParams, rate_hz: u32) -> Fallback {
        Fallback {
            transmitter,
            tx: TxState::new(),
            status: Status {
                mode: Mode::Fallback,
                ..params.board.status(
                    u16::try_from(rate_hz).unwrap_or(u16::MAX),
                    params.image_crc,
                    FaultFlags::CONFIG_FALLBACK,
                )
            },
        }
    }

    /// The status as last reported.
    pub fn status(&self) -> &Status {
        &self.status
    }

    /// One sample: the board's health into the status, and the heartbeat when due (the
    /// output is empty: nothing evaluated, nothing decided).
    pub fn tick(&mut self, sample: &AdcSample, health: &Health) -> TickResult {
        heartbeat_only(
            &self.transmitter,
            &mut self.tx,
            &mut self.status,
            sample,
            health,
        )
    }
}

/// What the detector task runs: the engine, or the fallback when the detector could not
/// be put in service.
// One instance, in a static, and no heap to box the engine in: the size is the engine's
// either way.
#[allow(clippy::large_enum_variant)]
pub enum Service<'d, T: DetectorTick> {
    /// The detector runs.
    Running(Engine<'d, T>),
    /// The detector is out of service, and why.
    Fallback(Fallback, FallbackReason),
}

impl<'d, T: DetectorTick> Service<'d, T> {
    /// The detector, when it runs.
    pub fn detector(&self) -> Option<&Detector> {
        match self {
            Service::Running(e) => Some(e.detector()),
            Service::Fallback(..) => None,
        }
    }

    /// The receiver for the CAN receive task, when the detector runs (the fallback
    /// reads nothing).
    pub fn receiver(&self) -> Option<Receiver> {
        match self {
            Service::Running(e) => Some(e.receiver()),
            Service::Fallback(..) => None,
        }
    }

    /// Why the detector is out of service; `None` while it runs.
    pub fn fallback_reason(&self) -> Option<FallbackReason> {
        match self {
            Service::Running(_) => None,
            Service::Fallback(_, reason) => Some(*reason),
        }
    }

    /// The status as last reported.
    pub fn status(&self) -> &Status {
        match self {
            Service::Running(e) => e.status(),
            Service::Fallback(f, _) => f.status(),
        }
    }

    /// Samples (ticks) per second.
    pub fn rate_hz(&self) -> u32 {
        u32::from(self.status().tick_rate_hz)
    }

    /// One tick on the newest analog sample ([`Engine::tick`] or [`Fallback::tick`]).
    pub fn tick(&mut self, sample: &AdcSample, rx: &RxShared, health: &Health) -> TickResult {
        match self {
            Service::Running(e) => e.tick(sample, rx, health),
            Service::Fallback(f, _) => f.tick(sample, health),
        }
    }
}

/// The detector task's bookkeeping around [`Service::tick`]: publishing the tick, timing
/// its computation and its lateness (from the sample's conversion to the end of the tick,
/// frames queued and in the transmit buffers included), flagging late ticks, lost scans
/// and frames not sent, and clearing the latched flags a heartbeat reported (once its
/// frames are queued). The board supplies the cycle counter and the transmit path
/// ([`crate::txqueue`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickRunner {
    timing: TickTiming,
    lateness: Lateness,
    core_hz: u32,
    worst_tenths: u16,
    worst_late_tenths: u16,
    lost_scans: u32,
    /// Frames the transmit path had not sent (refused, pushed out, flushed) as of the
    /// last tick.
    tx_lost: u32,
}

impl TickRunner {
    /// Bookkeeping for a detector at `rate_hz` on a core clocked at `core_hz`; a tick is
    /// late when it ends more than one period after its sample's conversion.
    pub const fn new(core_hz: u32, rate_hz: u32) -> TickRunner {
        let period = budget_cycles(core_hz, rate_hz);
        TickRunner {
            timing: TickTiming::new(period),
            lateness: Lateness::new(period),
            core_hz,
            worst_tenths: 0,
            worst_late_tenths: 0,
            lost_scans: 0,
            tx_lost: 0,
        }
    }

    /// One tick on `sample` (its `converted_at` on the same cycle counter). `cycles` reads
    /// the free-running cycle counter (it may wrap); `send` queues the tick's frames on the
    /// transmit path and says what it did with them
    /// ([`TxScheduler::push`](crate::txqueue::TxScheduler::push), then a pump).
    pub fn step<T: DetectorTick>(
        &mut self,
        service: &mut Service<'_, T>,
        sample: &AdcSample,
        shared: &mut DetectorHandle<'_>,
        cycles: impl Fn() -> u32,
        send: impl FnOnce(&[CanFrame]) -> Pushed,
    ) -> TickResult {
        // The receive task stamps frames with this tick: never newer than the tick being
        // judged (the receiver would read a negative age as stale).
        shared.set_now(sample.tick);
        let start = cycles();
        let counters = shared.counters();
        let lost_scans = counters.lost_samples.get();
        if lost_scans != self.lost_scans {
            self.lost_scans = lost_scans;
            shared.raise(FaultFlags::LATE);
        }
        let health = Health {
            worst_lateness: self.worst_late_tenths,
            late_ticks: self.lateness.late(),
            worst_tick: self.worst_tenths,
            lost_scans,
            bus_errors: counters.bus_errors(),
            tx_dropped: self.tx_lost,
            latched: shared.latched(),
            sensor_fault: shared.sensor_fault(),
        };
        let result = service.tick(sample, shared.rx(), &health);
        let pushed = send(&result.frames);
        // Frames refused now, or lost since (flushed after bus-off): flagged.
        if pushed.lost != self.tx_lost {
            self.tx_lost = pushed.lost;
            shared.raise(FaultFlags::TX_DROPPED);
        }
        // A heartbeat the queue refused reported nothing: its flags wait for the next.
        if result.heartbeat && !pushed.status_lost {
            shared.clear_reported(FaultFlags(health.latched.0 & LATCHED_FLAGS.0));
        }
        let end = cycles();
        let previous = (self.timing.worst(), self.lateness.worst());
        self.timing.record(end.wrapping_sub(start));
        if self.lateness.record(end.wrapping_sub(sample.converted_at)) {
            shared.raise(FaultFlags::LATE);
        }
        if self.timing.worst() != previous.0 {
            self.worst_tenths = cycles_to_tenths_us(self.timing.worst(), self.core_hz);
        }
        if self.lateness.worst() != previous.1 {
            self.worst_late_tenths = cycles_to_tenths_us(self.lateness.worst(), self.core_hz);
        }
        shared.check_in();
        result
    }

    /// The ticks' lateness so far.
    pub const fn lateness(&self) -> &Lateness {
        &self.lateness
    }

    /// The tick timing so far.
    pub const fn timing(&self) -> &TickTiming {
        &self.timing
    }

    /// Frames the transmit path had not sent as of the last tick (refused, pushed out,
    /// flushed).
    pub const fn tx_lost(&self) -> u32 {
        self.tx_lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::boot::{self, ApproachTick};
    use crate::checksum::crc32;
    use crate::shared::Shared;
    use detector_core::{Level, Signal};
    use fingertip_can::{
        Address, ContextGroup, ContextMsg, ContextPart, ContextPartMsg, ContextSlot, Counter,
        EventMsg, Message, PhaseMsg, StatusPage,
    };

    /// The factor, worked out in 128-bit integers: m × 2^shift / den rounded half up.
    fn exact_factor(scale: f32, per_si: u32) -> i64 {
        if scale.is_nan() {
            return 0;
        }
        if scale.is_infinite() {
            return if scale > 0.0 { i64::MAX } else { -i64::MAX };
        }
        let bits = scale.to_bits();
        let (exponent, fraction) = ((bits >> 23) & 0xff, bits & 0x7f_ffff);
        let (m, e) = match exponent {
            0 => (u128::from(fraction), -149),
            _ => (u128::from(fraction | 0x80_0000), exponent as i32 - 150),
        };
        let den = u128::from(per_si.max(1));
        let shift = e + 32;
        let magnitude = if shift >= 0 {
            if shift > 100 {
                u128::MAX
            } else {
                ((m << shift) + den / 2) / den
            }
        } else if shift < -100 {
            0
        } else {
            let d = den << shift.unsigned_abs();
            (m + d / 2) / d
        };
        let magnitude = i64::try_from(magnitude).unwrap_or(i64::MAX);
        if scale.is_sign_negative() {
            -magnitude
        } else {
            magnitude
        }
    }

    #[test]
    fn factors_are_the_scales_over_the_steps() {
        // A force in N per 2⁻¹⁶ N; a position error in µm per µm step; m/s² per 2 mm/s².
        assert_eq!(factor(1.0, 1 << 16), 1 << 16);
        assert_eq!(factor(100.0, 1 << 16), 100 << 16);
        assert_eq!(factor(1e6, ContextPart::PositionError.per_si()), 1 << 32);
        assert_eq!(factor(-2.5, ContextPart::Velocity.per_si()), -1_073_742);
        assert_eq!(factor(f32::NAN, 500), 0);
        assert_eq!(factor(f32::INFINITY, 500), i64::MAX);
        assert_eq!(factor(f32::NEG_INFINITY, 500), -i64::MAX);
        assert_eq!(factor(f32::MIN_POSITIVE / 8.0, 1), 0);
        assert_eq!(factor(f32::MAX, 1), i64::MAX);
    }

    proptest::proptest! {
        /// Every bit pattern of a scale, against every source's step and the extremes.
        #[test]
        fn factors_are_exact(
            bits in proptest::prelude::any::<u32>(),
            per_si in proptest::prop_oneof![
                proptest::strategy::Just(1u32),
                proptest::strategy::Just(500),
                proptest::strategy::Just(10_000),
                proptest::strategy::Just(65_536),
                proptest::strategy::Just(1_000_000),
                proptest::strategy::Just(u32::MAX),
                proptest::prelude::any::<u32>(),
            ],
        ) {
            let scale = f32::from_bits(bits);
            proptest::prop_assert_eq!(factor(scale, per_si), exact_factor(scale, per_si));
        }

        /// Scales of the working range (powers of ten from 10⁻³ to 10⁷), as the double
        /// precision product gave them.
        #[test]
        fn factors_agree_with_double_precision(
            mantissa in 1.0f32..10.0,
            decade in -3i32..7,
            per_si in proptest::prop_oneof![
                proptest::strategy::Just(500u32),
                proptest::strategy::Just(10_000),
                proptest::strategy::Just(65_536),
                proptest::strategy::Just(1_000_000),
            ],
        ) {
            let scale = mantissa * 10f32.powi(decade);
            let x = f64::from(scale) / f64::from(per_si) * 65536.0 * 65536.0;
            let want = (x + 0.5f64.copysign(x)) as i64;
            proptest::prop_assert!((factor(scale, per_si) - want).abs() <= 1);
        }
    }

    /// A small configuration of our own, so these tests check the plumbing whatever the
    /// tuning of `configs/approach.toml`. Channels in an order unlike the board's.
    const TEST_CONFIG: &str = r#"
        rate_hz = 5000.0
        channel = [
            { name = "vel_des_x", unit = "m/s" }, { name = "vel_des_y", unit = "m/s" },
            { name = "skin_accel", unit = "m/s^2" }, { name = "force_x", unit = "N" },
            { name = "acc_des_x", unit = "m/s^2" }, { name = "acc_des_y", unit = "m/s^2" },
            { name = "pos_err_x", unit = "m" }, { name = "pos_err_y", unit = "m" },
        ]
        feature = [
            { name = "push", stage = { raw = { input = "force_x" } } },
            { name = "speed", stage = { magnitude = { of = ["vel_des_x", "vel_des_y"] } } },
            { name = "err", stage = { raw = { input = "pos_err_x" } } },
            { name = "vib", stage = { abs = { input = "skin_accel" } } },
            { name = "acc", stage = { magnitude = { of = ["acc_des_x", "acc_des_y"] } } },
        ]
        [[event]]
        name = "press"
        context = [{ feature = "speed", cdf = { sigmoid = { low = 0.002, high = 0.008 } } }]
        sensor = [{ feature = "push", weight = 1.0, cdf = { binary = { threshold = -0.5, above = false } } }]
        alert = { on = 0.5, off = 0.3 }
        confirm = { on = 0.75, off = 0.5 }
        [[event]]
        name = "bump"
        context = [{ feature = "acc", cdf = { bell = { center = 0.0, half_width = 2.0 } } }]
        sensor = [
            { feature = "vib", weight = 0.5, cdf = { binary = { threshold = 10.0, above = true } } },
            { feature = "err", weight = 0.5, cdf = { binary = { threshold = 0.001, above = true } } },
        ]
        alert = { on = 0.5, off = 0.3 }
        confirm = { on = 0.75, off = 0.5 }
        [[phase]]
        name = "approach"
        events = ["press", "bump"]
        [[phase]]
        name = "hold"
        events = ["bump"]
    "#;

    const PRESS: u8 = 0b01;
    const BUMP: u8 = 0b10;

    fn config() -> detector_build::Config {
        detector_build::Config::from_toml(TEST_CONFIG).expect("test config")
    }

    fn detector() -> Detector {
        detector_build::build(&config()).expect("builds")
    }

    /// A detector of its own for an engine, alive to the end of the test.
    fn leak(d: &Detector) -> &'static mut Detector {
        Box::leak(Box::new(d.clone()))
    }

    /// An engine running the interpreter on `d`.
    fn engine(d: &Detector) -> Engine<'_, Detector> {
        Engine::new(leak(d), d.clone(), params()).unwrap()
    }

    /// The embedded detector, loaded as the board loads it.
    fn embedded() -> Box<Detector> {
        let mut d = Box::new(Detector::empty());
        boot::load_detector(&mut d, boot::DETECTOR_IMAGE).unwrap();
        d
    }

    /// The parameters of the board's engine: the embedded image's CRC.
    fn board_params() -> EngineParams {
        EngineParams::new(board(), crc32(boot::DETECTOR_IMAGE))
    }

    fn node() -> NodeId {
        NodeId::new(3).unwrap()
    }

    /// The board of these tests: node 3 from its straps, after a power-on reset.
    fn board() -> BoardInfo {
        BoardInfo {
            node: node(),
            node_source: NodeIdSource::Straps,
            format: BusFormat::Fd,
            reset: ResetReason::PowerOn,
            clock_fallback: false,
        }
    }

    fn params() -> EngineParams {
        EngineParams::new(board(), 0xDEAD_BEEF)
    }

    /// An analog sample: force_x, force_y, skin_accel, stress_rate.
    fn sample(tick: Tick, force_x: f64, skin_accel: f64) -> AdcSample {
        let mut s = AdcSample {
            tick,
            ..AdcSample::default()
        };
        s.values[0] = Signal::from_f64(force_x);
        s.values[2] = Signal::from_f64(skin_accel);
        s
    }

    /// Hands a frame to the receive state as the CAN receive task does.
    fn deliver<T: DetectorTick>(rx: &RxShared, engine: &Engine<'_, T>, now: Tick, frame: CanFrame) {
        let r = engine.receiver();
        rx.with(|rx| r.receive(rx, now, frame.id().into(), frame.data()))
            .expect("accepted");
    }

    /// The broadcast context frame of the node's group, sent at tick `now` (the
    /// controller's clock in step), with the node's slot: velocity `vx` (m/s) and position
    /// error `x` (m) along the normal.
    fn context(now: Tick, counter: u8, vx: f64, x: f64) -> CanFrame {
        let mut m = ContextMsg {
            counter: Counter(counter),
            time_us: now.wrapping_mul(200),
            ..ContextMsg::default()
        };
        m.slots[ContextGroup::slot_of(node())] = Some(ContextSlot {
            vel_des: [(vx / 1e-4) as i16, 0],
            acc_des: [0, 0],
            pos_err: [(x / 1e-6) as i16, 0],
        });
        m.encode(ContextGroup::of(node())).unwrap()
    }

    /// A classic context part frame for the node.
    fn part(counter: u8, part: ContextPart, value: [i16; 2]) -> CanFrame {
        ContextPartMsg {
            counter: Counter(counter),
            part,
            value,
        }
        .encode(node())
        .unwrap()
    }

    fn phase(counter: u8, index: u8, sequence: u8) -> CanFrame {
        PhaseMsg {
            counter: Counter(counter),
            phase: index,
            sequence,
        }
        .encode(node())
        .unwrap()
    }

    fn decode(frames: &TxFrames) -> Vec<Message> {
        frames
            .iter()
            .map(|f| {
                let (n, m) = Message::decode(f.id().into(), f.data()).expect("our frames decode");
                assert_eq!(n, Address::Node(node()));
                m
            })
            .collect()
    }

    /// The status pages among `frames`.
    fn status_pages(frames: &TxFrames) -> Vec<StatusPage> {
        decode(frames)
            .into_iter()
            .filter_map(|m| match m {
                Message::Status(s) => Some(s.page),
                _ => None,
            })
            .collect()
    }

    fn events(frames: &TxFrames) -> Vec<EventMsg> {
        decode(frames)
            .into_iter()
            .filter_map(|m| match m {
                Message::Event(e) => Some(e),
                _ => None,
            })
            .collect()
    }

    /// Fresh context (5 cm/s, no position error) at `now`.
    fn fresh<T: DetectorTick>(shared: &RxShared, e: &Engine<'_, T>, now: Tick, counter: u8) {
        deliver(shared, e, now, context(now, counter, 0.05, 0.0));
    }

    /// The test configuration with the press event's threshold at `threshold` N, as an
    /// image.
    fn image_with_threshold(threshold: f64) -> Vec<u8> {
        let toml = TEST_CONFIG.replace("threshold = -0.5", &format!("threshold = {threshold}"));
        let config = detector_build::Config::from_toml(&toml).expect("test config");
        detector_build::compile(&config).expect("compiles").image()
    }

    /// Runs `e` over ticks `ticks` with a push of `force` N and fresh context; the
    /// outputs.
    fn push<T: DetectorTick>(
        e: &mut Engine<'_, T>,
        rx: &RxShared,
        ticks: core::ops::Range<Tick>,
        force: f64,
    ) -> Vec<Output> {
        ticks
            .map(|t| {
                if t % 5 == 0 {
                    fresh(rx, e, t, (t / 5) as u8);
                }
                e.tick(&sample(t, force, 0.0), rx, &Health::default())
                    .output
            })
            .collect()
    }

    #[test]
    fn a_staged_detector_takes_over_at_the_phase_entry_in_that_tick() {
        let d = detector();
        let mut e = engine(&d).with_name(DetectorName::try_from("test").unwrap());
        let rx = RxShared::new();
        // A detector that needs 2 N to press, where this one needs 0.5.
        let stiff = image_with_threshold(-2.0);
        let mut spare = Detector::empty();
        let mut loader = crate::load::Loader::new(&mut spare, 5000.0);
        let staged = loader.stage("stiff", &stiff).unwrap();
        assert!(e.stage(staged).is_none());
        assert_eq!(e.staged_crc(), Some(crc32(&stiff)));
        // Running on: the old detector presses at 1 N.
        let before = push(&mut e, &rx, 0..50, -1.0);
        assert!(before.iter().all(|o| o.evaluated == PRESS | BUMP));
        assert!(before.iter().any(|o| o.confirmed & PRESS != 0));
        let (mode, crc, name) = e.in_service();
        assert_eq!(
            (mode, crc, name.as_str()),
            (Mode::BuiltIn, 0xDEAD_BEEF, "test")
        );
        // The controller enters phase 1 ("hold") at tick 50: the new detector runs that
        // tick, in that phase.
        deliver(&rx, &e, 50, phase(0, 1, 1));
        let after = push(&mut e, &rx, 50..100, -1.0);
        assert_eq!(
            after[0].evaluated, BUMP,
            "the phase entered by the new detector"
        );
        assert_eq!(e.staged_crc(), None);
        let (mode, crc, name) = e.in_service();
        assert_eq!(
            (mode, crc, name.as_str()),
            (Mode::Loaded, crc32(&stiff), "stiff")
        );
        assert_eq!(e.status().config_checksum, crc32(&stiff));
        // Tick for tick what the new detector computes from a fresh state on the same
        // inputs.
        let mut reference = Detector::empty();
        reference.load_image(&stiff).unwrap();
        let mut fresh_engine = engine(&reference);
        let rx2 = RxShared::new();
        deliver(&rx2, &fresh_engine, 50, phase(0, 1, 1));
        assert_eq!(push(&mut fresh_engine, &rx2, 50..100, -1.0), after);
        // And the detector it replaced comes back to be loaded into next.
        let old = e.take_retired().expect("retired");
        assert_eq!(old.events(), d.events());
        assert!(e.take_retired().is_none());
    }

    /// The status pages a full round of heartbeats from tick `from` sends.
    fn status_round<T: DetectorTick>(
        e: &mut Engine<'_, T>,
        rx: &RxShared,
        from: Tick,
    ) -> Vec<StatusPage> {
        (from..from + 250 * u32::from(fingertip_can::STATUS_PAGES))
            .flat_map(|t| {
                status_pages(&e.tick(&sample(t, 0.0, 0.0), rx, &Health::default()).frames)
            })
            .collect()
    }

    /// The name the detector-name pages spell.
    fn spelled(pages: &[StatusPage]) -> String {
        let mut name = [0u8; 16];
        for p in pages {
            if let StatusPage::DetectorName { part, bytes } = p {
                let at = usize::from(*part) * 4;
                name[at..at + 4].copy_from_slice(bytes);
            }
        }
        String::from_utf8_lossy(&name)
            .trim_end_matches('\0')
            .to_string()
    }

    #[test]
    fn the_heartbeat_tells_the_firmware_and_the_detector_in_service() {
        let d = detector();
        let mut e = engine(&d).with_name(DetectorName::try_from("approach-2026").unwrap());
        let rx = RxShared::new();
        let pages = status_round(&mut e, &rx, 0);
        assert!(pages.contains(&StatusPage::Firmware {
            version: crate::version::VERSION,
            mode: Mode::BuiltIn
        }));
        assert!(pages.contains(&StatusPage::Build {
            hash: crate::version::BUILD_HASH
        }));
        assert_eq!(spelled(&pages), "approach-2026");
        // A loaded detector: its name, its CRC, the interpreter.
        let lax = image_with_threshold(-0.1);
        let mut spare = Detector::empty();
        let mut loader = crate::load::Loader::new(&mut spare, 5000.0);
        e.stage(loader.stage("lax-fit", &lax).unwrap());
        e.activate();
        let pages = status_round(&mut e, &rx, 10_000);
        assert_eq!(spelled(&pages), "lax-fit");
        assert!(pages.contains(&StatusPage::Config {
            checksum: crc32(&lax)
        }));
        assert!(pages.contains(&StatusPage::Firmware {
            version: crate::version::VERSION,
            mode: Mode::Loaded
        }));
    }

    #[test]
    fn activation_puts_it_in_service_at_the_next_tick_in_the_current_phase() {
        let d = detector();
        let mut e = engine(&d);
        let rx = RxShared::new();
        deliver(&rx, &e, 0, phase(0, 1, 1));
        assert!(!e.activate(), "nothing staged");
        push(&mut e, &rx, 0..10, 0.0);
        let lax = image_with_threshold(-0.1);
        let mut spare = Detector::empty();
        let mut loader = crate::load::Loader::new(&mut spare, 5000.0);
        e.stage(loader.stage("lax", &lax).unwrap());
        // Staged, not yet in service: 0.2 N presses nothing.
        let out = push(&mut e, &rx, 10..20, -0.2);
        assert!(out.iter().all(|o| o.confirmed == 0));
        assert!(e.activate());
        let out = push(&mut e, &rx, 20..40, -0.2);
        assert_eq!(e.in_service().1, crc32(&lax));
        // In phase 1, where only "bump" is evaluated: the phase was entered anew.
        assert!(out.iter().all(|o| o.evaluated == BUMP));
        // A phase entry without anything staged changes nothing.
        deliver(&rx, &e, 40, phase(1, 0, 2));
        let out = push(&mut e, &rx, 40..80, -0.2);
        assert_eq!(e.in_service().1, crc32(&lax));
        assert!(out.iter().any(|o| o.confirmed & PRESS != 0));
    }

    #[test]
    fn channels_map_by_name() {
        let d = detector();
        let m = ChannelMap::resolve(&d);
        assert_eq!(m.adc, [Some(3), None, Some(2), None]);
        assert_eq!(m.context, [Some(0), Some(1), Some(4), Some(5)]);
        assert_eq!(m.tip_state, [Some(6), Some(7)]);
        assert_eq!(m.context_channels(), ChannelSet::from_bits(0b11_0011));
        assert_eq!(m.tip_state_channels(), ChannelSet::from_bits(0b1100_0000));
    }

    #[test]
    fn the_default_detector_reads_each_channel_in_its_working_unit() {
        // configs/approach.toml works in cN, µm and mm/s: the board converts the
        // calibrated newtons and the frames' raw steps to those in one rounding, as the
        // PC's replay converts a trace's SI values.
        let d = embedded();
        let mut e = Engine::new(leak(&d), ApproachTick, board_params()).unwrap();
        let shared = RxShared::new();
        deliver(&shared, &e, 0, context(0, 0, 0.05, 12e-6));
        e.tick(&sample(0, -1.25, 2.0), &shared, &Health::default());
        let t = e.ticked().expect("the detector ran");
        let at = |name: &str| t.inputs.samples[d.channel(name).unwrap()];
        assert_eq!(
            at("force_x"),
            d.sample_from_si(d.channel("force_x").unwrap(), -1.25)
        );
        assert_eq!(at("force_x").to_f64(), -125.0, "centinewtons");
        assert_eq!(at("skin_accel").to_f64(), 2.0);
        assert_eq!(at("vel_des_x").to_f64(), 50.0, "mm/s");
        assert_eq!(
            at("pos_err_x"),
            d.sample_from_si(d.channel("pos_err_x").unwrap(), 12e-6),
            "12 µm in the detector's unit: no coarser than the frame's 1 µm"
        );
        assert_eq!(at("pos_err_x").to_f64(), 12.0, "micrometres");
    }

    #[test]
    fn the_embedded_configuration_maps_every_channel() {
        let d = embedded();
        let m = ChannelMap::resolve(&d);
        let fed = m
            .adc
            .iter()
            .chain(&m.context)
            .chain(&m.tip_state)
            .flatten()
            .count();
        assert_eq!(
            fed,
            d.channels().len(),
            "build.rs refuses channels nothing feeds"
        );
        let mut e = Engine::new(leak(&d), ApproachTick, board_params()).unwrap();
        let r = e.tick(&sample(0, 0.0, 0.0), &RxShared::new(), &Health::default());
        assert!(r.output.decisions.is_empty());
        assert!(r.heartbeat);
    }

    #[test]
    fn without_context_the_events_are_unjudgeable_and_the_heartbeat_says_why() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        let r = e.tick(&sample(0, -1.0, 50.0), &shared, &Health::default());
        assert_eq!(r.output.evaluated, PRESS | BUMP);
        assert_eq!(r.output.unjudgeable, PRESS | BUMP);
        assert!(r.output.decisions.is_empty(), "no event is invented");
        // The first tick sends the stream and the heartbeat at once.
        assert!(r.heartbeat);
        let (reset, faults) = status_pages(&r.frames)
            .iter()
            .find_map(|p| match p {
                StatusPage::Health { reset, faults, .. } => Some((*reset, *faults)),
                _ => None,
            })
            .expect("a health page");
        assert_eq!(reset, ResetReason::PowerOn);
        assert!(faults.contains(FaultFlags::CONTEXT_STALE | FaultFlags::TIP_STATE_STALE));
        assert!(faults.contains(FaultFlags::PHASE_STALE));
        assert!(!faults.contains(FaultFlags::SENSOR_FAULT));
    }

    #[test]
    fn a_decision_goes_out_in_the_same_tick_ahead_of_everything_else() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        fresh(&shared, &e, 0, 0);
        let r = e.tick(&sample(0, 0.0, 0.0), &shared, &Health::default());
        assert!(r.output.decisions.is_empty());
        let r = e.tick(&sample(1, -1.0, 0.0), &shared, &Health::default());
        let ev = events(&r.frames);
        assert_eq!(ev.len(), 2, "alert and confirm together: {ev:?}");
        assert!(
            ev.iter()
                .all(|m| m.event == d.event("press").unwrap() && m.tick == 1)
        );
        assert_eq!(
            ev.iter().map(|m| m.level).collect::<Vec<_>>(),
            [Level::Alert, Level::Confirm]
        );
        // Event frames lead the tick's frames.
        let first = decode(&r.frames);
        assert!(matches!(first[0], Message::Event(_)) && matches!(first[1], Message::Event(_)));
    }

    #[test]
    fn stale_context_makes_its_events_unjudgeable_until_fresh_again() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        fresh(&shared, &e, 0, 0);
        // 20 ms at 5 kHz = 100 ticks: fresh up to an age of 100 ticks.
        let r = e.tick(&sample(100, -1.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, 0);
        let r = e.tick(&sample(101, -1.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, PRESS | BUMP);
        assert!(e.status().faults.contains(FaultFlags::CONTEXT_STALE));
        fresh(&shared, &e, 150, 1);
        let r = e.tick(&sample(151, -1.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, 0);
        assert!(!e.status().faults.contains(FaultFlags::CONTEXT_STALE));
        // Context and tip state each went stale once.
        assert_eq!(shared.with(|rx| rx.counts().stale_episodes()), 2);
    }

    #[test]
    fn frames_must_be_stamped_with_the_detectors_tick_not_the_samplers() {
        // Why the receive task stamps frames with the detector's tick
        // (`DetectorHandle::set_now`): a frame stamped with a tick the detector has not
        // judged yet (the sampler runs a block ahead) has a negative age, which reads as
        // stale.
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        fresh(&shared, &e, 14, 0);
        let r = e.tick(&sample(10, 0.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, PRESS | BUMP);
        // And the core latches staleness until the next good frame.
        let r = e.tick(&sample(14, 0.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, PRESS | BUMP);
        fresh(&shared, &e, 14, 1);
        let r = e.tick(&sample(15, 0.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.unjudgeable, 0);
    }

    #[test]
    fn a_stale_tip_state_only_degrades_the_events_that_read_it() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        // Classic CAN: velocity and acceleration came, the position error did not.
        deliver(&shared, &e, 0, part(0, ContextPart::Velocity, [500, 0]));
        deliver(&shared, &e, 0, part(1, ContextPart::Acceleration, [0, 0]));
        let r = e.tick(&sample(1, 0.0, 0.0), &shared, &Health::default());
        // bump reads pos_err_x in one of its two sensor terms.
        assert_eq!((r.output.unjudgeable, r.output.degraded), (0, BUMP));
    }

    #[test]
    fn a_stuck_adc_channel_degrades_or_stops_the_events_that_read_it() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        fresh(&shared, &e, 0, 0);
        let mut s = sample(1, -1.0, 50.0);
        s.faults = ChannelSet::from_bits(0b0100); // skin_accel: one of bump's two sensor terms
        let r = e.tick(&s, &shared, &Health::default());
        assert_eq!((r.output.unjudgeable, r.output.degraded), (0, BUMP));
        assert!(e.status().faults.contains(FaultFlags::SENSOR_FAULT));
        s.faults = ChannelSet::from_bits(0b0001); // force_x: press's only sensor term
        let r = e.tick(&s, &shared, &Health::default());
        assert_eq!((r.output.unjudgeable, r.output.degraded), (PRESS, 0));
        assert!(
            r.output
                .decisions
                .iter()
                .all(|d| d.event != e.detector.event("press").unwrap())
        );
        // A channel the configuration does not read (force_y) changes nothing but the flag.
        s.faults = ChannelSet::from_bits(0b0010);
        let r = e.tick(&s, &shared, &Health::default());
        assert_eq!((r.output.unjudgeable, r.output.degraded), (0, 0));
        assert!(e.status().faults.contains(FaultFlags::SENSOR_FAULT));
    }

    #[test]
    fn the_controllers_phase_is_followed() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        fresh(&shared, &e, 0, 0);
        deliver(&shared, &e, 0, phase(0, 1, 7));
        let r = e.tick(&sample(1, -1.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.evaluated, BUMP);
        assert_eq!(e.state().phase().index(), 1);
        assert_eq!((e.status().phase, e.status().phase_seq), (Some(1), 7));
        assert!(!e.status().faults.contains(FaultFlags::PHASE_STALE));
        deliver(&shared, &e, 2, phase(1, 0, 8));
        let r = e.tick(&sample(2, -1.0, 0.0), &shared, &Health::default());
        assert_eq!(r.output.evaluated, PRESS | BUMP);
        assert!(
            !events(&r.frames).is_empty(),
            "press judged again in its phase"
        );
    }

    #[test]
    fn health_reaches_the_heartbeat() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        let health = Health {
            worst_lateness: 1_234,
            late_ticks: 3,
            worst_tick: 2_345,
            lost_scans: 7,
            bus_errors: 2,
            tx_dropped: 5,
            latched: FaultFlags::LATE | FaultFlags::TX_DROPPED,
            sensor_fault: true,
        };
        let (mut pages, mut faults, mut beats) = (Vec::new(), None, 0);
        // Pages 1..=10 come round once every ten heartbeats (50 ms each).
        for t in 0..(10 * 250 + 1) {
            let r = e.tick(&sample(t, 0.0, 0.0), &shared, &health);
            beats += usize::from(r.heartbeat);
            for p in status_pages(&r.frames) {
                match p {
                    StatusPage::Health { faults: f, .. } => faults = Some(f),
                    p => pages.push(p),
                }
            }
        }
        assert_eq!(beats, 11);
        let f = faults.unwrap();
        assert!(f.contains(FaultFlags::LATE | FaultFlags::TX_DROPPED | FaultFlags::SENSOR_FAULT));
        assert!(!f.contains(FaultFlags::BUS_ERROR));
        for want in [
            StatusPage::Lateness {
                worst: 1_234,
                late_ticks: 3,
            },
            StatusPage::Compute {
                worst_tick: 2_345,
                lost_scans: 7,
            },
            StatusPage::Bus {
                bus_errors: 2,
                tx_dropped: 5,
            },
            StatusPage::Config {
                checksum: 0xDEAD_BEEF,
            },
        ] {
            assert!(pages.contains(&want), "{want:?} not in {pages:?}");
        }
        assert!(pages.iter().any(|p| matches!(
            p,
            StatusPage::Identity {
                tick_rate_hz: 5000,
                ..
            }
        )));
    }

    #[test]
    fn the_boards_identity_and_clock_fallback_are_in_every_heartbeat() {
        let d = detector();
        let fallback_clock = BoardInfo {
            node_source: NodeIdSource::Store,
            clock_fallback: true,
            ..board()
        };
        let mut e = Engine::new(leak(&d), d.clone(), EngineParams::new(fallback_clock, 1)).unwrap();
        let mut pages = Vec::new();
        for t in 0..=500 {
            let r = e.tick(&sample(t, 0.0, 0.0), &RxShared::new(), &Health::default());
            pages.extend(status_pages(&r.frames));
        }
        let health: Vec<FaultFlags> = pages
            .iter()
            .filter_map(|p| match p {
                StatusPage::Health { faults, .. } => Some(*faults),
                _ => None,
            })
            .collect();
        assert_eq!(health.len(), 3);
        assert!(
            health
                .iter()
                .all(|f| f.contains(FaultFlags::CLOCK_FALLBACK))
        );
        assert!(pages.iter().any(|p| matches!(
            p,
            StatusPage::Identity {
                node_source: NodeIdSource::Store,
                format: BusFormat::Fd,
                ..
            }
        )));
        let plain = engine(&d);
        assert!(!plain.status().faults.contains(FaultFlags::CLOCK_FALLBACK));
    }

    #[test]
    fn the_confidence_stream_is_decimated_to_every_twentieth_tick() {
        let d = detector();
        let mut e = engine(&d);
        let shared = RxShared::new();
        let mut stream_ticks = Vec::new();
        for t in 0..100 {
            if t % 5 == 0 {
                fresh(&shared, &e, t, (t / 5 % 15) as u8);
            }
            let r = e.tick(&sample(t, 0.0, 0.0), &shared, &Health::default());
            if decode(&r.frames)
                .iter()
                .any(|m| matches!(m, Message::Stream(_)))
            {
                stream_ticks.push(t);
            }
        }
        assert_eq!(stream_ticks, [0, 20, 40, 60, 80]);
    }

    #[test]
    fn raw_adc_counts_go_through_calibration_to_an_event_frame() {
        use crate::calib::NOMINAL;
        use crate::sampling::FrontEnd;
        let d = detector();
        let mut e = engine(&d);
        let mut fe = FrontEnd::new(NOMINAL, 5000);
        let shared = RxShared::new();
        fresh(&shared, &e, 0, 0);
        // Mid-rail: no force. Then 1 N against the motion (−205 counts at 4.88 mN/count).
        let quiet = fe.process(0, &[2048, 2048, 2048, 2048]);
        assert!(events(&e.tick(&quiet, &shared, &Health::default()).frames).is_empty());
        let press = fe.process(1, &[2048 - 205, 2048, 2048, 2048]);
        let ev = events(&e.tick(&press, &shared, &Health::default()).frames);
        assert_eq!(ev.len(), 2);
        assert!(ev.iter().all(|m| m.event == d.event("press").unwrap()));
    }

    #[test]
    fn a_tick_generated_for_another_detector_is_refused() {
        let d = detector();
        let crc = crc32(&detector_build::compile(&config()).unwrap().image());
        let params = EngineParams::new(board(), crc);
        let tick = ApproachTick
            .image_crc()
            .expect("a generated tick knows its image");
        assert_eq!(
            Engine::new(leak(&d), ApproachTick, params).err(),
            Some(EngineError::TickImage { tick, loaded: crc })
        );
        // The interpreter runs whatever it is given.
        assert!(Engine::new(leak(&d), d.clone(), params).is_ok());
        // And the generated tick is accepted for its own image only.
        assert_eq!(tick, boot::CONFIG_CHECKSUM);
        assert!(Engine::new(leak(&embedded()), ApproachTick, board_params()).is_ok());
    }

    /// The generated tick against the interpreter, each in an engine on the embedded
    /// detector: every analog channel wobbling, with pushes (force against the motion,
    /// stress-rate bursts) every 100 ms and a channel stuck now and then, context and tip
    /// state every millisecond but for a gap, the tick counter across its wrap.
    #[test]
    fn the_generated_tick_is_the_interpreters_through_the_engine() {
        let d = embedded();
        let mut interpreted = Engine::new(leak(&d), (*d).clone(), board_params()).unwrap();
        let mut generated = Engine::new(leak(&d), ApproachTick, board_params()).unwrap();
        let (rx_a, rx_b) = (RxShared::new(), RxShared::new());
        let mut alerted = 0;
        for k in 0..6000u32 {
            let now = k.wrapping_add(u32::MAX - 2000);
            if k % 5 == 0 && !(3000..3300).contains(&k) {
                let counter = (k / 5 % 15) as u8;
                let err = 2e-6 * f64::from(k % 50);
                for (rx, e) in [
                    (&rx_a, &interpreted.receiver()),
                    (&rx_b, &generated.receiver()),
                ] {
                    let f = context(k, counter, 0.05, err);
                    rx.with(|s| e.receive(s, now, f.id().into(), f.data()))
                        .expect("accepted");
                }
            }
            let push = k % 500 >= 250;
            let mut s = AdcSample {
                tick: now,
                ..AdcSample::default()
            };
            for (c, v) in s.values.iter_mut().enumerate() {
                let wobble = 0.01 * (k as f64 * 0.013 * (c + 1) as f64).sin();
                *v = Signal::from_f64(match c {
                    0 if push => -0.2 * f64::from(k % 500 - 250),
                    2 => wobble + if push { 20.0 * (k as f64).sin() } else { 0.0 },
                    3 if push && k % 500 < 300 => 40.0 * (k as f64).sin(),
                    _ => wobble,
                });
            }
            if k % 700 < 40 {
                s.faults.insert((k / 700 % 4) as usize);
            }
            let a = interpreted.tick(&s, &rx_a, &Health::default());
            let b = generated.tick(&s, &rx_b, &Health::default());
            assert_eq!(a, b, "tick {k}");
            alerted |= a.output.alerting;
        }
        assert_eq!(interpreted.state(), generated.state());
        assert_ne!(alerted, 0, "the inputs never raise a level: a weak test");
    }

    #[test]
    fn timeouts_convert_to_ticks() {
        assert_eq!(ms_to_ticks(20, 5000), 100);
        assert_eq!(ms_to_ticks(1, 1500), 2);
        assert_eq!(ms_to_ticks(0, 5000), 1);
        assert_eq!(ms_to_ticks(u32::MAX, 5000), u32::MAX.div_ceil(1000));
    }

    #[test]
    fn the_runner_times_ticks_measures_lateness_and_flags_refused_frames() {
        use crate::supervise::Task;
        use core::cell::Cell;
        let d = detector();
        let mut e = Service::Running(engine(&d));
        let mut shared = Shared::new();
        let mut h = shared.split();
        let mut runner = TickRunner::new(170_000_000, 5000);
        // A cycle counter near its wrap that advances 40 000 cycles per read: every tick
        // computes longer than its 34 000, and ends 45 000 after its sample's conversion.
        let clock = Cell::new(u32::MAX - 10_000);
        let cycles = || {
            let now = clock.get();
            clock.set(now.wrapping_add(40_000));
            now
        };
        let converted = |t: Tick| AdcSample {
            converted_at: clock.get().wrapping_sub(5_000),
            ..sample(t, 0.0, 0.0)
        };
        // The first tick sends the stream and a heartbeat; the queue refuses everything.
        let s0 = converted(0);
        let r = runner.step(&mut e, &s0, &mut h.detector, cycles, |f| Pushed {
            refused: f.len() as u32,
            status_lost: true,
            lost: f.len() as u32,
        });
        assert!(r.heartbeat);
        let refused = r.frames.len() as u32;
        assert_eq!(runner.tx_lost(), refused);
        assert_eq!(runner.timing().worst(), 40_000);
        assert_eq!(
            (runner.lateness().worst(), runner.lateness().late()),
            (45_000, 1)
        );
        // Latched after the heartbeat was built: reported by the next one.
        assert!(
            h.detector
                .latched()
                .contains(FaultFlags::LATE | FaultFlags::TX_DROPPED)
        );
        assert_eq!(h.can_rx.now(), 0);
        assert!(h.watchdog.round(Task::Detector as u8));
        let mut reported = None;
        for t in 1..=250 {
            let st = converted(t);
            let r = runner.step(&mut e, &st, &mut h.detector, cycles, |_| Pushed {
                lost: refused,
                ..Pushed::default()
            });
            if r.heartbeat {
                reported = health_flags(&r.frames);
            }
        }
        let f = reported.expect("a heartbeat at tick 250");
        assert!(f.contains(FaultFlags::LATE | FaultFlags::TX_DROPPED));
        // Every tick was late again, so LATE is latched anew; TX_DROPPED was cleared.
        assert!(h.detector.latched().contains(FaultFlags::LATE));
        assert!(!h.detector.latched().contains(FaultFlags::TX_DROPPED));
        assert_eq!(h.can_rx.now(), 250);
        // 40 000 cycles at 170 MHz = 235.2 µs, 45 000 = 264.7 µs, reported from the second
        // tick on.
        assert_eq!(
            (e.status().worst_tick, e.status().worst_lateness),
            (2352, 2647)
        );
        assert_eq!(
            (runner.lateness().late(), e.status().late_ticks),
            (251, 250)
        );
    }

    #[test]
    fn a_prompt_tick_is_not_late_but_lost_scans_are_flagged() {
        let d = detector();
        let mut e = Service::Running(engine(&d));
        let mut shared = Shared::new();
        let mut h = shared.split();
        let mut runner = TickRunner::new(170_000_000, 5000);
        // Ends 20 000 cycles (118 µs) after its sample's conversion: within the period.
        let s = AdcSample {
            converted_at: 1_000,
            ..sample(0, 0.0, 0.0)
        };
        runner.step(&mut e, &s, &mut h.detector, || 21_000, |_| lost(0));
        assert_eq!(
            (runner.lateness().late(), runner.lateness().worst()),
            (0, 20_000)
        );
        assert!(!h.detector.latched().contains(FaultFlags::LATE));
        // The sampler lost two scans: flagged at the next tick, counted in the status.
        h.sampler.set_lost_samples(2);
        runner.step(
            &mut e,
            &AdcSample { tick: 3, ..s },
            &mut h.detector,
            || 21_000,
            |_| lost(0),
        );
        assert!(h.detector.latched().contains(FaultFlags::LATE));
        assert_eq!(e.status().lost_scans, 2);
    }

    /// The health page of the heartbeat among `frames`, if any.
    fn health_flags(frames: &TxFrames) -> Option<FaultFlags> {
        status_pages(frames).into_iter().find_map(|p| match p {
            StatusPage::Health { faults, .. } => Some(faults),
            _ => None,
        })
    }

    /// A transmit path that takes every frame of the tick, having lost `lost` since boot.
    fn lost(lost: u32) -> Pushed {
        Pushed {
            lost,
            ..Pushed::default()
        }
    }

    /// Runs the ticks `ticks` with quiet samples and every frame taken (`lost_before`
    /// lost before); the health flags of the heartbeats among them, in order.
    fn quiet_heartbeats(
        runner: &mut TickRunner,
        service: &mut Service<'_, Detector>,
        handle: &mut DetectorHandle<'_>,
        ticks: core::ops::RangeInclusive<Tick>,
        lost_before: u32,
    ) -> Vec<FaultFlags> {
        ticks
            .filter_map(|t| {
                let r = runner.step(
                    service,
                    &sample(t, 0.0, 0.0),
                    handle,
                    || 0,
                    |_| lost(lost_before),
                );
                health_flags(&r.frames)
            })
            .collect()
    }

    #[test]
    fn a_frame_dropped_again_during_a_heartbeat_tick_is_reported_by_the_next() {
        let d = detector();
        let mut e = Service::Running(engine(&d));
        let mut shared = Shared::new();
        let mut h = shared.split();
        let mut runner = TickRunner::new(170_000_000, 5000);
        // Ticks well within budget.
        let cycles = || 0;
        runner.step(
            &mut e,
            &sample(0, 0.0, 0.0),
            &mut h.detector,
            cycles,
            |_| lost(0),
        );
        // A frame lost before the next heartbeat (at tick 250; flushed after a bus-off,
        // say) ...
        for t in 1..250 {
            runner.step(
                &mut e,
                &sample(t, 0.0, 0.0),
                &mut h.detector,
                cycles,
                |_| lost(1),
            );
        }
        // ... is reported by it; while that heartbeat is being queued, another frame is
        // lost: the same flag, raised between the read and the clear.
        let r = runner.step(
            &mut e,
            &sample(250, 0.0, 0.0),
            &mut h.detector,
            cycles,
            |_| lost(2),
        );
        assert!(health_flags(&r.frames).is_some_and(|f| f.contains(FaultFlags::TX_DROPPED)));
        // The next heartbeat reports the second loss, and the one after has nothing new.
        let reported = quiet_heartbeats(&mut runner, &mut e, &mut h.detector, 251..=750, 2);
        assert_eq!(reported.len(), 2);
        assert!(reported[0].contains(FaultFlags::TX_DROPPED));
        assert!(!reported[1].contains(FaultFlags::TX_DROPPED));
    }

    #[test]
    fn a_heartbeat_the_queue_refused_reported_nothing() {
        let d = detector();
        let mut e = Service::Running(engine(&d));
        let mut shared = Shared::new();
        let mut h = shared.split();
        let mut runner = TickRunner::new(170_000_000, 5000);
        let cycles = || 0;
        h.bus.bus_error();
        // The first tick's heartbeat reports the bus error, but the queue refuses the
        // status frames.
        let r = runner.step(&mut e, &sample(0, 0.0, 0.0), &mut h.detector, cycles, |f| {
            let refused = f.iter().filter(|f| is_status(f)).count() as u32;
            Pushed {
                refused,
                status_lost: true,
                lost: refused,
            }
        });
        assert!(health_flags(&r.frames).is_some_and(|f| f.contains(FaultFlags::BUS_ERROR)));
        let reported = quiet_heartbeats(&mut runner, &mut e, &mut h.detector, 1..=250, 2);
        // Reported again at the next heartbeat, with the refused frames' own flag.
        assert_eq!(reported.len(), 1);
        assert!(reported[0].contains(FaultFlags::BUS_ERROR | FaultFlags::TX_DROPPED));
        assert_eq!(h.detector.latched(), FaultFlags(0));
    }

    #[test]
    fn the_fallback_sends_heartbeats_only_with_its_flag_and_the_boards_faults() {
        let transmitter = Transmitter::with_defaults(node(), BusFormat::Fd, 5000).unwrap();
        let reason = FallbackReason::Image(ImageError::Magic);
        let mut service: Service<'_, Detector> =
            Service::Fallback(Fallback::new(transmitter, &params(), 5000), reason);
        assert!(service.detector().is_none() && service.receiver().is_none());
        assert_eq!(service.fallback_reason(), Some(reason));
        assert_eq!(service.rate_hz(), 5000);
        // The controller commands a phase: nothing is read.
        let shared = RxShared::new();
        let receiver = Receiver::new(node(), 2, 100, 500).unwrap();
        let command = phase(0, 1, 7);
        shared
            .with(|rx| receiver.receive(rx, 0, command.id().into(), command.data()))
            .expect("accepted");
        let mut s = sample(0, -1.0, 50.0);
        s.faults = ChannelSet::from_bits(0b0100);
        let health = Health {
            latched: FaultFlags::LATE,
            ..Health::default()
        };
        let mut messages = Vec::new();
        for t in 0..=500 {
            s.tick = t;
            let r = service.tick(&s, &shared, &health);
            assert_eq!(r.output, Output::default());
            assert_eq!(r.heartbeat, t % 250 == 0);
            messages.extend(decode(&r.frames));
        }
        assert_eq!(
            messages.len(),
            6,
            "two status pages per heartbeat, nothing else"
        );
        let pages: Vec<StatusPage> = messages
            .iter()
            .map(|m| match m {
                Message::Status(s) => s.page,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(
            pages[0],
            StatusPage::Health {
                reset: ResetReason::PowerOn,
                phase: None,
                faults: FaultFlags::CONFIG_FALLBACK | FaultFlags::LATE | FaultFlags::SENSOR_FAULT,
                phase_seq: 0,
            }
        );
        assert_eq!(pages[1], StatusPage::Uptime { uptime: 0 });
        assert!(matches!(
            pages[3],
            StatusPage::Identity {
                tick_rate_hz: 5000,
                ..
            }
        ));
        assert_eq!(service.status().config_checksum, 0xDEAD_BEEF);
    }
}
