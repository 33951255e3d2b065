//! The fingertip simulator: the approach phase of a planar, position-controlled finger with
//! a soft sensing fingertip, reproducing the paper's Table 1 runs and event-free motion.
//!
//! [`simulate`] runs one [`Scenario`] and returns a [`Trace`] in the project's one trace
//! format, with the ten input channels of [`CHANNELS`], a `phase` column (`approach`) and a
//! `truth` column (the expected event's name from its physical onset on).
//!
//! - The physics is integrated at an internal rate chosen per run from its stiffest mode
//!   (an integer multiple of the detector rate, at least twice it and at least
//!   [`MIN_INTERNAL_RATE_HZ`]) and every analog channel passes an anti-alias filter
//!   ([`filters`]) before it is sampled at the detector rate (5 kHz by default).
//! - Nominal runs (`randomize: false`) use the nominal parameters of [`params`]; only the
//!   sensor noise and hum phases depend on the seed. Randomized runs draw every parameter
//!   the scenario uses from its documented range. Either way the same scenario, options
//!   and seed give an identical trace.
//! - `docs/simulator.md` describes the model, the numbers and their ranges.

pub mod filters;
pub mod long;
pub mod params;

mod engine;
mod trajectory;

use crate::trace::{Labels, Trace, TraceError};
use engine::{
    ContactLaw, DisturbanceKind, DisturbanceSetup, Happened, Linkage, ObjectSetup, ObstacleSetup,
    Setup, Struck,
};
use params::{
    Braking, Draws, HardObject, Knock, LargeDisturbance, Motion, MovableObject, Obstacle, Plant,
    Sensors, SmallDisturbance, SoftObject, SuddenAccel, Surface, VerySoftObject,
};
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use std::fmt;
use std::str::FromStr;
use trajectory::Trajectory;

pub use filters::{ANTI_ALIAS_CUTOFF_RATIO, AntiAliasFilter, decimate};
pub use params::ParamRange;

/// The event name of a fingertip contact.
pub const CONTACT: &str = "contact";
/// The event name of a collision of the finger's proximal link.
pub const LINK_COLLISION: &str = "link_collision";
/// The event name of an external disturbance.
pub const DISTURBANCE: &str = "disturbance";
/// The phase every simulated row is in.
pub const APPROACH: &str = "approach";

/// The internal (integration) rate is the smallest multiple of the detector rate that
/// resolves the run's stiffest mode (at most 0.35 rad of its phase per step), and at least
/// this and twice the detector rate: five steps per tick of the fastest joint loop.
pub const MIN_INTERNAL_RATE_HZ: f64 = 10_000.0;
/// The default detector rate.
pub const DEFAULT_RATE_HZ: f64 = 5000.0;
/// The default rate of the robot controller's ticks (context updates).
pub const DEFAULT_CONTROLLER_RATE_HZ: f64 = 1000.0;
/// Length of a Table 1 run after the event's onset.
pub const AFTER_ONSET_S: f64 = 0.130;
/// Default length of a free-motion run.
pub const FREE_MOTION_S: f64 = 10.0;

/// A 12-bit bipolar ADC channel: codes -2048..=2047, one LSB = 2 x full scale / 4096.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Adc12 {
    /// The reading clips at +- this (in the channel's unit).
    pub full_scale: f64,
    /// RMS of the white noise at the ADC input at noise scale 1 (in the channel's unit).
    pub noise_rms: f64,
}

/// One input channel of a simulated trace.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelSpec {
    /// The column name.
    pub name: &'static str,
    /// The SI unit.
    pub unit: &'static str,
    /// The ADC, for analog channels sampled on the fingertip; `None` for the context the
    /// controller sends (held between its ticks).
    pub adc: Option<Adc12>,
    /// What the channel is.
    pub doc: &'static str,
}

/// The channels of a simulated trace, in column order.
pub const CHANNELS: [ChannelSpec; 10] = [
    ChannelSpec {
        name: "force_x",
        unit: "N",
        adc: Some(Adc12 {
            full_scale: 20.0,
            noise_rms: 0.01,
        }),
        doc: "fingertip force sensor, x (pad normal): force of the environment on the fingertip plus the inertial load of the fingertip's own mass",
    },
    ChannelSpec {
        name: "force_y",
        unit: "N",
        adc: Some(Adc12 {
            full_scale: 20.0,
            noise_rms: 0.01,
        }),
        doc: "fingertip force sensor, y (tangential)",
    },
    ChannelSpec {
        name: "skin_accel",
        unit: "m/s^2",
        adc: Some(Adc12 {
            full_scale: 500.0,
            noise_rms: 0.5,
        }),
        doc: "skin accelerometer, along x, AC-coupled",
    },
    ChannelSpec {
        name: "stress_rate",
        unit: "N/s",
        adc: Some(Adc12 {
            full_scale: 1000.0,
            noise_rms: 0.5,
        }),
        doc: "skin stress-rate sensor (PVDF film and charge amplifier), calibrated as the rate of the normal contact force",
    },
    ChannelSpec {
        name: "pos_err_x",
        unit: "m",
        adc: None,
        doc: "tip position error from the controller: commanded minus encoder-measured position, x (the encoders resolve 1 um unless a run sets otherwise)",
    },
    ChannelSpec {
        name: "pos_err_y",
        unit: "m",
        adc: None,
        doc: "tip position error, y",
    },
    ChannelSpec {
        name: "vel_des_x",
        unit: "m/s",
        adc: None,
        doc: "commanded tip velocity, x",
    },
    ChannelSpec {
        name: "vel_des_y",
        unit: "m/s",
        adc: None,
        doc: "commanded tip velocity, y",
    },
    ChannelSpec {
        name: "acc_des_x",
        unit: "m/s^2",
        adc: None,
        doc: "commanded tip acceleration, x",
    },
    ChannelSpec {
        name: "acc_des_y",
        unit: "m/s^2",
        adc: None,
        doc: "commanded tip acceleration, y",
    },
];

/// The longest lead-in a run takes ([`SimOptions::lead_in_s`], s).
pub const MAX_LEAD_IN_S: f64 = 10.0;

/// The largest [`SimOptions::noise_factor`].
pub const MAX_NOISE_FACTOR: f64 = 10.0;

/// The resolution of the tip position the controller reads from its joint encoders in
/// every run of the envelope (µm), [`SimOptions::encoder_resolution_um`]'s default.
pub const DEFAULT_ENCODER_RESOLUTION_UM: f64 = 1.0;

/// The finest and the coarsest [`SimOptions::encoder_resolution_um`] (µm).
pub const ENCODER_RESOLUTION_RANGE_UM: (f64, f64) = (0.1, 100.0);

/// The highest [`SimOptions::film_highpass_hz`] (Hz).
pub const MAX_FILM_HIGHPASS_HZ: f64 = 10.0;

/// The highest [`SimOptions::velocity_filter_hz`] (Hz).
pub const MAX_VELOCITY_FILTER_HZ: f64 = 2000.0;

/// How much sooner a run whose loops differentiate their encoders starts than its trace
/// (s): the structure's lightly damped modes (1-4 % at 100-400 Hz: a time constant of up to
/// 0.16 s) take that long to ring up to the loops' noise, which a detector would otherwise
/// meet rising.
pub const VELOCITY_WARM_S: f64 = 0.5;

/// The largest [`SimOptions::context_turned_deg`], either way (degrees).
pub const MAX_CONTEXT_TURNED_DEG: f64 = 90.0;

/// The context's vectors, as (x, y) pairs of [`CHANNELS`] names: position error,
/// commanded velocity, commanded acceleration.
const CONTEXT_VECTORS: [(&str, &str); 3] = [
    ("pos_err_x", "pos_err_y"),
    ("vel_des_x", "vel_des_y"),
    ("acc_des_x", "acc_des_y"),
];

/// Metadata key of the physical onset time in seconds (absent when nothing happened).
pub const META_ONSET: &str = "onset_s";
/// Metadata key of the scenario name.
pub const META_SCENARIO: &str = "scenario";
/// Metadata key of the expected event (`none` when no event should be confirmed).
pub const META_EXPECTED: &str = "expected";

/// A simulated run: one of the paper's Table 1 runs, or event-free motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Scenario {
    /// Contact with a hard object at 8 cm/s.
    ContactHard8,
    /// Contact with a hard object at 5 cm/s.
    ContactHard5,
    /// Contact with a hard object at 2 cm/s.
    ContactHard2,
    /// Contact with a soft object at 8 cm/s.
    ContactSoft8,
    /// Contact with a soft object at 5 cm/s.
    ContactSoft5,
    /// Contact with a soft object at 2 cm/s.
    ContactSoft2,
    /// Contact at 5 cm/s with an object that slides away on its table.
    ObjectMoves5,
    /// A link (link 1 nominally, either in randomized runs) strikes an obstacle at 8 cm/s.
    LinkCollision8,
    /// A link strikes an obstacle at 2 cm/s.
    LinkCollision2,
    /// A large disturbance while moving at 5 cm/s.
    DisturbanceLarge5,
    /// A small disturbance while moving at 5 cm/s.
    DisturbanceSmall5,
    /// A sudden commanded acceleration from standstill.
    SuddenAccelStandstill,
    /// A sudden commanded acceleration while moving at 5 cm/s.
    SuddenAccelMoving5,
    /// Contact with a hard or a soft object while the finger brakes.
    ContactBraking,
    /// Contact with a very soft object at 1 cm/s.
    ContactVerySoft1,
    /// A large or small disturbance while cruising at 2 cm/s.
    DisturbanceSlow2,
    /// A knock (tap or burst) on link 1, the proximal link, while moving at 5 cm/s.
    KnockLink1,
    /// A knock on link 2, the distal link, while moving at 5 cm/s.
    KnockLink2,
    /// A knock on the pad, pressing it from in front, while moving at 5 cm/s.
    KnockPad,
    /// Random event-free motion (pauses, moves, gentle velocity changes, sudden
    /// accelerations), no contact.
    FreeMotion,
}

/// What happens in a scenario.
#[derive(Clone, Copy, Debug)]
enum Kind {
    Contact(ObjectKind),
    /// A contact while braking: a hard or a soft object.
    BrakingContact,
    Collision,
    Disturbance(Size),
    Knock(Struck),
    SuddenAccel,
    Free,
}

#[derive(Clone, Copy, Debug)]
enum ObjectKind {
    Hard,
    Soft,
    VerySoft,
    Movable,
}

/// A disturbance's size: one of the two groups, or either (equally likely in randomized
/// runs, large in nominal ones).
#[derive(Clone, Copy, Debug)]
enum Size {
    Large,
    Small,
    Either,
}

impl Scenario {
    /// Every scenario: the 13 Table 1 runs, the 6 runs that widen the envelope beyond
    /// them, then free motion.
    pub const ALL: [Scenario; 20] = [
        Scenario::ContactHard8,
        Scenario::ContactHard5,
        Scenario::ContactHard2,
        Scenario::ContactSoft8,
        Scenario::ContactSoft5,
        Scenario::ContactSoft2,
        Scenario::ObjectMoves5,
        Scenario::LinkCollision8,
        Scenario::LinkCollision2,
        Scenario::DisturbanceLarge5,
        Scenario::DisturbanceSmall5,
        Scenario::SuddenAccelStandstill,
        Scenario::SuddenAccelMoving5,
        Scenario::ContactBraking,
        Scenario::ContactVerySoft1,
        Scenario::DisturbanceSlow2,
        Scenario::KnockLink1,
        Scenario::KnockLink2,
        Scenario::KnockPad,
        Scenario::FreeMotion,
    ];

    /// Every scenario: the 13 Table 1 runs, the 6 beyond them, then free motion.
    pub fn all() -> &'static [Scenario] {
        &Scenario::ALL
    }

    /// The 13 runs of the paper's Table 1.
    pub fn table1() -> &'static [Scenario] {
        &Scenario::ALL[..13]
    }

    /// Every scenario with one event (or one sudden acceleration) per run: all but free
    /// motion, the runs `fingertip evaluate` scores one by one.
    pub fn single_event() -> &'static [Scenario] {
        &Scenario::ALL[..19]
    }

    /// The single-event scenarios whose expected event is a disturbance (taps and bursts
    /// on the tip or a link, knocks), in table order.
    pub fn disturbances() -> impl Iterator<Item = Scenario> {
        Scenario::single_event()
            .iter()
            .copied()
            .filter(|s| s.expected() == Some(DISTURBANCE))
    }

    /// The scenario's name, e.g. `contact_hard_8`.
    pub fn name(self) -> &'static str {
        match self {
            Scenario::ContactHard8 => "contact_hard_8",
            Scenario::ContactHard5 => "contact_hard_5",
            Scenario::ContactHard2 => "contact_hard_2",
            Scenario::ContactSoft8 => "contact_soft_8",
            Scenario::ContactSoft5 => "contact_soft_5",
            Scenario::ContactSoft2 => "contact_soft_2",
            Scenario::ObjectMoves5 => "object_moves_5",
            Scenario::LinkCollision8 => "link_collision_8",
            Scenario::LinkCollision2 => "link_collision_2",
            Scenario::DisturbanceLarge5 => "disturbance_large_5",
            Scenario::DisturbanceSmall5 => "disturbance_small_5",
            Scenario::SuddenAccelStandstill => "sudden_accel_standstill",
            Scenario::SuddenAccelMoving5 => "sudden_accel_moving_5",
            Scenario::ContactBraking => "contact_braking",
            Scenario::ContactVerySoft1 => "contact_very_soft_1",
            Scenario::DisturbanceSlow2 => "disturbance_slow_2",
            Scenario::KnockLink1 => "knock_link1",
            Scenario::KnockLink2 => "knock_link2",
            Scenario::KnockPad => "knock_pad",
            Scenario::FreeMotion => "free_motion",
        }
    }

    /// The scenario with this name.
    pub fn from_name(name: &str) -> Option<Scenario> {
        Scenario::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The event a detector should confirm: `contact`, `link_collision`, `disturbance`,
    /// or `None` (sudden acceleration and free motion: nothing may be confirmed).
    pub fn expected(self) -> Option<&'static str> {
        match self.kind() {
            Kind::Contact(_) | Kind::BrakingContact => Some(CONTACT),
            Kind::Collision => Some(LINK_COLLISION),
            Kind::Disturbance(_) | Kind::Knock(_) => Some(DISTURBANCE),
            Kind::SuddenAccel | Kind::Free => None,
        }
    }

    /// The nominal commanded speed before the event (before braking in
    /// `contact_braking`), in m/s (0 for free motion and the standstill start).
    pub fn nominal_speed(self) -> f64 {
        match self {
            Scenario::ContactHard8 | Scenario::ContactSoft8 | Scenario::LinkCollision8 => 0.08,
            Scenario::ContactHard2
            | Scenario::ContactSoft2
            | Scenario::LinkCollision2
            | Scenario::DisturbanceSlow2 => 0.02,
            Scenario::ContactVerySoft1 => 0.01,
            Scenario::SuddenAccelStandstill | Scenario::FreeMotion => 0.0,
            _ => 0.05,
        }
    }

    /// One line saying what happens.
    pub fn description(self) -> &'static str {
        match self {
            Scenario::ContactHard8 => "fingertip contacts a hard object at 8 cm/s",
            Scenario::ContactHard5 => "fingertip contacts a hard object at 5 cm/s",
            Scenario::ContactHard2 => "fingertip contacts a hard object at 2 cm/s",
            Scenario::ContactSoft8 => "fingertip contacts a soft object at 8 cm/s",
            Scenario::ContactSoft5 => "fingertip contacts a soft object at 5 cm/s",
            Scenario::ContactSoft2 => "fingertip contacts a soft object at 2 cm/s",
            Scenario::ObjectMoves5 => "fingertip contacts, at 5 cm/s, an object that slides away",
            Scenario::LinkCollision8 => "link 1 or link 2 strikes an obstacle at 8 cm/s",
            Scenario::LinkCollision2 => "link 1 or link 2 strikes an obstacle at 2 cm/s",
            Scenario::DisturbanceLarge5 => {
                "large tap or vibration burst on the tip, link 2 or link 1 while moving at 5 cm/s"
            }
            Scenario::DisturbanceSmall5 => {
                "small tap or vibration burst on the tip, link 2 or link 1 while moving at 5 cm/s"
            }
            Scenario::SuddenAccelStandstill => "sudden commanded acceleration from standstill",
            Scenario::SuddenAccelMoving5 => "sudden commanded acceleration while moving at 5 cm/s",
            Scenario::ContactBraking => {
                "fingertip contacts a hard or a soft object while braking from 5 cm/s"
            }
            Scenario::ContactVerySoft1 => "fingertip contacts a very soft object at 1 cm/s",
            Scenario::DisturbanceSlow2 => {
                "large or small tap or vibration burst on the finger while moving at 2 cm/s"
            }
            Scenario::KnockLink1 => "a tap or burst strikes link 1 while moving at 5 cm/s",
            Scenario::KnockLink2 => "a tap or burst strikes link 2 while moving at 5 cm/s",
            Scenario::KnockPad => {
                "a tap or burst strikes the pad from in front, pressing it, while moving at 5 cm/s"
            }
            Scenario::FreeMotion => "random event-free motion, touching nothing",
        }
    }

    fn kind(self) -> Kind {
        match self {
            Scenario::ContactHard8 | Scenario::ContactHard5 | Scenario::ContactHard2 => {
                Kind::Contact(ObjectKind::Hard)
            }
            Scenario::ContactSoft8 | Scenario::ContactSoft5 | Scenario::ContactSoft2 => {
                Kind::Contact(ObjectKind::Soft)
            }
            Scenario::ObjectMoves5 => Kind::Contact(ObjectKind::Movable),
            Scenario::ContactVerySoft1 => Kind::Contact(ObjectKind::VerySoft),
            Scenario::ContactBraking => Kind::BrakingContact,
            Scenario::LinkCollision8 | Scenario::LinkCollision2 => Kind::Collision,
            Scenario::DisturbanceLarge5 => Kind::Disturbance(Size::Large),
            Scenario::DisturbanceSmall5 => Kind::Disturbance(Size::Small),
            Scenario::DisturbanceSlow2 => Kind::Disturbance(Size::Either),
            Scenario::KnockLink1 => Kind::Knock(Struck::Link1),
            Scenario::KnockLink2 => Kind::Knock(Struck::Link2),
            Scenario::KnockPad => Kind::Knock(Struck::Pad),
            Scenario::SuddenAccelStandstill | Scenario::SuddenAccelMoving5 => Kind::SuddenAccel,
            Scenario::FreeMotion => Kind::Free,
        }
    }
}

/// How `fingertip evaluate` splits a scenario's runs into bins of the parameter that
/// matters most for detecting its event, so that a weak region shows instead of averaging
/// away.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Binning {
    /// The parameter each run is placed by (and plotted against), e.g. `object stiffness`.
    pub parameter: &'static str,
    /// Its unit.
    pub unit: &'static str,
    /// Whether it spans decades (log bins and a log axis).
    pub log: bool,
    /// The bins.
    pub split: Split,
}

/// The bins of a [`Binning`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Split {
    /// Ranges of the parameter between consecutive edges (ascending, in its unit); a value
    /// beyond the outer edges counts in the outer bin.
    Edges(&'static [f64]),
    /// Kinds of run named in the trace's metadata (struck link, tap or burst and the body
    /// struck), in this order.
    Categories(&'static [&'static str]),
}

/// Where one run falls in its scenario's [`Binning`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunBin {
    /// Its bin, an index into [`Binning::labels`].
    pub bin: usize,
    /// Its value of the binning parameter (in the binning's unit).
    pub value: f64,
}

impl Binning {
    /// Each bin's label: a range such as `1e+04-2.2e+04 N/m`, or a category.
    pub fn labels(&self) -> Vec<String> {
        match self.split {
            Split::Edges(edges) => edges
                .windows(2)
                .map(|w| format!("{}-{} {}", short(w[0]), short(w[1]), self.unit))
                .collect(),
            Split::Categories(names) => names.iter().map(|n| n.to_string()).collect(),
        }
    }
}

/// Two significant digits, in scientific notation from 10,000 on.
fn short(v: f64) -> String {
    if v.abs() >= 1e4 {
        format!("{v:.1e}")
    } else if v.abs() >= 10.0 || v == v.round() {
        format!("{v:.0}")
    } else {
        format!("{v:.2}")
    }
}

const STIFFNESS: &str = "object stiffness";
const PEAK: &str = "peak force";
const DISTURBANCE_CATEGORIES: &[&str] = &[
    "tap on tip",
    "tap on link2",
    "tap on link1",
    "burst on tip",
    "burst on link2",
    "burst on link1",
];

impl Scenario {
    /// The parameter that matters most for detecting this scenario's event and its bins:
    /// object stiffness for contacts (mass for a movable object), the struck link for
    /// collisions and, for link 1, the share of the commanded speed the obstacle takes
    /// (plotted against that share, the whole speed for link 2), tap or burst and the body struck for
    /// disturbances (size and kind at 2 cm/s, kind for knocks; plotted against the peak
    /// force), the acceleration for sudden accelerations. `None` for free motion.
    pub fn binning(self) -> Option<Binning> {
        let edges = |parameter, unit, log, edges| Binning {
            parameter,
            unit,
            log,
            split: Split::Edges(edges),
        };
        let categories = |parameter, unit, log, names| Binning {
            parameter,
            unit,
            log,
            split: Split::Categories(names),
        };
        Some(match self.kind() {
            Kind::Contact(ObjectKind::Hard) => {
                edges(STIFFNESS, "N/m", true, &[1e4, 2.15e4, 4.64e4, 1e5])
            }
            Kind::Contact(ObjectKind::Soft) => {
                edges(STIFFNESS, "N/m", true, &[100.0, 300.0, 1000.0, 3000.0])
            }
            Kind::Contact(ObjectKind::VerySoft) => {
                edges(STIFFNESS, "N/m", true, &[40.0, 70.0, 120.0])
            }
            Kind::Contact(ObjectKind::Movable) => {
                edges("object mass", "kg", true, &[0.05, 0.1, 0.2, 0.5])
            }
            Kind::BrakingContact => edges(
                STIFFNESS,
                "N/m",
                true,
                &[100.0, 300.0, 1e3, 3e3, 3.16e4, 1e5],
            ),
            Kind::Collision => categories(
                "share of the commanded speed the obstacle takes",
                "1",
                false,
                &["link1, < 50 %", "link1, > 50 %", "link2"],
            ),
            Kind::Disturbance(Size::Either) => categories(
                PEAK,
                "N",
                true,
                &["large tap", "large burst", "small tap", "small burst"],
            ),
            Kind::Disturbance(_) => categories(PEAK, "N", true, DISTURBANCE_CATEGORIES),
            Kind::Knock(_) => categories(PEAK, "N", true, &["tap", "burst"]),
            Kind::SuddenAccel => edges(
                "commanded acceleration",
                "m/s^2",
                false,
                &[8.0, 13.0, 19.0, 25.0],
            ),
            Kind::Free => return None,
        })
    }

    /// Where a run of this scenario falls in its [`Binning`], from the trace's metadata;
    /// `None` when the trace lacks what it needs (not this simulator's, or free motion).
    pub fn run_bin(self, trace: &Trace) -> Option<RunBin> {
        let binning = self.binning()?;
        let param =
            |key: &str| -> Option<f64> { trace.meta(&format!("param.{key}"))?.parse().ok() };
        let tap = || trace.meta("disturbance_kind").map(|k| k == "impulse");
        // The peak force of the disturbance or knock, from its group's tap or burst fields.
        let peak = |group: &str| -> Option<f64> {
            let field = if tap()? {
                "peak"
            } else {
                "vibration_amplitude"
            };
            let field = match (group, field) {
                ("knock", f) => f.to_string(),
                (_, "peak") => "impulse_peak".to_string(),
                (_, f) => f.to_string(),
            };
            param(&format!("{group}.{field}"))
        };
        let size = || match self.kind() {
            Kind::Disturbance(Size::Large) => Some("large"),
            Kind::Disturbance(Size::Small) => Some("small"),
            _ => trace.meta("disturbance_size"),
        };
        let value = match self.kind() {
            Kind::Contact(ObjectKind::Hard) => param("hard_object.stiffness"),
            Kind::Contact(ObjectKind::Soft) => param("soft_object.stiffness"),
            Kind::Contact(ObjectKind::VerySoft) => param("very_soft_object.stiffness"),
            Kind::Contact(ObjectKind::Movable) => param("movable_object.mass"),
            Kind::BrakingContact => {
                param("hard_object.stiffness").or_else(|| param("soft_object.stiffness"))
            }
            // A link 2 obstacle stops the tip: the whole speed.
            Kind::Collision => match trace.meta("struck_link")? {
                "link1" => trace.meta("link1_speed_share")?.parse().ok(),
                _ => Some(1.0),
            },
            Kind::Disturbance(_) => peak(&format!("{}_disturbance", size()?)),
            Kind::Knock(_) => peak("knock"),
            Kind::SuddenAccel => param("sudden_accel.amplitude"),
            Kind::Free => None,
        }?;
        let bin = match binning.split {
            Split::Edges(edges) => edges[1..edges.len() - 1]
                .iter()
                .take_while(|&&e| value >= e)
                .count(),
            Split::Categories(names) => {
                let kind = || tap().map(|t| if t { "tap" } else { "burst" });
                let name = match self.kind() {
                    Kind::Collision => match trace.meta("struck_link")? {
                        "link1" if value < 0.5 => "link1, < 50 %",
                        "link1" => "link1, > 50 %",
                        link => link,
                    }
                    .to_string(),
                    Kind::Disturbance(Size::Either) => format!("{} {}", size()?, kind()?),
                    Kind::Disturbance(_) => {
                        format!("{} on {}", kind()?, trace.meta("disturbance_body")?)
                    }
                    _ => kind()?.to_string(),
                };
                names.iter().position(|n| *n == name)?
            }
        };
        Some(RunBin { bin, value })
    }
}

impl fmt::Display for Scenario {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The name is not one of [`Scenario::all`]'s.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown scenario `{0}` (known: contact_hard_8, contact_hard_5, contact_hard_2, contact_soft_8, contact_soft_5, contact_soft_2, object_moves_5, link_collision_8, link_collision_2, disturbance_large_5, disturbance_small_5, sudden_accel_standstill, sudden_accel_moving_5, contact_braking, contact_very_soft_1, disturbance_slow_2, knock_link1, knock_link2, knock_pad, free_motion)"
)]
pub struct UnknownScenario(pub String);

impl FromStr for Scenario {
    type Err = UnknownScenario;

    fn from_str(s: &str) -> Result<Scenario, UnknownScenario> {
        Scenario::from_name(s).ok_or_else(|| UnknownScenario(s.to_string()))
    }
}

/// How to run a simulation.
#[derive(Clone, Debug, PartialEq)]
pub struct SimOptions {
    /// Seeds every random draw (parameters, free-motion trajectory, noise). The scenario's
    /// name is mixed in, so equal seeds of different scenarios are independent.
    pub seed: u64,
    /// Draw the physical and sensor parameters from their ranges (true) or use the
    /// nominal ones (false: the Table 1 reproductions, event at 20 ms).
    pub randomize: bool,
    /// The detector rate: the trace's sampling rate (200 Hz to 20 kHz).
    pub rate_hz: f64,
    /// The rate of the robot controller's context messages to the fingertip and of its
    /// trajectory's ticks (500 Hz to 10 kHz); its joint loop runs at its own rate
    /// (`plant.control_rate`).
    pub controller_rate_hz: f64,
    /// Length of the run in seconds (at most 3600). `None`: onset + 130 ms for single-event
    /// runs, 10 s for free motion.
    pub duration_s: Option<f64>,
    /// How long the motion runs before a single-event run's event window (0 to 10 s): the
    /// event begins this much after its drawn onset (`param.motion.onset`, 15-40 ms), so
    /// that a detector started with the run has learnt its sensors' usual readings by
    /// then. 0, the default, is the paper's protocol: the detector starts cold 15-40 ms
    /// before the event. Free motion has no event and ignores it.
    pub lead_in_s: f64,
    /// Multiplies every analog channel's white noise beyond its drawn
    /// `sensors.noise_scale` (0 to 10; 1, the default, keeps the envelope): how a detector
    /// fares on sensors noisier (or quieter) than any simulated. The trace records the
    /// noise scale in effect and this factor.
    pub noise_factor: f64,
    /// The resolution of the tip position the controller reads from its joint encoders, in
    /// µm (0.1 to 100; 1, the default, in every run of the envelope): its loops act on it and
    /// its position error carries it. A coarser one shows how a detector fares on an arm
    /// whose encoders are. The trace records it when it is not the default.
    pub encoder_resolution_um: f64,
    /// The corner of an AC coupling of the stress-rate film's amplifier, in Hz (0 to 10;
    /// 0, the default, in every run of the envelope: the film reads the rate of its load
    /// down to DC). A piezoelectric film's charge leaks away through its amplifier's input
    /// (or a coupling capacitor blocks the amplifier's offset): a steady rate of loading
    /// then reads as a rate that dies away over 1 / (2 pi f) s. The trace records it when
    /// it is not 0.
    pub film_highpass_hz: f64,
    /// The corner of the first-order low-pass through which the joint loops take their
    /// velocity from the encoders' difference over one tick, in Hz (0 to 2,000; 0, the
    /// default, in every run of the envelope: the loops damp with the true velocity). That
    /// is how most digital joint controllers get it, and each encoder count is then a
    /// velocity step of one count per tick that the loops' damping turns into force: the
    /// arm shakes itself, most where a joint is slow. A run with it starts
    /// [`VELOCITY_WARM_S`] before its trace's first row, so that the trace (whose times
    /// then start there) meets the arm already shaking; free motion starts at rest and
    /// needs none. The trace records it when it is not 0.
    pub velocity_filter_hz: f64,
    /// The frame the controller reports its context in (position error, commanded velocity
    /// and acceleration), turned by this angle from the pad's, towards y (degrees, -90 to
    /// 90; 0, the default, in every run of the envelope and as the CAN protocol asks: x
    /// along the pad normal). A controller whose model of the pad's orientation is off, or
    /// one that reports in a task frame fixed at one posture, which the pad turns away
    /// from as the arm moves: a vector with components (x, y) in the pad's frame reads
    /// (x cos a + y sin a, y cos a - x sin a). The trace records it when it is not 0.
    pub context_turned_deg: f64,
    /// Parameters a randomized run draws from another range than the envelope's (the
    /// last one given for a parameter counts): how a detector fares on one arm's, sensor's
    /// or object's range, or beyond the envelope. Each is recorded in the trace as
    /// `range.GROUP.NAME`; a non-randomized run refuses them.
    pub ranges: Vec<ParamRange>,
    /// For a link collision or a contact: the obstacle or the object gives way this long
    /// after the link or the skin first touches it (s, 0 to 1), and pushes no more, as a
    /// light object knocked aside or a hand that lets go would. The run is then the event's
    /// twin: the same readings, bit for bit, until it gives way, and a finger set free
    /// after a blow of that length (on the link, or on the pad) from then on. It tells how
    /// soon any detector can tell a collision or a contact from a blow (the `twins`
    /// example). The trace records it and the largest force the obstacle or the object
    /// pushed with (`gives_way_s`, `gives_way_peak_force_n`), and keeps the event's
    /// labels.
    pub gives_way_s: Option<f64>,
}

impl SimOptions {
    /// How the run chooses its parameters.
    fn draws(&self) -> Draws<'_> {
        if self.randomize {
            Draws::Randomized(&self.ranges)
        } else {
            Draws::Nominal
        }
    }
}

impl Default for SimOptions {
    fn default() -> SimOptions {
        SimOptions {
            seed: 0,
            randomize: false,
            rate_hz: DEFAULT_RATE_HZ,
            controller_rate_hz: DEFAULT_CONTROLLER_RATE_HZ,
            duration_s: None,
            lead_in_s: 0.0,
            noise_factor: 1.0,
            encoder_resolution_um: DEFAULT_ENCODER_RESOLUTION_UM,
            film_highpass_hz: 0.0,
            velocity_filter_hz: 0.0,
            context_turned_deg: 0.0,
            ranges: Vec::new(),
            gives_way_s: None,
        }
    }
}

/// Why a simulation could not run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// An option is out of its range.
    #[error("simulation option `{name}` = {value} is out of range: {reason}")]
    BadOption {
        /// The option.
        name: &'static str,
        /// Its value.
        value: f64,
        /// The allowed range.
        reason: &'static str,
    },
    /// A parameter's range cannot be drawn from, or was given for a run that draws none.
    #[error("simulation option `ranges`: {0}")]
    BadRange(String),
    /// The trace could not be built (a bug: the simulator's output is always valid).
    #[error(transparent)]
    Trace(#[from] TraceError),
}

fn check(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    reason: &'static str,
) -> Result<(), SimError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(SimError::BadOption {
            name,
            value,
            reason,
        })
    }
}

/// The internal integration rate's oversampling factor for a detector rate `rate_hz` and
/// a run whose mechanics need at least `required_hz`.
fn oversampling(rate_hz: f64, required_hz: f64) -> usize {
    ((required_hz.max(MIN_INTERNAL_RATE_HZ) / rate_hz).ceil() as usize).max(2)
}

/// A 64-bit mix (SplitMix64's finalizer).
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The seed of one random stream of one run: the user's seed, the scenario's name
/// (FNV-1a) and the stream number, mixed.
fn stream_seed(seed: u64, scenario: &str, stream: u64) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in scenario.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    mix(mix(seed ^ h).wrapping_add(stream.wrapping_mul(0x9e37_79b9_7f4a_7c15)))
}

/// The golden runs that the bit-exactness check on the Cortex-M4 and the tick benchmark
/// share: every nominal Table 1 run, then one second of free motion, at `rate_hz`.
pub fn golden_runs(rate_hz: f64) -> Result<Vec<(Scenario, Trace)>, SimError> {
    Scenario::table1()
        .iter()
        .chain([&Scenario::FreeMotion])
        .map(|scenario| {
            let opts = SimOptions {
                rate_hz,
                duration_s: (*scenario == Scenario::FreeMotion).then_some(1.0),
                ..SimOptions::default()
            };
            simulate(scenario, &opts).map(|t| (*scenario, t))
        })
        .collect()
}

/// Checks the options' ranges.
fn check_options(opts: &SimOptions) -> Result<(), SimError> {
    check("rate_hz", opts.rate_hz, 200.0, 20_000.0, "200 Hz to 20 kHz")?;
    check(
        "controller_rate_hz",
        opts.controller_rate_hz,
        500.0,
        10_000.0,
        "500 Hz to 10 kHz",
    )?;
    if let Some(d) = opts.duration_s {
        check(
            "duration_s",
            d,
            2.0 / opts.rate_hz,
            3600.0,
            "two samples to 3600 s",
        )?;
    }
    check("lead_in_s", opts.lead_in_s, 0.0, MAX_LEAD_IN_S, "0 to 10 s")?;
    check(
        "noise_factor",
        opts.noise_factor,
        0.0,
        MAX_NOISE_FACTOR,
        "0 to 10",
    )?;
    let (finest, coarsest) = ENCODER_RESOLUTION_RANGE_UM;
    check(
        "encoder_resolution_um",
        opts.encoder_resolution_um,
        finest,
        coarsest,
        "0.1 to 100 um",
    )?;
    check(
        "film_highpass_hz",
        opts.film_highpass_hz,
        0.0,
        MAX_FILM_HIGHPASS_HZ,
        "0 to 10 Hz",
    )?;
    check(
        "velocity_filter_hz",
        opts.velocity_filter_hz,
        0.0,
        MAX_VELOCITY_FILTER_HZ,
        "0 to 2000 Hz",
    )?;
    check(
        "context_turned_deg",
        opts.context_turned_deg,
        -MAX_CONTEXT_TURNED_DEG,
        MAX_CONTEXT_TURNED_DEG,
        "-90 to 90 degrees",
    )?;
    if let Some(after) = opts.gives_way_s {
        check("gives_way_s", after, 0.0, 1.0, "0 to 1 s")?;
    }
    if let Some(r) = opts.ranges.first().filter(|_| !opts.randomize) {
        return Err(SimError::BadRange(format!(
            "{r}: a run with the nominal parameters draws none"
        )));
    }
    for r in &opts.ranges {
        r.check().map_err(SimError::BadRange)?;
    }
    Ok(())
}

/// Expresses the context's vectors of `channels` (in the pad's frame) in a frame turned by
/// `degrees` from it.
fn turn_context(channels: &mut [Vec<f64>], degrees: f64) {
    if degrees == 0.0 {
        return;
    }
    let (s, c) = degrees.to_radians().sin_cos();
    let index = |name: &str| CHANNELS.iter().position(|ch| ch.name == name);
    for (x, y) in CONTEXT_VECTORS {
        let (Some(ix), Some(iy)) = (index(x), index(y)) else {
            continue;
        };
        let (xs, ys) = channels.split_at_mut(iy);
        for (x, y) in xs[ix].iter_mut().zip(ys[0].iter_mut()) {
            (*x, *y) = (c * *x + s * *y, c * *y - s * *x);
        }
    }
}

/// Runs one scenario and returns its trace.
///
/// The trace has the columns `t`, the ten [`CHANNELS`], `phase` and `truth`, and metadata
/// comments: the scenario, expected event, seed, options, the physical onset
/// ([`META_ONSET`]), each channel's unit and full scale, and every parameter's value.
pub fn simulate(scenario: &Scenario, opts: &SimOptions) -> Result<Trace, SimError> {
    let scenario = *scenario;
    check_options(opts)?;
    let name = scenario.name();
    let mut prng = Xoshiro256PlusPlus::seed_from_u64(stream_seed(opts.seed, name, 0));
    let mut noise = Xoshiro256PlusPlus::seed_from_u64(stream_seed(opts.seed, name, 1));
    let mut traj_rng = Xoshiro256PlusPlus::seed_from_u64(stream_seed(opts.seed, name, 2));
    let r = opts.draws();
    let plant = Plant::choose(&mut prng, r);
    let mut sensors = Sensors::choose(&mut prng, r);
    sensors.noise_scale *= opts.noise_factor;
    let mut meta: Vec<(String, String)> = Vec::new();
    let mut values: Vec<(String, f64)> = plant.values();
    values.extend(sensors.values());
    // A run whose loops differentiate their encoders starts sooner, by a lead-in whose rows
    // are dropped (free motion starts at rest, where the encoders do not move).
    let warm_rows = if opts.velocity_filter_hz > 0.0 && !matches!(scenario.kind(), Kind::Free) {
        (VELOCITY_WARM_S * opts.rate_hz).round() as usize
    } else {
        0
    };
    let warm_s = warm_rows as f64 / opts.rate_hz;
    let scene = match scenario.kind() {
        Kind::Free => free_motion_scene(opts, &mut traj_rng),
        kind => approach_scene(
            scenario,
            kind,
            &SimOptions {
                lead_in_s: opts.lead_in_s + warm_s,
                ..opts.clone()
            },
            &plant,
            &mut prng,
            &mut values,
            &mut meta,
        ),
    };

    let duration = opts
        .duration_s
        .map_or(scene.default_duration, |d| d + warm_s);
    let rows = (duration * opts.rate_hz).round() as usize + 1;
    let (stiffest, required) =
        engine::required_rate(&plant, scene.object.as_ref(), scene.obstacle.as_ref());
    let n_over = oversampling(opts.rate_hz, required);
    meta.push((
        "stiffest_mode_hz".into(),
        fmt_f64(stiffest / std::f64::consts::TAU),
    ));
    let gives_way = opts
        .gives_way_s
        .filter(|_| scene.obstacle.is_some() || scene.object.is_some());
    let mut setup = Setup {
        plant,
        sensors,
        trajectory: scene.trajectory,
        object: scene.object,
        obstacle: scene.obstacle,
        disturbance: scene.disturbance,
        rows,
        rate_hz: opts.rate_hz,
        oversampling: n_over,
        context_rate_hz: opts.controller_rate_hz,
        encoder_resolution: opts.encoder_resolution_um / 1e6,
        film_highpass_hz: opts.film_highpass_hz,
        velocity_filter_hz: opts.velocity_filter_hz,
        gives_way_s: gives_way,
    };
    let mut out = engine::run(&mut setup, &mut noise);
    for column in &mut out.channels {
        column.drain(..warm_rows.min(column.len()));
    }
    turn_context(&mut out.channels, opts.context_turned_deg);
    if let Some(after) = gives_way {
        meta.push(("gives_way_s".into(), fmt_f64(after)));
        meta.push(("gives_way_peak_force_n".into(), fmt_f64(out.peak_force)));
    }

    let t: Vec<f64> = (warm_rows..rows).map(|k| k as f64 / opts.rate_hz).collect();
    let rows = t.len();
    // The onset's time on the rows' clock, and the first row of the trace sampled at or
    // after it (the sample of the onset's own step included).
    let onset = out.onset.map(|(step, happened)| {
        let (row, within) = (step / n_over as u64, step % n_over as u64);
        let t_on = row as f64 / opts.rate_hz + within as f64 / (opts.rate_hz * n_over as f64);
        let first = (row + u64::from(within > 0)).saturating_sub(warm_rows as u64);
        (t_on, first, happened)
    });
    let truth = truth(scenario, onset, rows);
    let channels = CHANNELS
        .iter()
        .zip(out.channels)
        .map(|(c, v)| (c.name.to_string(), v))
        .collect();
    let mut trace = Trace::from_columns(name, t, channels)?
        .with_phase(Labels::uniform(APPROACH, rows))?
        .with_truth(truth)?;

    push_metadata(
        &mut trace,
        scenario,
        opts,
        n_over,
        scene.scheduled_onset,
        onset.map(|o| o.0),
        &meta,
        &values,
    )?;
    Ok(trace)
}

/// What a scenario puts in the finger's way, and the motion it commands.
struct Scene {
    trajectory: Trajectory,
    object: Option<ObjectSetup>,
    obstacle: Option<ObstacleSetup>,
    disturbance: Option<DisturbanceSetup>,
    /// When the event is due, for scenarios whose event the setup places.
    scheduled_onset: Option<f64>,
    /// The run's length when the options set none.
    default_duration: f64,
}

/// Random event-free motion, long enough for the run.
fn free_motion_scene(opts: &SimOptions, traj_rng: &mut Xoshiro256PlusPlus) -> Scene {
    let period = 1.0 / opts.controller_rate_hz;
    let d = opts.duration_s.unwrap_or(FREE_MOTION_S);
    let ticks = (d * opts.controller_rate_hz).ceil() as u64 + 1;
    Scene {
        trajectory: Trajectory::free_motion(period, ticks, traj_rng, &opts.ranges),
        object: None,
        obstacle: None,
        disturbance: None,
        scheduled_onset: None,
        default_duration: FREE_MOTION_S,
    }
}

/// An approach at the scenario's speed with its event (`kind`) at the motion's onset, every
/// parameter drawn and recorded in `values`; the scenario's own entries go to `meta`.
fn approach_scene(
    scenario: Scenario,
    kind: Kind,
    opts: &SimOptions,
    plant: &Plant,
    prng: &mut Xoshiro256PlusPlus,
    values: &mut Vec<(String, f64)>,
    meta: &mut Vec<(String, String)>,
) -> Scene {
    let r = opts.draws();
    let period = 1.0 / opts.controller_rate_hz;
    let motion = Motion::choose(prng, r);
    values.extend(motion.values());
    let speed = scenario.nominal_speed() * motion.speed_factor;
    let dir = [motion.approach_angle.cos(), motion.approach_angle.sin()];
    let v0 = [speed * dir[0], speed * dir[1]];
    let onset = motion.onset + opts.lead_in_s;
    let mut scene = Scene {
        trajectory: Trajectory::new(period, v0),
        object: None,
        obstacle: None,
        disturbance: None,
        scheduled_onset: None,
        default_duration: onset + AFTER_ONSET_S,
    };
    match kind {
        Kind::Contact(ok) => {
            let reach = [v0[0] * onset, v0[1] * onset];
            scene.object = Some(contact_object(ok, reach, prng, r, values));
            scene.scheduled_onset = Some(onset);
        }
        Kind::Collision => {
            let o = Obstacle::choose(prng, r);
            values.extend(o.values());
            let body = if r.random() && prng.random::<f64>() < 0.5 {
                Struck::Link2
            } else {
                Struck::Link1
            };
            meta.push(("struck_link".into(), body.name().into()));
            // Link 2 meets the obstacle along the approach; link 1 where joint 1 moves
            // the tip, and the tip loses joint 1's share of its velocity.
            let normal = match body {
                Struck::Link1 => {
                    let linkage = Linkage::new(plant);
                    let lost = linkage.joint1_share(v0);
                    let share = (lost[0].hypot(lost[1]) / speed * 1e4).round() / 1e4;
                    meta.push(("link1_speed_share".into(), fmt_f64(share)));
                    linkage.joint1_normal(v0)
                }
                _ => [1.0, 0.0],
            };
            scene.obstacle = Some(ObstacleSetup {
                normal,
                position: (v0[0] * normal[0] + v0[1] * normal[1]) * onset,
                stiffness: o.stiffness,
                damping: o.damping,
                body,
            });
            scene.scheduled_onset = Some(onset);
        }
        Kind::BrakingContact => {
            let b = Braking::choose(prng, r);
            values.extend(b.values());
            let start = (onset / period).round() as u64;
            let stop_ticks = (speed / b.deceleration / period).round() as u64;
            let contact = start + (b.contact_fraction * stop_ticks as f64).round() as u64;
            let decel = [-b.deceleration * dir[0], -b.deceleration * dir[1]];
            scene.trajectory.set_accel(start, decel);
            scene.trajectory.set_accel(start + stop_ticks, [0.0; 2]);
            let reach = scene.trajectory.at(contact).p;
            let hard = !r.random() || prng.random::<f64>() < 0.5;
            let object = if hard {
                ObjectKind::Hard
            } else {
                ObjectKind::Soft
            };
            meta.push(("object".into(), if hard { "hard" } else { "soft" }.into()));
            meta.push(("brake_onset_s".into(), fmt_f64(start as f64 * period)));
            scene.object = Some(contact_object(object, reach, prng, r, values));
            scene.scheduled_onset = Some(contact as f64 * period);
            scene.default_duration = contact as f64 * period + AFTER_ONSET_S;
        }
        Kind::Disturbance(size) => {
            let large = match size {
                Size::Large => true,
                Size::Small => false,
                Size::Either => !r.random() || prng.random::<f64>() < 0.5,
            };
            if matches!(size, Size::Either) {
                let name = if large { "large" } else { "small" };
                meta.push(("disturbance_size".into(), name.into()));
            }
            scene.disturbance = Some(disturbance_setup(large, onset, prng, r, values, meta));
            scene.scheduled_onset = Some(onset);
        }
        Kind::Knock(body) => {
            let k = Knock::choose(prng, r);
            values.extend(k.values());
            // Nominal: a tap against the approach. Randomized: tap or burst, +x or -x; on
            // the pad always against the approach (from in front, pressing it).
            let burst = r.random() && prng.random::<f64>() < 0.5;
            let direction = match body {
                Struck::Pad => std::f64::consts::PI,
                _ => random_direction(prng, r),
            } + k.direction_offset;
            let kind = if burst {
                DisturbanceKind::Vibration {
                    amplitude: k.vibration_amplitude,
                    frequency: k.vibration_frequency,
                    duration: k.vibration_duration,
                }
            } else {
                DisturbanceKind::Impulse {
                    peak: k.peak,
                    duration: k.duration,
                }
            };
            push_disturbance_meta(meta, kind, direction, body);
            scene.disturbance = Some(DisturbanceSetup {
                start: onset,
                kind,
                direction,
                body,
            });
            scene.scheduled_onset = Some(onset);
        }
        Kind::SuddenAccel => {
            let a = SuddenAccel::choose(prng, r);
            values.extend(a.values());
            let start = (onset / period).round() as u64;
            let ticks = ((a.velocity_change / a.amplitude / period).round() as u64).max(1);
            let acc = [a.amplitude * dir[0], a.amplitude * dir[1]];
            scene.trajectory.set_accel(start, acc);
            scene.trajectory.set_accel(start + ticks, [0.0; 2]);
            meta.push(("command_onset_s".into(), fmt_f64(start as f64 * period)));
        }
        Kind::Free => {}
    }
    scene
}

/// The truth column of `rows` rows: the name of the event that happened from the first row
/// sampled at or after its physical `onset` (time, that row, what happened) on, when the
/// scenario expects one.
fn truth(scenario: Scenario, onset: Option<(f64, u64, Happened)>, rows: usize) -> Labels {
    let truth_start = match (scenario.expected(), onset) {
        (Some(_), Some((_, row, _))) => (row as usize).min(rows),
        _ => rows,
    };
    let label = match onset.map(|o| o.2) {
        Some(Happened::Contact) => CONTACT,
        Some(Happened::Collision) => LINK_COLLISION,
        Some(Happened::Disturbance) => DISTURBANCE,
        None => "",
    };
    Labels::switch_at("", label, truth_start, rows)
}

/// The object a contact scenario touches, its surface crossed when the command has moved
/// by `reach` (m, x and y), with its surface's and its own parameters drawn (and recorded
/// in `values`).
fn contact_object(
    kind: ObjectKind,
    reach: [f64; 2],
    prng: &mut Xoshiro256PlusPlus,
    r: Draws<'_>,
    values: &mut Vec<(String, f64)>,
) -> ObjectSetup {
    let surface = Surface::choose(prng, r);
    values.extend(surface.values());
    let linear = |stiffness| ContactLaw::Linear { stiffness };
    let (law, damping, movable) = match kind {
        ObjectKind::Hard => {
            let o = HardObject::choose(prng, r);
            values.extend(o.values());
            (
                ContactLaw::Hertz {
                    stiffness: o.stiffness,
                },
                o.damping,
                None,
            )
        }
        ObjectKind::Soft => {
            let o = SoftObject::choose(prng, r);
            values.extend(o.values());
            (linear(o.stiffness), o.damping, None)
        }
        ObjectKind::VerySoft => {
            let o = VerySoftObject::choose(prng, r);
            values.extend(o.values());
            (linear(o.stiffness), o.damping, None)
        }
        ObjectKind::Movable => {
            let o = MovableObject::choose(prng, r);
            values.extend(o.values());
            (
                ContactLaw::Hertz {
                    stiffness: o.stiffness,
                },
                o.damping,
                Some((o.mass, o.friction, o.friction * o.static_ratio)),
            )
        }
    };
    // Rigid objects do not relax.
    let relaxes = matches!(law, ContactLaw::Linear { .. }) && surface.relaxation > 0.0;
    let (sin, cos) = surface.tilt.sin_cos();
    ObjectSetup {
        surface: cos * reach[0] + sin * reach[1],
        tilt: surface.tilt,
        law,
        damping,
        relaxation: relaxes.then_some((surface.relaxation, surface.relaxation_time)),
        movable,
    }
}

/// A disturbance of the given size starting at `onset`, with its parameters drawn
/// (recorded in `values`) and its kind, direction and struck body recorded in `meta`.
fn disturbance_setup(
    large: bool,
    onset: f64,
    prng: &mut Xoshiro256PlusPlus,
    r: Draws<'_>,
    values: &mut Vec<(String, f64)>,
    meta: &mut Vec<(String, String)>,
) -> DisturbanceSetup {
    // Both groups have the same fields; take the one of this size.
    let (peak, duration, amplitude, frequency, burst, offset) = if large {
        let d = LargeDisturbance::choose(prng, r);
        values.extend(d.values());
        (
            d.impulse_peak,
            d.impulse_duration,
            d.vibration_amplitude,
            d.vibration_frequency,
            d.vibration_duration,
            d.direction_offset,
        )
    } else {
        let d = SmallDisturbance::choose(prng, r);
        values.extend(d.values());
        (
            d.impulse_peak,
            d.impulse_duration,
            d.vibration_amplitude,
            d.vibration_frequency,
            d.vibration_duration,
            d.direction_offset,
        )
    };
    // Nominal: a vibration against the approach (-x) on link 2. Randomized: tap or
    // vibration, towards +x or -x, on the tip, link 2 or link 1, each equally likely.
    let impulse = r.random() && prng.random::<f64>() < 0.5;
    let base = random_direction(prng, r);
    let body = if r.random() {
        [Struck::Tip, Struck::Link2, Struck::Link1][prng.random_range(0..3usize)]
    } else {
        Struck::Link2
    };
    let kind = if impulse {
        DisturbanceKind::Impulse { peak, duration }
    } else {
        DisturbanceKind::Vibration {
            amplitude,
            frequency,
            duration: burst,
        }
    };
    push_disturbance_meta(meta, kind, base + offset, body);
    DisturbanceSetup {
        start: onset,
        kind,
        direction: base + offset,
        body,
    }
}

/// Records a disturbance's kind (`impulse`: a tap, or `vibration`: a burst), its
/// direction and the body it strikes.
fn push_disturbance_meta(
    meta: &mut Vec<(String, String)>,
    kind: DisturbanceKind,
    direction: f64,
    body: Struck,
) {
    let name = match kind {
        DisturbanceKind::Impulse { .. } => "impulse",
        DisturbanceKind::Vibration { .. } => "vibration",
    };
    meta.push(("disturbance_kind".into(), name.into()));
    meta.push(("disturbance_direction_rad".into(), fmt_f64(direction)));
    meta.push(("disturbance_body".into(), body.name().into()));
}

/// A disturbance's base direction: against the approach (-x, angle pi) in nominal runs,
/// +x or -x equally likely in randomized ones.
fn random_direction(prng: &mut Xoshiro256PlusPlus, r: Draws<'_>) -> f64 {
    if r.random() && prng.random::<f64>() < 0.5 {
        0.0
    } else {
        std::f64::consts::PI
    }
}

/// Writes the run's metadata: scenario, options, onsets, the scenario's own entries
/// (`meta`), each channel's unit and full scale, and every parameter's value.
#[allow(
    clippy::too_many_arguments,
    reason = "one argument per metadata source"
)]
fn push_metadata(
    trace: &mut Trace,
    scenario: Scenario,
    opts: &SimOptions,
    n_over: usize,
    scheduled_onset: Option<f64>,
    onset: Option<f64>,
    meta: &[(String, String)],
    values: &[(String, f64)],
) -> Result<(), SimError> {
    let name = scenario.name();
    trace.push_metadata(META_SCENARIO, name)?;
    trace.push_metadata("description", scenario.description())?;
    trace.push_metadata(META_EXPECTED, scenario.expected().unwrap_or("none"))?;
    trace.push_metadata("seed", &opts.seed.to_string())?;
    trace.push_metadata("randomized", &opts.randomize.to_string())?;
    trace.push_metadata("rate_hz", &fmt_f64(opts.rate_hz))?;
    trace.push_metadata("controller_rate_hz", &fmt_f64(opts.controller_rate_hz))?;
    trace.push_metadata("internal_rate_hz", &fmt_f64(opts.rate_hz * n_over as f64))?;
    if opts.lead_in_s > 0.0 && !matches!(scenario.kind(), Kind::Free) {
        trace.push_metadata("lead_in_s", &fmt_f64(opts.lead_in_s))?;
    }
    if opts.noise_factor != 1.0 {
        trace.push_metadata("noise_factor", &fmt_f64(opts.noise_factor))?;
    }
    if opts.encoder_resolution_um != DEFAULT_ENCODER_RESOLUTION_UM {
        trace.push_metadata(
            "encoder_resolution_um",
            &fmt_f64(opts.encoder_resolution_um),
        )?;
    }
    if opts.film_highpass_hz > 0.0 {
        trace.push_metadata("film_highpass_hz", &fmt_f64(opts.film_highpass_hz))?;
    }
    if opts.velocity_filter_hz > 0.0 {
        trace.push_metadata("velocity_filter_hz", &fmt_f64(opts.velocity_filter_hz))?;
    }
    if opts.context_turned_deg != 0.0 {
        trace.push_metadata("context_turned_deg", &fmt_f64(opts.context_turned_deg))?;
    }
    for r in &opts.ranges {
        trace.push_metadata(
            &format!("range.{}", r.name),
            &format!("{}..{}", fmt_f64(r.min), fmt_f64(r.max)),
        )?;
    }
    if let Some(s) = scheduled_onset {
        trace.push_metadata("scheduled_onset_s", &fmt_f64(s))?;
    }
    if let Some(t_on) = onset {
        trace.push_metadata(META_ONSET, &fmt_f64(t_on))?;
    }
    for (k, v) in meta {
        trace.push_metadata(k, v)?;
    }
    for c in &CHANNELS {
        trace.push_metadata(&format!("unit.{}", c.name), c.unit)?;
        if let Some(adc) = c.adc {
            trace.push_metadata(&format!("full_scale.{}", c.name), &fmt_f64(adc.full_scale))?;
        }
    }
    for (k, v) in values {
        trace.push_metadata(&format!("param.{k}"), &fmt_f64(*v))?;
    }
    Ok(())
}

/// Shortest decimal that reads back to the same `f64`.
fn fmt_f64(v: f64) -> String {
    format!("{v}")
}
