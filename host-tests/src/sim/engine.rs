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
//!                   obstacle (x)                         │  distal link and carrier)     friction on y)
//!                                                   disturbance
//! ```
//!
//! - `arm`: the proximal part of the finger, position-controlled by a PD law with
//!   feedforward of the commanded acceleration, run at the controller rate on the
//!   motor-side position (quantized to the encoder resolution). The drive adds a small
//!   force ripple whose frequency follows the commanded speed. In a link collision the arm
//!   strikes the obstacle (Hunt-Crossley contact along x).
//! - `distal`: the distal link and the fingertip's carrier, joined to the arm by the
//!   structural compliance. Disturbances act here, below the force sensor.
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

/// A disturbance force on the distal link.
#[derive(Clone, Debug)]
pub(crate) struct DisturbanceSetup {
    pub start: f64,
    pub kind: DisturbanceKind,
    pub direction: f64,
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

/// Runs the simulation. `noise` drives the sensor noise and the hum phases.
pub(crate) fn run<R: Rng>(setup: &mut Setup, noise: &mut R) -> Output {
    let p = &setup.plant;
    let s = &setup.sensors;
    let n_over = setup.oversampling.max(1);
    let internal_rate = setup.rate_hz * n_over as f64;
    let dt = 1.0 / internal_rate;

    // Masses: the distal body carries the carrier (rigid through the stiff force sensor).
    let ma = p.arm_mass;
    let mc = p.carrier_mass;
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
    // Position controller.
    let wc = TAU * p.control_bandwidth;
    let kp = m_tot * wc * wc;
    let kd = 2.0 * p.control_damping_ratio * m_tot * wc;
    let ctrl_period = 1.0 / setup.controller_rate_hz;
    let friction = |v: f64| -> f64 {
        p.arm_coulomb_friction * (v / FRICTION_SPEED).clamp(-1.0, 1.0) + p.arm_viscous_friction * v
    };
    let tick_step =
        |k: u64| -> u64 { (k as f64 * ctrl_period * internal_rate - 1e-6).ceil() as u64 };

    // Sensor chain.
    let mut aa: Vec<AntiAliasFilter> = (0..4)
        .map(|_| AntiAliasFilter::new(internal_rate, setup.rate_hz))
        .collect();
    let mut hp = HighPass1::new(s.accel_highpass, internal_rate);
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
    let mut gauss = Gauss { spare: None };
    // Mains phase, advanced once per output sample.
    let (mut mains_c, mut mains_s) = (1.0f64, 0.0f64);
    let (mains_dc, mains_ds) = {
        let (sn, cs) = (TAU * s.hum_frequency / setup.rate_hz).sin_cos();
        (cs, sn)
    };
    let mut until_sample = 0usize;

    // Initial state: steady motion at the commanded initial velocity, all springs relaxed,
    // the whole finger lagging the command by the position error that balances friction.
    let c0 = setup.trajectory.at(0);
    let lag = [friction(c0.v[0]) / kp, friction(c0.v[1]) / kp];
    let start = |k: usize| Axis {
        xa: -lag[k],
        va: c0.v[k],
        xd: -lag[k],
        vd: c0.v[k],
        xs: -lag[k],
        vs: c0.v[k],
    };
    let mut ax = start(0);
    let mut ay = start(1);
    let surface0 = setup.object.as_ref().map_or(0.0, |o| o.surface) + ax.xs;
    let obstacle0 = setup.obstacle.as_ref().map_or(0.0, |o| o.position) + ax.xa;
    let (mut xo, mut vo, mut stuck) = (0.0f64, 0.0f64, true);
    let mut anchor = 0.0f64;
    let mut in_contact = false;

    // Controller outputs, held between ticks.
    let mut fcx = 0.0;
    let mut fcy = 0.0;
    let mut ctx = [0.0f64; 6];
    let mut tick: u64 = 0;
    let mut next_tick = 0u64;
    // Drive ripple: a rotating phasor advanced by the commanded speed.
    let (mut rc, mut rs) = (1.0f64, 0.0f64);
    let (mut dc, mut ds) = (1.0f64, 0.0f64);
    let mut ripple_dir = [0.0f64; 2];

    let dist = setup.disturbance.clone();
    let (dist_start, dist_end) = match &dist {
        Some(d) => (d.start, d.start + d.duration()),
        None => (f64::INFINITY, f64::INFINITY),
    };
    let (dist_cos, dist_sin) = dist
        .as_ref()
        .map(|d| (d.direction.cos(), d.direction.sin()))
        .unwrap_or((0.0, 0.0));

    let mut prev_fn = 0.0f64;
    let mut prev_ff = 0.0f64;
    let mut onset: Option<(f64, Happened)> = None;
    let mut out: Vec<Vec<f64>> = (0..CHANNELS.len())
        .map(|_| Vec::with_capacity(setup.rows))
        .collect();
    let total_steps = (setup.rows.saturating_sub(1) * n_over) as u64;

    for i in 0..=total_steps {
        let t = i as f64 * dt;

        // The controller's tick.
        if i == next_tick {
            let cmd = setup.trajectory.at(tick);
            let mx = (ax.xa / ENCODER_RESOLUTION).round() * ENCODER_RESOLUTION;
            let my = (ay.xa / ENCODER_RESOLUTION).round() * ENCODER_RESOLUTION;
            fcx = m_tot * cmd.a[0] + kp * (cmd.p[0] - mx) + kd * (cmd.v[0] - ax.va);
            fcy = m_tot * cmd.a[1] + kp * (cmd.p[1] - my) + kd * (cmd.v[1] - ay.va);
            ctx = [
                cmd.p[0] - mx,
                cmd.p[1] - my,
                cmd.v[0],
                cmd.v[1],
                cmd.a[0],
                cmd.a[1],
            ];
            let speed = cmd.v[0].hypot(cmd.v[1]);
            if speed > 1e-9 && p.drive_ripple > 0.0 {
                ripple_dir = [cmd.v[0] / speed, cmd.v[1] / speed];
                let step_angle = TAU * speed * dt / p.ripple_pitch;
                (ds, dc) = step_angle.sin_cos();
            } else {
                ripple_dir = [0.0; 2];
                (ds, dc) = (0.0, 1.0);
            }
            let norm = rc.hypot(rs);
            rc /= norm;
            rs /= norm;
            tick += 1;
            next_tick = tick_step(tick);
        }
        (rc, rs) = (rc * dc - rs * ds, rs * dc + rc * ds);
        let ripple = p.drive_ripple * rs;

        // Disturbance on the distal body.
        let (dx, dy) = if t >= dist_start && t < dist_end {
            let f = dist.as_ref().map_or(0.0, |d| d.force(t - dist_start));
            (f * dist_cos, f * dist_sin)
        } else {
            (0.0, 0.0)
        };

        // Skin-object contact.
        let mut f_n = 0.0;
        let mut f_t = 0.0;
        if let Some(obj) = &setup.object {
            let depth = ax.xs - (surface0 + xo);
            if depth > 0.0 {
                f_n = (obj.stiffness * depth * (1.0 + obj.damping * (ax.vs - vo))).max(0.0);
            }
            if f_n > 0.0 {
                if !in_contact {
                    anchor = ay.xs;
                    in_contact = true;
                }
                let limit = p.skin_friction * f_n / p.tangential_stiffness;
                let mut e = ay.xs - anchor;
                if e.abs() > limit {
                    e = limit.copysign(e);
                    anchor = ay.xs - e;
                }
                f_t = -p.tangential_stiffness * e;
            } else {
                in_contact = false;
            }
        }
        // Arm-obstacle contact.
        let mut f_ob = 0.0;
        if let Some(ob) = &setup.obstacle {
            let depth = ax.xa - obstacle0;
            if depth > 0.0 {
                f_ob = (ob.stiffness * depth * (1.0 + ob.damping * ax.va)).max(0.0);
            }
        }
        if onset.is_none() {
            if f_n > 0.0 {
                onset = Some((t, Happened::Contact));
            } else if f_ob > 0.0 {
                onset = Some((t, Happened::Collision));
            } else if dx != 0.0 || dy != 0.0 {
                onset = Some((t, Happened::Disturbance));
            }
        }

        // Forces and accelerations, x.
        let fl = kl * (ax.xa - ax.xd) + cl * (ax.va - ax.vd);
        let ff = kf * (ax.xd - ax.xs) + cf * (ax.vd - ax.vs);
        let aa_x = (fcx + ripple * ripple_dir[0] - friction(ax.va) - fl - f_ob) / ma;
        let ad_x = (fl - ff + dx) / md;
        let as_x = (ff - f_n) / ms;
        // y.
        let fly = kl * (ay.xa - ay.xd) + cl * (ay.va - ay.vd);
        let ffy = kfy * (ay.xd - ay.xs) + cfy * (ay.vd - ay.vs);
        let aa_y = (fcy + ripple * ripple_dir[1] - friction(ay.va) - fly) / ma;
        let ad_y = (fly - ffy + dy) / md;
        let as_y = (ffy + f_t) / ms;
        // The movable object.
        let mut ao = 0.0;
        if let Some(ObjectSetup {
            movable: Some((m_o, mu_k, mu_s)),
            ..
        }) = &setup.object
        {
            let normal = m_o * GRAVITY;
            if stuck && f_n > mu_s * normal {
                stuck = false;
            }
            if !stuck {
                ao = (f_n - mu_k * normal) / m_o;
            }
        }

        // Sensors, at the internal rate.
        let force_x = -mc * ad_x - ff;
        let force_y = -mc * ad_y - ffy;
        let accel = hp.process(as_x + s.accel_cross_axis * as_y);
        let stress =
            (f_n - prev_fn) * internal_rate + s.stress_crosstalk * (ff - prev_ff) * internal_rate;
        prev_fn = f_n;
        prev_ff = ff;
        let y0 = aa[0].process(force_x);
        let y1 = aa[1].process(force_y);
        let y2 = aa[2].process(accel);
        let y3 = aa[3].process(stress);
        if until_sample == 0 {
            until_sample = n_over;
            let row = i / n_over as u64;
            let ts = row as f64 / setup.rate_hz;
            for (k, y) in [y0, y1, y2, y3].into_iter().enumerate() {
                let z = gauss.next(noise);
                out[k].push(adc[k].convert(y, ts, (mains_c, mains_s), z));
            }
            (mains_c, mains_s) = (
                mains_c * mains_dc - mains_s * mains_ds,
                mains_s * mains_dc + mains_c * mains_ds,
            );
            if row.is_multiple_of(1024) {
                let norm = mains_c.hypot(mains_s);
                mains_c /= norm;
                mains_s /= norm;
            }
            for (k, v) in ctx.iter().enumerate() {
                out[4 + k].push(round_context(*v));
            }
        }

        until_sample -= 1;

        // Integrate (semi-implicit Euler: velocities first, positions with the new ones).
        ax.va += aa_x * dt;
        ax.vd += ad_x * dt;
        ax.vs += as_x * dt;
        ax.xa += ax.va * dt;
        ax.xd += ax.vd * dt;
        ax.xs += ax.vs * dt;
        ay.va += aa_y * dt;
        ay.vd += ad_y * dt;
        ay.vs += as_y * dt;
        ay.xa += ay.va * dt;
        ay.xd += ay.vd * dt;
        ay.xs += ay.vs * dt;
        if !stuck {
            vo += ao * dt;
            if vo <= 0.0 {
                vo = 0.0;
                stuck = true;
            }
            xo += vo * dt;
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
