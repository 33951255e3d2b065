//! The detector's configuration as a user describes it: channels, features, events with
//! their confidence functions, weights and decision levels, and phases. Plain data, loaded
//! from TOML (the format of `configs/*.toml`); [`crate::compile`] validates it.
//!
//! Names and lists are plain `String`s and `Vec`s: what does not fit the detector (a name
//! longer than [`detector_core::NAME_LEN`], more items than a capacity such as [`detector_core::MAX_CHANNELS`]) is
//! refused by [`crate::compile`], naming the item and the limit.

use detector_core::{CdfError, CdfSpec, ImageError, NAME_LEN, StageError, StageSpec};

/// A whole detector configuration.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Detector rate in Hz (ticks per second), 10..=50 000. The default configuration runs
    /// at 5 000 Hz.
    pub rate_hz: f32,
    /// Input channels, in the order the caller supplies samples.
    #[serde(rename = "channel")]
    pub channels: Vec<ChannelSpec>,
    /// Features, computed every tick in this order; each may read channels and earlier
    /// features.
    #[serde(rename = "feature")]
    pub features: Vec<FeatureSpec>,
    /// Events and how their confidence is computed (eq. 14) and decided.
    #[serde(rename = "event")]
    pub events: Vec<EventSpec>,
    /// Manipulation phases, each with the events possible in it. The first is active after
    /// start.
    #[serde(rename = "phase")]
    pub phases: Vec<PhaseSpec>,
}

/// An input channel.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// The channel's name, as in trace column headers.
    pub name: String,
    /// The unit the detector works in for this channel, for documentation and plots
    /// (e.g. `N`, `m/s^2`, `mm`).
    pub unit: String,
    /// The detector sees each sample as its SI value times `scale` (default 1), in `unit`.
    /// For a quantity much smaller than one SI unit, such as a position error in metres,
    /// a scale of 1000 (`unit = "mm"`) keeps resolution: a [`detector_core::Signal`] resolves
    /// 2⁻¹⁶ of the working unit. CDF parameters of features reading the channel are in
    /// the working unit. Positive and finite.
    #[serde(default = "unit_scale")]
    pub scale: f32,
}

fn unit_scale() -> f32 {
    1.0
}

/// A feature: a named stage.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeatureSpec {
    /// The feature's name.
    pub name: String,
    /// How it is computed.
    pub stage: StageSpec<String>,
}

/// A context-based term of an event: its confidence multiplies the event's confidence, so
/// it can veto the event.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContextTerm {
    /// The feature judged.
    pub feature: String,
    /// How its value maps to a confidence for this event.
    pub cdf: CdfSpec,
}

/// A sensor-based term of an event: its confidence, times its weight, adds to the event's
/// weighted sum.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorTerm {
    /// The feature judged.
    pub feature: String,
    /// Its weight in [0, 1]; an event's weights sum to at most 3 (eq. 14's sum saturates at
    /// 1: terms whose weights together exceed 1 are each sufficient to that extent).
    pub weight: f32,
    /// How its value maps to a confidence for this event.
    pub cdf: CdfSpec,
}

/// A decision level with hysteresis, a minimum dwell and a hold.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LevelSpec {
    /// The level is raised once the confidence has stayed at or above `on` for the dwell.
    pub on: f32,
    /// ... and cleared once the confidence has stayed below `off` (≤ `on`) for the hold.
    pub off: f32,
    /// Minimum time at or above `on` before the level is raised, in ms: the level is
    /// raised on the n-th consecutive tick at or above `on`, n = max(1, round(dwell_ms ·
    /// rate / 1000)); 0 (the default) raises it on the first such tick.
    #[serde(default)]
    pub dwell_ms: f32,
    /// Minimum time below `off` before a raised level is cleared, in ms, rounded to ticks as
    /// the dwell; 0 (the default) clears it on the first such tick. A confidence that dips
    /// below `off` for less than the hold and comes back keeps the level up: one physical
    /// event, one rise of the level.
    #[serde(default)]
    pub hold_ms: f32,
    /// A shorter dwell, taken once a feature has shown what the event is: the level is
    /// raised after `early.dwell_ms` instead once the feature has been above its level at
    /// one of the ticks of the run at or above `on`. Default: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub early: Option<EarlySpec>,
}

/// A level's shorter dwell (see [`LevelSpec::early`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EarlySpec {
    /// The feature watched; it may read only channels the event's terms read, so that a
    /// fault on them degrades the event (while an event is degraded, nothing shows).
    pub feature: String,
    /// The level the feature must pass, in its unit; below 32768 in magnitude.
    pub above: f32,
    /// The shorter dwell in ms, rounded to ticks as `dwell_ms`; at most the level's dwell
    /// once both are rounded.
    pub dwell_ms: f32,
}

/// An event (eq. 14): Ψ = Π context confidences × Σ weight × sensor confidence.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EventSpec {
    /// The event's name (e.g. `contact`).
    pub name: String,
    /// Context-based terms, at most [`detector_core::MAX_TERMS`].
    #[serde(default)]
    pub context: Vec<ContextTerm>,
    /// Sensor-based terms, 1 to [`detector_core::MAX_TERMS`].
    pub sensor: Vec<SensorTerm>,
    /// The early-warning level.
    pub alert: LevelSpec,
    /// The confirmation level (`on` at least the alert's).
    pub confirm: LevelSpec,
    /// The onset reported with a decision is the first tick of the current run of
    /// confidence above this level, in [0, alert.on). Default 0: when the confidence
    /// first left zero.
    #[serde(default)]
    pub onset_level: f32,
    /// Events this one excludes: while this event's confirm level is up, their levels are
    /// held down, so that what follows a physical event (a struck finger's ringing, a
    /// contact's stalled arm) is not reported as another. Default: none.
    #[serde(default)]
    pub excludes: Vec<String>,
}

/// A manipulation phase.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PhaseSpec {
    /// The phase's name (e.g. `approach`).
    pub name: String,
    /// The events possible in it; only these are evaluated while it is active.
    pub events: Vec<String>,
}

/// The item of a configuration an error is about.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Item {
    /// The configuration as a whole.
    Config,
    /// A channel.
    Channel(String),
    /// A feature.
    Feature(String),
    /// An event.
    Event(String),
    /// A sensor term of an event: (event, feature).
    SensorTerm(String, String),
    /// A context term of an event: (event, feature).
    ContextTerm(String, String),
    /// A decision level of an event: (event, `alert` or `confirm`).
    Level(String, &'static str),
    /// A phase.
    Phase(String),
}

impl core::fmt::Display for Item {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Item::Config => write!(f, "configuration"),
            Item::Channel(n) => write!(f, "channel '{n}'"),
            Item::Feature(n) => write!(f, "feature '{n}'"),
            Item::Event(n) => write!(f, "event '{n}'"),
            Item::SensorTerm(e, t) => write!(f, "event '{e}', sensor term '{t}'"),
            Item::ContextTerm(e, t) => write!(f, "event '{e}', context term '{t}'"),
            Item::Level(e, l) => write!(f, "event '{e}', {l} level"),
            Item::Phase(n) => write!(f, "phase '{n}'"),
        }
    }
}

/// What is wrong with an item.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Problem {
    /// `rate_hz` is not finite or outside 10..=50 000.
    Rate(f32),
    /// The name is empty.
    EmptyName,
    /// The name is longer than a detector holds (its length in bytes given).
    NameLength(usize),
    /// The name has a character outside the allowed set (letters, digits, `_`, `-`).
    NameCharacter(char),
    /// The name is one of the trace format's own columns (`t`, `phase`, `truth`).
    ReservedName,
    /// A list has more items than a detector holds: (what, how many, the limit).
    TooMany(&'static str, usize, usize),
    /// A channel's unit is longer than 12 bytes or has a control character.
    Unit,
    /// Another item of the same kind has this name.
    Duplicate,
    /// A list that must not be empty is (its name given).
    Empty(&'static str),
    /// A feature reads a name that is neither a channel nor an earlier feature.
    UnknownInput(String),
    /// A term names an undefined feature.
    UnknownFeature(String),
    /// A phase or an exclusion names an undefined event.
    UnknownEvent(String),
    /// A phase or an exclusion lists the same event twice.
    RepeatedEvent(String),
    /// An event excludes itself.
    ExcludesItself,
    /// A feature's parameters.
    Stage(StageError),
    /// A confidence distribution function's parameters.
    Cdf(CdfError),
    /// A weight is not within [0, 1].
    Weight(f32),
    /// The sensor weights sum above 3.
    WeightSum(f32),
    /// A confidence level (`on`, `off` or `onset_level`) is not within its allowed range.
    Level {
        /// The parameter.
        param: &'static str,
        /// Its value.
        value: f32,
        /// What it must satisfy.
        rule: &'static str,
    },
    /// A level's dwell or hold time is negative, not finite, or longer than 65 535 ticks.
    Time {
        /// `dwell_ms` or `hold_ms`.
        param: &'static str,
        /// Its value.
        value: f32,
    },
    /// A channel's scale is not a positive, finite number.
    Scale(f32),
    /// An early dwell's level is not finite or not below 32768 in magnitude.
    EarlyLevel(f32),
    /// An early dwell is longer than the level's own dwell, in ticks: (early, own), in ms.
    EarlyDwell(f32, f32),
    /// An early dwell's feature reads channel `.1`, which none of the event's terms read
    /// (the feature's name first).
    EarlyChannel(String, String),
    /// The term would be one distinct (feature, CDF) pair more than the detector holds
    /// (the limit given).
    DistinctTerms(usize),
    /// The compiled detector's image was refused by the core's loader (a bug of the
    /// compiler, never of a configuration).
    Image(ImageError),
}

impl core::fmt::Display for Problem {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Problem::Rate(r) => write!(f, "rate_hz = {r} must be between 10 and 50000"),
            Problem::EmptyName => write!(f, "the name is empty"),
            Problem::NameLength(n) => {
                write!(
                    f,
                    "the name is {n} bytes long, more than the {NAME_LEN} allowed"
                )
            }
            Problem::NameCharacter(c) => write!(
                f,
                "the name has the character {c:?}; names are letters, digits, '_' and '-'"
            ),
            Problem::ReservedName => write!(
                f,
                "the name is a column of the trace format (t, phase, truth); choose another"
            ),
            Problem::TooMany(what, n, limit) => {
                write!(f, "{n} {what}s, more than the {limit} a detector holds")
            }
            Problem::Unit => write!(
                f,
                "unit must be at most 12 bytes, without control characters"
            ),
            Problem::Duplicate => write!(f, "the name is used twice"),
            Problem::Empty(what) => write!(f, "needs at least one {what}"),
            Problem::UnknownInput(n) => write!(
                f,
                "reads '{n}', which is neither a channel nor a feature defined before it"
            ),
            Problem::UnknownFeature(n) => write!(f, "names feature '{n}', which is not defined"),
            Problem::UnknownEvent(n) => write!(f, "names event '{n}', which is not defined"),
            Problem::RepeatedEvent(n) => write!(f, "lists event '{n}' twice"),
            Problem::ExcludesItself => write!(f, "excludes itself"),
            Problem::Stage(e) => write!(f, "{e}"),
            Problem::Cdf(e) => write!(f, "cdf: {e}"),
            Problem::Weight(w) => write!(f, "weight = {w} must be within [0, 1]"),
            Problem::WeightSum(s) => write!(f, "sensor weights sum to {s:.3}, above 3"),
            Problem::Level { param, value, rule } => write!(f, "{param} = {value} {rule}"),
            Problem::Scale(k) => write!(f, "scale = {k} must be a positive, finite number"),
            Problem::EarlyLevel(v) => write!(
                f,
                "early.above = {v} must be finite and below 32768 in magnitude"
            ),
            Problem::EarlyDwell(early, own) => write!(
                f,
                "early.dwell_ms = {early} must be at most the level's dwell_ms = {own}"
            ),
            Problem::EarlyChannel(feature, channel) => write!(
                f,
                "early.feature '{feature}' reads channel '{channel}', which none of the event's terms read (a fault on it would go unnoticed)"
            ),
            Problem::DistinctTerms(n) => write!(
                f,
                "the events' terms judge more than {n} distinct (feature, CDF) pairs"
            ),
            Problem::Image(e) => write!(f, "the compiled image does not load: {e}"),
            Problem::Time { param, value } => write!(
                f,
                "{param} = {value} must be a finite, non-negative time of at most 65535 ticks"
            ),
        }
    }
}

/// Something legal but probably unintended in a configuration: the tools print it, a build
/// script reports it as a Cargo warning.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Warning {
    /// The event is in no phase, so it is never evaluated.
    EventInNoPhase(String),
    /// The phase lists no event, so nothing is detected while it is active.
    PhaseWithoutEvents(String),
}

impl core::fmt::Display for Warning {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Warning::EventInNoPhase(e) => {
                write!(f, "event '{e}' is in no phase, so it is never evaluated")
            }
            Warning::PhaseWithoutEvents(p) => write!(
                f,
                "phase '{p}' lists no event, so nothing is detected while it is active"
            ),
        }
    }
}

/// A rejected configuration: which item, and what is wrong with it.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigError {
    /// The offending item.
    pub item: Item,
    /// What is wrong.
    pub problem: Problem,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}: {}", self.item, self.problem)
    }
}

impl core::error::Error for ConfigError {}
