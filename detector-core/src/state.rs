//! What a tick works on: its [`Inputs`] and [`Output`], a detector's [`State`], the
//! decision types, and the steps of a tick one item at a time. The interpreter
//! ([`Detector`](crate::Detector)) loops over its tables and calls the steps; a tick
//! generated at build time calls them with constants (through `detector_core::__private`).
//! Indices are masked to their array's power-of-two length: one instruction, no bounds
//! check, no panic whatever they are.

use heapless::Vec;

use crate::cdf::Cdf;
use crate::expr::Rust;
use crate::feature::{MAX_SLOTS, Stage, StageState, WINDOW_POOL};
use crate::image::{ImageError, Reader, Sink};
use crate::num::{ChannelMask, Confidence, EventMask, Signal, Tick};
use crate::{MAX_CHANNELS, MAX_DISTINCT_TERMS as MAX_PSI, MAX_EVENTS, MAX_FEATURES};

// Reads of `State`'s arrays mask their index with the length - 1: one instruction, no bounds
// check.
const _: () = assert!(
    MAX_PSI.is_power_of_two()
        && MAX_PSI <= 256
        && MAX_CHANNELS.is_power_of_two()
        && MAX_FEATURES.is_power_of_two()
        && MAX_EVENTS.is_power_of_two()
);

/// The index of an event in its configuration, `0..MAX_EVENTS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EventId(pub u8);

/// A phase of a particular detector; only obtainable from it, so always valid for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseId(pub(crate) u8);

impl PhaseId {
    /// The phase's index in the configuration.
    pub const fn index(self) -> u8 {
        self.0
    }
}

/// A decision level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Level {
    /// Early warning: the event may be happening.
    Alert,
    /// Confirmation: the controller may act on it.
    Confirm,
}

impl Level {
    /// The level's name as the tools and the CAN stream write it.
    pub const fn name(self) -> &'static str {
        match self {
            Level::Alert => "alert",
            Level::Confirm => "confirm",
        }
    }
}

/// A level raised for an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Decision {
    /// Which event.
    pub event: EventId,
    /// Which level was raised.
    pub level: Level,
    /// The event's confidence at that tick.
    pub confidence: Confidence,
    /// Back-dated onset: the first tick of the current run of confidence above the
    /// event's `onset_level` (by default, when the confidence last left zero).
    pub onset: Tick,
    /// The tick at which the level was raised.
    pub tick: Tick,
}

/// One tick's inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Inputs {
    /// Channel samples in each channel's working unit (SI × its scale, see
    /// [`Detector::sample_from_si`](crate::Detector::sample_from_si)), in the configuration's channel order; entries past
    /// the channel count are ignored.
    pub samples: [Signal; MAX_CHANNELS],
    /// Channels currently known bad (sensor fault, stale context): bit `i` for channel `i`.
    pub faults: ChannelMask,
}

impl Default for Inputs {
    fn default() -> Self {
        Inputs {
            samples: [Signal::ZERO; MAX_CHANNELS],
            faults: 0,
        }
    }
}

/// One tick's results.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Output {
    /// Each event's confidence, by [`EventId`]; zero for events not evaluated.
    pub confidences: [Confidence; MAX_EVENTS],
    /// The events of the active phase (the ones evaluated).
    pub evaluated: EventMask,
    /// Events of the phase that cannot be judged because a context feature, or every
    /// sensor feature, reads a faulty channel: confidence 0, no decision.
    pub unjudgeable: EventMask,
    /// Events judged without some sensor terms, whose features read a faulty channel
    /// (those terms count as 0, so the confidence can only be lower).
    pub degraded: EventMask,
    /// Events whose alert level is up after this tick.
    pub alerting: EventMask,
    /// Events whose confirm level is up after this tick.
    pub confirmed: EventMask,
    /// Levels raised at this tick, at most two per event.
    pub decisions: Vec<Decision, { 2 * MAX_EVENTS }>,
}

impl Output {
    /// Clears every field for a new tick (no allocation, no copy of a whole `Output`).
    #[inline(always)]
    pub fn clear(&mut self) {
        self.confidences = [Confidence::ZERO; MAX_EVENTS];
        self.evaluated = 0;
        self.unjudgeable = 0;
        self.degraded = 0;
        self.alerting = 0;
        self.confirmed = 0;
        self.decisions.clear();
    }
}

/// A shorter dwell for a level, taken once a feature has shown what the event is: the level
/// is raised after `dwell` ticks in a row at or above `on` instead of its own dwell once the
/// feature in `slot` has been above `above` at one of the ticks of the run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Early {
    pub(crate) slot: u8,
    pub(crate) above: i32,
    pub(crate) dwell: u16,
}

impl Early {
    /// The shorter dwell `dwell` (at least 1 tick) once the feature in `slot` (a feature's
    /// slot, `MAX_CHANNELS..MAX_SLOTS`) has been above `above` (raw 16.16); `None` outside
    /// those ranges.
    pub const fn new(slot: u8, above: i32, dwell: u16) -> Option<Early> {
        if dwell == 0 || (slot as usize) < MAX_CHANNELS || slot as usize >= MAX_SLOTS {
            None
        } else {
            Some(Early { slot, above, dwell })
        }
    }

    /// The slot of the feature watched.
    pub const fn slot(&self) -> u8 {
        self.slot
    }

    /// The level (raw 16.16) the feature must pass.
    pub const fn above(&self) -> i32 {
        self.above
    }

    /// Ticks in a row at or above `on` before the level is raised, once the feature has
    /// passed its level.
    pub const fn dwell(&self) -> u16 {
        self.dwell
    }
}

/// A decision level: up at `on` (Q15) after `dwell` ticks in a row (or `early`'s, once its
/// feature has shown), down below `off` after `hold` ticks in a row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelParams {
    pub(crate) on: u16,
    pub(crate) off: u16,
    pub(crate) dwell: u16,
    pub(crate) hold: u16,
    pub(crate) early: Option<Early>,
}

impl LevelParams {
    /// A level raised once the confidence has stayed at or above `on` (Q15, in (0, 1]) for
    /// `dwell` ticks in a row (at least 1) and lowered once it has stayed below `off` (at
    /// most `on`) for `hold` ticks in a row (at least 1); with `early`, raised after its
    /// dwell (at most `dwell`) instead once its feature has passed its level during the
    /// run. `None` outside those ranges.
    ///
    /// The hold makes one physical event one rise of the level: a confidence that dips
    /// below `off` for less than `hold` ticks and comes back keeps the level up instead of
    /// raising it a second time.
    pub const fn new(
        on: u16,
        off: u16,
        dwell: u16,
        hold: u16,
        early: Option<Early>,
    ) -> Option<LevelParams> {
        let early_fits = match early {
            Some(e) => e.dwell <= dwell,
            None => true,
        };
        if on == 0
            || on > Confidence::ONE.to_bits()
            || off > on
            || dwell == 0
            || hold == 0
            || !early_fits
        {
            None
        } else {
            Some(LevelParams {
                on,
                off,
                dwell,
                hold,
                early,
            })
        }
    }

    /// [`LevelParams::new`] for generated code's constants: values it refuses fail the
    /// build of the generated code.
    #[doc(hidden)]
    pub const fn checked(
        on: u16,
        off: u16,
        dwell: u16,
        hold: u16,
        early: Option<(u8, i32, u16)>,
    ) -> LevelParams {
        let early = match early {
            Some((slot, above, dwell)) => match Early::new(slot, above, dwell) {
                Some(e) => Some(e),
                None => panic!("decision level's early dwell"),
            },
            None => None,
        };
        match LevelParams::new(on, off, dwell, hold, early) {
            Some(l) => l,
            None => panic!("decision level"),
        }
    }

    /// The confidence (Q15) at or above which the level counts ticks.
    pub const fn on(&self) -> u16 {
        self.on
    }

    /// The confidence (Q15) below which a raised level counts ticks towards falling.
    pub const fn off(&self) -> u16 {
        self.off
    }

    /// Ticks in a row at or above `on` before the level is raised.
    pub const fn dwell(&self) -> u16 {
        self.dwell
    }

    /// Ticks in a row below `off` before a raised level falls.
    pub const fn hold(&self) -> u16 {
        self.hold
    }

    /// The shorter dwell taken once a feature has shown, if any.
    pub const fn early(&self) -> Option<Early> {
        self.early
    }

    /// Whether the early dwell's feature shows at this tick in `state`: above its level,
    /// the event not `degraded` (a feature reading a faulty channel shows nothing). False
    /// without an early dwell.
    #[inline(always)]
    pub fn shown(&self, state: &State, degraded: bool) -> bool {
        match self.early {
            Some(e) => !degraded && state.values[usize::from(e.slot) & (MAX_SLOTS - 1)] > e.above,
            None => false,
        }
    }

    /// This level as a Rust expression for generated code.
    pub fn rust(&self) -> Rust<'_, LevelParams> {
        Rust(self)
    }

    pub(crate) fn read_image(r: &mut Reader<'_>) -> Result<LevelParams, ImageError> {
        let (on, off, dwell, hold) = (r.u16()?, r.u16()?, r.u16()?, r.u16()?);
        let early = match r.u8()? {
            0 => None,
            1 => {
                let (slot, above, dwell) = (r.u8()?, r.i32()?, r.u16()?);
                Some(Early::new(slot, above, dwell).ok_or(ImageError::Invalid("early dwell"))?)
            }
            _ => return Err(ImageError::Invalid("early dwell flag")),
        };
        LevelParams::new(on, off, dwell, hold, early).ok_or(ImageError::Invalid("decision level"))
    }

    /// Appends this level to a detector image.
    pub fn write_image(&self, w: &mut impl Sink) {
        w.u16(self.on);
        w.u16(self.off);
        w.u16(self.dwell);
        w.u16(self.hold);
        match self.early {
            None => w.u8(0),
            Some(e) => {
                w.u8(1);
                w.u8(e.slot);
                w.i32(e.above);
                w.u16(e.dwell);
            }
        }
    }
}

impl core::fmt::Display for Rust<'_, LevelParams> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let l = self.0;
        write!(
            f,
            "LevelParams::checked({}, {}, {}, {}, ",
            l.on, l.off, l.dwell, l.hold
        )?;
        match l.early {
            None => f.write_str("None)"),
            Some(e) => write!(f, "Some(({}, {}, {})))", e.slot, e.above, e.dwell),
        }
    }
}

/// One decision level's state: the tick a detector runs for each event's alert and confirm
/// levels, public so that a PC tool can try other levels on the same confidences (the
/// default is down).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LevelState {
    pub(crate) up: bool,
    /// Ticks in a row at or above `on` while down, below `off` while up.
    run: u16,
    /// While down: the early dwell's feature has passed its level during the run.
    shown: bool,
}

impl LevelState {
    /// Whether the level is up.
    pub fn is_up(&self) -> bool {
        self.up
    }

    /// One tick of a level at confidence `q` (Q15): up at `on` after `dwell` ticks in a
    /// row (after the early dwell once `shown` has been true at a tick of the run), down
    /// below `off` after `hold` ticks in a row. `shown` says whether the early dwell's
    /// feature is above its level at this tick (ignored without an early dwell). Returns
    /// whether the level was raised at this tick.
    #[inline(always)]
    pub fn step(&mut self, p: &LevelParams, q: u16, shown: bool) -> bool {
        if self.up {
            self.run = if q < p.off {
                self.run.saturating_add(1)
            } else {
                0
            };
            if self.run >= p.hold {
                *self = LevelState::default();
            }
            false
        } else if q >= p.on {
            self.run = self.run.saturating_add(1);
            let dwell = match p.early {
                Some(e) => {
                    self.shown |= shown;
                    if self.shown { e.dwell } else { p.dwell }
                }
                None => p.dwell,
            };
            if self.run >= dwell {
                *self = LevelState {
                    up: true,
                    run: 0,
                    shown: false,
                };
            }
            self.up
        } else {
            *self = LevelState::default();
            false
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct EventState {
    pub(crate) rising: bool,
    pub(crate) onset: Tick,
    pub(crate) levels: [LevelState; 2],
}

/// Everything a detector changes as it runs. Fixed size, no allocation; see
/// [`State::SIZE`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct State {
    /// Channel samples then feature values, raw 16.16.
    pub(crate) values: [i32; MAX_SLOTS],
    pub(crate) stages: [StageState; MAX_FEATURES],
    pub(crate) ring: [u64; WINDOW_POOL],
    /// Each ψ's confidence at the last tick (Q15), by the detector's ψ index.
    pub(crate) psi: [u16; MAX_PSI],
    pub(crate) events: [EventState; MAX_EVENTS],
    pub(crate) phase: u8,
}

impl State {
    /// The size of a detector's state in bytes.
    pub const SIZE: usize = core::mem::size_of::<State>();

    /// The current value of feature `index` (in configuration order).
    pub fn feature(&self, index: usize) -> Option<Signal> {
        let slot = MAX_CHANNELS
            .checked_add(index)
            .filter(|_| index < MAX_FEATURES)?;
        self.values.get(slot).map(|&v| Signal::from_bits(v))
    }

    /// The active phase.
    pub fn phase(&self) -> PhaseId {
        PhaseId(self.phase)
    }

    /// Bytes of a saved state ([`State::save`]).
    pub const SAVED_BYTES: usize = 4
        + 1
        + 4 * MAX_SLOTS
        + StageState::BYTES * MAX_FEATURES
        + 8 * WINDOW_POOL
        + 2 * MAX_PSI
        + EVENT_BYTES * MAX_EVENTS;

    /// Writes the state into `out` in its saved form: [`SAVED_MAGIC`], then the phase,
    /// the values, the stages, the window history, the ψs and the events, little-endian
    /// (docs/trace-format.md). A flight recorder keeps it as the start of a recording;
    /// [`Detector::restore`](crate::Detector::restore) reads it back.
    pub fn save(&self, out: &mut [u8; State::SAVED_BYTES]) {
        let mut w = Cursor { buf: out, at: 0 };
        w.put(SAVED_MAGIC);
        w.put([self.phase]);
        for v in &self.values {
            w.put(v.to_le_bytes());
        }
        for st in &self.stages {
            w.put(st.save());
        }
        for e in &self.ring {
            w.put(e.to_le_bytes());
        }
        for p in &self.psi {
            w.put(p.to_le_bytes());
        }
        for e in &self.events {
            w.put([u8::from(e.rising)]);
            w.put(e.onset.to_le_bytes());
            for l in &e.levels {
                w.put([u8::from(l.up)]);
                w.put(l.run.to_le_bytes());
                w.put([u8::from(l.shown)]);
            }
        }
    }

    /// Reads a saved state's fields, checking only their own ranges (flags 0 or 1, ψ at
    /// most 1); the detector's checks are [`Detector::restore`](crate::Detector::restore)'s.
    pub(crate) fn read_saved(bytes: &[u8]) -> Result<State, StateError> {
        if bytes.len() != State::SAVED_BYTES {
            return Err(StateError::Length(bytes.len()));
        }
        let mut r = Reading { bytes };
        if r.take::<4>() != SAVED_MAGIC {
            return Err(StateError::Magic);
        }
        let flag = |b: u8| match b {
            0 => Ok(false),
            1 => Ok(true),
            _ => Err(StateError::Flag),
        };
        let phase = r.take::<1>()[0];
        let mut values = [0i32; MAX_SLOTS];
        for v in &mut values {
            *v = i32::from_le_bytes(r.take());
        }
        let mut stages = [StageState::default(); MAX_FEATURES];
        for st in &mut stages {
            *st = StageState::restore(r.take()).ok_or(StateError::Flag)?;
        }
        let mut ring = [0u64; WINDOW_POOL];
        for e in &mut ring {
            *e = u64::from_le_bytes(r.take());
        }
        let mut psi = [0u16; MAX_PSI];
        for (index, p) in psi.iter_mut().enumerate() {
            *p = u16::from_le_bytes(r.take());
            if u32::from(*p) > ONE {
                return Err(StateError::Confidence(index));
            }
        }
        let mut events = [EventState::default(); MAX_EVENTS];
        for e in &mut events {
            e.rising = flag(r.take::<1>()[0])?;
            e.onset = Tick::from_le_bytes(r.take());
            for l in &mut e.levels {
                l.up = flag(r.take::<1>()[0])?;
                l.run = u16::from_le_bytes(r.take());
                l.shown = flag(r.take::<1>()[0])?;
            }
        }
        Ok(State {
            values,
            stages,
            ring,
            psi,
            events,
            phase,
        })
    }
}

/// The first bytes of a saved state: its format, version 7 (128 features; filter states
/// holding their output times 2³², primed by their sample count, an envelope that has seen
/// no sample by the least value; levels keeping whether their early dwell's feature has
/// shown).
pub const SAVED_MAGIC: [u8; 4] = *b"FTS7";

/// Bytes of an event's saved state: rising, onset, and each level's up, run and shown.
const EVENT_BYTES: usize = 1 + 4 + 2 * (1 + 2 + 1);

/// Writes a saved state front to back (the buffer is exactly as long as what is written).
struct Cursor<'b> {
    buf: &'b mut [u8],
    at: usize,
}

impl Cursor<'_> {
    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        if let Some(dst) = self.buf.get_mut(self.at..self.at + N) {
            dst.copy_from_slice(&bytes);
        }
        self.at += N;
    }
}

/// Reads a saved state front to back (its length checked first, so every read has its
/// bytes).
struct Reading<'b> {
    bytes: &'b [u8],
}

impl Reading<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        match self.bytes.split_first_chunk::<N>() {
            Some((head, rest)) => {
                self.bytes = rest;
                *head
            }
            None => [0; N],
        }
    }
}

/// Why saved bytes are not a state a detector can run on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StateError {
    /// Not [`State::SAVED_BYTES`] long (the length found).
    Length(usize),
    /// It does not start with [`SAVED_MAGIC`].
    Magic,
    /// A flag byte is neither 0 nor 1.
    Flag,
    /// The phase is not one of the detector's (the phase, the detector's phase count).
    Phase(u8, usize),
    /// ψ number `.0` is above 1.
    Confidence(usize),
    /// Feature number `.0`'s running state is one its stage cannot reach (another
    /// detector's state, or a corrupted one).
    Feature(usize),
}

impl core::fmt::Display for StateError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            StateError::Length(n) => write!(
                f,
                "a saved detector state is {} bytes, not {n}",
                State::SAVED_BYTES
            ),
            StateError::Magic => write!(
                f,
                "not a saved detector state (it does not start with `{}`)",
                core::str::from_utf8(&SAVED_MAGIC).unwrap_or("?")
            ),
            StateError::Flag => f.write_str("a flag of the saved state is neither 0 nor 1"),
            StateError::Phase(p, n) => {
                write!(
                    f,
                    "the saved state is in phase {p}, but the detector has {n} phases"
                )
            }
            StateError::Confidence(i) => write!(f, "confidence {i} of the saved state is above 1"),
            StateError::Feature(i) => write!(
                f,
                "feature {i}'s saved running state is out of its stage's range (the state of another detector?)"
            ),
        }
    }
}

/// A context product's starting value, 1 in Q15.
pub const ONE: u32 = 1 << 15;

/// One step of an event's context product: `acc · q` in Q15, rounded to nearest. Both are at
/// most 2¹⁵, so the result is too.
#[inline(always)]
pub const fn product(acc: u32, q: u32) -> u32 {
    (acc * q + (1 << 14)) >> 15
}

/// Eq. 14 from an event's context `product` (Q15, at most 2¹⁵: [`product`] of confidences
/// from [`ONE`]) and the sum of its sensor terms' weight (Q15) × ψ (Q15): product ×
/// min(1, Σ w ψ), rounded to nearest, itself at most 2¹⁵ without a clamp. Weights sum to at
/// most [`MAX_WEIGHT_SUM_Q15`](crate::MAX_WEIGHT_SUM_Q15) (3 · 2¹⁵ + 3), so the sum stays
/// below 2³²  − 2¹⁴.
#[inline(always)]
pub const fn eq14(product: u32, weighted_sum: u32) -> Confidence {
    let sum = (weighted_sum + (1 << 14)) >> 15;
    let sum = if sum > 1 << 15 { 1 << 15 } else { sum };
    Confidence::from_bits_within_one((product * sum + (1 << 14)) >> 15)
}

/// Stores channel `c`'s sample from `inputs` in its slot.
#[inline(always)]
pub fn load_sample(state: &mut State, c: usize, inputs: &Inputs) {
    let c = c & (MAX_CHANNELS - 1);
    state.values[c] = inputs.samples[c].to_bits();
}

/// Updates feature `k`, computed by `stage`; `taps` are the detector's STE window taps.
#[inline(always)]
pub fn step_feature(state: &mut State, k: usize, stage: &Stage, taps: &[u32]) {
    let k = k & (MAX_FEATURES - 1);
    let y = stage.update(&mut state.stages[k], &state.values, &mut state.ring, taps);
    state.values[(MAX_CHANNELS + k) & (MAX_SLOTS - 1)] = y;
}

/// Evaluates ψ `k`: `cdf` of the value in `slot`. Returns its confidence (Q15).
#[inline(always)]
pub fn eval_psi(state: &mut State, k: usize, slot: u8, cdf: &Cdf) -> u32 {
    let x = state.values[usize::from(slot) & (MAX_SLOTS - 1)];
    let q = cdf.eval(Signal::from_bits(x)).to_bits();
    state.psi[k & (MAX_PSI - 1)] = q;
    u32::from(q)
}

/// Sets ψ `k` to one minus ψ `j`, evaluated before it this tick: `k`'s CDF mirrors `j`'s on
/// the same feature ([`Cdf::mirrors`]), so this is what [`eval_psi`] would store, by a
/// subtraction instead of a CDF's evaluation.
#[inline(always)]
pub fn mirror_psi(state: &mut State, k: usize, j: usize) {
    state.psi[k & (MAX_PSI - 1)] = (1 << 15) - state.psi[j & (MAX_PSI - 1)];
}

/// ψ `k`'s confidence at the last tick (Q15).
#[inline(always)]
pub fn psi_value(state: &State, k: usize) -> u32 {
    u32::from(state.psi[k & (MAX_PSI - 1)])
}

/// Lowers every level of event `i` and forgets its onset (it cannot be judged).
#[inline(always)]
pub fn reset_event(state: &mut State, i: usize) {
    state.events[i & (MAX_EVENTS - 1)] = EventState::default();
}

/// Sets ψ `k` to 0 (its feature reads a faulty channel).
#[inline(always)]
pub fn clear_psi(state: &mut State, k: usize) {
    state.psi[k & (MAX_PSI - 1)] = 0;
}

/// Whether event `j`'s confirm level is up, as it stands: what holds down the events it
/// excludes. Generated code tests each excluding event with it, one load each.
#[inline(always)]
pub fn confirmed(state: &State, j: usize) -> bool {
    state.events[j & (MAX_EVENTS - 1)].levels[1].up
}

/// Whether any event of `mask` has its confirm level up ([`confirmed`] over the mask).
#[inline(always)]
pub fn any_confirmed(state: &State, mask: EventMask) -> bool {
    let mut rest = mask;
    let mut any = false;
    while rest != 0 {
        any |= confirmed(state, rest.trailing_zeros() as usize);
        rest &= rest - 1;
    }
    any
}

/// Decision levels and onset of event `i` at confidence `c`: tracks the onset, steps the
/// alert and confirm levels, and reports them in `out`. While `excluded` (an event that
/// excludes this one has its confirm level up, as it stands when this event is decided:
/// this tick's for events decided before it, the last tick's for those after), both
/// levels are held down.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn decide_event(
    state: &mut State,
    i: usize,
    levels: &[LevelParams; 2],
    onset_level: u16,
    excluded: bool,
    c: Confidence,
    now: Tick,
    out: &mut Output,
) {
    let i = i & (MAX_EVENTS - 1);
    let bit: EventMask = 1 << i;
    let degraded = out.degraded & bit != 0;
    let shown = [
        levels[0].shown(state, degraded),
        levels[1].shown(state, degraded),
    ];
    let st = &mut state.events[i];
    let q = c.to_bits();
    if q <= onset_level {
        st.rising = false;
    } else if !st.rising {
        st.rising = true;
        st.onset = now;
    }
    let [alert, confirm] = &mut st.levels;
    if excluded {
        *alert = LevelState::default();
        *confirm = LevelState::default();
    }
    let raised_alert = !excluded && alert.step(&levels[0], q, shown[0]);
    let raised_confirm = !excluded && confirm.step(&levels[1], q, shown[1]);
    out.alerting |= bit * EventMask::from(alert.up);
    out.confirmed |= bit * EventMask::from(confirm.up);
    let decision = |level| Decision {
        event: EventId(i as u8),
        level,
        confidence: c,
        onset: st.onset,
        tick: now,
    };
    // Capacity is two per event, so neither push can fail.
    if raised_alert {
        let _ = out.decisions.push(decision(Level::Alert));
    }
    if raised_confirm {
        let _ = out.decisions.push(decision(Level::Confirm));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eq14_saturates_at_the_largest_weighted_sum_an_image_may_carry() {
        // Every sensor term at 1 with the weights at their largest allowed sum: the sum
        // saturates at 1 without overflowing (debug builds check the arithmetic).
        let full = crate::MAX_WEIGHT_SUM_Q15 * ONE;
        assert_eq!(eq14(ONE, full), Confidence::ONE);
        assert_eq!(eq14(ONE / 2, full).to_bits(), 1 << 14);
        assert_eq!(eq14(0, full), Confidence::ZERO);
        // Just below saturation the sum counts as it is.
        assert_eq!(eq14(ONE, ONE * (1 << 14)).to_bits(), 1 << 14);
    }
}
