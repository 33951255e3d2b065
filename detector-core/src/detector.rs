//! The engine: a [`Detector`] (validated parameters, immutable) and its [`State`] (what
//! changes every tick), kept apart so the same parameters can drive several states.
//!
//! A tick runs four stages, each public so a profiler can time them one by one:
//! [`Detector::update_features`] → [`Detector::term_confidences`] →
//! [`Detector::combine`] → [`Detector::decide`]; [`Detector::tick`] runs them in order.

use heapless::Vec;

#[cfg(feature = "std")]
#[path = "codegen.rs"]
mod codegen;

use crate::cdf::{Cdf, CdfSpec};
use crate::compiled;
use crate::config::{Config, ConfigError, Item, LevelSpec, Name, Problem};
use crate::feature::{MAX_SLOTS, STE_POOL, Stage, StageState, taps_valid};
use crate::image::{ImageError, Reader};
#[cfg(feature = "std")]
use crate::image::{MAGIC, Writer};
use crate::num::{ChannelMask, Confidence, EventMask, Signal, Tick};
use crate::{
    MAX_CHANNELS, MAX_DISTINCT_TERMS as MAX_PSI, MAX_EVENTS, MAX_FEATURES, MAX_PHASES, MAX_TERMS,
};

/// The index of an event in its configuration, `0..MAX_EVENTS`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EventId(pub u8);

/// A phase of a particular detector; only obtainable from it, so always valid for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseId(u8);

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
    /// [`Detector::sample_from_si`]), in the configuration's channel order; entries past
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

// Reads of `State`'s arrays mask their index with the length - 1: one instruction, no bounds
// check.
const _: () = assert!(
    MAX_PSI.is_power_of_two()
        && MAX_PSI <= 256
        && MAX_CHANNELS.is_power_of_two()
        && MAX_FEATURES.is_power_of_two()
        && MAX_EVENTS.is_power_of_two()
);

/// One feature judged by one CDF (the paper's ψ), evaluated once per tick however many
/// terms of however many events name the same pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Psi {
    slot: u8,
    cdf: Cdf,
    /// The channels the feature reads: a fault on any of them makes ψ 0.
    channels: ChannelMask,
    /// The events whose terms use it: it is evaluated when one of them is active.
    events: EventMask,
}

impl Psi {
    /// A ψ used by no event yet; its channels are those `slot` depends on.
    fn new(slot: u8, cdf: Cdf, slot_channels: &[ChannelMask; MAX_SLOTS]) -> Psi {
        Psi {
            slot,
            cdf,
            channels: slot_channels.get(usize::from(slot)).copied().unwrap_or(0),
            events: 0,
        }
    }
}

/// Marks ψ `k` as used by the events in `bit` and gives the channels it reads (none for an
/// index past the table).
fn use_psi(psis: &mut [Psi], k: usize, bit: EventMask) -> ChannelMask {
    psis.get_mut(k).map_or(0, |p| {
        p.events |= bit;
        p.channels
    })
}

/// A sensor term: which ψ, and its weight (Q15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Weighted {
    psi: u8,
    weight: u16,
}

/// A decision level: up at `on` (Q15) after `dwell` ticks in a row, down below `off`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelParams {
    /// Confidence at or above which the level counts ticks (Q15).
    pub on: u16,
    /// Confidence below which a raised level falls (Q15).
    pub off: u16,
    /// Ticks in a row at or above `on` before the level is raised.
    pub dwell: u16,
}

#[derive(Clone, Debug, PartialEq, Eq)]
struct Event {
    /// Context terms, as indices into the detector's ψ table.
    context: Vec<u8, MAX_TERMS>,
    sensor: Vec<Weighted, MAX_TERMS>,
    /// The channels the context terms read, together.
    context_channels: ChannelMask,
    /// The channels the sensor terms read, together.
    sensor_channels: ChannelMask,
    levels: [LevelParams; 2],
    onset_level: u16,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct LevelState {
    up: bool,
    run: u16,
}

impl LevelState {
    /// One tick of a level at confidence `q` (Q15): up at `on` after `dwell` ticks in a
    /// row, down below `off`. Returns whether the level was raised at this tick.
    #[inline(always)]
    fn step(&mut self, p: &LevelParams, q: u16) -> bool {
        if self.up {
            if q < p.off {
                *self = LevelState::default();
            }
            false
        } else if q >= p.on {
            self.run = self.run.saturating_add(1);
            self.up = self.run >= p.dwell;
            self.up
        } else {
            self.run = 0;
            false
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct EventState {
    rising: bool,
    onset: Tick,
    levels: [LevelState; 2],
}

/// Everything a detector changes as it runs. Fixed size, no allocation; see
/// [`State::SIZE`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct State {
    /// Channel samples then feature values, raw 16.16.
    values: [i32; MAX_SLOTS],
    stages: [StageState; MAX_FEATURES],
    ring: [u64; STE_POOL],
    /// Each ψ's confidence at the last tick (Q15), by the detector's ψ index.
    psi: [u16; MAX_PSI],
    events: [EventState; MAX_EVENTS],
    phase: u8,
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

    /// The term confidences computed for `event` at the last tick: (context terms, sensor
    /// terms), in configuration order. Stale for events outside the active phase.
    pub fn terms(
        &self,
        detector: &Detector,
        event: EventId,
    ) -> Option<(TermConfidences, TermConfidences)> {
        let e = detector.events.get(usize::from(event.0))?;
        let psi = |k: u8| self.psi.get(usize::from(k)).copied().unwrap_or(0);
        Some((
            TermConfidences(e.context.iter().map(|&k| psi(k)).collect()),
            TermConfidences(e.sensor.iter().map(|w| psi(w.psi)).collect()),
        ))
    }

    /// The active phase.
    pub fn phase(&self) -> PhaseId {
        PhaseId(self.phase)
    }

    // The steps of a tick, one item at a time: the interpreter ([`Detector::tick_into`])
    // loops over its tables and calls them, a generated tick (`Detector::to_rust`) calls
    // them with constants. Indices are masked to their array's power-of-two length: one
    // instruction, no bounds check, no panic whatever they are.

    /// Stores channel `c`'s sample from `inputs` in its slot.
    #[doc(hidden)]
    #[inline(always)]
    pub fn load_sample(&mut self, c: usize, inputs: &Inputs) {
        let c = c & (MAX_CHANNELS - 1);
        self.values[c] = inputs.samples[c].to_bits();
    }

    /// Updates feature `k`, computed by `stage` of `detector`.
    #[doc(hidden)]
    #[inline(always)]
    pub fn step_feature(&mut self, k: usize, stage: &Stage, detector: &Detector) {
        let k = k & (MAX_FEATURES - 1);
        let y = stage.update(
            &mut self.stages[k],
            &self.values,
            &mut self.ring,
            &detector.weights,
        );
        self.values[(MAX_CHANNELS + k) & (MAX_SLOTS - 1)] = y;
    }

    /// Evaluates ψ `k`: `cdf` of the value in `slot`. Returns its confidence (Q15).
    #[doc(hidden)]
    #[inline(always)]
    pub fn eval_psi(&mut self, k: usize, slot: u8, cdf: &Cdf) -> u32 {
        let x = self.values[usize::from(slot) & (MAX_SLOTS - 1)];
        let q = cdf.eval(Signal::from_bits(x)).to_bits();
        self.psi[k & (MAX_PSI - 1)] = q;
        u32::from(q)
    }

    /// ψ `k`'s confidence at the last tick (Q15).
    #[doc(hidden)]
    #[inline(always)]
    pub fn psi_value(&self, k: usize) -> u32 {
        u32::from(self.psi[k & (MAX_PSI - 1)])
    }

    /// Lowers every level of event `i` and forgets its onset (it cannot be judged).
    #[doc(hidden)]
    #[inline(always)]
    pub fn reset_event(&mut self, i: usize) {
        self.events[i & (MAX_EVENTS - 1)] = EventState::default();
    }

    /// Sets ψ `k` to 0 (its feature reads a faulty channel).
    #[doc(hidden)]
    #[inline(always)]
    pub fn clear_psi(&mut self, k: usize) {
        self.psi[k & (MAX_PSI - 1)] = 0;
    }

    /// Decision levels and onset of event `i` at confidence `c`: tracks the onset, steps
    /// the alert and confirm levels, and reports them in `out`.
    #[doc(hidden)]
    #[inline(always)]
    pub fn decide_event(
        &mut self,
        i: usize,
        levels: &[LevelParams; 2],
        onset_level: u16,
        c: Confidence,
        now: Tick,
        out: &mut Output,
    ) {
        let i = i & (MAX_EVENTS - 1);
        let st = &mut self.events[i];
        let bit: EventMask = 1 << i;
        let q = c.to_bits();
        if q <= onset_level {
            st.rising = false;
        } else if !st.rising {
            st.rising = true;
            st.onset = now;
        }
        let [alert, confirm] = &mut st.levels;
        let raised_alert = alert.step(&levels[0], q);
        let raised_confirm = confirm.step(&levels[1], q);
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
}

/// The confidences of an event's terms of one kind, in configuration order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TermConfidences(Vec<u16, MAX_TERMS>);

impl TermConfidences {
    /// The confidences.
    pub fn iter(&self) -> impl Iterator<Item = Confidence> + '_ {
        self.0
            .iter()
            .map(|&b| Confidence::from_bits_clamped(u32::from(b)))
    }
}

/// A validated detector: compiled features, events, phases and decision levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Detector {
    rate_hz: f32,
    channel_names: Vec<Name, MAX_CHANNELS>,
    channel_scales: Vec<f32, MAX_CHANNELS>,
    feature_names: Vec<Name, MAX_FEATURES>,
    event_names: Vec<Name, MAX_EVENTS>,
    phase_names: Vec<Name, MAX_PHASES>,
    stages: Vec<Stage, MAX_FEATURES>,
    /// Channel dependencies of each slot.
    slot_channels: [ChannelMask; MAX_SLOTS],
    weights: [u32; STE_POOL],
    /// The distinct (feature, CDF) pairs of all events' terms.
    psis: Vec<Psi, MAX_PSI>,
    events: Vec<Event, MAX_EVENTS>,
    phases: Vec<EventMask, MAX_PHASES>,
}

fn err<T>(item: Item, problem: Problem) -> Result<T, ConfigError> {
    Err(ConfigError { item, problem })
}

/// Checks names are non-empty and distinct.
fn unique<'a>(
    names: impl Iterator<Item = &'a Name> + Clone,
    item: fn(Name) -> Item,
) -> Result<(), ConfigError> {
    for (i, n) in names.clone().enumerate() {
        if n.is_empty() {
            return err(item(n.clone()), Problem::EmptyName);
        }
        if names.clone().take(i).any(|m| m == n) {
            return err(item(n.clone()), Problem::Duplicate);
        }
    }
    Ok(())
}

fn confidence_param(
    item: &Item,
    param: &'static str,
    value: f32,
    rule: &'static str,
) -> Result<u16, ConfigError> {
    match Confidence::from_f32(value) {
        Some(c) => Ok(c.to_bits()),
        None => err(item.clone(), Problem::Level { param, value, rule }),
    }
}

fn level(
    event: &Name,
    name: &'static str,
    spec: &LevelSpec,
    rate_hz: f32,
) -> Result<LevelParams, ConfigError> {
    let item = Item::Level(event.clone(), name);
    let on = confidence_param(&item, "on", spec.on, "must be within (0, 1]")?;
    if on == 0 {
        return err(
            item,
            Problem::Level {
                param: "on",
                value: spec.on,
                rule: "must be within (0, 1]",
            },
        );
    }
    let off = confidence_param(&item, "off", spec.off, "must be within [0, on]")?;
    if off > on {
        return err(
            item,
            Problem::Level {
                param: "off",
                value: spec.off,
                rule: "must be within [0, on]",
            },
        );
    }
    let ticks = spec.dwell_ms * rate_hz / 1000.0;
    if !(ticks.is_finite() && (0.0..=65535.0).contains(&ticks)) {
        return err(item, Problem::Dwell(spec.dwell_ms));
    }
    Ok(LevelParams {
        on,
        off,
        dwell: ((ticks + 0.5) as u16).max(1),
    })
}

impl Detector {
    /// Validates a configuration and compiles it. Every rule is checked; the first
    /// violation is returned, naming the item and the value.
    pub fn build(config: &Config) -> Result<Detector, ConfigError> {
        let rate_hz = config.rate_hz;
        if !(rate_hz.is_finite() && (10.0..=50_000.0).contains(&rate_hz)) {
            return err(Item::Config, Problem::Rate(rate_hz));
        }
        if config.channels.is_empty() {
            return err(Item::Config, Problem::Empty("channel"));
        }
        if config.events.is_empty() {
            return err(Item::Config, Problem::Empty("event"));
        }
        if config.phases.is_empty() {
            return err(Item::Config, Problem::Empty("phase"));
        }
        let channel_names: Vec<Name, MAX_CHANNELS> =
            config.channels.iter().map(|c| c.name.clone()).collect();
        unique(channel_names.iter(), Item::Channel)?;
        let mut channel_scales = Vec::new();
        for c in &config.channels {
            if !(c.scale.is_finite() && c.scale > 0.0) {
                return err(Item::Channel(c.name.clone()), Problem::Scale(c.scale));
            }
            let _ = channel_scales.push(c.scale);
        }
        let feature_names: Vec<Name, MAX_FEATURES> =
            config.features.iter().map(|f| f.name.clone()).collect();
        unique(feature_names.iter(), Item::Feature)?;
        for f in &feature_names {
            if channel_names.contains(f) {
                return err(Item::Feature(f.clone()), Problem::Duplicate);
            }
        }
        let event_names: Vec<Name, MAX_EVENTS> =
            config.events.iter().map(|e| e.name.clone()).collect();
        unique(event_names.iter(), Item::Event)?;
        let phase_names: Vec<Name, MAX_PHASES> =
            config.phases.iter().map(|p| p.name.clone()).collect();
        unique(phase_names.iter(), Item::Phase)?;

        let mut slot_channels = [0 as ChannelMask; MAX_SLOTS];
        for (i, mask) in slot_channels
            .iter_mut()
            .take(channel_names.len())
            .enumerate()
        {
            *mask = 1 << i;
        }
        let mut stages = Vec::new();
        let mut weights = [0u32; STE_POOL];
        let mut pool_used = 0;
        for (k, f) in config.features.iter().enumerate() {
            let item = || Item::Feature(f.name.clone());
            let mut deps: ChannelMask = 0;
            let resolved = f.stage.map_inputs(|name| {
                let slot = channel_names.iter().position(|c| c == name).or_else(|| {
                    feature_names
                        .iter()
                        .take(k)
                        .position(|g| g == name)
                        .map(|j| MAX_CHANNELS + j)
                });
                match slot {
                    Some(s) => {
                        deps |= slot_channels.get(s).copied().unwrap_or(0);
                        Ok(s as u8)
                    }
                    None => err(item(), Problem::UnknownInput(name.clone())),
                }
            })?;
            let stage = Stage::compile(&resolved, rate_hz, &mut pool_used, &mut weights)
                .or_else(|e| err(item(), Problem::Stage(e)))?;
            if let Some(m) = slot_channels.get_mut(MAX_CHANNELS + k) {
                *m = deps;
            }
            // Capacity matches the feature list's, so this cannot fail.
            let _ = stages.push(stage);
        }

        let feature_slot = |feature: &Name, item: Item| -> Result<u8, ConfigError> {
            match feature_names.iter().position(|g| g == feature) {
                Some(j) => Ok((MAX_CHANNELS + j) as u8),
                None => err(item, Problem::UnknownFeature(feature.clone())),
            }
        };
        let mut psis: Vec<Psi, MAX_PSI> = Vec::new();
        // The index of the ψ for (feature, CDF), added if new; `bit` is the event using it.
        let mut psi_index = |feature: &Name, spec: &CdfSpec, item: Item, bit: EventMask| {
            let slot = feature_slot(feature, item.clone())?;
            let cdf = Cdf::new(spec).or_else(|c| err(item.clone(), Problem::Cdf(c)))?;
            let k = match psis.iter().position(|p| p.slot == slot && p.cdf == cdf) {
                Some(k) => k,
                None => {
                    if psis.push(Psi::new(slot, cdf, &slot_channels)).is_err() {
                        return err(item, Problem::DistinctTerms(MAX_PSI));
                    }
                    psis.len() - 1
                }
            };
            Ok::<_, ConfigError>((k as u8, use_psi(&mut psis, k, bit)))
        };
        let mut events = Vec::new();
        for (i, e) in config.events.iter().enumerate() {
            if e.sensor.is_empty() {
                return err(Item::Event(e.name.clone()), Problem::Empty("sensor term"));
            }
            let bit: EventMask = 1 << i;
            let mut context = Vec::new();
            let mut context_channels = 0;
            for t in &e.context {
                let item = Item::ContextTerm(e.name.clone(), t.feature.clone());
                let (k, channels) = psi_index(&t.feature, &t.cdf, item, bit)?;
                context_channels |= channels;
                let _ = context.push(k);
            }
            let mut sensor = Vec::new();
            let mut sensor_channels = 0;
            let mut total = 0.0f32;
            let mut total_q15 = 0u32;
            for t in &e.sensor {
                let item = Item::SensorTerm(e.name.clone(), t.feature.clone());
                let Some(weight) = Confidence::from_f32(t.weight) else {
                    return err(item, Problem::Weight(t.weight));
                };
                let (k, channels) = psi_index(&t.feature, &t.cdf, item, bit)?;
                sensor_channels |= channels;
                total += t.weight;
                total_q15 += u32::from(weight.to_bits());
                let _ = sensor.push(Weighted {
                    psi: k,
                    weight: weight.to_bits(),
                });
            }
            // A little float slack so that weights like 0.1 + 0.2 + 0.7 pass; the
            // quantized sum must still not exceed one.
            if total > 1.0 + 1e-5 || total_q15 > u32::from(Confidence::ONE.to_bits()) + 2 {
                return err(Item::Event(e.name.clone()), Problem::WeightSum(total));
            }
            let alert = level(&e.name, "alert", &e.alert, rate_hz)?;
            let confirm = level(&e.name, "confirm", &e.confirm, rate_hz)?;
            if confirm.on < alert.on {
                return err(
                    Item::Level(e.name.clone(), "confirm"),
                    Problem::Level {
                        param: "on",
                        value: e.confirm.on,
                        rule: "must be at least the alert level's on",
                    },
                );
            }
            let onset_rule = "must be within [0, alert on)";
            let onset_level = confidence_param(
                &Item::Event(e.name.clone()),
                "onset_level",
                e.onset_level,
                onset_rule,
            )?;
            if onset_level >= alert.on {
                return err(
                    Item::Event(e.name.clone()),
                    Problem::Level {
                        param: "onset_level",
                        value: e.onset_level,
                        rule: onset_rule,
                    },
                );
            }
            let _ = events.push(Event {
                context,
                sensor,
                context_channels,
                sensor_channels,
                levels: [alert, confirm],
                onset_level,
            });
        }

        let mut phases = Vec::new();
        for p in &config.phases {
            let mut mask: EventMask = 0;
            for name in &p.events {
                let Some(i) = event_names.iter().position(|n| n == name) else {
                    return err(
                        Item::Phase(p.name.clone()),
                        Problem::UnknownEvent(name.clone()),
                    );
                };
                if mask & (1 << i) != 0 {
                    return err(
                        Item::Phase(p.name.clone()),
                        Problem::RepeatedEvent(name.clone()),
                    );
                }
                mask |= 1 << i;
            }
            let _ = phases.push(mask);
        }

        Ok(Detector {
            rate_hz,
            channel_names,
            channel_scales,
            feature_names,
            event_names,
            phase_names,
            stages,
            slot_channels,
            weights,
            psis,
            events,
            phases,
        })
    }

    /// A detector with nothing configured: no channel, no event, every tick evaluates
    /// nothing. `const`, so a detector can be a static in `.bss` that
    /// [`Detector::load_image`] fills in place.
    pub const fn empty() -> Detector {
        Detector {
            rate_hz: 0.0,
            channel_names: Vec::new(),
            channel_scales: Vec::new(),
            feature_names: Vec::new(),
            event_names: Vec::new(),
            phase_names: Vec::new(),
            stages: Vec::new(),
            slot_channels: [0; MAX_SLOTS],
            weights: [0; STE_POOL],
            psis: Vec::new(),
            events: Vec::new(),
            phases: Vec::new(),
        }
    }

    /// This detector as an image (see [`crate::image`]): what the firmware embeds.
    #[cfg(feature = "std")]
    pub fn to_image(&self) -> std::vec::Vec<u8> {
        let mut w = Writer::default();
        w.0.extend_from_slice(&MAGIC);
        w.f32(self.rate_hz);
        w.count(self.channel_names.len());
        for (name, scale) in self.channel_names.iter().zip(&self.channel_scales) {
            w.name(name);
            w.f32(*scale);
        }
        w.count(self.stages.len());
        for (name, stage) in self.feature_names.iter().zip(&self.stages) {
            w.name(name);
            stage.write_image(&mut w);
        }
        self.slot_channels.iter().for_each(|&m| w.u32(m));
        self.weights.iter().for_each(|&t| w.u32(t));
        w.count(self.psis.len());
        for p in &self.psis {
            w.u8(p.slot);
            p.cdf.write_image(&mut w);
        }
        w.count(self.events.len());
        for (name, e) in self.event_names.iter().zip(&self.events) {
            w.name(name);
            w.count(e.context.len());
            e.context.iter().for_each(|&k| w.u8(k));
            w.count(e.sensor.len());
            for t in &e.sensor {
                w.u8(t.psi);
                w.u16(t.weight);
            }
            for l in &e.levels {
                w.u16(l.on);
                w.u16(l.off);
                w.u16(l.dwell);
            }
            w.u16(e.onset_level);
        }
        w.count(self.phases.len());
        for (name, mask) in self.phase_names.iter().zip(&self.phases) {
            w.name(name);
            w.u8(*mask);
        }
        w.0
    }

    /// Replaces this detector with the one in `image` (made by `Detector::to_image`),
    /// in place: the stack holds one event at a time, never a whole detector or
    /// configuration. Every value is checked; on error the detector is left empty (see
    /// [`Detector::empty`]) and the error names what was wrong.
    pub fn load_image(&mut self, image: &[u8]) -> Result<(), ImageError> {
        let result = self.read_image(&mut Reader::new(image));
        if result.is_err() {
            self.clear();
        }
        result
    }

    /// Empties every list and table in place.
    fn clear(&mut self) {
        self.rate_hz = 0.0;
        self.channel_names.clear();
        self.channel_scales.clear();
        self.feature_names.clear();
        self.event_names.clear();
        self.phase_names.clear();
        self.stages.clear();
        self.slot_channels = [0; MAX_SLOTS];
        self.weights = [0; STE_POOL];
        self.psis.clear();
        self.events.clear();
        self.phases.clear();
    }

    fn read_image(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        // Counts are checked against the capacities, so no push below can fail.
        self.clear();
        r.magic()?;
        let rate = r.f32()?;
        if !(rate.is_finite() && (10.0..=50_000.0).contains(&rate)) {
            return Err(ImageError::Invalid("detector rate"));
        }
        self.rate_hz = rate;
        for _ in 0..r.count(MAX_CHANNELS, "channel count")? {
            let name = r.name()?;
            let scale = r.f32()?;
            if !(scale.is_finite() && scale > 0.0) {
                return Err(ImageError::Invalid("channel scale"));
            }
            let _ = self.channel_names.push(name);
            let _ = self.channel_scales.push(scale);
        }
        for k in 0..r.count(MAX_FEATURES, "feature count")? {
            let _ = self.feature_names.push(r.name()?);
            let _ = self.stages.push(Stage::read_image(r, MAX_CHANNELS + k)?);
        }
        for m in self.slot_channels.iter_mut() {
            *m = r.u32()?;
        }
        for t in self.weights.iter_mut() {
            *t = r.u32()?;
        }
        if !self.stages.iter().all(|s| taps_valid(s, &self.weights)) {
            return Err(ImageError::Invalid("STE window taps"));
        }
        for _ in 0..r.count(MAX_PSI, "CDF count")? {
            let slot = r.below(MAX_SLOTS, "term feature")?;
            let psi = Psi::new(slot, Cdf::read_image(r)?, &self.slot_channels);
            let _ = self.psis.push(psi);
        }
        let events = r.count(MAX_EVENTS, "event count")?;
        for i in 0..events {
            let _ = self.event_names.push(r.name()?);
            let mut e = Event {
                context: Vec::new(),
                sensor: Vec::new(),
                context_channels: 0,
                sensor_channels: 0,
                levels: [LevelParams {
                    on: 0,
                    off: 0,
                    dwell: 0,
                }; 2],
                onset_level: 0,
            };
            let psis = self.psis.len();
            for _ in 0..r.count(MAX_TERMS, "context term count")? {
                let k = r.below(psis, "context term CDF")?;
                e.context_channels |= use_psi(&mut self.psis, usize::from(k), 1 << i);
                let _ = e.context.push(k);
            }
            let mut total = 0u32;
            for _ in 0..r.count(MAX_TERMS, "sensor term count")? {
                let k = r.below(psis, "sensor term CDF")?;
                let weight = r.u16()?;
                total += u32::from(weight);
                // Build allows the quantized weights two units of rounding above one.
                if total > u32::from(Confidence::ONE.to_bits()) + 2 {
                    return Err(ImageError::Invalid("term weights"));
                }
                e.sensor_channels |= use_psi(&mut self.psis, usize::from(k), 1 << i);
                let _ = e.sensor.push(Weighted { psi: k, weight });
            }
            if e.sensor.is_empty() {
                return Err(ImageError::Invalid("sensor term count"));
            }
            for l in e.levels.iter_mut() {
                *l = LevelParams {
                    on: r.u16()?,
                    off: r.u16()?,
                    dwell: r.u16()?,
                };
                if l.on == 0 || l.on > Confidence::ONE.to_bits() || l.off > l.on || l.dwell == 0 {
                    return Err(ImageError::Invalid("decision level"));
                }
            }
            e.onset_level = r.u16()?;
            if e.onset_level >= e.levels[0].on {
                return Err(ImageError::Invalid("onset level"));
            }
            let _ = self.events.push(e);
        }
        for _ in 0..r.count(MAX_PHASES, "phase count")? {
            let _ = self.phase_names.push(r.name()?);
            let mask = r.u8()?;
            if u32::from(mask) >> events != 0 {
                return Err(ImageError::Invalid("phase events"));
            }
            let _ = self.phases.push(mask);
        }
        if self.channel_names.is_empty() || self.events.is_empty() || self.phases.is_empty() {
            return Err(ImageError::Invalid("detector (empty)"));
        }
        r.finish()
    }

    /// A fresh state: features empty, first phase active, no level up.
    pub fn new_state(&self) -> State {
        State {
            values: [0; MAX_SLOTS],
            stages: [StageState::default(); MAX_FEATURES],
            ring: [0; STE_POOL],
            psi: [0; MAX_PSI],
            events: [EventState::default(); MAX_EVENTS],
            phase: 0,
        }
    }

    /// The detector rate in Hz.
    pub fn rate_hz(&self) -> f32 {
        self.rate_hz
    }

    /// Channel names, in sample order.
    pub fn channels(&self) -> &[Name] {
        &self.channel_names
    }

    /// Each channel's scale: the detector sees SI value × scale (see
    /// [`crate::ChannelSpec::scale`]).
    pub fn channel_scales(&self) -> &[f32] {
        &self.channel_scales
    }

    /// The sample for channel `index` from its value in SI units: scaled, rounded and
    /// saturated (NaN gives zero).
    pub fn sample_from_si(&self, index: usize, si: f64) -> Signal {
        let scale = self.channel_scales.get(index).copied().unwrap_or(1.0);
        Signal::from_f64(si * f64::from(scale))
    }

    /// Feature names, in evaluation order.
    pub fn features(&self) -> &[Name] {
        &self.feature_names
    }

    /// Event names, by [`EventId`].
    pub fn events(&self) -> &[Name] {
        &self.event_names
    }

    /// Phase names, by index.
    pub fn phases(&self) -> &[Name] {
        &self.phase_names
    }

    /// The index of a channel by name.
    pub fn channel(&self, name: &str) -> Option<usize> {
        self.channel_names.iter().position(|n| n == name)
    }

    /// An event by name.
    pub fn event(&self, name: &str) -> Option<EventId> {
        self.event_names
            .iter()
            .position(|n| n == name)
            .map(|i| EventId(i as u8))
    }

    /// A phase by name.
    pub fn phase(&self, name: &str) -> Option<PhaseId> {
        self.phase_names
            .iter()
            .position(|n| n == name)
            .map(|i| PhaseId(i as u8))
    }

    /// A phase by index, `None` if this detector has no such phase.
    pub fn phase_at(&self, index: u8) -> Option<PhaseId> {
        (usize::from(index) < self.phases.len()).then_some(PhaseId(index))
    }

    /// The events possible in a phase.
    pub fn phase_events(&self, phase: PhaseId) -> EventMask {
        self.phases.get(usize::from(phase.0)).copied().unwrap_or(0)
    }

    /// The channels an event's features read (context and sensor terms together).
    pub fn event_channels(&self, event: EventId) -> ChannelMask {
        self.events
            .get(usize::from(event.0))
            .map_or(0, |e| e.context_channels | e.sensor_channels)
    }

    /// Switches phase. Switching to another phase lowers every level and forgets onsets;
    /// "switching" to the active phase changes nothing. Features keep running in every
    /// phase, so they are warm in the new one.
    pub fn set_phase(&self, state: &mut State, phase: PhaseId) {
        if state.phase != phase.0 {
            state.phase = phase.0;
            state.events = [EventState::default(); MAX_EVENTS];
        }
    }

    /// One whole tick: features, term confidences, event confidences, decisions.
    pub fn tick(&self, state: &mut State, now: Tick, inputs: &Inputs) -> Output {
        let mut out = Output::default();
        self.tick_into(state, now, inputs, &mut out);
        out
    }

    /// [`Detector::tick`] writing into a caller's `out`, which is cleared first: no
    /// [`Output`] is built and copied per tick (the firmware's way).
    pub fn tick_into(&self, state: &mut State, now: Tick, inputs: &Inputs, out: &mut Output) {
        out.clear();
        self.update_features(state, inputs);
        self.term_confidences(state, inputs.faults, out);
        self.combine(state, out);
        self.decide(state, now, out);
    }

    /// Stage 1: stores the samples and updates every feature, in order. Features run in
    /// every phase so they are warm when the phase changes.
    pub fn update_features(&self, state: &mut State, inputs: &Inputs) {
        for c in 0..self.channel_names.len() {
            state.load_sample(c, inputs);
        }
        for (k, stage) in self.stages.iter().enumerate() {
            state.step_feature(k, stage, self);
        }
    }

    /// Stage 2: the confidence of every term of the active phase's events; terms reading a
    /// faulty channel get 0. Terms of different events that judge the same feature with
    /// the same CDF are evaluated once. Sets `evaluated`, `unjudgeable` and `degraded` in
    /// `out`.
    pub fn term_confidences(&self, state: &mut State, faults: ChannelMask, out: &mut Output) {
        let active = self.phase_events(PhaseId(state.phase));
        out.evaluated = active;
        for (k, p) in self.psis.iter().enumerate() {
            if p.events & active == 0 {
                continue;
            }
            if p.channels & faults != 0 {
                state.clear_psi(k);
            } else {
                state.eval_psi(k, p.slot, &p.cdf);
            }
        }
        if faults == 0 {
            return;
        }
        for (i, e) in self.events.iter().enumerate() {
            let bit: EventMask = 1 << i;
            if active & bit == 0 || (e.context_channels | e.sensor_channels) & faults == 0 {
                continue;
            }
            let faulty = |k: u8| {
                self.psis
                    .get(usize::from(k))
                    .is_none_or(|p| p.channels & faults != 0)
            };
            if e.context_channels & faults != 0 || e.sensor.iter().all(|t| faulty(t.psi)) {
                out.unjudgeable |= bit;
            } else if e.sensor_channels & faults != 0 {
                out.degraded |= bit;
            }
        }
    }

    /// Stage 3: eq. 14 for every judgeable event of the active phase, from the term
    /// confidences: Π context × min(1, Σ weight × sensor), each product rounded to nearest
    /// in Q15.
    pub fn combine(&self, state: &State, out: &mut Output) {
        let psi = |k: u8| state.psi_value(usize::from(k));
        let judged = out.evaluated & !out.unjudgeable;
        for (i, (e, c)) in self
            .events
            .iter()
            .zip(out.confidences.iter_mut())
            .enumerate()
        {
            if judged & (1 << i) == 0 {
                continue;
            }
            let product = e
                .context
                .iter()
                .fold(compiled::ONE, |acc, &k| compiled::product(acc, psi(k)));
            let sum: u32 = e
                .sensor
                .iter()
                .map(|t| u32::from(t.weight) * psi(t.psi))
                .sum();
            *c = compiled::eq14(product, sum);
        }
    }

    /// Stage 4: decision levels with hysteresis and dwell, and onset tracking, for the
    /// active phase's events. An unjudgeable event has every level lowered.
    pub fn decide(&self, state: &mut State, now: Tick, out: &mut Output) {
        for (i, e) in self.events.iter().enumerate() {
            let bit: EventMask = 1 << i;
            if out.evaluated & bit == 0 {
                continue;
            }
            if out.unjudgeable & bit != 0 {
                state.reset_event(i);
                continue;
            }
            let c = out.confidences[i & (MAX_EVENTS - 1)];
            state.decide_event(i, &e.levels, e.onset_level, c, now, out);
        }
    }
}
