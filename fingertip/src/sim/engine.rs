//! The physics and the sensor chain, integrated at the internal rate and sampled at the
//! detector rate.
//!
//! # Mechanics (each axis x and y in the fingertip frame)
//!
//! Three bodies in a chain, integrated with semi-implicit (symplectic) Euler:
//!
//! ```text
//!  controller force ─> [arm] ──link spring/damper── [distal link + carrier] ──foam── [skin] ─> object
//!                        │                               │ (force sensor between        (contact on x,
//!                   obstacle (x),                        │  distal link and carrier)     friction on y)
//!                   knock                           disturbance
//! ```
//!
//! - `arm`: the proximal part of the finger, position-controlled by a PD law with
//!   feedforward of the commanded acceleration, run at the controller rate on the
//!   motor-side position (quantized to the encoder resolution). The drive adds a small
//!   force ripple whose frequency follows the commanded speed. In a link collision the arm
//!   strikes the obstacle (Hunt-Crossley contact along x); a knock on the proximal link
//!   acts here.
//! - `distal`: the distal link and the fingertip's carrier, joined to the arm by the
//!   structural compliance. Other disturbances act here, below the force sensor.
//! - `skin`: the rubber skin on the foam core. Contact with an object acts on the skin:
//!   a Hunt-Crossley normal force along x and a stick-slip (spring-slider) friction along y.
//!   A movable object is a mass on a table with Coulomb friction (static and kinetic).
//!
//! # Sensors
//!
//! - Force (x, y): the load the fingertip above the sensor puts on it,
//!   `-(carrier_mass * distal_accel) - foam_force_on_skin`: in quiet contact this is the
//!   force the environment exerts on the fingertip; in free motion it is the inertia of the
//!   carrier and skin, so it oscillates about zero when the fingertip rings and reads
//!   `-m a` in a commanded acceleration.
//! - Skin acceleration: the skin's x acceleration plus a cross-axis share of its y
//!   acceleration, through a first-order AC coupling.
//! - Stress rate: the rate of change of the contact's normal force, plus a small crosstalk
//!   from the rate of the foam force (film bending), zero when nothing changes.
//! - Every analog channel then passes the 4th-order anti-alias filter at the internal rate
//!   and is sampled at the detector rate by a 12-bit ADC with gain error, offset, drift,
//!   50 Hz hum and white noise, clipped at its full scale.
//! - Context (from the controller, held between its ticks): position error (commanded
//!   minus the encoder-measured tip position), commanded velocity and acceleration.

use super::CHANNELS;
use super::filters::{AntiAliasFilter, HighPass1};
use super::params::{Plant, Sensors};
use super::trajectory::Trajectory;
use rand::{Rng, RngExt};
use std::f64::consts::{PI, TAU};

/// Standard gravity, for the movable object's friction.
const GRAVITY: f64 = 9.81;

/// Below this speed the drive's Coulomb friction is regularized (proportional to speed).
const FRICTION_SPEED: f64 = 0.001;

/// Resolution of the tip position the controller computes from its joint encoders.
pub(crate) const ENCODER_RESOLUTION: f64 = 1e-6;

/// An object the skin can touch (its surface is normal to x).
#[derive(Clone, Debug)]
pub(crate) struct ObjectSetup {
    /// Position of the surface along x, from the skin's position at time zero.
    pub surface: f64,
    pub stiffness: f64,
    pub damping: f64,
    /// `(mass, kinetic friction, static friction)` for an object that can slide.
    pub movable: Option<(f64, f64, f64)>,
}

/// The obstacle the arm (proximal link) can strike along x.
#[derive(Clone, Debug)]
pub(crate) struct ObstacleSetup {
    /// Position of the obstacle along x, from the arm's position at time zero.
    pub position: f64,
    pub stiffness: f64,
    pub damping: f64,
}

/// The shape of a disturbance force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum DisturbanceKind {
    /// Half-sine pulse.
    Impulse { peak: f64, duration: f64 },
    /// Sine burst starting at phase zero.
    Vibration {
        amplitude: f64,
        frequency: f64,
        duration: f64,
    },
}

/// The body a disturbance strikes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Struck {
    /// The proximal link (the arm body, where the controller acts).
    Arm,
    /// The distal link, below the force sensor.
    Distal,
}

/// A disturbance force on one of the finger's links.
#[derive(Clone, Debug)]
pub(crate) struct DisturbanceSetup {
    pub start: f64,
    pub kind: DisturbanceKind,
    pub direction: f64,
    pub body: Struck,
}

impl DisturbanceSetup {
    fn duration(&self) -> f64 {
        match self.kind {
            DisturbanceKind::Impulse { duration, .. } => duration,
            DisturbanceKind::Vibration { duration, .. } => duration,
        }
    }

    /// Signed force magnitude `tau` seconds after the start.
    fn force(&self, tau: f64) -> f64 {
        match self.kind {
            DisturbanceKind::Impulse { peak, duration } => peak * (PI * tau / duration).sin(),
            DisturbanceKind::Vibration {
                amplitude,
                frequency,
                ..
            } => amplitude * (TAU * frequency * tau).sin(),
        }
    }
}

/// Everything one run needs.
pub(crate) struct Setup {
    pub plant: Plant,
    pub sensors: Sensors,
    pub trajectory: Trajectory,
    pub object: Option<ObjectSetup>,
    pub obstacle: Option<ObstacleSetup>,
    pub disturbance: Option<DisturbanceSetup>,
    /// Number of output rows.
    pub rows: usize,
    pub rate_hz: f64,
    /// Internal steps per output sample.
    pub oversampling: usize,
    pub controller_rate_hz: f64,
}

/// What the physical event was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Happened {
    Contact,
    Collision,
    Disturbance,
}

/// The sampled channels (in [`CHANNELS`] order) and the physical onset.
pub(crate) struct Output {
    pub channels: Vec<Vec<f64>>,
    /// First internal instant at which an event force was non-zero.
    pub onset: Option<(f64, Happened)>,
}

/// The ADC of one analog channel.
struct Adc {
    lsb: f64,
    gain: f64,
    offset: f64,
    drift: f64,
    hum: f64,
    /// cos and sin of the hum's phase on this channel.
    hum_phase: (f64, f64),
    sigma: f64,
}

impl Adc {
    fn new(channel: usize, gain: f64, offset: f64, drift: f64, s: &Sensors, phase: f64) -> Adc {
        let (full_scale, noise_rms) = CHANNELS[channel]
            .adc
            .map_or((1.0, 0.0), |a| (a.full_scale, a.noise_rms));
        let lsb = 2.0 * full_scale / 4096.0;
        Adc {
            lsb,
            gain,
            offset,
            drift,
            hum: s.hum_lsb * lsb,
            hum_phase: (phase.cos(), phase.sin()),
            sigma: noise_rms * s.noise_scale,
        }
    }

    /// Converts `v` at time `t`; `mains` is (cos, sin) of the mains phase, `z` a standard
    /// normal deviate.
    #[inline]
    fn convert(&self, v: f64, t: f64, mains: (f64, f64), z: f64) -> f64 {
        // sin(mains + phase)
        let hum = mains.1 * self.hum_phase.0 + mains.0 * self.hum_phase.1;
        let y = self.gain * v + self.offset + self.drift * t + self.hum * hum + self.sigma * z;
        // Adding zero turns a negative zero into a positive one.
        (y / self.lsb).round().clamp(-2048.0, 2047.0) * self.lsb + 0.0
    }
}

/// Standard normal deviates by Marsaglia's polar method (two per accepted pair).
struct Gauss {
    spare: Option<f64>,
}

impl Gauss {
    fn next<R: Rng>(&mut self, rng: &mut R) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        loop {
            let u = 2.0 * rng.random::<f64>() - 1.0;
            let v = 2.0 * rng.random::<f64>() - 1.0;
            let q = u * u + v * v;
            // Accepts about 79 % of pairs; q > 0 keeps the logarithm finite.
            if q > 0.0 && q < 1.0 {
                let k = (-2.0 * q.ln() / q).sqrt();
                self.spare = Some(v * k);
                return u * k;
            }
        }
    }
}

/// A spring and a damper in parallel.
#[derive(Clone, Copy, Debug)]
struct SpringDamper {
    stiffness: f64,
    damping: f64,
}

impl SpringDamper {
    /// The force for an extension `dx` and an extension rate `dv`.
    fn force(&self, dx: f64, dv: f64) -> f64 {
        self.stiffness * dx + self.damping * dv
    }
}

/// The three-body chain's coefficients, derived once from the plant's parameters.
struct Chain {
    arm_mass: f64,
    /// The distal link and the carrier, rigid through the stiff force sensor.
    distal_mass: f64,
    skin_mass: f64,
    /// The whole finger, arm to skin.
    total_mass: f64,
    /// The structural compliance between the arm and the distal body (its mode at the
    /// plant's link frequency).
    link: SpringDamper,
    /// The foam between the distal body and the skin: normal (x) and shear (y).
    foam: [SpringDamper; 2],
    arm_coulomb_friction: f64,
    arm_viscous_friction: f64,
}

impl Chain {
    fn new(p: &Plant) -> Chain {
        let ma = p.arm_mass;
        let md = p.distal_mass + p.carrier_mass;
        let ms = p.skin_mass;
        let m_tip = md + ms;
        let m_tot = ma + m_tip;
        // Foam.
        let kf = p.foam_stiffness;
        let cf = 2.0 * p.foam_damping_ratio * (kf * ms).sqrt();
        let kfy = kf * p.foam_shear_ratio;
        let cfy = 2.0 * p.foam_damping_ratio * (kfy * ms).sqrt();
        // Structural mode: arm against the distal body and skin.
        let mu = ma * m_tip / m_tot;
        let wl = TAU * p.link_frequency;
        let kl = mu * wl * wl;
        let cl = 2.0 * p.link_damping_ratio * mu * wl;
        Chain {
            arm_mass: ma,
            distal_mass: md,
            skin_mass: ms,
            total_mass: m_tot,
            link: SpringDamper {
                stiffness: kl,
                damping: cl,
            },
            foam: [
                SpringDamper {
                    stiffness: kf,
                    damping: cf,
                },
                SpringDamper {
                    stiffness: kfy,
                    damping: cfy,
                },
            ],
            arm_coulomb_friction: p.arm_coulomb_friction,
            arm_viscous_friction: p.arm_viscous_friction,
        }
    }

    /// The drive's friction force at arm velocity `v`: Coulomb (regularized below
    /// [`FRICTION_SPEED`]) plus viscous.
    fn friction(&self, v: f64) -> f64 {
        self.arm_coulomb_friction * (v / FRICTION_SPEED).clamp(-1.0, 1.0)
            + self.arm_viscous_friction * v
    }
}

/// The forces from outside the chain on one axis's bodies.
struct Loads {
    /// The drive's force on the arm: controller, ripple and friction.
    drive: f64,
    /// The obstacle's force pushing the arm back.
    obstacle: f64,
    /// A disturbance striking the arm (the proximal link).
    knock: f64,
    /// A disturbance striking the distal body.
    disturbance: f64,
    /// The object's force on the skin.
    object: f64,
}

/// The accelerations of one axis's bodies, and the foam's force on the skin.
struct Accelerations {
    arm: f64,
    distal: f64,
    skin: f64,
    foam_force: f64,
}

/// State of one axis of the three-body chain.
#[derive(Clone, Copy, Debug, Default)]
struct Axis {
    xa: f64,
    va: f64,
    xd: f64,
    vd: f64,
    xs: f64,
    vs: f64,
}

impl Axis {
    /// Steady motion at velocity `v`, all springs relaxed, lagging the command by `lag`.
    fn start(v: f64, lag: f64) -> Axis {
        Axis {
            xa: -lag,
            va: v,
            xd: -lag,
            vd: v,
            xs: -lag,
            vs: v,
        }
    }

    /// Newton's law for the three bodies: the link and the foam (`foam`, this axis's) pull
    /// them together, the `loads` act from outside.
    fn accelerations(&self, chain: &Chain, foam: &SpringDamper, loads: &Loads) -> Accelerations {
        let fl = chain.link.force(self.xa - self.xd, self.va - self.vd);
        let ff = foam.force(self.xd - self.xs, self.vd - self.vs);
        Accelerations {
            arm: (loads.drive - fl - loads.obstacle + loads.knock) / chain.arm_mass,
            distal: (fl - ff + loads.disturbance) / chain.distal_mass,
            skin: (ff + loads.object) / chain.skin_mass,
            foam_force: ff,
        }
    }

    /// One semi-implicit Euler step: velocities first, positions with the new ones.
    fn integrate(&mut self, a: &Accelerations, dt: f64) {
        self.va += a.arm * dt;
        self.vd += a.distal * dt;
        self.vs += a.skin * dt;
        self.xa += self.va * dt;
        self.xd += self.vd * dt;
        self.xs += self.vs * dt;
    }
}

/// A unit phasor `(cos, sin)` turned by a fixed step at each [`Phasor::rotate`].
struct Phasor {
    cos: f64,
    sin: f64,
    /// Sine and cosine of the step.
    step: (f64, f64),
}

impl Phasor {
    /// The step of a phasor that stands still.
    const STILL: (f64, f64) = (0.0, 1.0);

    /// At phase zero, turning by `step` radians.
    fn new(step: f64) -> Phasor {
        Phasor {
            cos: 1.0,
            sin: 0.0,
            step: step.sin_cos(),
        }
    }

    fn rotate(&mut self) {
        let (ds, dc) = self.step;
        (self.cos, self.sin) = (self.cos * dc - self.sin * ds, self.sin * dc + self.cos * ds);
    }

    /// Brings the magnitude back to one (rounding makes it wander).
    fn normalize(&mut self) {
        let norm = self.cos.hypot(self.sin);
        self.cos /= norm;
        self.sin /= norm;
    }
}

/// The drive's force ripple: a sinusoid along the commanded direction whose phase advances
/// by one period per ripple pitch of commanded travel.
struct DriveRipple {
    amplitude: f64,
    pitch: f64,
    /// The integration step.
    dt: f64,
    phasor: Phasor,
    /// Unit vector of the commanded velocity (zero at standstill).
    direction: [f64; 2],
}

impl DriveRipple {
    /// Follows the commanded velocity `v` (at a controller tick).
    fn follow(&mut self, v: [f64; 2]) {
        let speed = v[0].hypot(v[1]);
        if speed > 1e-9 && self.amplitude > 0.0 {
            self.direction = [v[0] / speed, v[1] / speed];
            let step_angle = TAU * speed * self.dt / self.pitch;
            self.phasor.step = step_angle.sin_cos();
        } else {
            self.direction = [0.0; 2];
            self.phasor.step = Phasor::STILL;
        }
        self.phasor.normalize();
    }

    /// Advances one integration step and returns the ripple force along x and y.
    fn force(&mut self) -> [f64; 2] {
        self.phasor.rotate();
        let ripple = self.amplitude * self.phasor.sin;
        [ripple * self.direction[0], ripple * self.direction[1]]
    }
}

/// The tip position the controller measures: the arm's, quantized by the encoders.
fn encoder(x: f64) -> f64 {
    (x / ENCODER_RESOLUTION).round() * ENCODER_RESOLUTION
}

/// The robot's position controller: a PD law with feedforward of the commanded
/// acceleration, run at its own rate; its force and context are held between ticks.
struct Controller {
    total_mass: f64,
    kp: f64,
    kd: f64,
    /// The tick period.
    period: f64,
    internal_rate: f64,
    /// The force on the arm, x and y.
    force: [f64; 2],
    /// The context it sends: position error, commanded velocity and acceleration (x, y).
    context: [f64; 6],
    tick: u64,
    /// The integration step of the next tick.
    next_tick: u64,
}

impl Controller {
    fn new(p: &Plant, total_mass: f64, rate_hz: f64, internal_rate: f64) -> Controller {
        let wc = TAU * p.control_bandwidth;
        Controller {
            total_mass,
            kp: total_mass * wc * wc,
            kd: 2.0 * p.control_damping_ratio * total_mass * wc,
            period: 1.0 / rate_hz,
            internal_rate,
            force: [0.0; 2],
            context: [0.0; 6],
            tick: 0,
            next_tick: 0,
        }
    }

    /// Runs the tick due at integration step `i`, if any: reads the command and the
    /// encoders, updates the force and the context, and retunes the drive `ripple`.
    fn update(
        &mut self,
        i: u64,
        trajectory: &mut Trajectory,
        axes: &[Axis; 2],
        ripple: &mut DriveRipple,
    ) {
        if i != self.next_tick {
            return;
        }
        let cmd = trajectory.at(self.tick);
        let measured = [encoder(axes[0].xa), encoder(axes[1].xa)];
        self.force = std::array::from_fn(|k| {
            self.total_mass * cmd.a[k]
                + self.kp * (cmd.p[k] - measured[k])
                + self.kd * (cmd.v[k] - axes[k].va)
        });
        self.context = [
            cmd.p[0] - measured[0],
            cmd.p[1] - measured[1],
            cmd.v[0],
            cmd.v[1],
            cmd.a[0],
            cmd.a[1],
        ];
        ripple.follow(cmd.v);
        self.tick += 1;
        self.next_tick = (self.tick as f64 * self.period * self.internal_rate - 1e-6).ceil() as u64;
    }
}

/// The disturbance's force on the distal body, x and y.
struct Disturbance<'a> {
    setup: &'a DisturbanceSetup,
    end: f64,
    /// Cosine and sine of its direction.
    direction: (f64, f64),
}

impl Disturbance<'_> {
    fn new(setup: &DisturbanceSetup) -> Disturbance<'_> {
        Disturbance {
            setup,
            end: setup.start + setup.duration(),
            direction: (setup.direction.cos(), setup.direction.sin()),
        }
    }

    /// The force at time `t`.
    fn force(&self, t: f64) -> [f64; 2] {
        if t >= self.setup.start && t < self.end {
            let f = self.setup.force(t - self.setup.start);
            [f * self.direction.0, f * self.direction.1]
        } else {
            [0.0; 2]
        }
    }
}

/// A Hunt-Crossley contact force at penetration `depth` and penetration rate `velocity`:
/// zero out of contact, and never pulling.
fn hunt_crossley(stiffness: f64, damping: f64, depth: f64, velocity: f64) -> f64 {
    if depth > 0.0 {
        (stiffness * depth * (1.0 + damping * velocity)).max(0.0)
    } else {
        0.0
    }
}

/// The obstacle the arm strikes along x.
struct ArmObstacle<'a> {
    setup: &'a ObstacleSetup,
    /// Its position in the arm's coordinates.
    position: f64,
}

impl ArmObstacle<'_> {
    /// The force pushing the arm back.
    fn force(&self, arm: &Axis) -> f64 {
        hunt_crossley(
            self.setup.stiffness,
            self.setup.damping,
            arm.xa - self.position,
            arm.va,
        )
    }
}

/// The skin's contact with the object: a normal force along x, a stick-slip friction along
/// y (a spring anchored on the object that slides when it would exceed the friction
/// limit), and a movable object's own motion on its table.
struct ObjectContact<'a> {
    setup: &'a ObjectSetup,
    /// The surface's position at time zero, in the skin's coordinates.
    surface: f64,
    /// The movable object's displacement and velocity along x.
    position: f64,
    velocity: f64,
    /// Static friction holds the movable object.
    stuck: bool,
    /// The skin's y position at which the friction spring is relaxed.
    anchor: f64,
    in_contact: bool,
}

impl ObjectContact<'_> {
    fn new(setup: &ObjectSetup, skin: f64) -> ObjectContact<'_> {
        ObjectContact {
            setup,
            surface: setup.surface + skin,
            position: 0.0,
            velocity: 0.0,
            stuck: true,
            anchor: 0.0,
            in_contact: false,
        }
    }

    /// The normal force (pushing the skin back along x) and the friction force on the skin
    /// (along y).
    fn forces(&mut self, axes: &[Axis; 2], p: &Plant) -> (f64, f64) {
        let (x, y) = (&axes[0], &axes[1]);
        let depth = x.xs - (self.surface + self.position);
        let f_n = hunt_crossley(
            self.setup.stiffness,
            self.setup.damping,
            depth,
            x.vs - self.velocity,
        );
        let mut f_t = 0.0;
        if f_n > 0.0 {
            if !self.in_contact {
                self.anchor = y.xs;
                self.in_contact = true;
            }
            let limit = p.skin_friction * f_n / p.tangential_stiffness;
            let mut e = y.xs - self.anchor;
            if e.abs() > limit {
                e = limit.copysign(e);
                self.anchor = y.xs - e;
            }
            f_t = -p.tangential_stiffness * e;
        } else {
            self.in_contact = false;
        }
        (f_n, f_t)
    }

    /// One step of a movable object under the normal force `f_n`: it breaks free when
    /// `f_n` exceeds static friction, slides against kinetic friction and sticks again
    /// when it stops.
    fn slide(&mut self, f_n: f64, dt: f64) {
        let Some((m_o, mu_k, mu_s)) = self.setup.movable else {
            return;
        };
        let normal = m_o * GRAVITY;
        if self.stuck && f_n > mu_s * normal {
            self.stuck = false;
        }
        if !self.stuck {
            let ao = (f_n - mu_k * normal) / m_o;
            self.velocity += ao * dt;
            if self.velocity <= 0.0 {
                self.velocity = 0.0;
                self.stuck = true;
            }
            self.position += self.velocity * dt;
        }
    }
}

/// The event the forces of one step show, if any (a contact before a collision before a
/// disturbance).
fn event(f_n: f64, f_ob: f64, disturbance: [f64; 2]) -> Option<Happened> {
    if f_n > 0.0 {
        Some(Happened::Contact)
    } else if f_ob > 0.0 {
        Some(Happened::Collision)
    } else if disturbance[0] != 0.0 || disturbance[1] != 0.0 {
        Some(Happened::Disturbance)
    } else {
        None
    }
}

/// The fingertip's sensors and their anti-alias filters at the internal rate, and the ADCs
/// sampling them at the detector rate.
struct SensorChain {
    carrier_mass: f64,
    accel_cross_axis: f64,
    stress_crosstalk: f64,
    internal_rate: f64,
    rate_hz: f64,
    oversampling: usize,
    /// The accelerometer's AC coupling.
    highpass: HighPass1,
    anti_alias: [AntiAliasFilter; 4],
    adc: [Adc; 4],
    gauss: Gauss,
    /// The mains phase, advanced once per output sample.
    mains: Phasor,
    /// The normal contact force and the foam's x force at the previous step.
    previous: (f64, f64),
    /// Integration steps until the next sample.
    until_sample: usize,
}

impl SensorChain {
    /// Draws the hum's phase on each channel from `noise`.
    fn new<R: Rng>(
        s: &Sensors,
        carrier_mass: f64,
        rate_hz: f64,
        oversampling: usize,
        noise: &mut R,
    ) -> SensorChain {
        let internal_rate = rate_hz * oversampling as f64;
        let anti_alias = std::array::from_fn(|_| AntiAliasFilter::new(internal_rate, rate_hz));
        let highpass = HighPass1::new(s.accel_highpass, internal_rate);
        let adc = [
            Adc::new(
                0,
                s.force_x_gain,
                s.force_x_offset,
                s.force_x_drift,
                s,
                noise.random::<f64>() * TAU,
            ),
            Adc::new(
                1,
                s.force_y_gain,
                s.force_y_offset,
                s.force_y_drift,
                s,
                noise.random::<f64>() * TAU,
            ),
            Adc::new(
                2,
                s.accel_gain,
                s.accel_offset,
                s.accel_drift,
                s,
                noise.random::<f64>() * TAU,
            ),
            Adc::new(
                3,
                s.stress_gain,
                s.stress_offset,
                s.stress_drift,
                s,
                noise.random::<f64>() * TAU,
            ),
        ];
        SensorChain {
            carrier_mass,
            accel_cross_axis: s.accel_cross_axis,
            stress_crosstalk: s.stress_crosstalk,
            internal_rate,
            rate_hz,
            oversampling,
            highpass,
            anti_alias,
            adc,
            gauss: Gauss { spare: None },
            mains: Phasor::new(TAU * s.hum_frequency / rate_hz),
            previous: (0.0, 0.0),
            until_sample: 0,
        }
    }

    /// The analog signals of one step (force x and y, skin acceleration, stress rate) from
    /// the axes' accelerations and the normal contact force `f_n`.
    fn transduce(&mut self, axes: &[Accelerations; 2], f_n: f64) -> [f64; 4] {
        let (x, y) = (&axes[0], &axes[1]);
        let force_x = -self.carrier_mass * x.distal - x.foam_force;
        let force_y = -self.carrier_mass * y.distal - y.foam_force;
        let accel = self
            .highpass
            .process(x.skin + self.accel_cross_axis * y.skin);
        let (prev_fn, prev_ff) = self.previous;
        let stress = (f_n - prev_fn) * self.internal_rate
            + self.stress_crosstalk * (x.foam_force - prev_ff) * self.internal_rate;
        self.previous = (f_n, x.foam_force);
        [force_x, force_y, accel, stress]
    }

    /// Filters the `analog` signals of integration step `i` and, on a sampling step,
    /// returns the ADCs' readings.
    fn sample<R: Rng>(&mut self, i: u64, analog: [f64; 4], noise: &mut R) -> Option<[f64; 4]> {
        let mut filtered = [0.0; 4];
        for ((y, filter), v) in filtered.iter_mut().zip(&mut self.anti_alias).zip(analog) {
            *y = filter.process(v);
        }
        let readings = (self.until_sample == 0).then(|| {
            self.until_sample = self.oversampling;
            self.convert(i / self.oversampling as u64, filtered, noise)
        });
        self.until_sample -= 1;
        readings
    }

    /// The ADCs' readings of output row `row`.
    fn convert<R: Rng>(&mut self, row: u64, filtered: [f64; 4], noise: &mut R) -> [f64; 4] {
        let ts = row as f64 / self.rate_hz;
        let mains = (self.mains.cos, self.mains.sin);
        let mut readings = [0.0; 4];
        for ((r, adc), y) in readings.iter_mut().zip(&self.adc).zip(filtered) {
            let z = self.gauss.next(noise);
            *r = adc.convert(y, ts, mains, z);
        }
        self.mains.rotate();
        if row.is_multiple_of(1024) {
            self.mains.normalize();
        }
        readings
    }
}

/// Runs the simulation. `noise` drives the sensor noise and the hum phases.
pub(crate) fn run<R: Rng>(setup: &mut Setup, noise: &mut R) -> Output {
    let p = &setup.plant;
    let n_over = setup.oversampling.max(1);
    let internal_rate = setup.rate_hz * n_over as f64;
    let dt = 1.0 / internal_rate;

    let chain = Chain::new(p);
    let mut controller =
        Controller::new(p, chain.total_mass, setup.controller_rate_hz, internal_rate);
    let mut sensors =
        SensorChain::new(&setup.sensors, p.carrier_mass, setup.rate_hz, n_over, noise);

    // Initial state: steady motion at the commanded initial velocity, all springs relaxed,
    // the whole finger lagging the command by the position error that balances friction.
    let c0 = setup.trajectory.at(0);
    let mut axes: [Axis; 2] =
        std::array::from_fn(|k| Axis::start(c0.v[k], chain.friction(c0.v[k]) / controller.kp));
    let mut contact = setup
        .object
        .as_ref()
        .map(|o| ObjectContact::new(o, axes[0].xs));
    let obstacle = setup.obstacle.as_ref().map(|o| ArmObstacle {
        setup: o,
        position: o.position + axes[0].xa,
    });
    let disturbance = setup.disturbance.as_ref().map(Disturbance::new);
    let mut ripple = DriveRipple {
        amplitude: p.drive_ripple,
        pitch: p.ripple_pitch,
        dt,
        phasor: Phasor::new(0.0),
        direction: [0.0; 2],
    };

    let mut onset: Option<(f64, Happened)> = None;
    let mut out: Vec<Vec<f64>> = (0..CHANNELS.len())
        .map(|_| Vec::with_capacity(setup.rows))
        .collect();
    let total_steps = (setup.rows.saturating_sub(1) * n_over) as u64;

    for i in 0..=total_steps {
        let t = i as f64 * dt;

        controller.update(i, &mut setup.trajectory, &axes, &mut ripple);
        let ripple_force = ripple.force();
        let f_d = disturbance.as_ref().map_or([0.0; 2], |d| d.force(t));
        let (f_n, f_t) = contact.as_mut().map_or((0.0, 0.0), |c| c.forces(&axes, p));
        let f_ob = obstacle.as_ref().map_or(0.0, |o| o.force(&axes[0]));
        if onset.is_none() {
            onset = event(f_n, f_ob, f_d).map(|h| (t, h));
        }

        let drive = |k: usize| -> f64 {
            controller.force[k] + ripple_force[k] - chain.friction(axes[k].va)
        };
        let on_arm = disturbance
            .as_ref()
            .is_some_and(|d| d.setup.body == Struck::Arm);
        let (knock, f_d) = if on_arm {
            (f_d, [0.0; 2])
        } else {
            ([0.0; 2], f_d)
        };
        let loads = [
            Loads {
                drive: drive(0),
                obstacle: f_ob,
                knock: knock[0],
                disturbance: f_d[0],
                object: -f_n,
            },
            Loads {
                drive: drive(1),
                obstacle: 0.0,
                knock: knock[1],
                disturbance: f_d[1],
                object: f_t,
            },
        ];
        let accelerations: [Accelerations; 2] =
            std::array::from_fn(|k| axes[k].accelerations(&chain, &chain.foam[k], &loads[k]));

        let analog = sensors.transduce(&accelerations, f_n);
        if let Some(readings) = sensors.sample(i, analog, noise) {
            for (column, v) in out.iter_mut().zip(readings) {
                column.push(v);
            }
            for (column, v) in out[4..].iter_mut().zip(controller.context) {
                column.push(round_context(v));
            }
        }

        for (axis, a) in axes.iter_mut().zip(&accelerations) {
            axis.integrate(a, dt);
        }
        if let Some(c) = &mut contact {
            c.slide(f_n, dt);
        }
    }
    Output {
        channels: out,
        onset,
    }
}

/// Context values are sent with a resolution of 1e-9 of their unit (they are the
/// controller's own numbers; this only drops floating-point dust such as 1e-20 m).
fn round_context(v: f64) -> f64 {
    (v * 1e9).round() / 1e9 + 0.0
}
