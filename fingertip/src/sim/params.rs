//! The simulator's parameters: nominal values (the Table 1 reproductions) and the ranges
//! randomized runs draw from.
//!
//! Every parameter is declared once, below, with its unit, nominal value, range and
//! meaning; [`all_specs`] lists them all and `docs/simulator.md` carries the same table
//! (a test keeps the two in step). Randomized runs draw each parameter of the groups a
//! scenario from its range, independently, in declaration order: uniformly; log-uniformly
//! (every decade equally likely) for those marked `log`, the ones that span decades such
//! as stiffnesses; or, for those marked `either_sign`, a magnitude drawn uniformly from
//! the range with either sign equally likely (an angle that can lie on either side).

use rand::{Rng, RngExt};

/// One simulator parameter: its nominal value and the range randomized runs draw from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamSpec {
    /// Group and name, e.g. `plant.foam_stiffness`.
    pub group: &'static str,
    /// The parameter's name within its group.
    pub name: &'static str,
    /// SI unit, or `1` for a ratio.
    pub unit: &'static str,
    /// The value of non-randomized runs.
    pub nominal: f64,
    /// The smallest value (or, drawn with either sign, the smallest magnitude) a randomized
    /// run draws.
    pub min: f64,
    /// The largest value (or magnitude) a randomized run draws.
    pub max: f64,
    /// How a randomized run draws it from the range.
    pub draw: Draw,
    /// For a parameter the envelope holds at one value (one it does not draw yet), the
    /// largest magnitude a [`ParamRange`] may reach; otherwise [`RANGE_REACH`] times the
    /// envelope's.
    pub beyond: Option<f64>,
    /// What the parameter is.
    pub doc: &'static str,
}

impl ParamSpec {
    /// The largest magnitude a [`ParamRange`] on this parameter may reach: its
    /// [`ParamSpec::beyond`], else [`RANGE_REACH`] times the envelope's larger bound.
    pub fn reach(&self) -> f64 {
        self.beyond
            .unwrap_or(RANGE_REACH * self.min.abs().max(self.max.abs()))
    }
}

/// How a randomized run draws a parameter from its range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Draw {
    /// Uniformly.
    Uniform,
    /// Log-uniformly: every decade equally likely.
    Log,
    /// A magnitude drawn uniformly from the range, with either sign equally likely.
    EitherSign,
}

impl Draw {
    /// A draw from `[lo, hi]` this way.
    fn from<R: Rng>(self, rng: &mut R, lo: f64, hi: f64) -> f64 {
        match self {
            Draw::Uniform => uniform(rng, lo, hi),
            Draw::Log => log_uniform(rng, lo, hi),
            Draw::EitherSign => {
                let magnitude = uniform(rng, lo, hi);
                if rng.random::<bool>() {
                    magnitude
                } else {
                    -magnitude
                }
            }
        }
    }

    /// Whether `v` is a value this way of drawing from `[lo, hi]` gives.
    pub fn admits(self, v: f64, lo: f64, hi: f64) -> bool {
        match self {
            Draw::Uniform | Draw::Log => (lo..=hi).contains(&v),
            Draw::EitherSign => (lo..=hi).contains(&v.abs()),
        }
    }
}

/// A uniform draw from `[lo, hi]` (exactly `lo` when the range is empty).
pub(crate) fn uniform<R: Rng>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    if hi > lo {
        lo + (hi - lo) * rng.random::<f64>()
    } else {
        lo
    }
}

/// A log-uniform draw from `[lo, hi]` (`0 < lo`): every decade equally likely.
pub(crate) fn log_uniform<R: Rng>(rng: &mut R, lo: f64, hi: f64) -> f64 {
    uniform(rng, lo.ln(), hi.ln()).exp().clamp(lo, hi)
}

/// A parameter drawn from another range than the envelope's: `group.name=min..max` on the
/// command line, e.g. `plant.control_bandwidth=10..15` for the slow loops of one arm, or a
/// range beyond the envelope to see where a detector stops holding.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamRange {
    /// The parameter, `group.name` as in [`all_specs`] and the trace's `param.` metadata.
    pub name: String,
    /// The smallest value drawn (with [`Draw::EitherSign`], the smallest magnitude).
    pub min: f64,
    /// The largest.
    pub max: f64,
}

impl std::str::FromStr for ParamRange {
    type Err = String;

    /// `group.name=min..max`; the name and the values are checked by [`ParamRange::check`].
    fn from_str(s: &str) -> Result<ParamRange, String> {
        let syntax = || format!("`{s}` is not of the form group.name=min..max");
        let (name, range) = s.split_once('=').ok_or_else(syntax)?;
        let (min, max) = range.split_once("..").ok_or_else(syntax)?;
        let value = |v: &str| {
            v.trim()
                .parse::<f64>()
                .map_err(|_| format!("`{v}` in `{s}` is not a number"))
        };
        Ok(ParamRange {
            name: name.trim().to_string(),
            min: value(min)?,
            max: value(max)?,
        })
    }
}

impl std::fmt::Display for ParamRange {
    /// As [`ParamRange`]'s `FromStr` reads it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}={}..{}", self.name, self.min, self.max)
    }
}

/// How far beyond the envelope a [`ParamRange`] may reach: a factor on the larger of the
/// envelope's bounds' magnitudes.
pub const RANGE_REACH: f64 = 10.0;

impl ParamRange {
    /// Why this range cannot be drawn from, if it cannot: an unknown parameter, bounds not
    /// finite or in the wrong order, a sign the parameter cannot take (a mass, a
    /// stiffness or a rate drawn from a positive envelope stays positive; one that may be
    /// 0 stays at or above 0; a magnitude drawn with either sign stays at or above 0), or
    /// bounds more than [`RANGE_REACH`] times the envelope's larger one (for a parameter
    /// the envelope does not draw, beyond its [`ParamSpec::beyond`]).
    pub fn check(&self) -> Result<(), String> {
        let spec = all_specs()
            .into_iter()
            .find(|p| self.names(p.group, p.name))
            .ok_or_else(|| {
                format!(
                    "`{}` is not a simulator parameter (docs/simulator.md lists them)",
                    self.name
                )
            })?;
        let (lo, hi) = (self.min, self.max);
        if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
            return Err(format!(
                "{self}: the bounds must be finite numbers, min <= max"
            ));
        }
        let reach = spec.reach();
        if lo < -reach || hi > reach {
            let why = match spec.beyond {
                Some(_) => "the reach of a parameter the envelope does not draw".to_string(),
                None => format!("{RANGE_REACH} times the envelope's larger bound"),
            };
            return Err(format!(
                "{self}: the bounds must stay within +-{reach} ({why}; the envelope's {} .. {})",
                spec.min, spec.max
            ));
        }
        let positive = spec.min > 0.0 || spec.draw == Draw::Log;
        let non_negative = spec.min >= 0.0 || spec.draw == Draw::EitherSign;
        if positive && lo <= 0.0 {
            return Err(format!(
                "{self}: this parameter is above 0 (the envelope's {} .. {})",
                spec.min, spec.max
            ));
        }
        if non_negative && lo < 0.0 {
            return Err(format!(
                "{self}: this parameter is 0 or more (the envelope's {} .. {})",
                spec.min, spec.max
            ));
        }
        Ok(())
    }

    /// Whether this range is parameter `group.name`'s.
    fn names(&self, group: &str, name: &str) -> bool {
        self.name.split_once('.') == Some((group, name))
    }
}

/// The range `ranges` gives parameter `group.name`, else the envelope's.
pub(crate) fn range_of(
    ranges: &[ParamRange],
    group: &str,
    name: &str,
    envelope: (f64, f64),
) -> (f64, f64) {
    ranges
        .iter()
        .rev()
        .find(|r| r.names(group, name))
        .map_or(envelope, |r| (r.min, r.max))
}

/// How a run chooses its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Draws<'a> {
    /// The nominal values.
    Nominal,
    /// Drawn from their ranges: the envelope's, or those given here.
    Randomized(&'a [ParamRange]),
}

impl Draws<'_> {
    /// Whether the run is randomized.
    pub fn random(self) -> bool {
        matches!(self, Draws::Randomized(_))
    }
}

macro_rules! param_group {
    (@draw) => { Draw::Uniform };
    (@draw log) => { Draw::Log };
    (@draw either_sign) => { Draw::EitherSign };
    (@beyond) => { None };
    (@beyond $reach:expr) => { Some($reach) };
    (
        $(#[doc = $sdoc:literal])+
        struct $name:ident, group $group:literal {
            $( $(#[doc = $doc:literal])+ $field:ident: $unit:literal = $nom:expr, [$lo:expr, $hi:expr $(; beyond $reach:expr)?] $($scale:ident)?; )+
        }
    ) => {
        $(#[doc = $sdoc])+
        #[derive(Clone, Debug, PartialEq)]
        pub struct $name {
            $( $(#[doc = $doc])+ pub $field: f64, )+
        }

        impl $name {
            /// Every parameter of this group, in drawing order.
            pub const SPECS: &'static [ParamSpec] = &[
                $( ParamSpec {
                    group: $group,
                    name: stringify!($field),
                    unit: $unit,
                    nominal: $nom,
                    min: $lo,
                    max: $hi,
                    draw: param_group!(@draw $($scale)?),
                    beyond: param_group!(@beyond $($reach)?),
                    doc: concat!($($doc),+),
                }, )+
            ];

            /// The nominal values.
            pub fn nominal() -> Self {
                Self { $( $field: $nom, )+ }
            }

            /// Every parameter drawn from its range as marked ([`Draw`]), in declaration
            /// order.
            pub fn draw<R: Rng>(rng: &mut R) -> Self {
                Self::draw_within(rng, &[])
            }

            /// Every parameter drawn as [`Self::draw`] draws it, those named in `ranges`
            /// from the range given there instead of the envelope's.
            pub fn draw_within<R: Rng>(rng: &mut R, ranges: &[ParamRange]) -> Self {
                Self { $( $field: {
                    let (lo, hi) = range_of(ranges, $group, stringify!($field), ($lo, $hi));
                    param_group!(@draw $($scale)?).from(rng, lo, hi)
                }, )+ }
            }

            /// Nominal values, or drawn ones.
            pub fn choose<R: Rng>(rng: &mut R, draws: Draws<'_>) -> Self {
                match draws {
                    Draws::Nominal => Self::nominal(),
                    Draws::Randomized(ranges) => Self::draw_within(rng, ranges),
                }
            }

            /// `(group.name, value)` of every parameter, in declaration order.
            pub fn values(&self) -> Vec<(String, f64)> {
                vec![ $( (concat!($group, ".", stringify!($field)).to_string(), self.$field), )+ ]
            }
        }
    };
}

/// 5 degrees (rad): the mounting tolerance of a sensor.
const FIVE_DEGREES: f64 = 0.087_266_462_599_716_48;

/// 35 degrees (rad): the least flexion of joint 2 while approaching (a less flexed finger
/// is close to stretched, where its joints move the tip along one line).
const FLEXION_MIN: f64 = 0.610_865_238_198_015_2;

/// 25 degrees (rad): the pad's nominal angle on the distal link.
const PAD_ANGLE_NOMINAL: f64 = 0.436_332_312_998_582_4;

/// 15 degrees (rad): the largest tilt of an object's surface from the approach.
const FIFTEEN_DEGREES: f64 = 0.261_799_387_799_149_4;

param_group! {
    /// The finger and its fingertip: masses, the foam core, the distal structure's
    /// compliance, the joint controller, its context messages and the drive.
    struct Plant, group "plant" {
        /// Effective mass, at the tip, of the proximal part of the finger (motors reflected
        /// through the transmission and link 1, the proximal link), where the joint
        /// controllers act and which link collisions and knocks on link 1 strike: each
        /// joint's reflected inertia is this mass times the square of the tip's travel per
        /// radian of that joint, so the mass is this along either joint's own direction of
        /// motion and anisotropic where the two directions are not square.
        arm_mass: "kg" = 0.30, [0.25, 0.50];
        /// Mass of link 2 (the distal link) below the force sensor.
        distal_mass: "kg" = 0.05, [0.03, 0.08];
        /// Mass of the fingertip above the force sensor (housing, electronics, foam base):
        /// the mass whose inertia loads the force sensor in a sudden acceleration, and the
        /// body a tap on the tip strikes.
        carrier_mass: "kg" = 0.030, [0.020, 0.045];
        /// Mass riding on the foam core: the rubber skin with its accelerometer and
        /// stress-rate film, and any pad or nail it carries (a thin skin weighs a few grams,
        /// a padded tip tens of grams).
        skin_mass: "kg" = 0.002, [0.0015, 0.03] log;
        /// Normal stiffness of the foam core between carrier and skin.
        foam_stiffness: "N/m" = 4000.0, [500.0, 6000.0] log;
        /// Damping ratio of the fingertip's suspension mode: the skin (and pad) on the foam,
        /// at sqrt(foam_stiffness / skin_mass) / 2 pi: 225 Hz nominal, 20 Hz (a padded tip on
        /// soft foam) to 320 Hz (a thin skin on firm foam).
        foam_damping_ratio: "1" = 0.08, [0.05, 0.15];
        /// Tangential (shear) stiffness of the foam as a fraction of its normal stiffness.
        foam_shear_ratio: "1" = 0.5, [0.3, 0.7];
        /// Frequency of the distal structure's bending mode: link 2 and the fingertip
        /// vibrating against link 1 on the finger's compliance (link bending, joint 2's
        /// transmission). It rings after a collision or a knock.
        link_frequency: "Hz" = 120.0, [80.0, 400.0] log;
        /// Damping ratio of that bending mode.
        link_damping_ratio: "1" = 0.05, [0.01, 0.08];
        /// Rate of the joint controller's loop (PD with feedforward, on the motor-side
        /// position quantized to 1 um).
        control_rate: "Hz" = 1000.0, [1000.0, 2000.0];
        /// Bandwidth of the joint position loop.
        control_bandwidth: "Hz" = 30.0, [10.0, 50.0];
        /// Damping ratio of the position loop.
        control_damping_ratio: "1" = 0.8, [0.7, 1.0];
        /// Error of the controller's feedforward model: it feeds forward (1 + this) x the
        /// finger's mass x the commanded acceleration.
        feedforward_error: "1" = 0.0, [-0.15, 0.15];
        /// Share of the drive's friction the controller compensates, from the commanded
        /// velocity (Coulomb and viscous, with the true coefficients).
        friction_compensation: "1" = 0.0, [0.0, 0.8];
        /// Force limit of the drive at the tip (the joints' torque limits): each joint's
        /// torque saturates at what makes this force along that joint's own direction of
        /// motion.
        force_limit: "N" = 20.0, [8.0, 30.0];
        /// Latency of the controller's context messages (position error, commanded
        /// velocity and acceleration): each reaches the fingertip this long after the
        /// controller computed it.
        context_latency: "s" = 0.0002, [0.0002, 0.0008];
        /// Coulomb friction of the drive, at the tip (proportional to speed below 1 mm/s).
        /// What the controller leaves uncompensated, with the viscous friction, sets the
        /// position error's baseline while moving: friction / (stiffness of the position
        /// loop).
        arm_coulomb_friction: "N" = 0.15, [0.05, 0.3];
        /// Viscous friction of the drive, at the tip.
        arm_viscous_friction: "N s/m" = 1.0, [0.0, 2.0];
        /// Amplitude of the drive's force ripple (gear mesh, cogging) while moving.
        drive_ripple: "N" = 0.03, [0.0, 0.08];
        /// Tip travel per ripple period (the ripple's frequency is speed / pitch).
        ripple_pitch: "m" = 0.0005, [0.0003, 0.001];
        /// Friction coefficient between skin and object (tangential contact force limit).
        skin_friction: "1" = 1.0, [0.3, 1.2];
        /// Tangential stiffness of the skin-object contact while sticking.
        tangential_stiffness: "N/m" = 5000.0, [3000.0, 8000.0];
        /// Length of link 1, the proximal link, from joint 1 to joint 2 (a robot finger's
        /// proximal phalanx).
        link1_length: "m" = 0.05, [0.035, 0.07];
        /// Length of link 2 from joint 2 to the pad's centre.
        link2_length: "m" = 0.04, [0.025, 0.05];
        /// Angle of joint 2 during the approach (0: the finger stretched, where the two
        /// joints move the tip along one line; 90 degrees: square).
        flexion: "rad" = std::f64::consts::FRAC_PI_3, [FLEXION_MIN, std::f64::consts::FRAC_PI_2];
        /// Angle of the pad normal x from the direction joint 2 alone moves the tip
        /// (perpendicular to link 2): how the pad sits on the distal link, on either side.
        /// It sets how the approach splits between the joints: at 0, joint 2 would make it
        /// alone and link 1 would not move (nor strike anything). The magnitude sets the
        /// share of the tip's velocity that link 1 carries, what a link 1 collision takes
        /// away: 12 % to 290 % of the commanded speed over the ranges drawn (median 84 %;
        /// above 100 %, joint 2 alone moves the tip partly backwards), the same on either
        /// side. The side sets its direction: turned away from joint 1's direction
        /// (positive), mostly along the approach; turned towards it (negative), mostly
        /// across the approach.
        pad_angle: "rad" = PAD_ANGLE_NOMINAL, [FIFTEEN_DEGREES, std::f64::consts::FRAC_PI_4] either_sign;
        /// Share of the skin's mass (`skin_mass`) above the stress-rate film: the film,
        /// pressed by the skin it carries, also reads that mass times the rate of the
        /// skin's acceleration along the pad normal. 0: a film at the surface, carrying
        /// nothing; 0.6: a film at the bottom of a skin whose pad rides on it (up to 18 g
        /// in a padded tip).
        film_share: "1" = 0.25, [0.0, 0.6];
        /// The largest offset by which the drive moves the tip off its path and lets it
        /// back, whatever the command: a joint whose transmission takes up its soft zone
        /// and hysteresis as its torque passes through zero, or that sticks and breaks
        /// away from its friction (the sixth separately written model's arms: 25 um over
        /// 40 ms at a steady 34 mm/s, back over 35). Each bump is a smooth push of 50
        /// to 100 ms (a raised cosine) along one joint's own direction of motion, either
        /// way, of a third of this to all of it, as the loops' stiffness holds it. The
        /// envelope's drives do not bump (and draw nothing for it); `--range
        /// plant.drive_bump=1e-5..3e-5` gives a run drives that do.
        drive_bump: "m" = 0.0, [0.0, 0.0; beyond 1e-4];
        /// How often the drive bumps the tip, on average: at random times, independently.
        drive_bump_rate: "1/s" = 1.0, [1.0, 1.0];
    }
}

param_group! {
    /// The sensors and their analog front ends (full scales and base noise are per channel,
    /// see [`super::CHANNELS`]).
    struct Sensors, group "sensors" {
        /// Gain error of the force sensor's x axis (reading = gain x true).
        force_x_gain: "1" = 1.0, [0.9, 1.1];
        /// Gain error of the force sensor's y axis.
        force_y_gain: "1" = 1.0, [0.9, 1.1];
        /// Gain error of the skin accelerometer.
        accel_gain: "1" = 1.0, [0.9, 1.1];
        /// Gain error of the stress-rate sensor.
        stress_gain: "1" = 1.0, [0.9, 1.1];
        /// Cross-axis sensitivity of the force sensor's x axis to the force along its y axis.
        force_x_cross_axis: "1" = 0.0, [-0.03, 0.03];
        /// Cross-axis sensitivity of the force sensor's y axis to the force along its x axis.
        force_y_cross_axis: "1" = 0.0, [-0.03, 0.03];
        /// Mounting misalignment of the force sensor: its axes turned by this angle from the
        /// fingertip's.
        force_misalignment: "rad" = 0.0, [-FIVE_DEGREES, FIVE_DEGREES];
        /// Mounting misalignment of the accelerometer's axis from the pad normal x, towards y.
        accel_misalignment: "rad" = 0.0, [-FIVE_DEGREES, FIVE_DEGREES];
        /// Multiplies every analog channel's base noise (see the channel table).
        noise_scale: "1" = 1.0, [0.5, 2.0];
        /// Amplitude of the mains hum's fundamental on each analog channel, in LSB of that
        /// channel.
        hum_lsb: "1" = 1.0, [0.0, 3.0];
        /// Mains frequency.
        hum_frequency: "Hz" = 50.0, [49.9, 50.1];
        /// Amplitude of the hum's second harmonic as a fraction of its fundamental.
        hum_harmonic2: "1" = 0.0, [0.0, 0.5];
        /// Amplitude of the hum's third harmonic as a fraction of its fundamental.
        hum_harmonic3: "1" = 0.0, [0.0, 0.5];
        /// Residual offset of the force x axis after taring.
        force_x_offset: "N" = 0.0, [-0.05, 0.05];
        /// Residual offset of the force y axis after taring.
        force_y_offset: "N" = 0.0, [-0.05, 0.05];
        /// Offset of the accelerometer's amplifier after its AC coupling.
        accel_offset: "m/s^2" = 0.0, [-1.0, 1.0];
        /// Offset of the stress-rate charge amplifier.
        stress_offset: "N/s" = 0.0, [-2.0, 2.0];
        /// Slow (thermal) drift of the force x axis.
        force_x_drift: "N/s" = 0.0, [-0.005, 0.005];
        /// Slow drift of the force y axis.
        force_y_drift: "N/s" = 0.0, [-0.005, 0.005];
        /// Slow drift of the accelerometer's offset.
        accel_drift: "m/s^3" = 0.0, [-0.05, 0.05];
        /// Slow drift of the stress-rate offset.
        stress_drift: "N/s^2" = 0.0, [-0.1, 0.1];
        /// Corner of the accelerometer's AC coupling (first-order high-pass).
        accel_highpass: "Hz" = 15.0, [10.0, 20.0];
        /// Cross-axis sensitivity of the accelerometer to the skin's acceleration across its
        /// axis.
        accel_cross_axis: "1" = 0.03, [-0.05, 0.05];
        /// Stress-rate crosstalk from the foam's deformation (film bending) as a fraction
        /// of the rate of the foam force: what makes the sensor not perfectly silent
        /// without contact.
        stress_crosstalk: "1" = 0.002, [0.0, 0.005];
    }
}

param_group! {
    /// The commanded approach motion and the event's timing, for the Table 1 runs.
    struct Motion, group "motion" {
        /// Commanded speed as a fraction of the scenario's nominal speed (8, 5 or 2 cm/s).
        speed_factor: "1" = 1.0, [0.8, 1.2];
        /// Angle of the commanded velocity from the pad normal x, towards y.
        approach_angle: "rad" = 0.0, [-0.1745, 0.1745];
        /// When the event (first contact, collision or disturbance) begins (in
        /// `contact_braking`, when the braking begins), after the run's lead-in (none
        /// unless asked for). Every single-event run lasts its lead-in + onset + 130 ms.
        onset: "s" = 0.020, [0.015, 0.040];
    }
}

param_group! {
    /// The surface of any object the fingertip touches.
    struct Surface, group "surface" {
        /// Tilt of the surface's normal from the approach direction x, towards y: the
        /// contact's normal force and its friction turn with it.
        tilt: "rad" = 0.0, [-FIFTEEN_DEGREES, FIFTEEN_DEGREES];
        /// Viscoelastic relaxation of a soft object (foam, fruit; a standard linear solid):
        /// the share of its stiffness that relaxes away under a held deformation. Rigid
        /// (Hertz) objects do not relax.
        relaxation: "1" = 0.0, [0.0, 0.5];
        /// Time constant of that relaxation.
        relaxation_time: "s" = 0.2, [0.02, 1.0] log;
    }
}

param_group! {
    /// A rigid object: a Hertz contact of the skin on it, force = K depth^1.5 (1 + damping x
    /// depth rate), K such that the force is 1 N at a depth of 1 N / stiffness.
    struct HardObject, group "hard_object" {
        /// Secant stiffness at 1 N: the contact force over the depth when pressing with 1 N
        /// (the tangent stiffness is 1.5 times that there, and grows as force^(1/3)).
        stiffness: "N/m" = 80_000.0, [10_000.0, 100_000.0] log;
        /// Hunt-Crossley damping.
        damping: "s/m" = 15.0, [5.0, 30.0];
    }
}

param_group! {
    /// A soft object (sponge, fruit, foam rubber): a linear Hunt-Crossley contact,
    /// force = stiffness x depth x (1 + damping x depth rate), never pulling.
    struct SoftObject, group "soft_object" {
        /// Contact stiffness.
        stiffness: "N/m" = 2000.0, [100.0, 3000.0] log;
        /// Hunt-Crossley damping.
        damping: "s/m" = 40.0, [20.0, 80.0];
    }
}

param_group! {
    /// A very soft object (open-cell foam, a ripe fruit's skin), touched slowly: the force
    /// builds at only stiffness x speed (0.4 to 1.2 N/s at 1 cm/s).
    struct VerySoftObject, group "very_soft_object" {
        /// Contact stiffness.
        stiffness: "N/m" = 80.0, [40.0, 120.0];
        /// Hunt-Crossley damping.
        damping: "s/m" = 40.0, [20.0, 80.0];
    }
}

param_group! {
    /// A contact while the finger brakes, as a real approach slows near the object: the
    /// commanded velocity falls at a constant deceleration from `motion.onset` on (until
    /// the finger would stop), and the object's surface is where the command is a chosen
    /// fraction of that stopping time later. Randomized runs touch a hard object or a
    /// soft one (the `hard_object` or `soft_object` ranges), equally likely; nominal runs
    /// a hard one. On a soft object the finger comes to rest pressing it by what the
    /// command still travels, a few cN on the softest.
    struct Braking, group "braking" {
        /// The commanded deceleration.
        deceleration: "m/s^2" = 0.6, [0.3, 1.0];
        /// When the contact happens, as a fraction of the time the deceleration would take
        /// to stop the finger.
        contact_fraction: "1" = 0.4, [0.2, 0.6];
    }
}

param_group! {
    /// A knock: a tap (a half-sine force pulse) or a vibration burst struck on a link of the
    /// finger, not on the fingertip (a person's hand, a tool, a neighbouring finger), in a
    /// direction within 45 degrees of +x or -x (equally likely in randomized runs, as tap
    /// or burst; nominal: a tap against the approach). The finger is pushed off its path
    /// and the controller brings it back.
    struct Knock, group "knock" {
        /// Peak force of a tap.
        peak: "N" = 6.0, [2.0, 15.0];
        /// Duration of a tap.
        duration: "s" = 0.001, [0.0005, 0.003];
        /// Amplitude of a sinusoidal burst (starting at phase zero).
        vibration_amplitude: "N" = 2.0, [0.5, 3.0];
        /// Frequency of a burst.
        vibration_frequency: "Hz" = 100.0, [40.0, 400.0] log;
        /// Duration of a burst.
        vibration_duration: "s" = 0.050, [0.010, 0.100];
        /// Angle of the force from the nearer of +x and -x, towards y.
        direction_offset: "rad" = 0.0, [-std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4];
    }
}

param_group! {
    /// An object resting on a table that slides when pushed (Coulomb friction), touched
    /// through a Hertz contact as a hard object is.
    struct MovableObject, group "movable_object" {
        /// The object's mass.
        mass: "kg" = 0.2, [0.05, 0.5];
        /// Kinetic friction coefficient with the table (normal force mass x 9.81 m/s^2).
        friction: "1" = 0.5, [0.3, 0.6];
        /// Static over kinetic friction.
        static_ratio: "1" = 1.2, [1.0, 1.4];
        /// Secant stiffness at 1 N of the Hertz contact of skin on the object.
        stiffness: "N/m" = 50_000.0, [10_000.0, 100_000.0] log;
        /// Hunt-Crossley damping of that contact.
        damping: "s/m" = 15.0, [5.0, 30.0];
    }
}

param_group! {
    /// The obstacle a link strikes in a link collision: link 1 (the proximal link, nominal)
    /// or link 2 (the distal link, below the force sensor), equally likely in randomized
    /// runs.
    struct Obstacle, group "obstacle" {
        /// Contact stiffness of link on obstacle: from a padded post or a person's arm
        /// (a few 10^3) to a rigid fixture.
        stiffness: "N/m" = 1_000_000.0, [2_000.0, 2_000_000.0] log;
        /// Hunt-Crossley damping.
        damping: "s/m" = 10.0, [5.0, 20.0];
    }
}

param_group! {
    /// A large disturbance: a tap or a vibration burst struck on the finger while the
    /// fingertip touches nothing: on link 2 below the force sensor (nominal), on link 1, or
    /// on the fingertip's housing above the sensor (the tip). Randomized runs pick tap or
    /// burst, the struck body, and a direction within 45 degrees of +x or -x, each equally
    /// likely; nominal runs are bursts against the approach (the paper's Figure 4).
    /// Directions nearer y are not drawn: the skin accelerometer measures along x only,
    /// and such a disturbance would show on `force_y` alone.
    struct LargeDisturbance, group "large_disturbance" {
        /// Peak of a tap (a half-sine force pulse).
        impulse_peak: "N" = 6.0, [4.0, 10.0];
        /// Duration of a tap.
        impulse_duration: "s" = 0.001, [0.0005, 0.003];
        /// Amplitude of a sinusoidal vibration burst (starting at phase zero).
        vibration_amplitude: "N" = 2.0, [1.0, 3.0];
        /// Frequency of the burst.
        vibration_frequency: "Hz" = 200.0, [40.0, 400.0] log;
        /// Duration of the burst.
        vibration_duration: "s" = 0.040, [0.010, 0.100];
        /// Angle of the force from the nearer of +x and -x, towards y.
        direction_offset: "rad" = 0.0, [-std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4];
    }
}

param_group! {
    /// A small disturbance: as a large one, with smaller forces. Still well above the
    /// sensors' noise: its skin acceleration peaks at several m/s^2 or more.
    struct SmallDisturbance, group "small_disturbance" {
        /// Peak of a tap.
        impulse_peak: "N" = 1.5, [1.0, 3.0];
        /// Duration of a tap.
        impulse_duration: "s" = 0.001, [0.0005, 0.003];
        /// Amplitude of a sinusoidal vibration burst (starting at phase zero).
        vibration_amplitude: "N" = 0.5, [0.3, 0.8];
        /// Frequency of the burst.
        vibration_frequency: "Hz" = 200.0, [40.0, 400.0] log;
        /// Duration of the burst.
        vibration_duration: "s" = 0.040, [0.010, 0.100];
        /// Angle of the force from the nearer of +x and -x, towards y.
        direction_offset: "rad" = 0.0, [-std::f64::consts::FRAC_PI_4, std::f64::consts::FRAC_PI_4];
    }
}

param_group! {
    /// A sudden commanded acceleration along the approach direction: a step of commanded
    /// acceleration at a controller tick, held until the velocity has changed by the
    /// chosen amount, then back to zero.
    struct SuddenAccel, group "sudden_accel" {
        /// The commanded acceleration.
        amplitude: "m/s^2" = 15.0, [8.0, 25.0];
        /// The change of commanded speed it brings.
        velocity_change: "m/s" = 0.08, [0.05, 0.12];
    }
}

param_group! {
    /// Event-free motion: a sequence of segments, each a point-to-point move (trapezoidal
    /// speed profile, sudden accelerations included) or a change of the cruising velocity
    /// (a gentle ramp to a new speed and direction, then cruising: slowing down, speeding
    /// up, turning, stopping), with pauses; each segment draws its own values from these
    /// ranges (the nominal values are only used to describe them).
    struct FreeMotion, group "free_motion" {
        /// Probability that a pause (fingertip at rest) precedes a point-to-point move.
        pause_probability: "1" = 0.5, [0.5, 0.5];
        /// Duration of a pause.
        pause: "s" = 0.1, [0.02, 0.3];
        /// Probability that a segment is a change of cruising velocity rather than a
        /// point-to-point move.
        change_probability: "1" = 0.5, [0.5, 0.5];
        /// Length of a point-to-point move.
        distance: "m" = 0.015, [0.002, 0.03];
        /// Peak speed of a point-to-point move.
        speed: "m/s" = 0.05, [0.01, 0.10];
        /// Acceleration of a point-to-point move (sudden ones included).
        acceleration: "m/s^2" = 2.0, [0.2, 25.0] log;
        /// The new cruising speed of a velocity change (0: it stops).
        cruise_speed: "m/s" = 0.05, [0.0, 0.10];
        /// Acceleration of a velocity change.
        gentle_acceleration: "m/s^2" = 1.0, [0.2, 3.0] log;
        /// How long the finger cruises after a velocity change.
        cruise: "s" = 0.1, [0.02, 0.5];
        /// Moves stay within this distance of the start point.
        workspace_radius: "m" = 0.04, [0.04, 0.04];
    }
}

/// Every parameter of every group, in a stable order (plant, sensors, motion, objects and
/// braking, obstacle, disturbances and knocks, sudden acceleration, free motion).
pub fn all_specs() -> Vec<ParamSpec> {
    let mut v = Vec::new();
    for g in [
        Plant::SPECS,
        Sensors::SPECS,
        Motion::SPECS,
        HardObject::SPECS,
        Surface::SPECS,
        SoftObject::SPECS,
        VerySoftObject::SPECS,
        Braking::SPECS,
        MovableObject::SPECS,
        Obstacle::SPECS,
        LargeDisturbance::SPECS,
        SmallDisturbance::SPECS,
        Knock::SPECS,
        SuddenAccel::SPECS,
        FreeMotion::SPECS,
    ] {
        v.extend_from_slice(g);
    }
    v
}

/// The parameter table as Markdown (the one in `docs/simulator.md`).
pub fn specs_markdown() -> String {
    let mut s = String::from(
        "| parameter | unit | nominal | randomized range | meaning |\n|---|---|---|---|---|\n",
    );
    for p in all_specs() {
        s.push_str(&format!(
            "| `{}.{}` | {} | {} | {}{} .. {}{} | {} |\n",
            p.group,
            p.name,
            p.unit,
            fmt_num(p.nominal),
            if p.draw == Draw::EitherSign {
                "±("
            } else {
                ""
            },
            fmt_num(p.min),
            fmt_num(p.max),
            match (p.draw, p.beyond) {
                (Draw::EitherSign, _) => ")".into(),
                (_, Some(reach)) => format!(" (not drawn; a range up to {})", fmt_num(reach)),
                (Draw::Uniform, None) => String::new(),
                (Draw::Log, None) => " (log)".into(),
            },
            p.doc.trim().replace("  ", " ")
        ));
    }
    s
}

fn fmt_num(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if (1e-4..1e7).contains(&a) {
        let s = format!("{v:.6}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{v:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nominal_inside_ranges_and_names_unique() {
        let specs = all_specs();
        for p in &specs {
            assert!(p.draw.admits(p.nominal, p.min, p.max), "{p:?}");
            assert!(!p.doc.trim().is_empty(), "{p:?}");
        }
        for (i, p) in specs.iter().enumerate() {
            for q in &specs[..i] {
                assert!(
                    (p.group, p.name) != (q.group, q.name),
                    "duplicate {}.{}",
                    p.group,
                    p.name
                );
            }
        }
    }

    /// A log-uniform parameter is below its range's geometric mean half the time; a uniform
    /// draw would put about 80 % of 100 .. 3000 above it.
    #[test]
    fn log_parameters_are_drawn_evenly_per_decade() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(11);
        let spec = SoftObject::SPECS[0];
        assert_eq!(spec.draw, Draw::Log);
        let middle = (spec.min * spec.max).sqrt();
        let n = 4000;
        let below = (0..n)
            .filter(|_| SoftObject::draw(&mut rng).stiffness < middle)
            .count();
        assert!((1800..2200).contains(&below), "{below} of {n}");
    }

    /// The pad sits on either side of the distal link in about half the runs each.
    #[test]
    fn either_sign_parameters_take_both_signs() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(5);
        let n = 4000;
        let negative = (0..n)
            .filter(|_| Plant::draw(&mut rng).pad_angle < 0.0)
            .count();
        assert!((1800..2200).contains(&negative), "{negative} of {n}");
    }

    #[test]
    fn draws_stay_in_range() {
        use rand::SeedableRng;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        for _ in 0..200 {
            let p = Plant::draw(&mut rng);
            for ((name, v), s) in p.values().iter().zip(Plant::SPECS) {
                assert!(s.draw.admits(*v, s.min, s.max), "{name} = {v}");
            }
        }
    }
}
