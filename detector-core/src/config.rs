//! The detector's configuration as a user describes it: channels, features, events with
//! their confidence functions, weights and decision levels, and phases. Plain data; a
//! [`crate::Detector`] is built from it once, which validates everything.
//!
//! No allocation: names and lists are `heapless` with the capacities in the crate root.
//! With the `serde` feature the configuration (de)serializes (postcard on the chip); with
//! `std` it loads from TOML, the format of `configs/*.toml`.

use heapless::{String, Vec};

use crate::cdf::{CdfError, CdfSpec};
use crate::feature::{StageError, StageSpec};
use crate::{MAX_CHANNELS, MAX_EVENTS, MAX_FEATURES, MAX_PHASES, MAX_TERMS, NAME_LEN};

/// A name of a channel, feature, event or phase: 1 to [`NAME_LEN`] bytes.
pub type Name = String<NAME_LEN>;

/// A whole detector configuration.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct Config {
    /// Detector rate in Hz (ticks per second), 10..=50 000. The default configuration runs
    /// at 5 000 Hz.
    pub rate_hz: f32,
    /// Input channels, in the order the caller supplies samples.
    #[cfg_attr(feature = "serde", serde(rename = "channel"))]
    pub channels: Vec<ChannelSpec, MAX_CHANNELS>,
    /// Features, computed every tick in this order; each may read channels and earlier
    /// features.
    #[cfg_attr(feature = "serde", serde(rename = "feature"))]
    pub features: Vec<FeatureSpec, MAX_FEATURES>,
    /// Events and how their confidence is computed (eq. 14) and decided.
    #[cfg_attr(feature = "serde", serde(rename = "event"))]
    pub events: Vec<EventSpec, MAX_EVENTS>,
    /// Manipulation phases, each with the events possible in it. The first is active after
    /// start.
    #[cfg_attr(feature = "serde", serde(rename = "phase"))]
    pub phases: Vec<PhaseSpec, MAX_PHASES>,
}

/// An input channel.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ChannelSpec {
    /// The channel's name, as in trace column headers.
    pub name: Name,
    /// The unit the detector works in for this channel, for documentation and plots
    /// (e.g. `N`, `m/s^2`, `mm`).
    pub unit: String<12>,
    /// The detector sees each sample as its SI value times `scale` (default 1), in `unit`.
    /// For a quantity much smaller than one SI unit, such as a position error in metres,
    /// a scale of 1000 (`unit = "mm"`) keeps resolution: a [`crate::Signal`] resolves
    /// 2⁻¹⁶ of the working unit. CDF parameters of features reading the channel are in
    /// the working unit. Positive and finite.
    #[cfg_attr(feature = "serde", serde(default = "unit_scale"))]
    pub scale: f32,
}

#[cfg(feature = "serde")]
fn unit_scale() -> f32 {
    1.0
}

/// A feature: a named stage.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct FeatureSpec {
    /// The feature's name.
    pub name: Name,
    /// How it is computed.
    pub stage: StageSpec<Name>,
}

/// A context-based term of an event: its confidence multiplies the event's confidence, so
/// it can veto the event.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct ContextTerm {
    /// The feature judged.
    pub feature: Name,
    /// How its value maps to a confidence for this event.
    pub cdf: CdfSpec,
}

/// A sensor-based term of an event: its confidence, times its weight, adds to the event's
/// weighted sum.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct SensorTerm {
    /// The feature judged.
    pub feature: Name,
    /// Its weight in [0, 1]; an event's weights sum to at most 1.
    pub weight: f32,
    /// How its value maps to a confidence for this event.
    pub cdf: CdfSpec,
}

/// A decision level with hysteresis and a minimum dwell.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct LevelSpec {
    /// The level is raised once the confidence has stayed at or above `on` for the dwell.
    pub on: f32,
    /// ... and cleared when the confidence falls below `off` (≤ `on`).
    pub off: f32,
    /// Minimum time at or above `on` before the level is raised, in ms: the level is
    /// raised on the n-th consecutive tick at or above `on`, n = max(1, round(dwell_ms ·
    /// rate / 1000)); 0 (the default) raises it on the first such tick.
    #[cfg_attr(feature = "serde", serde(default))]
    pub dwell_ms: f32,
}

/// An event (eq. 14): Ψ = Π context confidences × Σ weight × sensor confidence.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct EventSpec {
    /// The event's name (e.g. `contact`).
    pub name: Name,
    /// Context-based terms, at most [`MAX_TERMS`].
    #[cfg_attr(feature = "serde", serde(default))]
    pub context: Vec<ContextTerm, MAX_TERMS>,
    /// Sensor-based terms, 1 to [`MAX_TERMS`].
    pub sensor: Vec<SensorTerm, MAX_TERMS>,
    /// The early-warning level.
    pub alert: LevelSpec,
    /// The confirmation level (`on` at least the alert's).
    pub confirm: LevelSpec,
    /// The onset reported with a decision is the first tick of the current run of
    /// confidence above this level, in [0, alert.on). Default 0: when the confidence
    /// first left zero.
    #[cfg_attr(feature = "serde", serde(default))]
    pub onset_level: f32,
}

/// A manipulation phase.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(deny_unknown_fields))]
pub struct PhaseSpec {
    /// The phase's name (e.g. `approach`).
    pub name: Name,
    /// The events possible in it; only these are evaluated while it is active.
    pub events: Vec<Name, MAX_EVENTS>,
}

/// The item of a configuration an error is about.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum Item {
    /// The configuration as a whole.
    Config,
    /// A channel.
    Channel(Name),
    /// A feature.
    Feature(Name),
    /// An event.
    Event(Name),
    /// A sensor term of an event: (event, feature).
    SensorTerm(Name, Name),
    /// A context term of an event: (event, feature).
    ContextTerm(Name, Name),
    /// A decision level of an event: (event, `alert` or `confirm`).
    Level(Name, &'static str),
    /// A phase.
    Phase(Name),
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
    /// Another item of the same kind has this name.
    Duplicate,
    /// A list that must not be empty is (its name given).
    Empty(&'static str),
    /// A feature reads a name that is neither a channel nor an earlier feature.
    UnknownInput(Name),
    /// A term names an undefined feature.
    UnknownFeature(Name),
    /// A phase names an undefined event.
    UnknownEvent(Name),
    /// A phase lists the same event twice.
    RepeatedEvent(Name),
    /// A feature's parameters.
    Stage(StageError),
    /// A confidence distribution function's parameters.
    Cdf(CdfError),
    /// A weight is not within [0, 1].
    Weight(f32),
    /// The sensor weights sum above 1.
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
    /// A dwell is negative, not finite, or longer than 65 535 ticks.
    Dwell(f32),
    /// A channel's scale is not a positive, finite number.
    Scale(f32),
    /// The term would be one distinct (feature, CDF) pair more than the detector holds
    /// (the limit given).
    DistinctTerms(usize),
}

impl core::fmt::Display for Problem {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Problem::Rate(r) => write!(f, "rate_hz = {r} must be between 10 and 50000"),
            Problem::EmptyName => write!(f, "the name is empty"),
            Problem::Duplicate => write!(f, "the name is used twice"),
            Problem::Empty(what) => write!(f, "needs at least one {what}"),
            Problem::UnknownInput(n) => write!(
                f,
                "reads '{n}', which is neither a channel nor a feature defined before it"
            ),
            Problem::UnknownFeature(n) => write!(f, "names feature '{n}', which is not defined"),
            Problem::UnknownEvent(n) => write!(f, "names event '{n}', which is not defined"),
            Problem::RepeatedEvent(n) => write!(f, "lists event '{n}' twice"),
            Problem::Stage(e) => write!(f, "{e}"),
            Problem::Cdf(e) => write!(f, "cdf: {e}"),
            Problem::Weight(w) => write!(f, "weight = {w} must be within [0, 1]"),
            Problem::WeightSum(s) => write!(f, "sensor weights sum to {s:.3}, above 1"),
            Problem::Level { param, value, rule } => write!(f, "{param} = {value} {rule}"),
            Problem::Scale(k) => write!(f, "scale = {k} must be a positive, finite number"),
            Problem::DistinctTerms(n) => write!(
                f,
                "the events' terms judge more than {n} distinct (feature, CDF) pairs"
            ),
            Problem::Dwell(d) => write!(
                f,
                "dwell_ms = {d} must be a finite, non-negative time of at most 65535 ticks"
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

/// Why a configuration file could not be loaded.
#[cfg(feature = "std")]
#[derive(Debug)]
pub enum LoadError {
    /// The text is not valid TOML or does not have the configuration's shape (the message
    /// gives line and column).
    Syntax(toml::de::Error),
    /// It parsed, but the configuration is invalid.
    Invalid(ConfigError),
}

#[cfg(feature = "std")]
impl core::fmt::Display for LoadError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            // The toml crate's own text spans several lines (a source excerpt); keep its
            // position line and its message, on one line.
            LoadError::Syntax(e) => {
                let text = e.to_string();
                let position = text.lines().next().unwrap_or("TOML parse error");
                write!(f, "{position}: {}", e.message().trim_end())
            }
            LoadError::Invalid(e) => write!(f, "{e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LoadError {}

#[cfg(feature = "std")]
impl Config {
    /// Parses a TOML configuration (the format of `configs/approach.toml`) and validates it
    /// by building a detector from it.
    pub fn from_toml(text: &str) -> Result<Config, LoadError> {
        let config: Config = toml::from_str(text).map_err(LoadError::Syntax)?;
        crate::Detector::build(&config).map_err(LoadError::Invalid)?;
        Ok(config)
    }

    /// The configuration as TOML text.
    pub fn to_toml(&self) -> std::string::String {
        // Serializing plain data with only string keys cannot fail.
        toml::to_string_pretty(self).unwrap_or_default()
    }
}
