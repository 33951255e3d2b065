//! A configuration validated and turned into the detector's fixed-point tables
//! ([`Compiled`]): what the image writer ([`Compiled::image`]) and the code generator
//! ([`Compiled::to_rust`]) both read. Every rule is checked here with an error that names
//! the item; the core's image loader checks the invariants the tick relies on once more.

use detector_core::feature::{MAX_SLOTS, Stage, WINDOW_POOL};
use detector_core::{
    Cdf, CdfSpec, ChannelMask, Confidence, Early, EventMask, LevelParams, MAX_CHANNELS,
    MAX_DISTINCT_TERMS, MAX_EVENTS, MAX_FEATURES, MAX_PHASES, MAX_TERMS, NAME_LEN, Name,
};

use crate::config::{Config, ConfigError, EarlySpec, EventSpec, Item, LevelSpec, Problem, Warning};

/// One feature judged by one CDF (the paper's ψ): evaluated once per tick however many
/// terms of however many events name the same pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Psi {
    /// The slot (channel or feature) judged.
    pub slot: u8,
    /// How it is judged.
    pub cdf: Cdf,
    /// The channels the slot depends on: a fault on any of them makes ψ 0.
    pub channels: ChannelMask,
    /// The events whose terms use it.
    pub events: EventMask,
}

/// A sensor term: which ψ, and its weight (Q15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Weighted {
    /// Index into [`Compiled::psis`].
    pub psi: u8,
    /// The weight, Q15.
    pub weight: u16,
}

/// An event's compiled terms and decision levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Event {
    /// The event's name.
    pub name: Name,
    /// Context terms, as indices into [`Compiled::psis`].
    pub context: Vec<u8>,
    /// Sensor terms.
    pub sensor: Vec<Weighted>,
    /// The channels the context terms read, together.
    pub context_channels: ChannelMask,
    /// The channels the sensor terms read, together.
    pub sensor_channels: ChannelMask,
    /// Alert, then confirm.
    pub levels: [LevelParams; 2],
    /// Confidence (Q15) above which a rise counts as the event's onset.
    pub onset_level: u16,
    /// The events (bit i: event i) whose confirm level, while up, holds this one's down.
    pub excluded_by: EventMask,
}

/// A validated configuration in the detector's fixed-point form.
#[derive(Clone, Debug, PartialEq)]
pub struct Compiled {
    /// Ticks per second.
    pub rate_hz: f32,
    /// Channels: name and scale, in sample order.
    pub channels: Vec<(Name, f32)>,
    /// Features: name and compiled stage, in evaluation order.
    pub features: Vec<(Name, Stage)>,
    /// The channels each slot depends on.
    pub slot_channels: [ChannelMask; MAX_SLOTS],
    /// Tapered STE windows' taps (Q24), at each window's offset.
    pub taps: [u32; WINDOW_POOL],
    /// The distinct (feature, CDF) pairs of all events' terms.
    pub psis: Vec<Psi>,
    /// Events, by index.
    pub events: Vec<Event>,
    /// Phases: name and the events possible in it.
    pub phases: Vec<(Name, EventMask)>,
    /// What is legal but probably unintended.
    pub warnings: Vec<Warning>,
}

fn err<T>(item: Item, problem: Problem) -> Result<T, ConfigError> {
    Err(ConfigError { item, problem })
}

/// Names the trace format uses for its own columns.
const RESERVED: [&str; 3] = ["t", "phase", "truth"];

/// A name a detector can hold and a trace or CSV output can carry: 1 to [`NAME_LEN`]
/// bytes of letters, digits, `_` and `-`, not a column of the trace format.
fn check_name(name: &str) -> Result<(), Problem> {
    if name.is_empty() {
        return Err(Problem::EmptyName);
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-'))
    {
        return Err(Problem::NameCharacter(c));
    }
    if name.len() > NAME_LEN {
        return Err(Problem::NameLength(name.len()));
    }
    if RESERVED.contains(&name) {
        return Err(Problem::ReservedName);
    }
    Ok(())
}

/// The core's form of a name [`check_name`] accepted.
fn core_name(name: &str) -> Name {
    Name::try_from(name).unwrap_or_default()
}

/// Checks names are valid and distinct.
fn unique<'a>(
    names: impl Iterator<Item = &'a String> + Clone,
    item: fn(String) -> Item,
) -> Result<(), ConfigError> {
    for (i, n) in names.clone().enumerate() {
        check_name(n).or_else(|p| err(item(n.clone()), p))?;
        if names.clone().take(i).any(|m| m == n) {
            return err(item(n.clone()), Problem::Duplicate);
        }
    }
    Ok(())
}

/// At most `limit` items of a list.
fn at_most(what: &'static str, n: usize, limit: usize, item: Item) -> Result<(), ConfigError> {
    if n > limit {
        return err(item, Problem::TooMany(what, n, limit));
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
    event: &str,
    name: &'static str,
    spec: &LevelSpec,
    rate_hz: f32,
    early: Option<Early>,
) -> Result<LevelParams, ConfigError> {
    let item = Item::Level(event.to_owned(), name);
    let on_rule = "must be within (0, 1]";
    let on = confidence_param(&item, "on", spec.on, on_rule)?;
    if on == 0 {
        return err(
            item,
            Problem::Level {
                param: "on",
                value: spec.on,
                rule: on_rule,
            },
        );
    }
    let off_rule = "must be within [0, on]";
    let off = confidence_param(&item, "off", spec.off, off_rule)?;
    if off > on {
        return err(
            item,
            Problem::Level {
                param: "off",
                value: spec.off,
                rule: off_rule,
            },
        );
    }
    let dwell = ticks_of(&item, "dwell_ms", spec.dwell_ms, rate_hz)?;
    let hold = ticks_of(&item, "hold_ms", spec.hold_ms, rate_hz)?;
    if let (Some(e), Some(spec_early)) = (early, &spec.early)
        && e.dwell() > dwell
    {
        return err(
            item,
            Problem::EarlyDwell(spec_early.dwell_ms, spec.dwell_ms),
        );
    }
    // `on` in (0, 1], `off` at most `on`, a dwell and a hold of at least one tick, an early
    // dwell no longer than the dwell: always a level.
    LevelParams::new(on, off, dwell, hold, early).ok_or(ConfigError {
        item,
        problem: Problem::Time {
            param: "dwell_ms",
            value: spec.dwell_ms,
        },
    })
}

/// A level's time `ms` as ticks at `rate_hz`: max(1, round(ms · rate / 1000)).
fn ticks_of(item: &Item, param: &'static str, ms: f32, rate_hz: f32) -> Result<u16, ConfigError> {
    let ticks = ms * rate_hz / 1000.0;
    if !(ticks.is_finite() && (0.0..=65535.0).contains(&ticks)) {
        return err(item.clone(), Problem::Time { param, value: ms });
    }
    Ok(((ticks + 0.5) as u16).max(1))
}

/// Validates a configuration and compiles it. Every rule is checked; the first violation
/// is returned, naming the item and the value.
pub fn compile(config: &Config) -> Result<Compiled, ConfigError> {
    let rate_hz = config.rate_hz;
    if !(rate_hz.is_finite() && (10.0..=50_000.0).contains(&rate_hz)) {
        return err(Item::Config, Problem::Rate(rate_hz));
    }
    for (list, empty) in [
        (config.channels.is_empty(), "channel"),
        (config.events.is_empty(), "event"),
        (config.phases.is_empty(), "phase"),
    ] {
        if list {
            return err(Item::Config, Problem::Empty(empty));
        }
    }
    for (what, n, limit) in [
        ("channel", config.channels.len(), MAX_CHANNELS),
        ("feature", config.features.len(), MAX_FEATURES),
        ("event", config.events.len(), MAX_EVENTS),
        ("phase", config.phases.len(), MAX_PHASES),
    ] {
        at_most(what, n, limit, Item::Config)?;
    }
    check_names(config)?;
    let mut c = Compiled {
        rate_hz,
        channels: Vec::new(),
        features: Vec::new(),
        slot_channels: [0; MAX_SLOTS],
        taps: [0; WINDOW_POOL],
        psis: Vec::new(),
        events: Vec::new(),
        phases: Vec::new(),
        warnings: Vec::new(),
    };
    c.add_channels(config)?;
    c.add_features(config)?;
    for (i, e) in config.events.iter().enumerate() {
        c.add_event(config, i, e)?;
    }
    c.add_exclusions(config)?;
    c.add_phases(config)?;
    c.warn(config);
    Ok(c)
}

/// Every name non-empty and unique in its kind; no feature named like a channel.
fn check_names(config: &Config) -> Result<(), ConfigError> {
    unique(config.channels.iter().map(|c| &c.name), Item::Channel)?;
    unique(config.features.iter().map(|f| &f.name), Item::Feature)?;
    if let Some(f) = config
        .features
        .iter()
        .find(|f| config.channels.iter().any(|c| c.name == f.name))
    {
        return err(Item::Feature(f.name.clone()), Problem::Duplicate);
    }
    unique(config.events.iter().map(|e| &e.name), Item::Event)?;
    unique(config.phases.iter().map(|p| &p.name), Item::Phase)
}

impl Compiled {
    fn add_channels(&mut self, config: &Config) -> Result<(), ConfigError> {
        for (i, ch) in config.channels.iter().enumerate() {
            if !(ch.scale.is_finite() && ch.scale > 0.0) {
                return err(Item::Channel(ch.name.clone()), Problem::Scale(ch.scale));
            }
            if ch.unit.len() > 12 || ch.unit.chars().any(char::is_control) {
                return err(Item::Channel(ch.name.clone()), Problem::Unit);
            }
            self.channels.push((core_name(&ch.name), ch.scale));
            if let Some(mask) = self.slot_channels.get_mut(i) {
                *mask = 1 << i;
            }
        }
        Ok(())
    }

    /// The slot a feature reads: a channel, or a feature declared before feature `k`.
    fn input_slot(&self, config: &Config, k: usize, name: &String) -> Option<usize> {
        let channel = config.channels.iter().position(|c| &c.name == name);
        channel.or_else(|| {
            config
                .features
                .iter()
                .take(k)
                .position(|g| &g.name == name)
                .map(|j| MAX_CHANNELS + j)
        })
    }

    fn add_features(&mut self, config: &Config) -> Result<(), ConfigError> {
        let mut pool_used = 0;
        for (k, f) in config.features.iter().enumerate() {
            let item = || Item::Feature(f.name.clone());
            let mut deps: ChannelMask = 0;
            let resolved = f
                .stage
                .map_inputs(|name| match self.input_slot(config, k, name) {
                    Some(s) => {
                        deps |= self.slot_channels.get(s).copied().unwrap_or(0);
                        Ok(s as u8)
                    }
                    None => err(item(), Problem::UnknownInput(name.clone())),
                })?;
            let stage = Stage::compile(&resolved, self.rate_hz, &mut pool_used, &mut self.taps)
                .or_else(|e| err(item(), Problem::Stage(e)))?;
            if let Some(m) = self.slot_channels.get_mut(MAX_CHANNELS + k) {
                *m = deps;
            }
            self.features.push((core_name(&f.name), stage));
        }
        Ok(())
    }

    /// The index of the ψ for (feature, CDF), added if new and marked as used by `event`;
    /// and the channels it reads.
    fn psi(
        &mut self,
        config: &Config,
        feature: &String,
        spec: &CdfSpec,
        item: Item,
        event: usize,
    ) -> Result<(u8, ChannelMask), ConfigError> {
        let Some(j) = config.features.iter().position(|g| &g.name == feature) else {
            return err(item, Problem::UnknownFeature(feature.clone()));
        };
        let slot = (MAX_CHANNELS + j) as u8;
        let cdf = Cdf::new(spec).or_else(|c| err(item.clone(), Problem::Cdf(c)))?;
        let k = match self
            .psis
            .iter()
            .position(|p| p.slot == slot && p.cdf == cdf)
        {
            Some(k) => k,
            None if self.psis.len() < MAX_DISTINCT_TERMS => {
                self.psis.push(Psi {
                    slot,
                    cdf,
                    channels: self
                        .slot_channels
                        .get(usize::from(slot))
                        .copied()
                        .unwrap_or(0),
                    events: 0,
                });
                self.psis.len() - 1
            }
            None => return err(item, Problem::DistinctTerms(MAX_DISTINCT_TERMS)),
        };
        let psi = &mut self.psis[k];
        psi.events |= 1 << event;
        Ok((k as u8, psi.channels))
    }

    fn add_event(&mut self, config: &Config, i: usize, e: &EventSpec) -> Result<(), ConfigError> {
        if e.sensor.is_empty() {
            return err(Item::Event(e.name.clone()), Problem::Empty("sensor term"));
        }
        let item = || Item::Event(e.name.clone());
        at_most("context term", e.context.len(), MAX_TERMS, item())?;
        at_most("sensor term", e.sensor.len(), MAX_TERMS, item())?;
        let (mut context, mut context_channels) = (Vec::new(), 0);
        for t in &e.context {
            let item = Item::ContextTerm(e.name.clone(), t.feature.clone());
            let (k, channels) = self.psi(config, &t.feature, &t.cdf, item, i)?;
            context_channels |= channels;
            context.push(k);
        }
        let (mut sensor, mut sensor_channels) = (Vec::new(), 0);
        let mut total = 0.0f32;
        let mut total_q15 = 0u32;
        for t in &e.sensor {
            let item = Item::SensorTerm(e.name.clone(), t.feature.clone());
            let Some(weight) = Confidence::from_f32(t.weight) else {
                return err(item, Problem::Weight(t.weight));
            };
            let (k, channels) = self.psi(config, &t.feature, &t.cdf, item, i)?;
            sensor_channels |= channels;
            total += t.weight;
            total_q15 += u32::from(weight.to_bits());
            sensor.push(Weighted {
                psi: k,
                weight: weight.to_bits(),
            });
        }
        // A little float slack so that weights like 0.1 + 0.2 + 0.7 pass; the quantized
        // sum must still not exceed what the loader allows.
        if total > 3.0 + 1e-5 || total_q15 > detector_core::MAX_WEIGHT_SUM_Q15 {
            return err(Item::Event(e.name.clone()), Problem::WeightSum(total));
        }
        let reads = context_channels | sensor_channels;
        let early = |name, level: &LevelSpec| {
            let item = Item::Level(e.name.clone(), name);
            let spec = level.early.as_ref();
            spec.map(|spec| self.early(config, spec, item, reads))
                .transpose()
        };
        let early = [early("alert", &e.alert)?, early("confirm", &e.confirm)?];
        let levels = event_levels(e, self.rate_hz, early)?;
        self.events.push(Event {
            name: core_name(&e.name),
            context,
            sensor,
            context_channels,
            sensor_channels,
            levels,
            onset_level: onset_level(e, levels[0].on())?,
            excluded_by: 0,
        });
        Ok(())
    }

    /// A level's early dwell: its feature, which reads only channels in `reads` (the
    /// event's terms'), and its level in the feature's unit.
    fn early(
        &self,
        config: &Config,
        spec: &EarlySpec,
        item: Item,
        reads: ChannelMask,
    ) -> Result<Early, ConfigError> {
        let Some(j) = config.features.iter().position(|g| g.name == spec.feature) else {
            return err(item, Problem::UnknownFeature(spec.feature.clone()));
        };
        let slot = MAX_CHANNELS + j;
        let unread = self.slot_channels.get(slot).copied().unwrap_or(0) & !reads;
        if unread != 0 {
            let channel = config
                .channels
                .get(unread.trailing_zeros() as usize)
                .map(|c| c.name.clone())
                .unwrap_or_default();
            return err(item, Problem::EarlyChannel(spec.feature.clone(), channel));
        }
        let Some(above) = detector_core::Signal::parameter(spec.above) else {
            return err(item, Problem::EarlyLevel(spec.above));
        };
        let dwell = ticks_of(&item, "early.dwell_ms", spec.dwell_ms, self.rate_hz)?;
        // A feature's slot and a dwell of at least one tick: always an early dwell.
        Early::new(slot as u8, above.to_bits(), dwell).ok_or(ConfigError {
            item,
            problem: Problem::Time {
                param: "early.dwell_ms",
                value: spec.dwell_ms,
            },
        })
    }

    /// Each event's `excludes`, turned around: the events whose confirm level holds it down.
    fn add_exclusions(&mut self, config: &Config) -> Result<(), ConfigError> {
        for (i, e) in config.events.iter().enumerate() {
            let item = || Item::Event(e.name.clone());
            let mut seen: EventMask = 0;
            for name in &e.excludes {
                let Some(j) = config.events.iter().position(|o| &o.name == name) else {
                    return err(item(), Problem::UnknownEvent(name.clone()));
                };
                if j == i {
                    return err(item(), Problem::ExcludesItself);
                }
                if seen & (1 << j) != 0 {
                    return err(item(), Problem::RepeatedEvent(name.clone()));
                }
                seen |= 1 << j;
                self.events[j].excluded_by |= 1 << i;
            }
        }
        Ok(())
    }

    fn add_phases(&mut self, config: &Config) -> Result<(), ConfigError> {
        for p in &config.phases {
            let mut mask: EventMask = 0;
            for name in &p.events {
                let item = || Item::Phase(p.name.clone());
                let Some(i) = config.events.iter().position(|e| &e.name == name) else {
                    return err(item(), Problem::UnknownEvent(name.clone()));
                };
                if mask & (1 << i) != 0 {
                    return err(item(), Problem::RepeatedEvent(name.clone()));
                }
                mask |= 1 << i;
            }
            self.phases.push((core_name(&p.name), mask));
        }
        Ok(())
    }
}

impl Compiled {
    /// Events in no phase, phases without events.
    fn warn(&mut self, config: &Config) {
        let used = self.phases.iter().fold(0, |all, (_, mask)| all | mask);
        for (i, e) in config.events.iter().enumerate() {
            if used & (1 << i) == 0 {
                self.warnings.push(Warning::EventInNoPhase(e.name.clone()));
            }
        }
        for p in config.phases.iter().filter(|p| p.events.is_empty()) {
            self.warnings
                .push(Warning::PhaseWithoutEvents(p.name.clone()));
        }
    }
}

/// An event's alert and confirm levels; confirm's `on` at least alert's.
fn event_levels(
    e: &EventSpec,
    rate_hz: f32,
    early: [Option<Early>; 2],
) -> Result<[LevelParams; 2], ConfigError> {
    let alert = level(&e.name, "alert", &e.alert, rate_hz, early[0])?;
    let confirm = level(&e.name, "confirm", &e.confirm, rate_hz, early[1])?;
    if confirm.on() < alert.on() {
        return err(
            Item::Level(e.name.clone(), "confirm"),
            Problem::Level {
                param: "on",
                value: e.confirm.on,
                rule: "must be at least the alert level's on",
            },
        );
    }
    Ok([alert, confirm])
}

/// An event's onset level, below its alert level's `on`.
fn onset_level(e: &EventSpec, alert_on: u16) -> Result<u16, ConfigError> {
    let item = Item::Event(e.name.clone());
    let rule = "must be within [0, alert on)";
    let onset = confidence_param(&item, "onset_level", e.onset_level, rule)?;
    if onset >= alert_on {
        return err(
            item,
            Problem::Level {
                param: "onset_level",
                value: e.onset_level,
                rule,
            },
        );
    }
    Ok(onset)
}
