//! The physics and the sensor chain, integrated at the internal rate and sampled at the
//! detector rate.
//!
//! # Mechanics (each axis x and y in the fingertip frame)
//!
//! Three bodies in a chain, integrated with semi-implicit (symplectic) Euler:
//!
//! ```text
//!  joint controller ─> [link 1] ──bending mode── [link 2 + carrier] ──foam── [skin] ─> object
//!                        │                          │   (force sensor between     (normal force and
//!               obstacle, knock            obstacle, knock,  link 2 and carrier)   friction, on a
//!                                          tap on the tip                          tilted surface)
//! ```
//!
//! - `arm` (link 1): the proximal part of the finger, moved by two digital joint
//!   controllers (PD with an erring feedforward and partial friction compensation, at
//!   their own loop rate, on the motor-side position quantized to the encoder resolution,
//!   their force limited). The drive adds friction and a small force ripple whose frequency
//!   follows the commanded speed.
//! - The two joints are linearized at the run's posture (a run moves the tip by a few
//!   centimetres at most): the Jacobian's columns `J1`, `J2` (the tip's travel per radian
//!   of each joint) are constant. Each joint's reflected inertia is the arm's mass times
//!   `|Jj|^2`, and each joint's loop is tuned on its own inertia (the arm's and the
//!   fingertip's at the tip, along that joint's direction): at the tip, the arm's mass
//!   and the loops' stiffness and damping are that scalar times `A = J^-T diag(|Jj|^2)
//!   J^-1`, the identity when the two columns are square. Joint torques become tip forces
//!   through `J^-T`, so a force square to `J2` loads joint 1 alone: a link 1 collision
//!   (an obstacle blocking joint 1) is a stiff wall for the arm along the unit normal to
//!   `J2`, and the tip goes on along `J2` as joint 2's own loop drives it.
//! - `distal` (link 2 and the fingertip's carrier): joined to link 1 by the distal
//!   structure's compliance, its bending mode. A tap on the tip strikes the carrier, above
//!   the force sensor.
//! - `skin`: the skin (and any pad) on the foam core, the fingertip's suspension mode.
//!   Contact acts on the skin: a normal force along the surface's normal (Hunt-Crossley on a
//!   soft object, with viscoelastic relaxation; Hertz on a rigid one) and stick-slip
//!   friction along its tangent. Its damping is integrated implicitly, so that a stiff,
//!   well-damped contact stays stable at any force.
//!
//! # Sensors
//!
//! - Force (x, y): the load the fingertip above the sensor puts on it,
//!   `-(carrier_mass * distal_accel) - foam_force_on_skin + tap_on_tip`, seen through the
//!   sensor's mounting misalignment and cross-axis sensitivity.
//! - Skin acceleration: the skin's acceleration along the accelerometer's (misaligned)
//!   axis plus a cross-axis share, through a first-order AC coupling.
//! - Stress rate: the rate of change of the load on the film: the contact force pressing
//!   the pad (its component along the pad normal x) plus the inertia of the skin's share
//!   above the film (that mass times the skin's acceleration along x), and a small
//!   crosstalk from the rate of the foam force (film bending); zero when nothing changes.
//! - Every analog channel then passes the 4th-order anti-alias filter at the internal rate
//!   and is sampled at the detector rate by a 12-bit ADC with gain error, offset, drift,
//!   mains hum with its harmonics and white noise, clipped at its full scale.
//! - Context (from the controller at its own rate, each message arriving after a latency):
//!   position error (commanded minus the encoder-measured tip position), commanded
//!   velocity and acceleration.

use super::filters::{AntiAliasFilter, HighPass1};
use super::params::{Plant, Sensors, uniform};
use super::trajectory::Trajectory;
use super::{CHANNELS, MIN_INTERNAL_RATE_HZ};
use rand::{Rng, RngExt};
use rand_distr::StandardNormal;
use std::collections::VecDeque;
use std::f64::consts::{PI, TAU};

/// Standard gravity, for the movable object's friction.
const GRAVITY: f64 = 9.81;

/// Below this speed the drive's Coulomb friction is regularized (proportional to speed).
const FRICTION_SPEED: f64 = 0.001;

/// The fastest approach of any scenario (m/s), for bounding impact forces.
const FASTEST_APPROACH: f64 = 0.1;

/// The largest step of a mode's phase per integration step (rad) that the internal rate
/// allows: semi-implicit Euler then gets a mode's frequency right within 0.5 %.
const MAX_PHASE_STEP: f64 = 0.35;

/// A 2 x 2 matrix, by rows.
type Mat2 = [[f64; 2]; 2];

fn mul(m: &Mat2, v: [f64; 2]) -> [f64; 2] {
    [
        m[0][0] * v[0] + m[0][1] * v[1],
        m[1][0] * v[0] + m[1][1] * v[1],
    ]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The finger's two joints, linearized at the run's posture, in the fingertip's frame (x
/// the pad normal): the tip's travel per radian of each joint and the shape `A` their
/// independent loops give the arm's inertia and stiffness at the tip (see the module's
/// header).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Linkage {
    /// The Jacobian's columns `J1`, `J2` (m/rad).
    columns: [[f64; 2]; 2],
    /// `A` and its inverse `A^-1 = u1 u1^T + u2 u2^T` (the columns' unit vectors).
    shape: Mat2,
    shape_inv: Mat2,
}

impl Linkage {
    pub(crate) fn new(p: &Plant) -> Linkage {
        // Joint 2 moves the tip square to link 2, at the pad angle from the pad normal;
        // link 1 runs at the flexion from link 2, and joint 1 moves the tip by both links.
        let psi = p.pad_angle;
        let j2 = [p.link2_length * psi.cos(), p.link2_length * psi.sin()];
        let toward = psi - p.flexion;
        let j1 = [
            j2[0] + p.link1_length * toward.cos(),
            j2[1] + p.link1_length * toward.sin(),
        ];
        let unit = |c: [f64; 2]| {
            let n = dot(c, c).sqrt();
            [c[0] / n, c[1] / n]
        };
        let (u1, u2) = (unit(j1), unit(j2));
        let shape_inv = [
            [u1[0] * u1[0] + u2[0] * u2[0], u1[0] * u1[1] + u2[0] * u2[1]],
            [u1[1] * u1[0] + u2[1] * u2[0], u1[1] * u1[1] + u2[1] * u2[1]],
        ];
        let det = shape_inv[0][0] * shape_inv[1][1] - shape_inv[0][1] * shape_inv[1][0];
        let shape = [
            [shape_inv[1][1] / det, -shape_inv[0][1] / det],
            [-shape_inv[1][0] / det, shape_inv[0][0] / det],
        ];
        Linkage {
            columns: [j1, j2],
            shape,
            shape_inv,
        }
    }

    /// The joint rates (rad/s) that move the tip at `v` (m/s).
    fn joint_rates(&self, v: [f64; 2]) -> [f64; 2] {
        let [j1, j2] = self.columns;
        let det = j1[0] * j2[1] - j2[0] * j1[1];
        [
            (j2[1] * v[0] - j2[0] * v[1]) / det,
            (j1[0] * v[1] - j1[1] * v[0]) / det,
        ]
    }

    /// The tip velocity joint 1 contributes while the tip moves at `v` (m/s): what a link 1
    /// collision takes away from the tip's motion.
    pub(crate) fn joint1_share(&self, v: [f64; 2]) -> [f64; 2] {
        let q1 = self.joint_rates(v)[0];
        self.columns[0].map(|c| c * q1)
    }

    /// The unit normal, square to `J2`, along which a link 1 obstacle blocks the tip while
    /// it moves at `v`: pointing the way joint 1 moves it (x when joint 1 does not move).
    pub(crate) fn joint1_normal(&self, v: [f64; 2]) -> [f64; 2] {
        let j2 = self.columns[1];
        let n = dot(j2, j2).sqrt();
        let normal = [j2[1] / n, -j2[0] / n];
        let along = dot(normal, self.joint1_share(v));
        if along > 0.0 {
            normal
        } else if along < 0.0 {
            normal.map(|c| -c)
        } else {
            [1.0, 0.0]
        }
    }

    /// The tip force `f` (N) limited as the joints' torques are: each joint's torque
    /// `Jj . f` to what makes `limit` (N) along that joint's own direction, `limit |Jj|`.
    fn limit_torques(&self, f: [f64; 2], limit: f64) -> [f64; 2] {
        let [j1, j2] = self.columns;
        let t: [f64; 2] = std::array::from_fn(|j| {
            let c = self.columns[j];
            let most = limit * dot(c, c).sqrt();
            dot(c, f).clamp(-most, most)
        });
        // The tip force those torques make: J^T f = t.
        let det = j1[0] * j2[1] - j1[1] * j2[0];
        [
            (t[0] * j2[1] - t[1] * j1[1]) / det,
            (j1[0] * t[1] - j2[0] * t[0]) / det,
        ]
    }

    /// The smallest eigenvalue of `A` (0.5 to 1): the arm is lightest, for its mass, along
    /// that direction.
    fn lightest(&self) -> f64 {
        let [j1, j2] = self.columns;
        let cos = dot(j1, j2) / (dot(j1, j1) * dot(j2, j2)).sqrt();
        1.0 / (1.0 + cos.abs())
    }
}

/// How the normal force of a contact grows with depth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum ContactLaw {
    /// `stiffness x depth`: a soft object.
    Linear { stiffness: f64 },
    /// `K depth^1.5` (Hertz), with `K` such that the force is 1 N at a depth of
    /// `1 N / stiffness`: a rigid object.
    Hertz { stiffness: f64 },
}

impl ContactLaw {
    /// The tangent stiffness (N/m) at a normal force `force` (N).
    fn tangent_stiffness(self, force: f64) -> f64 {
        match self {
            ContactLaw::Linear { stiffness } => stiffness,
            ContactLaw::Hertz { stiffness } => 1.5 * stiffness * force.max(1.0).cbrt(),
        }
    }
}

/// An object the skin can touch.
#[derive(Clone, Debug)]
pub(crate) struct ObjectSetup {
    /// Distance along the surface's normal from the skin's position at time zero to the
    /// surface.
    pub surface: f64,
    /// Angle of the surface's normal from x, towards y (rad).
    pub tilt: f64,
    pub law: ContactLaw,
    /// Hunt-Crossley damping (s/m).
    pub damping: f64,
    /// `(share, time constant)` of a viscoelastic relaxation (linear contacts only).
    pub relaxation: Option<(f64, f64)>,
    /// `(mass, kinetic friction, static friction)` for an object that can slide.
    pub movable: Option<(f64, f64, f64)>,
}

/// The body of the finger an obstacle or a disturbance strikes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Struck {
    /// Link 1, the proximal link (the arm body, where the controller acts).
    Link1,
    /// Link 2, the distal link, below the force sensor.
    Link2,
    /// The fingertip's housing (the carrier), above the force sensor.
    Tip,
    /// The pad: the skin over the film, struck from in front. A blow there can only press
    /// it (a burst's pulling half pushes nothing), and the film reads it as it reads an
    /// object's push.
    Pad,
}

impl Struck {
    /// The body's name in traces' metadata and reports.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Struck::Link1 => "link1",
            Struck::Link2 => "link2",
            Struck::Tip => "tip",
            Struck::Pad => "pad",
        }
    }
}

/// The obstacle a link can strike.
#[derive(Clone, Debug)]
pub(crate) struct ObstacleSetup {
    /// The unit normal of the wall it makes for the struck body, in the fingertip's frame:
    /// x for link 2; for link 1, the direction of the tip's motion that joint 1 alone
    /// makes ([`Linkage::joint1_normal`]).
    pub normal: [f64; 2],
    /// Position of the obstacle along `normal`, from the struck body's position at time
    /// zero.
    pub position: f64,
    pub stiffness: f64,
    pub damping: f64,
    /// Link 1 or link 2.
    pub body: Struck,
}

/// The shape of a disturbance force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum DisturbanceKind {
    /// A tap: a half-sine pulse.
    Impulse { peak: f64, duration: f64 },
    /// A sine burst starting at phase zero.
    Vibration {
        amplitude: f64,
        frequency: f64,
        duration: f64,
    },
}

/// A disturbance force on one of the finger's bodies.
#[derive(Clone, Debug)]
pub(crate) struct DisturbanceSetup {
    pub start: f64,
    pub kind: DisturbanceKind,
    pub direction: f64,
    pub body: Struck,
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
    /// The rate of the controller's context messages (and of its trajectory's ticks).
    pub context_rate_hz: f64,
    /// The resolution of the tip position the controller reads from its encoders (m).
    pub encoder_resolution: f64,
    /// The corner of the stress-rate film's AC coupling (Hz); 0: none.
    pub film_highpass_hz: f64,
    /// The corner of the low-pass through which the joint loops take their velocity from
    /// the encoders' difference (Hz); 0: they read the true velocity.
    pub velocity_filter_hz: f64,
    /// How long after the first touch the obstacle (a link collision's) or the object (a
    /// contact's) gives way (s): from then on it pushes no more.
    pub gives_way_s: Option<f64>,
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
    /// The first integration step at which an event force was non-zero.
    pub onset: Option<(u64, Happened)>,
    /// The largest force the obstacle or the object pushed with (N; 0 without either).
    pub peak_force: f64,
}

/// The stiffest mode of a run's mechanics (rad/s) and the internal rate (Hz) it needs:
/// every mode advances at most [`MAX_PHASE_STEP`] per step, and the explicitly integrated
/// damping of a link on an obstacle stays well inside its stability bound.
pub(crate) fn required_rate(
    p: &Plant,
    object: Option<&ObjectSetup>,
    obstacle: Option<&ObstacleSetup>,
) -> (f64, f64) {
    let distal = p.distal_mass + p.carrier_mass;
    // The largest normal force a contact reaches: twice the drive's limit.
    let pressing = 2.0 * p.force_limit;
    let contact = object.map_or(0.0, |o| {
        o.law.tangent_stiffness(pressing) + p.tangential_stiffness
    });
    // The bending mode is tuned on the arm's mass; along the direction the arm is
    // lightest, it rings faster.
    let m_tip = distal + p.skin_mass;
    let reduced = |arm: f64| arm * m_tip / (arm + m_tip);
    let light = reduced(p.arm_mass * Linkage::new(p).lightest());
    let mut omega = [
        ((p.foam_stiffness + contact) / p.skin_mass).sqrt(),
        TAU * p.link_frequency * (reduced(p.arm_mass) / light).sqrt(),
    ]
    .into_iter()
    .fold(0.0, f64::max);
    let mut rate: f64 = MIN_INTERNAL_RATE_HZ;
    if let Some(o) = obstacle {
        // The arm weighs at least its mass along any wall's normal.
        let m = match o.body {
            Struck::Link1 => p.arm_mass,
            _ => distal,
        };
        omega = omega.max((o.stiffness / m).sqrt());
        // Hunt-Crossley damping is `damping x force` N s/m: keep its step below 0.5.
        let impact = FASTEST_APPROACH * (o.stiffness * (p.arm_mass + distal)).sqrt();
        rate = rate.max(2.0 * o.damping * impact.max(pressing) / m);
    }
    (omega, rate.max(omega / MAX_PHASE_STEP))
}

/// The ADC of one analog channel.
struct Adc {
    lsb: f64,
    /// 1 / lsb.
    per_lsb: f64,
    gain: f64,
    offset: f64,
    drift: f64,
    /// Amplitude of the hum's fundamental, second and third harmonic.
    hum: [f64; 3],
    /// cos and sin of each hum component's phase on this channel.
    hum_phase: [(f64, f64); 3],
    sigma: f64,
}

impl Adc {
    fn new<R: Rng>(
        channel: usize,
        (gain, offset, drift): (f64, f64, f64),
        s: &Sensors,
        noise: &mut R,
    ) -> Adc {
        let (full_scale, noise_rms) = CHANNELS[channel]
            .adc
            .map_or((1.0, 0.0), |a| (a.full_scale, a.noise_rms));
        let lsb = 2.0 * full_scale / 4096.0;
        let hum = s.hum_lsb * lsb;
        Adc {
            lsb,
            per_lsb: 1.0 / lsb,
            gain,
            offset,
            drift,
            hum: [hum, hum * s.hum_harmonic2, hum * s.hum_harmonic3],
            hum_phase: std::array::from_fn(|_| {
                let phase = noise.random::<f64>() * TAU;
                (phase.cos(), phase.sin())
            }),
            sigma: noise_rms * s.noise_scale,
        }
    }

    /// Converts `v` at time `t`; `mains` holds (cos, sin) of the mains phase and of its
    /// double and triple, `z` is a standard normal deviate.
    #[inline]
    fn convert(&self, v: f64, t: f64, mains: &[(f64, f64); 3], z: f64) -> f64 {
        let mut hum = 0.0;
        for ((a, (pc, ps)), (mc, ms)) in self.hum.iter().zip(&self.hum_phase).zip(mains) {
            // sin(k mains + phase)
            hum += a * (ms * pc + mc * ps);
        }
        let y = self.gain * v + self.offset + self.drift * t + hum + self.sigma * z;
        // Adding zero turns a negative zero into a positive one.
        round(y * self.per_lsb).clamp(-2048.0, 2047.0) * self.lsb + 0.0
    }
}

/// `x` rounded to the nearest integer (ties to even), for |x| < 2^51: one addition and one
/// subtraction instead of a call into the C library.
#[inline]
fn round(x: f64) -> f64 {
    const SHIFT: f64 = 6_755_399_441_055_744.0; // 1.5 x 2^52
    (x + SHIFT) - SHIFT
}

/// A unit phasor `(cos, sin)` turned by a fixed step at each [`Phasor::rotate`].
#[derive(Clone, Copy, Debug)]
struct Phasor {
    cos: f64,
    sin: f64,
    /// Sine and cosine of the step.
    step: (f64, f64),
}

impl Phasor {
    /// The step of a phasor that stands still.
    const STILL: (f64, f64) = (0.0, 1.0);

    /// At phase `angle`, turning by `step` radians.
    fn new(angle: f64, step: f64) -> Phasor {
        let (sin, cos) = angle.sin_cos();
        Phasor {
            cos,
            sin,
            step: step.sin_cos(),
        }
    }

    fn rotate(&mut self) {
        let (ds, dc) = self.step;
        (self.cos, self.sin) = (self.cos * dc - self.sin * ds, self.sin * dc + self.cos * ds);
    }

    /// Brings the magnitude back to one (rounding makes it wander; the magnitude stays far
    /// from overflow, so no `hypot`).
    fn normalize(&mut self) {
        let norm = (self.cos * self.cos + self.sin * self.sin).sqrt();
        self.cos /= norm;
        self.sin /= norm;
    }
}

/// The drive's bumps ([`Plant::drive_bump`]): smooth pushes on the arm, each of which the
/// loops' stiffness holds at an offset of the tip along one joint's own direction.
struct DriveBumps {
    /// Each bump's start and length (s) and its peak force (N, x and y), by start.
    bumps: Vec<(f64, f64, [f64; 2])>,
    /// The first bump not yet over.
    next: usize,
}

impl DriveBumps {
    /// The bumps of a run of `duration` s, at random times (a Poisson process at
    /// `drive_bump_rate`), drawn from `rng`; none, and nothing drawn, where the drive does
    /// not bump.
    fn new<R: Rng>(p: &Plant, chain: &Chain, kp: f64, duration: f64, rng: &mut R) -> DriveBumps {
        let mut bumps = Vec::new();
        if p.drive_bump > 0.0 && p.drive_bump_rate > 0.0 {
            let mut t = 0.0;
            loop {
                t -= (1.0 - rng.random::<f64>()).ln() / p.drive_bump_rate;
                if t >= duration {
                    break;
                }
                let size = p.drive_bump * uniform(rng, 1.0 / 3.0, 1.0);
                let length = uniform(rng, 0.05, 0.10);
                let column = chain.linkage.columns[usize::from(rng.random::<bool>())];
                let size = if rng.random::<bool>() { size } else { -size };
                let norm = dot(column, column).sqrt();
                // The loops hold the tip at `x` against a force `kp A x` (the module's
                // header).
                let offset = column.map(|c| c / norm * size);
                let force = mul(&chain.linkage.shape, offset).map(|f| f * kp);
                bumps.push((t, length, force));
            }
        }
        DriveBumps { bumps, next: 0 }
    }

    /// The bumps' force at `t` (s), x and y, `t` never decreasing: a raised cosine over
    /// each bump's length, those that overlap added.
    fn force(&mut self, t: f64) -> [f64; 2] {
        while self
            .bumps
            .get(self.next)
            .is_some_and(|&(start, length, _)| t >= start + length)
        {
            self.next += 1;
        }
        let mut f = [0.0; 2];
        for &(start, length, peak) in self.bumps[self.next..].iter().take_while(|b| t >= b.0) {
            if t < start + length {
                let w = (1.0 - (TAU * (t - start) / length).cos()) / 2.0;
                f = std::array::from_fn(|k| f[k] + peak[k] * w);
            }
        }
        f
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
    /// Follows the commanded velocity `v` (at a joint-loop tick).
    fn follow(&mut self, v: [f64; 2]) {
        let speed = (v[0] * v[0] + v[1] * v[1]).sqrt();
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

    /// The bodies' steady response to the ripple as [`DriveRipple::force`] will go on from
    /// here: displacements and velocities of arm, distal body and skin (x, y), about
    /// their steady motion. The chain is linearized: the joint loops as a continuous PD
    /// (their sampling and the encoders' quantization left out), the drive's friction by
    /// its viscous part.
    fn steady_response(
        &self,
        chain: &Chain,
        controller: &Controller,
    ) -> ([[f64; 2]; 3], [[f64; 2]; 3]) {
        let zero = ([[0.0; 2]; 3], [[0.0; 2]; 3]);
        let (ds, dc) = self.phasor.step;
        let w = ds.atan2(dc) / self.dt;
        if self.amplitude == 0.0 || w == 0.0 {
            return zero;
        }
        // Complex amplitudes X of x(t) = Im(X e^{iwt}), the force A e^{iwt} along the
        // ripple's direction; rows and columns are arm x, y, distal x, y, skin x, y, as
        // real and imaginary parts: (Kr + i Ki) X = F.
        let mut kr = [[0.0; 6]; 6];
        let mut ki = [[0.0; 6]; 6];
        let (kl, cl) = chain.link;
        for r in 0..2 {
            for c in 0..2 {
                let shape = controller.shape[r][c];
                kr[r][c] += shape * (controller.kp - chain.arm_mass * w * w);
                ki[r][c] += shape * controller.kd * w;
            }
            ki[r][r] += chain.viscous * w;
            let (a, d, s) = (r, 2 + r, 4 + r);
            let (kf, cf) = (chain.foam_k[r], chain.foam_c[r]);
            // Link 1 to link 2, link 2 to skin: a spring and damper each.
            for (i, j, k, c) in [(a, d, kl, cl), (d, s, kf, cf)] {
                kr[i][i] += k;
                kr[j][j] += k;
                kr[i][j] -= k;
                kr[j][i] -= k;
                ki[i][i] += c * w;
                ki[j][j] += c * w;
                ki[i][j] -= c * w;
                ki[j][i] -= c * w;
            }
            kr[d][d] -= chain.distal_mass * w * w;
            kr[s][s] -= chain.skin_mass * w * w;
        }
        let mut m = [[0.0; 13]; 12];
        for r in 0..6 {
            for c in 0..6 {
                m[r][c] = kr[r][c];
                m[r][6 + c] = -ki[r][c];
                m[6 + r][c] = ki[r][c];
                m[6 + r][6 + c] = kr[r][c];
            }
        }
        for (row, d) in m.iter_mut().zip(self.direction) {
            row[12] = self.amplitude * d;
        }
        let Some(x) = solve(m) else {
            return zero;
        };
        // The next step's force is A sin(w dt), so time zero is at phase w dt.
        let (sn, cs) = (w * self.dt).sin_cos();
        let mut out = zero;
        for body in 0..3 {
            for k in 0..2 {
                let (re, im) = (x[2 * body + k], x[6 + 2 * body + k]);
                // X e^{i phase}: its imaginary part is the displacement, w times its real
                // part the velocity.
                out.0[body][k] = re * sn + im * cs;
                out.1[body][k] = w * (re * cs - im * sn);
            }
        }
        out
    }
}

/// Solves the linear system whose augmented rows are `m` (12 unknowns, the right-hand side
/// last) by Gaussian elimination with partial pivoting; `None` when it is singular.
fn solve(mut m: [[f64; 13]; 12]) -> Option<[f64; 12]> {
    for col in 0..12 {
        let pivot = (col..12).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col] == 0.0 || !m[pivot][col].is_finite() {
            return None;
        }
        m.swap(col, pivot);
        let (done, rest) = m.split_at_mut(col + 1);
        let top = &done[col];
        for row in rest {
            let f = row[col] / top[col];
            for (v, t) in row[col..].iter_mut().zip(&top[col..]) {
                *v -= f * t;
            }
        }
    }
    let mut x = [0.0; 12];
    for row in (0..12).rev() {
        let tail: f64 = (row + 1..12).map(|c| m[row][c] * x[c]).sum();
        x[row] = (m[row][12] - tail) / m[row][row];
    }
    Some(x)
}

/// The tip position the controller measures: the arm's, quantized by encoders of
/// `resolution`.
fn encoder(x: f64, resolution: f64) -> f64 {
    round(x / resolution) * resolution
}

/// The integration step at or after time `t` of a clock at `internal_rate` (Hz).
fn step_at(t: f64, internal_rate: f64) -> u64 {
    (t * internal_rate - 1e-6).ceil().max(0.0) as u64
}

/// The positions and velocities of the three bodies, x and y.
#[derive(Clone, Copy, Debug)]
struct Bodies {
    xa: [f64; 2],
    va: [f64; 2],
    xd: [f64; 2],
    vd: [f64; 2],
    xs: [f64; 2],
    vs: [f64; 2],
}

/// The chain's coefficients, derived once from the plant's parameters.
struct Chain {
    arm_mass: f64,
    /// The arm's inverse mass at the tip, `A^-1 / arm_mass` (1/kg).
    arm_inv_mass: Mat2,
    linkage: Linkage,
    /// Link 2 and the carrier, rigid through the stiff force sensor.
    distal_mass: f64,
    skin_mass: f64,
    /// The whole finger, link 1 to skin.
    total_mass: f64,
    /// Stiffness and damping of the distal structure's bending (link 1 to link 2).
    link: (f64, f64),
    /// Stiffness and damping of the foam, normal (x) and shear (y).
    foam_k: [f64; 2],
    foam_c: [f64; 2],
    coulomb: f64,
    viscous: f64,
}

impl Chain {
    fn new(p: &Plant) -> Chain {
        let ma = p.arm_mass;
        let md = p.distal_mass + p.carrier_mass;
        let ms = p.skin_mass;
        let m_tip = md + ms;
        let m_tot = ma + m_tip;
        let foam_k = [p.foam_stiffness, p.foam_stiffness * p.foam_shear_ratio];
        // The bending mode: link 1 against link 2, fingertip and skin.
        let mu = ma * m_tip / m_tot;
        let wl = TAU * p.link_frequency;
        let linkage = Linkage::new(p);
        Chain {
            arm_mass: ma,
            arm_inv_mass: linkage.shape_inv.map(|row| row.map(|a| a / ma)),
            linkage,
            distal_mass: md,
            skin_mass: ms,
            total_mass: m_tot,
            link: (mu * wl * wl, 2.0 * p.link_damping_ratio * mu * wl),
            foam_k,
            foam_c: foam_k.map(|k| 2.0 * p.foam_damping_ratio * (k * ms).sqrt()),
            coulomb: p.arm_coulomb_friction,
            viscous: p.arm_viscous_friction,
        }
    }

    /// The drive's friction force at velocity `v`: Coulomb (regularized below
    /// [`FRICTION_SPEED`]) plus viscous.
    fn friction(&self, v: f64) -> f64 {
        self.coulomb * (v / FRICTION_SPEED).clamp(-1.0, 1.0) + self.viscous * v
    }
}

/// The digital joint controllers, seen at the tip: each joint's PD law on its motor-side
/// position, tuned on that joint's inertia, with feedforward of the commanded acceleration
/// (through an erring model of the joints' inertia) and of part of the friction, run at
/// their loop rate, their force limited and held between ticks.
struct Controller {
    /// The inertia the feedforward assumes, at the tip (kg).
    model_mass: Mat2,
    /// The loops' stiffness and damping at the tip: these scalars times `A`.
    kp: f64,
    kd: f64,
    shape: Mat2,
    linkage: Linkage,
    /// The compensated Coulomb and viscous friction.
    compensation: (f64, f64),
    limit: f64,
    rate: f64,
    internal_rate: f64,
    /// The force on link 1, x and y.
    force: [f64; 2],
    tick: u64,
    /// The integration step of the next tick.
    next_step: u64,
    /// The encoders' resolution at the tip (m).
    encoder: f64,
    /// The velocity the loops damp with, when they take it from the encoders.
    estimate: Option<VelocityEstimate>,
}

/// A joint loop's velocity as a digital controller takes it from its encoders: their
/// difference over one tick, through a first-order low-pass. Every step of one encoder
/// count is a velocity step of a count per tick (1 mm/s for 1 µm at 1 kHz), which the
/// low-pass smooths and the loop's damping turns into force.
#[derive(Clone, Copy, Debug)]
struct VelocityEstimate {
    /// The low-pass's gain per tick.
    gain: f64,
    /// The encoders' last reading, and the estimate; `None` before the first tick.
    state: Option<([f64; 2], [f64; 2])>,
}

impl VelocityEstimate {
    /// The estimate after a tick that read `position` (m); the first tick starts from the
    /// arm's true velocity `v` (m/s). `rate`: the loops' rate (Hz).
    fn update(&mut self, position: [f64; 2], v: [f64; 2], rate: f64) -> [f64; 2] {
        let estimate = match self.state {
            None => v,
            Some((last, estimate)) => std::array::from_fn(|k| {
                let difference = (position[k] - last[k]) * rate;
                estimate[k] + self.gain * (difference - estimate[k])
            }),
        };
        self.state = Some((position, estimate));
        estimate
    }
}

impl Controller {
    fn new(
        p: &Plant,
        chain: &Chain,
        internal_rate: f64,
        encoder: f64,
        velocity_filter_hz: f64,
    ) -> Controller {
        let m = chain.total_mass;
        let wc = TAU * p.control_bandwidth;
        let share = p.friction_compensation;
        let (shape, m_tip) = (chain.linkage.shape, m - chain.arm_mass);
        let err = 1.0 + p.feedforward_error;
        let model_mass = std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                let own = if r == c { m_tip } else { 0.0 };
                err * (chain.arm_mass * shape[r][c] + own)
            })
        });
        Controller {
            model_mass,
            kp: m * wc * wc,
            kd: 2.0 * p.control_damping_ratio * m * wc,
            shape,
            linkage: chain.linkage,
            compensation: (share * chain.coulomb, share * chain.viscous),
            limit: p.force_limit,
            rate: p.control_rate,
            internal_rate,
            force: [0.0; 2],
            tick: 0,
            next_step: 0,
            encoder,
            estimate: (velocity_filter_hz > 0.0).then(|| VelocityEstimate {
                gain: 1.0 - (-TAU * velocity_filter_hz / p.control_rate).exp(),
                state: None,
            }),
        }
    }

    /// The friction the controller compensates at commanded velocity `v`.
    fn compensated(&self, v: f64) -> f64 {
        self.compensation.0 * (v / FRICTION_SPEED).clamp(-1.0, 1.0) + self.compensation.1 * v
    }

    /// Runs the tick due at integration step `i`, if any: reads the command and the
    /// encoders, updates the force, and retunes the drive `ripple`.
    fn update(
        &mut self,
        i: u64,
        trajectory: &mut Trajectory,
        b: &Bodies,
        ripple: &mut DriveRipple,
    ) {
        if i != self.next_step {
            return;
        }
        let cmd = trajectory.at_time(self.tick as f64 / self.rate);
        let read: [f64; 2] = std::array::from_fn(|k| encoder(b.xa[k], self.encoder));
        let v = match self.estimate.as_mut() {
            Some(e) => e.update(read, b.va, self.rate),
            None => b.va,
        };
        let pd: [f64; 2] =
            std::array::from_fn(|k| self.kp * (cmd.p[k] - read[k]) + self.kd * (cmd.v[k] - v[k]));
        let pd = mul(&self.shape, pd);
        let ff = mul(&self.model_mass, cmd.a);
        let f = std::array::from_fn(|k| ff[k] + self.compensated(cmd.v[k]) + pd[k]);
        self.force = self.linkage.limit_torques(f, self.limit);
        ripple.follow(cmd.v);
        self.tick += 1;
        self.next_step = step_at(self.tick as f64 / self.rate, self.internal_rate);
    }
}

/// The controller's context messages: computed at its context rate (the trajectory's
/// ticks) and received by the fingertip a latency later, held until the next arrives.
struct ContextLink {
    rate: f64,
    latency: f64,
    internal_rate: f64,
    tick: u64,
    next_step: u64,
    /// Messages sent and not yet received: the step they arrive at, and their values.
    in_flight: VecDeque<(u64, [f64; 6])>,
    /// What the fingertip last received: position error, commanded velocity and
    /// acceleration (x, y), as sent (rounded to 1e-9 of their unit).
    received: [f64; 6],
    /// The encoders' resolution at the tip (m), as the controller reads them.
    encoder: f64,
}

impl ContextLink {
    /// The message of context tick `tick`, the finger being at `b`.
    fn message(&self, tick: u64, trajectory: &mut Trajectory, b: &Bodies) -> [f64; 6] {
        let cmd = trajectory.at(tick);
        [
            cmd.p[0] - encoder(b.xa[0], self.encoder),
            cmd.p[1] - encoder(b.xa[1], self.encoder),
            cmd.v[0],
            cmd.v[1],
            cmd.a[0],
            cmd.a[1],
        ]
    }

    /// Sends the message due at step `i`, if any, and receives those that arrive.
    fn update(&mut self, i: u64, trajectory: &mut Trajectory, b: &Bodies) {
        if i == self.next_step {
            let t = self.tick as f64 / self.rate;
            let values = self.message(self.tick, trajectory, b);
            self.in_flight
                .push_back((step_at(t + self.latency, self.internal_rate), values));
            self.tick += 1;
            self.next_step = step_at(self.tick as f64 / self.rate, self.internal_rate);
        }
        while let Some(&(arrives, values)) = self.in_flight.front() {
            if arrives > i {
                break;
            }
            self.received = values.map(round_context);
            self.in_flight.pop_front();
        }
    }
}

/// A disturbance's force: a half sine or a sine burst, from a phasor turned each step.
struct Disturbance {
    start: f64,
    end: f64,
    amplitude: f64,
    /// Angular frequency (rad/s).
    omega: f64,
    dt: f64,
    phasor: Option<Phasor>,
    /// Cosine and sine of its direction.
    direction: (f64, f64),
    body: Struck,
}

impl Disturbance {
    fn new(setup: &DisturbanceSetup, dt: f64) -> Disturbance {
        let (amplitude, omega, duration) = match setup.kind {
            DisturbanceKind::Impulse { peak, duration } => (peak, PI / duration, duration),
            DisturbanceKind::Vibration {
                amplitude,
                frequency,
                duration,
            } => (amplitude, TAU * frequency, duration),
        };
        Disturbance {
            start: setup.start,
            end: setup.start + duration,
            amplitude,
            omega,
            dt,
            phasor: None,
            direction: (setup.direction.cos(), setup.direction.sin()),
            body: setup.body,
        }
    }

    /// The force at time `t` (called once per step, in order).
    fn force(&mut self, t: f64) -> [f64; 2] {
        if t < self.start || t >= self.end {
            return [0.0; 2];
        }
        let phasor = self.phasor.get_or_insert_with(|| {
            Phasor::new(self.omega * (t - self.start), self.omega * self.dt)
        });
        let f = self.amplitude * phasor.sin;
        phasor.rotate();
        [f * self.direction.0, f * self.direction.1]
    }
}

/// A Hunt-Crossley force at penetration `depth` and penetration rate `velocity`: zero out
/// of contact, and never pulling.
fn hunt_crossley(stiffness: f64, damping: f64, depth: f64, velocity: f64) -> f64 {
    if depth > 0.0 {
        (stiffness * depth * (1.0 + damping * velocity)).max(0.0)
    } else {
        0.0
    }
}

/// The obstacle a link strikes.
struct Obstacle<'a> {
    setup: &'a ObstacleSetup,
    /// Its position in the struck body's coordinates.
    position: f64,
    gives_way: Option<GivesWay>,
}

/// An obstacle or an object that gives way: how long after the first touch (s), and when
/// that touch was, once it has happened.
struct GivesWay {
    after: f64,
    touch: Option<f64>,
}

impl GivesWay {
    fn new(after: Option<f64>) -> Option<GivesWay> {
        after.map(|after| GivesWay { after, touch: None })
    }

    /// It has given way by time `t`.
    fn gone(this: &Option<GivesWay>, t: f64) -> bool {
        this.as_ref()
            .is_some_and(|g| g.touch.is_some_and(|touch| t >= touch + g.after))
    }

    /// Notes the first touch: the first step that pushes.
    fn pushed(this: &mut Option<GivesWay>, t: f64, force: f64) {
        if let Some(g) = this
            && g.touch.is_none()
            && force > 0.0
        {
            g.touch = Some(t);
        }
    }
}

impl Obstacle<'_> {
    /// The force pushing the struck body back along the wall's normal at time `t`, from
    /// its position and velocity (called once per step, in order).
    fn force(&mut self, b: &Bodies, t: f64) -> f64 {
        if GivesWay::gone(&self.gives_way, t) {
            return 0.0;
        }
        let n = self.setup.normal;
        let (x, v) = match self.setup.body {
            Struck::Link1 => (dot(n, b.xa), dot(n, b.va)),
            _ => (dot(n, b.xd), dot(n, b.vd)),
        };
        let f = hunt_crossley(
            self.setup.stiffness,
            self.setup.damping,
            x - self.position,
            v,
        );
        GivesWay::pushed(&mut self.gives_way, t, f);
        f
    }
}

/// The skin's contact with an object: a normal force along the surface's normal `n`
/// (elastic, relaxing, and damped implicitly), a stick-slip friction along its tangent
/// `t` (a spring anchored on the object that slides when it would exceed the friction
/// limit), and a movable object's own motion on its table along `n`.
struct Contact<'a> {
    setup: &'a ObjectSetup,
    n: [f64; 2],
    t: [f64; 2],
    /// The surface's position along `n` at time zero.
    surface: f64,
    /// The movable object's displacement and velocity along `n`.
    position: f64,
    velocity: f64,
    /// Static friction holds the movable object.
    stuck: bool,
    /// The skin's tangential position at which the friction spring is relaxed.
    anchor: f64,
    in_contact: bool,
    /// The relaxing (Maxwell) part of the elastic force, the relaxing stiffness, its decay
    /// per step, and the depth at the previous step.
    relaxing: f64,
    relaxing_stiffness: f64,
    decay: f64,
    last_depth: f64,
    /// The contact's elastic stiffness, less the relaxing part, or Hertz's K.
    stiffness: f64,
    gives_way: Option<GivesWay>,
}

/// What the contact does to the skin in one step.
struct ContactForces {
    /// Normal force magnitude (N, pushing the skin back along -n).
    normal: f64,
    /// Friction along t (N).
    friction: f64,
}

impl Contact<'_> {
    fn new(setup: &ObjectSetup, skin: [f64; 2], dt: f64, gives_way: Option<f64>) -> Contact<'_> {
        let (s, c) = setup.tilt.sin_cos();
        let n = [c, s];
        let (stiffness, relaxing_stiffness, decay) = match (setup.law, setup.relaxation) {
            (ContactLaw::Linear { stiffness }, Some((share, tau))) => (
                stiffness * (1.0 - share),
                stiffness * share,
                (-dt / tau).exp(),
            ),
            (ContactLaw::Linear { stiffness }, None) => (stiffness, 0.0, 0.0),
            // K = k^1.5 / sqrt(1 N): the force is 1 N at a depth of 1 N / k.
            (ContactLaw::Hertz { stiffness }, _) => (stiffness.powf(1.5), 0.0, 0.0),
        };
        Contact {
            setup,
            n,
            t: [-s, c],
            surface: setup.surface + n[0] * skin[0] + n[1] * skin[1],
            position: 0.0,
            velocity: 0.0,
            stuck: true,
            anchor: 0.0,
            in_contact: false,
            relaxing: 0.0,
            relaxing_stiffness,
            decay,
            last_depth: 0.0,
            stiffness,
            gives_way: GivesWay::new(gives_way),
        }
    }

    /// The contact's forces on the skin at time `t`. `free` is the skin's velocity at the
    /// end of the step without the normal force (the other forces applied), `gain` the
    /// integration step over the skin's mass: the damping acts on the velocity the step
    /// ends with, so that it stays stable however stiff the contact.
    fn forces(
        &mut self,
        b: &Bodies,
        free: [f64; 2],
        gain: f64,
        p: &Plant,
        t: f64,
    ) -> ContactForces {
        if GivesWay::gone(&self.gives_way, t) {
            self.in_contact = false;
            return ContactForces {
                normal: 0.0,
                friction: 0.0,
            };
        }
        let n = self.n;
        let depth = n[0] * b.xs[0] + n[1] * b.xs[1] - (self.surface + self.position);
        let reached = depth.max(0.0);
        self.relaxing =
            self.relaxing * self.decay + self.relaxing_stiffness * (reached - self.last_depth);
        self.last_depth = reached;
        if depth <= 0.0 {
            self.in_contact = false;
            return ContactForces {
                normal: 0.0,
                friction: 0.0,
            };
        }
        let elastic = match self.setup.law {
            ContactLaw::Linear { .. } => (self.stiffness * depth + self.relaxing).max(0.0),
            ContactLaw::Hertz { .. } => self.stiffness * depth * depth.sqrt(),
        };
        // Hunt-Crossley: elastic x (1 + damping x depth rate), the rate taken at the end of
        // the step (implicit), never pulling.
        let b_n = self.setup.damping * elastic;
        let g = gain * b_n;
        let rate_free = n[0] * free[0] + n[1] * free[1] - self.velocity;
        let rate = (rate_free - gain * elastic) / (1.0 + g);
        let normal = (elastic + b_n * rate).max(0.0);
        GivesWay::pushed(&mut self.gives_way, t, normal);
        let tangential = self.t[0] * b.xs[0] + self.t[1] * b.xs[1];
        if !self.in_contact {
            self.anchor = tangential;
            self.in_contact = true;
        }
        let limit = p.skin_friction * normal / p.tangential_stiffness;
        let mut e = tangential - self.anchor;
        if e.abs() > limit {
            e = limit.copysign(e);
            self.anchor = tangential - e;
        }
        ContactForces {
            normal,
            friction: -p.tangential_stiffness * e,
        }
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

/// What the fingertip's sensors transduce in one step.
struct Physical {
    /// The load above the force sensor, x and y (N).
    load: [f64; 2],
    /// The skin's acceleration, x and y (m/s^2).
    skin: [f64; 2],
    /// The contact force pressing the pad, along x (N).
    pressing: f64,
    /// The foam's force on the skin along x (N).
    foam: f64,
}

/// The fingertip's sensors and their anti-alias filters at the internal rate, and the ADCs
/// sampling them at the detector rate.
struct SensorChain {
    /// cos and sin of the force sensor's misalignment, and its cross-axis sensitivities.
    force_axes: (f64, f64),
    force_cross: [f64; 2],
    /// cos and sin of the accelerometer's misalignment, and its cross-axis sensitivity.
    accel_axis: (f64, f64),
    accel_cross: f64,
    stress_crosstalk: f64,
    /// The skin's mass above the stress-rate film (kg).
    film_mass: f64,
    internal_rate: f64,
    rate_hz: f64,
    oversampling: usize,
    /// The accelerometer's AC coupling.
    highpass: HighPass1,
    /// The stress-rate film's AC coupling, where its amplifier has one.
    film_highpass: Option<HighPass1>,
    anti_alias: AntiAliasFilter<4>,
    adc: [Adc; 4],
    /// The mains phase, advanced once per output sample.
    mains: Phasor,
    /// The film's load (the pressing force and its mass's inertia) and the foam's x force
    /// at the previous step.
    previous: (f64, f64),
    /// Integration steps until the next sample.
    until_sample: usize,
}

impl SensorChain {
    /// Draws the hum's phases on each channel from `noise`. A `film_highpass_hz` above 0
    /// AC-couples the stress-rate film at that corner.
    fn new<R: Rng>(
        s: &Sensors,
        film_mass: f64,
        film_highpass_hz: f64,
        rate_hz: f64,
        oversampling: usize,
        noise: &mut R,
    ) -> SensorChain {
        let internal_rate = rate_hz * oversampling as f64;
        let adc = [
            Adc::new(
                0,
                (s.force_x_gain, s.force_x_offset, s.force_x_drift),
                s,
                noise,
            ),
            Adc::new(
                1,
                (s.force_y_gain, s.force_y_offset, s.force_y_drift),
                s,
                noise,
            ),
            Adc::new(2, (s.accel_gain, s.accel_offset, s.accel_drift), s, noise),
            Adc::new(
                3,
                (s.stress_gain, s.stress_offset, s.stress_drift),
                s,
                noise,
            ),
        ];
        let (fs, fc) = s.force_misalignment.sin_cos();
        let (as_, ac) = s.accel_misalignment.sin_cos();
        SensorChain {
            force_axes: (fc, fs),
            force_cross: [s.force_x_cross_axis, s.force_y_cross_axis],
            accel_axis: (ac, as_),
            accel_cross: s.accel_cross_axis,
            stress_crosstalk: s.stress_crosstalk,
            film_mass,
            internal_rate,
            rate_hz,
            oversampling,
            highpass: HighPass1::new(s.accel_highpass, internal_rate),
            film_highpass: (film_highpass_hz > 0.0)
                .then(|| HighPass1::new(film_highpass_hz, internal_rate)),
            anti_alias: AntiAliasFilter::new(internal_rate, rate_hz),
            adc,
            mains: Phasor::new(0.0, TAU * s.hum_frequency / rate_hz),
            previous: (0.0, 0.0),
            until_sample: 0,
        }
    }

    /// The analog signals of one step: force x and y, skin acceleration, stress rate.
    fn transduce(&mut self, ph: &Physical) -> [f64; 4] {
        let (c, s) = self.force_axes;
        let [lx, ly] = ph.load;
        let (fx, fy) = (c * lx + s * ly, c * ly - s * lx);
        let (ac, as_) = self.accel_axis;
        let [sx, sy] = ph.skin;
        let along = ac * sx + as_ * sy;
        let across = ac * sy - as_ * sx;
        let accel = self.highpass.process(along + self.accel_cross * across);
        let (prev_load, prev_f) = self.previous;
        let load = ph.pressing + self.film_mass * sx;
        let rate =
            ((load - prev_load) + self.stress_crosstalk * (ph.foam - prev_f)) * self.internal_rate;
        let stress = match &mut self.film_highpass {
            Some(hp) => hp.process(rate),
            None => rate,
        };
        self.previous = (load, ph.foam);
        [
            fx + self.force_cross[0] * fy,
            fy + self.force_cross[1] * fx,
            accel,
            stress,
        ]
    }

    /// Filters the `analog` signals of integration step `i` and, on a sampling step,
    /// returns the ADCs' readings.
    fn sample<R: Rng>(&mut self, i: u64, analog: [f64; 4], noise: &mut R) -> Option<[f64; 4]> {
        let filtered = self.anti_alias.process(analog);
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
        let (c, s) = (self.mains.cos, self.mains.sin);
        let (c2, s2) = (c * c - s * s, 2.0 * s * c);
        let mains = [(c, s), (c2, s2), (c * c2 - s * s2, s * c2 + c * s2)];
        let mut readings = [0.0; 4];
        for ((r, adc), y) in readings.iter_mut().zip(&self.adc).zip(filtered) {
            let z: f64 = noise.sample(StandardNormal);
            *r = adc.convert(y, ts, &mains, z);
        }
        self.mains.rotate();
        if row.is_multiple_of(1024) {
            self.mains.normalize();
        }
        readings
    }
}

/// Runs the simulation. `noise` drives the sensor noise, the hum phases and the drive's
/// bumps.
pub(crate) fn run<R: Rng>(setup: &mut Setup, noise: &mut R) -> Output {
    let p = &setup.plant;
    let n_over = setup.oversampling.max(1);
    let internal_rate = setup.rate_hz * n_over as f64;
    let dt = 1.0 / internal_rate;

    let chain = Chain::new(p);
    let mut controller = Controller::new(
        p,
        &chain,
        internal_rate,
        setup.encoder_resolution,
        setup.velocity_filter_hz,
    );
    let mut context = ContextLink {
        rate: setup.context_rate_hz,
        latency: p.context_latency,
        internal_rate,
        tick: 0,
        next_step: 0,
        in_flight: VecDeque::new(),
        received: [0.0; 6],
        encoder: setup.encoder_resolution,
    };
    let mut sensors = SensorChain::new(
        &setup.sensors,
        p.film_share * p.skin_mass,
        setup.film_highpass_hz,
        setup.rate_hz,
        n_over,
        noise,
    );

    // Initial state: steady motion at the commanded initial velocity, all springs relaxed,
    // the whole finger lagging the command by the position error that balances the
    // friction the controller leaves uncompensated.
    let c0 = setup.trajectory.at(0);
    let left: [f64; 2] =
        std::array::from_fn(|k| chain.friction(c0.v[k]) - controller.compensated(c0.v[k]));
    let lag = mul(&chain.linkage.shape_inv, left).map(|f| f / controller.kp);
    let start: [f64; 2] = std::array::from_fn(|k| -lag[k]);
    let mut ripple = DriveRipple {
        amplitude: p.drive_ripple,
        pitch: p.ripple_pitch,
        dt,
        phasor: Phasor::new(0.0, 0.0),
        direction: [0.0; 2],
    };
    let mut bumps = DriveBumps::new(
        p,
        &chain,
        controller.kp,
        setup.rows as f64 / setup.rate_hz,
        noise,
    );
    // The drive's ripple has rung the structure since long before: each body starts on its
    // steady response to it, not at rest, from which a lightly damped mode would build up
    // over tens of ms.
    ripple.follow(c0.v);
    let (x, v) = ripple.steady_response(&chain, &controller);
    let mut b = Bodies {
        xa: std::array::from_fn(|k| start[k] + x[0][k]),
        va: std::array::from_fn(|k| c0.v[k] + v[0][k]),
        xd: std::array::from_fn(|k| start[k] + x[1][k]),
        vd: std::array::from_fn(|k| c0.v[k] + v[1][k]),
        xs: std::array::from_fn(|k| start[k] + x[2][k]),
        vs: std::array::from_fn(|k| c0.v[k] + v[2][k]),
    };
    // The motion was steady before time zero: the fingertip holds the message of then.
    context.received = context
        .message(0, &mut setup.trajectory, &b)
        .map(round_context);
    let mut contact = setup
        .object
        .as_ref()
        .map(|o| Contact::new(o, b.xs, dt, setup.gives_way_s));
    let mut obstacle = setup.obstacle.as_ref().map(|o| Obstacle {
        setup: o,
        position: o.position + dot(o.normal, start),
        gives_way: GivesWay::new(setup.gives_way_s),
    });
    let mut disturbance = setup.disturbance.as_ref().map(|d| Disturbance::new(d, dt));
    let (inv_ma, inv_md, ms) = (chain.arm_inv_mass, 1.0 / chain.distal_mass, chain.skin_mass);
    let inv_ms = 1.0 / ms;
    let carrier = p.carrier_mass;

    let mut onset: Option<(u64, Happened)> = None;
    let mut peak_force = 0.0f64;
    let mut out: Vec<Vec<f64>> = (0..CHANNELS.len())
        .map(|_| Vec::with_capacity(setup.rows))
        .collect();
    let total_steps = (setup.rows.saturating_sub(1) * n_over) as u64;

    // An exclusive range: an inclusive one checks its end twice per step.
    for i in 0..total_steps + 1 {
        let t = i as f64 * dt;
        controller.update(i, &mut setup.trajectory, &b, &mut ripple);
        context.update(i, &mut setup.trajectory, &b);
        let ripple_force = ripple.force();
        let bump_force = bumps.force(t);
        // The outside forces on each body, x and y: the disturbance on the body it strikes,
        // the obstacle along x.
        let mut on_arm = [0.0; 2];
        let mut on_distal = [0.0; 2];
        let mut on_tip = [0.0; 2];
        let mut on_pad = [0.0; 2];
        let f_d = match disturbance.as_mut() {
            Some(d) => {
                let mut f = d.force(t);
                match d.body {
                    Struck::Link1 => on_arm = f,
                    Struck::Link2 => on_distal = f,
                    Struck::Tip => on_tip = f,
                    // The pad faces +x: a push along +x would pull it.
                    Struck::Pad => {
                        if f[0] > 0.0 {
                            f = [0.0; 2];
                        }
                        on_pad = f;
                    }
                }
                f
            }
            None => [0.0; 2],
        };
        let f_ob = match obstacle.as_mut() {
            Some(o) => {
                let f = o.force(&b, t);
                let on = match o.setup.body {
                    Struck::Link1 => &mut on_arm,
                    _ => &mut on_distal,
                };
                for (v, n) in on.iter_mut().zip(o.setup.normal) {
                    *v -= f * n;
                }
                f
            }
            None => 0.0,
        };

        // Both axes at once, the same arithmetic lane by lane.
        let (kl, cl) = chain.link;
        let link: [f64; 2] =
            std::array::from_fn(|k| kl * (b.xa[k] - b.xd[k]) + cl * (b.va[k] - b.vd[k]));
        let foam: [f64; 2] = std::array::from_fn(|k| {
            chain.foam_k[k] * (b.xd[k] - b.xs[k]) + chain.foam_c[k] * (b.vd[k] - b.vs[k])
        });
        let on_arm_total: [f64; 2] = std::array::from_fn(|k| {
            let drive =
                controller.force[k] + ripple_force[k] + bump_force[k] - chain.friction(b.va[k]);
            drive - link[k] + on_arm[k]
        });
        let a_arm = mul(&inv_ma, on_arm_total);
        let a_d: [f64; 2] =
            std::array::from_fn(|k| (link[k] - foam[k] + on_distal[k] + on_tip[k]) * inv_md);
        // The skin: foam and friction explicit, the contact's normal force implicit in its
        // damping.
        let (f_n, f_t, n, tn) = match contact.as_mut() {
            Some(c) => {
                let free: [f64; 2] = std::array::from_fn(|k| b.vs[k] + dt * foam[k] / ms);
                let f = c.forces(&b, free, dt / ms, p, t);
                (f.normal, f.friction, c.n, c.t)
            }
            None => (0.0, 0.0, [1.0, 0.0], [0.0, 1.0]),
        };
        let a_s: [f64; 2] =
            std::array::from_fn(|k| (foam[k] - f_n * n[k] + f_t * tn[k] + on_pad[k]) * inv_ms);
        peak_force = peak_force.max(f_ob).max(f_n);
        if onset.is_none() {
            onset = event(f_n, f_ob, f_d).map(|h| (i, h));
        }

        let physical = Physical {
            load: std::array::from_fn(|k| -carrier * a_d[k] - foam[k] + on_tip[k]),
            skin: a_s,
            pressing: f_n * n[0] - f_t * tn[0] - on_pad[0],
            foam: foam[0],
        };
        let analog = sensors.transduce(&physical);
        if let Some(readings) = sensors.sample(i, analog, noise) {
            for (column, v) in out.iter_mut().zip(readings) {
                column.push(v);
            }
            for (column, v) in out[4..].iter_mut().zip(context.received) {
                column.push(v);
            }
        }

        for k in 0..2 {
            b.va[k] += a_arm[k] * dt;
            b.vd[k] += a_d[k] * dt;
            b.vs[k] += a_s[k] * dt;
            b.xa[k] += b.va[k] * dt;
            b.xd[k] += b.vd[k] * dt;
            b.xs[k] += b.vs[k] * dt;
        }
        if let Some(c) = &mut contact {
            c.slide(f_n, dt);
        }
    }
    Output {
        channels: out,
        onset,
        peak_force,
    }
}

/// Context values are sent with a resolution of 1e-9 of their unit (they are the
/// controller's own numbers; this only drops floating-point dust such as 1e-20 m).
fn round_context(v: f64) -> f64 {
    round(v * 1e9) / 1e9 + 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The envelope's encoder resolution at the tip (m).
    const ENCODER_RESOLUTION: f64 = crate::sim::DEFAULT_ENCODER_RESOLUTION_UM / 1e6;

    fn object(law: ContactLaw, tilt: f64, relaxation: Option<(f64, f64)>) -> ObjectSetup {
        ObjectSetup {
            surface: 0.0,
            tilt,
            law,
            damping: 0.0,
            relaxation,
            movable: None,
        }
    }

    /// A skin at `x` moving at `v`, everything else at rest.
    fn skin_at(x: [f64; 2], v: [f64; 2]) -> Bodies {
        Bodies {
            xa: [0.0; 2],
            va: [0.0; 2],
            xd: [0.0; 2],
            vd: [0.0; 2],
            xs: x,
            vs: v,
        }
    }

    /// A rigid object's force grows as depth^1.5 and is 1 N at 1 N / stiffness; a soft
    /// one's is stiffness x depth.
    #[test]
    fn hertz_and_linear_contact_laws() {
        let p = Plant::nominal();
        let k = 50_000.0;
        let hertz = object(ContactLaw::Hertz { stiffness: k }, 0.0, None);
        let force = |setup: &ObjectSetup, depth: f64| {
            let mut c = Contact::new(setup, [0.0; 2], 1e-5, None);
            let b = skin_at([depth, 0.0], [0.0; 2]);
            c.forces(&b, [0.0; 2], 0.0, &p, 0.0).normal
        };
        assert!((force(&hertz, 1.0 / k) - 1.0).abs() < 1e-9);
        let ratio = force(&hertz, 4.0 / k) / force(&hertz, 1.0 / k);
        assert!((ratio - 8.0).abs() < 1e-9, "{ratio}");
        assert_eq!(force(&hertz, -1e-6), 0.0);
        let linear = object(ContactLaw::Linear { stiffness: 2000.0 }, 0.0, None);
        assert!((force(&linear, 1e-3) - 2.0).abs() < 1e-12);
        // The tangent stiffness the internal rate is chosen from: 1.5 x secant, growing as
        // the force's cube root.
        let h = ContactLaw::Hertz { stiffness: k };
        assert!((h.tangent_stiffness(8.0) / h.tangent_stiffness(1.0) - 2.0).abs() < 1e-12);
    }

    /// Held at a constant depth, a relaxing object's force falls from stiffness x depth to
    /// (1 - share) of it with the relaxation's time constant.
    #[test]
    fn viscoelastic_relaxation() {
        let p = Plant::nominal();
        let (share, tau, dt) = (0.4, 0.05, 1e-4);
        let setup = object(
            ContactLaw::Linear { stiffness: 1000.0 },
            0.0,
            Some((share, tau)),
        );
        let mut c = Contact::new(&setup, [0.0; 2], dt, None);
        let b = skin_at([1e-3, 0.0], [0.0; 2]);
        let mut at = |steps: usize| {
            let mut f = 0.0;
            for _ in 0..steps {
                f = c.forces(&b, [0.0; 2], 0.0, &p, 0.0).normal;
            }
            f
        };
        assert!((at(1) - 1.0).abs() < 1e-9, "the whole stiffness at first");
        let after_tau = at((tau / dt) as usize);
        let expected = 1.0 - share * (1.0 - (-1.0f64).exp());
        assert!(
            (after_tau - expected).abs() < 0.01,
            "{after_tau} vs {expected}"
        );
        let relaxed = at((10.0 * tau / dt) as usize);
        assert!((relaxed - (1.0 - share)).abs() < 1e-3, "{relaxed}");
    }

    /// On a tilted surface the depth is measured along its normal, and the friction acts
    /// along its tangent, up to mu x normal force.
    #[test]
    fn tilted_surface_turns_the_contact() {
        let p = Plant::nominal();
        let tilt = 0.2;
        let setup = object(ContactLaw::Linear { stiffness: 1000.0 }, tilt, None);
        let mut c = Contact::new(&setup, [0.0; 2], 1e-5, None);
        // 1 mm into the surface along its normal.
        let n = [tilt.cos(), tilt.sin()];
        let b = skin_at([1e-3 * n[0], 1e-3 * n[1]], [0.0; 2]);
        let f = c.forces(&b, [0.0; 2], 0.0, &p, 0.0);
        assert!((f.normal - 1.0).abs() < 1e-9, "{}", f.normal);
        assert_eq!(f.friction, 0.0, "stuck where it touched");
        // Slid far along the tangent: friction at its limit, against the slide.
        let t = [-tilt.sin(), tilt.cos()];
        let slid = skin_at([b.xs[0] + 0.01 * t[0], b.xs[1] + 0.01 * t[1]], [0.0; 2]);
        let f = c.forces(&slid, [0.0; 2], 0.0, &p, 0.0);
        assert!(
            (f.friction + p.skin_friction * f.normal).abs() < 1e-9,
            "{}",
            f.friction
        );
    }

    /// A stiff, strongly damped contact on a light skin, integrated at a coarse step:
    /// explicitly its damping would overshoot by far (damping x step / mass = 40), the
    /// implicit step settles, never pulling.
    #[test]
    fn implicit_contact_damping_is_stable() {
        let p = Plant::nominal();
        let mut setup = object(ContactLaw::Linear { stiffness: 3000.0 }, 0.0, None);
        setup.damping = 80.0;
        let (dt, m) = (1e-4, 0.002);
        let mut c = Contact::new(&setup, [0.0; 2], dt, None);
        // Pressed by 10 N: elastic force 10 N at 3.3 mm, damping 80 x 10 = 800 N s/m.
        let push = 10.0;
        let (mut x, mut v) = (0.0, 0.05);
        let mut forces = Vec::new();
        for _ in 0..2000 {
            let b = skin_at([x, 0.0], [v, 0.0]);
            let free = [v + dt * push / m, 0.0];
            let f = c.forces(&b, free, dt / m, &p, 0.0).normal;
            assert!(f >= 0.0);
            v += dt * (push - f) / m;
            x += v * dt;
            forces.push(f);
        }
        let last = &forces[forces.len() - 100..];
        for f in last {
            assert!((f - push).abs() < 0.01, "settles at the push: {f}");
        }
    }

    /// The linkage at a posture: joint 1's share and joint 2's make up the tip's velocity,
    /// joint 2's along `J2`; the wall a blocked joint 1 makes is square to `J2` and faces
    /// joint 1's motion; A is the identity for square columns and heavier than 1 along
    /// the finger as it stretches.
    #[test]
    fn linkage_splits_the_motion_between_the_joints() {
        let p = Plant::nominal();
        let l = Linkage::new(&p);
        let v = [0.08, 0.01];
        let lost = l.joint1_share(v);
        let kept = [v[0] - lost[0], v[1] - lost[1]];
        let j2 = l.columns[1];
        assert!(
            (kept[0] * j2[1] - kept[1] * j2[0]).abs() < 1e-12,
            "kept along J2"
        );
        let n = l.joint1_normal(v);
        assert!(dot(n, j2).abs() < 1e-12 && (dot(n, n) - 1.0).abs() < 1e-12);
        assert!(dot(n, lost) > 0.0);
        // A^-1 A = I.
        for r in 0..2 {
            for c in 0..2 {
                let e: f64 = (0..2).map(|k| l.shape_inv[r][k] * l.shape[k][c]).sum();
                assert!((e - f64::from(u8::from(r == c))).abs() < 1e-12);
            }
        }
        let mut q = Plant::nominal();
        // Square columns: J1 = J2 + l1 (cos(psi - q2), sin(psi - q2)) with J1 . J2 = 0.
        q.pad_angle = 0.0;
        q.link2_length = 0.03;
        q.link1_length = 0.06;
        q.flexion = std::f64::consts::PI - 0.5f64.acos();
        let sq = Linkage::new(&q);
        assert!(dot(sq.columns[0], sq.columns[1]).abs() < 1e-12);
        assert!((sq.shape[0][0] - 1.0).abs() < 1e-12 && sq.shape[0][1].abs() < 1e-12);
        assert!((sq.lightest() - 1.0).abs() < 1e-12);
        assert!(l.lightest() < 1.0);
    }

    /// The film reads the inertia of the skin above it: that mass times the rate of the
    /// skin's acceleration along x.
    #[test]
    fn film_reads_the_inertia_it_carries() {
        let s = Sensors::nominal();
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
        let mut chain = SensorChain::new(&s, 0.004, 0.0, 5000.0, 4, &mut rng);
        let at = |a: f64| Physical {
            load: [0.0; 2],
            skin: [a, 3.0],
            pressing: 0.0,
            foam: 0.0,
        };
        chain.transduce(&at(0.0));
        let analog = chain.transduce(&at(2.0));
        // 4 g x 2 m/s^2 over one step at 20 kHz.
        assert!(
            (analog[3] - 0.004 * 2.0 * 20_000.0).abs() < 1e-9,
            "{}",
            analog[3]
        );
    }

    /// The controller's force: feedforward through its erring mass model, the compensated
    /// share of friction, PD, limited.
    #[test]
    fn controller_feeds_forward_compensates_and_limits() {
        let mut p = Plant::nominal();
        p.feedforward_error = 0.1;
        p.friction_compensation = 0.5;
        p.force_limit = 3.0;
        let chain = Chain::new(&p);
        let mut c = Controller::new(&p, &chain, 20_000.0, ENCODER_RESOLUTION, 0.0);
        let mut tr = Trajectory::new(0.001, [0.02, 0.0]);
        tr.set_accel(0, [1.0, 0.0]);
        let b = Bodies {
            xa: [0.0; 2],
            va: [0.02, 0.0],
            xd: [0.0; 2],
            vd: [0.0; 2],
            xs: [0.0; 2],
            vs: [0.0; 2],
        };
        let mut ripple = DriveRipple {
            amplitude: 0.0,
            pitch: 1e-3,
            dt: 5e-5,
            phasor: Phasor::new(0.0, 0.0),
            direction: [0.0; 2],
        };
        c.update(0, &mut tr, &b, &mut ripple);
        // The joints' inertia at the tip: the arm's shaped by A, the fingertip's point mass.
        let shape = chain.linkage.shape;
        let m_tip = chain.total_mass - chain.arm_mass;
        let inertia = |k: usize| 1.1 * (chain.arm_mass * shape[k][0] + [m_tip, 0.0][k]);
        let expected = inertia(0) + 0.5 * (p.arm_coulomb_friction + p.arm_viscous_friction * 0.02);
        assert!(
            (c.force[0] - expected).abs() < 1e-12,
            "{} vs {expected}",
            c.force[0]
        );
        assert!((c.force[1] - inertia(1)).abs() < 1e-12, "{}", c.force[1]);
        // Far behind its command, it pushes at its limit only.
        let behind = Bodies {
            xa: [-0.01, 0.0],
            ..b
        };
        c.next_step = 1;
        c.update(1, &mut tr, &behind, &mut ripple);
        // ... each joint's torque at what makes the limit along its own direction.
        for j in chain.linkage.columns {
            let n = dot(j, j).sqrt();
            let along = dot(j, c.force) / n;
            assert!((along.abs() - 3.0).abs() < 1e-9, "{along}");
        }
        assert!(c.force[0] > 0.0);
    }

    /// The force sensor turned by its misalignment and crossed by its cross-axis
    /// sensitivity; the accelerometer likewise; the hum with its harmonics.
    #[test]
    fn sensor_chain_misalignment_cross_axis_and_hum() {
        let mut s = Sensors::nominal();
        s.force_misalignment = 0.05;
        s.force_y_cross_axis = 0.02;
        s.accel_misalignment = -0.04;
        s.accel_cross_axis = 0.0;
        s.accel_highpass = 0.001;
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
        let mut chain = SensorChain::new(&s, 0.0, 0.0, 5000.0, 4, &mut rng);
        let analog = chain.transduce(&Physical {
            load: [1.0, 0.0],
            skin: [0.0, 10.0],
            pressing: 0.0,
            foam: 0.0,
        });
        let (x, y) = (0.05f64.cos(), -(0.05f64.sin()));
        assert!((analog[0] - x).abs() < 1e-12);
        assert!((analog[1] - (y + 0.02 * x)).abs() < 1e-12);
        // The accelerometer's axis, turned by -0.04 rad, reads -sin(0.04) of y.
        assert!(
            (analog[2] - 10.0 * (-0.04f64).sin()).abs() < 1e-3,
            "{}",
            analog[2]
        );
        // A second harmonic of the mains: sin(2 theta + phase).
        let adc = Adc {
            lsb: 1e-3,
            per_lsb: 1e3,
            gain: 1.0,
            offset: 0.0,
            drift: 0.0,
            hum: [0.0, 1.0, 0.0],
            hum_phase: [(1.0, 0.0); 3],
            sigma: 0.0,
        };
        let theta: f64 = 0.3;
        let mains = [
            (theta.cos(), theta.sin()),
            ((2.0 * theta).cos(), (2.0 * theta).sin()),
            ((3.0 * theta).cos(), (3.0 * theta).sin()),
        ];
        let v = adc.convert(0.0, 0.0, &mains, 0.0);
        assert!((v - (2.0 * theta).sin()).abs() < 1e-3, "{v}");
    }

    /// The joint loop ticks at its own rate, on the first step at or after each tick's time:
    /// at 1.5 kHz on a 20 kHz clock, 13 or 14 steps apart, 1,500 ticks a second.
    #[test]
    fn joint_loop_ticks_at_its_rate() {
        let mut p = Plant::nominal();
        p.control_rate = 1500.0;
        let chain = Chain::new(&p);
        let mut c = Controller::new(&p, &chain, 20_000.0, ENCODER_RESOLUTION, 0.0);
        let mut tr = Trajectory::new(0.001, [0.01, 0.0]);
        let b = skin_at([0.0; 2], [0.0; 2]);
        let mut ripple = DriveRipple {
            amplitude: 0.0,
            pitch: 1e-3,
            dt: 5e-5,
            phasor: Phasor::new(0.0, 0.0),
            direction: [0.0; 2],
        };
        let mut ticks = Vec::new();
        for i in 0..20_000 {
            let before = c.tick;
            c.update(i, &mut tr, &b, &mut ripple);
            if c.tick > before {
                ticks.push(i);
            }
        }
        assert_eq!(ticks.len(), 1500);
        assert!(ticks.windows(2).all(|w| (13..=14).contains(&(w[1] - w[0]))));
        assert_eq!(ticks[3], 40, "tick 3 at 2 ms");
    }

    /// A finger cruising since long before time zero: the drive's ripple, tuned onto the
    /// bending mode (120 Hz, 1 % of damping), shakes the force sensor as hard in its first
    /// 5 ms as it does half a second later. Started from rest, the structure would read a
    /// third of that for the first 5 ms and build up over tens of ms.
    #[test]
    fn ripple_rings_the_structure_from_the_first_sample() {
        let mut plant = Plant::nominal();
        plant.link_damping_ratio = 0.01;
        plant.drive_ripple = 0.08;
        let speed = 0.06;
        plant.ripple_pitch = speed / plant.link_frequency;
        let mut sensors = Sensors::nominal();
        sensors.noise_scale = 0.0;
        let rate_hz = 5000.0;
        let (_, required) = required_rate(&plant, None, None);
        let mut setup = Setup {
            plant,
            sensors,
            trajectory: Trajectory::new(0.001, [speed, 0.0]),
            object: None,
            obstacle: None,
            disturbance: None,
            rows: 4001,
            rate_hz,
            oversampling: (required / rate_hz).ceil().max(2.0) as usize,
            context_rate_hz: 1000.0,
            encoder_resolution: ENCODER_RESOLUTION,
            film_highpass_hz: 0.0,
            velocity_filter_hz: 0.0,
            gives_way_s: None,
        };
        let mut noise = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(3);
        let out = run(&mut setup, &mut noise);
        let force = &out.channels[0];
        // RMS about the mean over rows `from..to`.
        let rms = |from: usize, to: usize| {
            let x = &force[from..to];
            let mean = x.iter().sum::<f64>() / x.len() as f64;
            (x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / x.len() as f64).sqrt()
        };
        let (early, late) = (rms(10, 35), rms(2500, 4000));
        assert!(late > 0.02, "the ripple shakes the sensor: {late} N RMS");
        assert!(
            (0.7..1.4).contains(&(early / late)),
            "{early} N RMS in the first 5 ms, {late} N after half a second"
        );
    }

    /// The context reaches the fingertip a latency after the controller sent it.
    #[test]
    fn context_arrives_after_its_latency() {
        let internal = 20_000.0;
        let mut link = ContextLink {
            rate: 1000.0,
            latency: 0.0005,
            internal_rate: internal,
            tick: 0,
            next_step: 0,
            in_flight: VecDeque::new(),
            received: [0.0; 6],
            encoder: ENCODER_RESOLUTION,
        };
        let mut tr = Trajectory::new(0.001, [0.0; 2]);
        tr.set_accel(3, [2.0, 0.0]);
        let b = skin_at([0.0; 2], [0.0; 2]);
        let mut arrived = None;
        for i in 0..200 {
            link.update(i, &mut tr, &b);
            if link.received[4] != 0.0 && arrived.is_none() {
                arrived = Some(i);
            }
        }
        // Sent at 3 ms (step 60), received 0.5 ms (10 steps) later.
        assert_eq!(arrived, Some(70));
    }
}
