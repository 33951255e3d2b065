//! Commanded tip trajectories: piecewise-constant acceleration switching at controller ticks.
//!
//! The robot's controller updates its command once per tick, so every change of commanded
//! acceleration falls on a tick, and the context the fingertip receives (desired velocity
//! and acceleration) is exactly what the controller applies.

use super::params::{FreeMotion, ParamRange, log_uniform, range_of, uniform};
use rand::{Rng, RngExt};
use std::f64::consts::{PI, TAU};

/// The commanded position, velocity and acceleration at one instant (x, y in the
/// fingertip frame).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Command {
    pub p: [f64; 2],
    pub v: [f64; 2],
    pub a: [f64; 2],
}

#[derive(Clone, Copy, Debug)]
struct Piece {
    /// First controller tick of the piece.
    tick: u64,
    /// State at that tick.
    p: [f64; 2],
    v: [f64; 2],
    /// Acceleration held from that tick on.
    a: [f64; 2],
}

/// A trajectory of constant-acceleration pieces, each starting at a controller tick.
#[derive(Clone, Debug)]
pub(crate) struct Trajectory {
    period: f64,
    pieces: Vec<Piece>,
    cursor: usize,
}

impl Trajectory {
    /// Starts at the origin with velocity `v0` and no acceleration; `period` is the
    /// controller's tick period.
    pub(crate) fn new(period: f64, v0: [f64; 2]) -> Trajectory {
        Trajectory {
            period,
            pieces: vec![Piece {
                tick: 0,
                p: [0.0; 2],
                v: v0,
                a: [0.0; 2],
            }],
            cursor: 0,
        }
    }

    /// Commands acceleration `a` from tick `tick` on. Ticks must be pushed in increasing
    /// order; a tick equal to the last piece's replaces that piece's acceleration.
    pub(crate) fn set_accel(&mut self, tick: u64, a: [f64; 2]) {
        let last = *self.pieces.last().unwrap_or(&Piece {
            tick: 0,
            p: [0.0; 2],
            v: [0.0; 2],
            a: [0.0; 2],
        });
        if tick <= last.tick {
            if let Some(l) = self.pieces.last_mut() {
                l.a = a;
            }
            return;
        }
        let dt = (tick - last.tick) as f64 * self.period;
        let mut p = [0.0; 2];
        let mut v = [0.0; 2];
        for k in 0..2 {
            p[k] = last.p[k] + last.v[k] * dt + 0.5 * last.a[k] * dt * dt;
            v[k] = last.v[k] + last.a[k] * dt;
        }
        self.pieces.push(Piece { tick, p, v, a });
    }

    /// The command at controller tick `tick`. Fast when ticks are asked in increasing order.
    pub(crate) fn at(&mut self, tick: u64) -> Command {
        self.at_time(tick as f64 * self.period)
    }

    /// The command at time `t` (s), between ticks too (the joint loop runs at its own
    /// rate). Fast when times are asked in increasing order.
    pub(crate) fn at_time(&mut self, t: f64) -> Command {
        // Half a nanosecond of slack: a tick's own time belongs to the piece it starts.
        let starts = |pc: &Piece| pc.tick as f64 * self.period <= t + 5e-10;
        // The joint loop and the context ask in turn, a step's worth apart at most: walk
        // back as far as needed.
        while self.cursor > 0 && !starts(&self.pieces[self.cursor]) {
            self.cursor -= 1;
        }
        while self.cursor + 1 < self.pieces.len() && starts(&self.pieces[self.cursor + 1]) {
            self.cursor += 1;
        }
        let pc = &self.pieces[self.cursor];
        let dt = (t - pc.tick as f64 * self.period).max(0.0);
        let mut c = Command {
            a: pc.a,
            ..Command::default()
        };
        for k in 0..2 {
            c.p[k] = pc.p[k] + pc.v[k] * dt + 0.5 * pc.a[k] * dt * dt;
            c.v[k] = pc.v[k] + pc.a[k] * dt;
        }
        c
    }

    /// Random event-free motion lasting at least `ticks` ticks, every value drawn from the
    /// ranges of [`FreeMotion`] (accelerations log-uniformly): segments that are either
    /// point-to-point moves from rest (after an optional pause) with trapezoidal (or
    /// triangular) speed profiles, or gentle changes of the cruising velocity (a ramp to a
    /// new speed and direction, then cruising). The motion stays near the start point:
    /// a move that would leave the workspace radius heads back towards the start instead,
    /// and so does every velocity change made more than a quarter of that radius away. It
    /// ends at rest. Those of `ranges` that name a `free_motion` parameter replace its
    /// range.
    pub(crate) fn free_motion<R: Rng>(
        period: f64,
        ticks: u64,
        rng: &mut R,
        ranges: &[ParamRange],
    ) -> Trajectory {
        let spec = |name: &str| {
            FreeMotion::SPECS
                .iter()
                .find(|s| s.name == name)
                .map(|s| range_of(ranges, s.group, s.name, (s.min, s.max)))
                .unwrap_or((0.0, 0.0))
        };
        let (pause_p, _) = spec("pause_probability");
        let (pause_lo, pause_hi) = spec("pause");
        let (change_p, _) = spec("change_probability");
        let (dist_lo, dist_hi) = spec("distance");
        let (speed_lo, speed_hi) = spec("speed");
        let (acc_lo, acc_hi) = spec("acceleration");
        let (cruise_speed_lo, cruise_speed_hi) = spec("cruise_speed");
        let (gentle_lo, gentle_hi) = spec("gentle_acceleration");
        let (cruise_lo, cruise_hi) = spec("cruise");
        let (radius, _) = spec("workspace_radius");
        let mut m = Mover {
            tr: Trajectory::new(period, [0.0; 2]),
            tick: 0,
            pos: [0.0; 2],
            vel: [0.0; 2],
        };
        while m.tick < ticks {
            if rng.random::<f64>() < change_p {
                let speed = uniform(rng, cruise_speed_lo, cruise_speed_hi);
                let mut angle = uniform(rng, 0.0, TAU);
                if m.pos[0].hypot(m.pos[1]) > radius / 4.0 {
                    angle = (-m.pos[1]).atan2(-m.pos[0]) + uniform(rng, -PI / 6.0, PI / 6.0);
                }
                let a = log_uniform(rng, gentle_lo, gentle_hi);
                m.ramp_to([speed * angle.cos(), speed * angle.sin()], a);
                // Cruise at most a quarter of the radius.
                let mut cruise = uniform(rng, cruise_lo, cruise_hi);
                if speed > 0.0 {
                    cruise = cruise.min(radius / 4.0 / speed);
                }
                m.hold(((cruise / period).round() as u64).max(1));
                continue;
            }
            if m.vel != [0.0; 2] {
                let a = log_uniform(rng, gentle_lo, gentle_hi);
                m.ramp_to([0.0; 2], a);
            }
            if rng.random::<f64>() < pause_p {
                m.hold(((uniform(rng, pause_lo, pause_hi) / period).round() as u64).max(1));
            }
            let mut angle = uniform(rng, 0.0, TAU);
            let dist = uniform(rng, dist_lo, dist_hi);
            let speed = uniform(rng, speed_lo, speed_hi);
            let acc = log_uniform(rng, acc_lo, acc_hi);
            let target = [m.pos[0] + dist * angle.cos(), m.pos[1] + dist * angle.sin()];
            if target[0].hypot(target[1]) > radius {
                angle = (-m.pos[1]).atan2(-m.pos[0]);
            }
            m.point_to_point([angle.cos(), angle.sin()], dist, speed, acc);
        }
        if m.vel != [0.0; 2] {
            m.ramp_to([0.0; 2], gentle_hi);
        }
        m.tr
    }
}

/// Builds a free-motion trajectory piece by piece, keeping track of where the command is.
struct Mover {
    tr: Trajectory,
    /// The tick the next piece starts at.
    tick: u64,
    /// The commanded position and velocity there.
    pos: [f64; 2],
    vel: [f64; 2],
}

impl Mover {
    /// Holds the velocity (no acceleration) for `n` ticks.
    fn hold(&mut self, n: u64) {
        self.accelerate([0.0; 2], n);
    }

    /// Accelerates by `a` for `n` ticks.
    fn accelerate(&mut self, a: [f64; 2], n: u64) {
        self.tr.set_accel(self.tick, a);
        let t = n as f64 * self.tr.period;
        for ((p, v), a) in self.pos.iter_mut().zip(&mut self.vel).zip(a) {
            *p += *v * t + 0.5 * a * t * t;
            *v += a * t;
        }
        self.tick += n;
    }

    /// Ramps the velocity to `v` at acceleration `a` (whole ticks, the last one exact),
    /// then holds it.
    fn ramp_to(&mut self, v: [f64; 2], a: f64) {
        let dv = [v[0] - self.vel[0], v[1] - self.vel[1]];
        let n = ((dv[0].hypot(dv[1]) / a / self.tr.period).round() as u64).max(1);
        let t = n as f64 * self.tr.period;
        self.accelerate([dv[0] / t, dv[1] / t], n);
        self.vel = v;
        self.tr.set_accel(self.tick, [0.0; 2]);
    }

    /// A move from rest of length `dist` along the unit vector `dir`: accelerate at about
    /// `acc` to `speed` (or less, for a short move), cruise, decelerate to rest.
    fn point_to_point(&mut self, dir: [f64; 2], dist: f64, speed: f64, acc: f64) {
        let period = self.tr.period;
        let mut v = speed;
        let mut n_acc = ((v / acc / period).round() as u64).max(1);
        let mut a = v / (n_acc as f64 * period);
        if v * n_acc as f64 * period > dist {
            // Too short to reach the speed: triangular profile.
            v = (dist * a).sqrt();
            n_acc = ((v / a / period).round() as u64).max(1);
            a = v / (n_acc as f64 * period);
        }
        let t_acc = n_acc as f64 * period;
        let n_cruise = (((dist - v * t_acc) / v).max(0.0) / period).round() as u64;
        self.accelerate([a * dir[0], a * dir[1]], n_acc);
        self.hold(n_cruise);
        self.accelerate([-a * dir[0], -a * dir[1]], n_acc);
        self.vel = [0.0; 2];
        self.tr.set_accel(self.tick, [0.0; 2]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn constant_velocity_and_step() {
        let mut tr = Trajectory::new(0.001, [0.05, 0.0]);
        tr.set_accel(20, [10.0, 0.0]);
        tr.set_accel(25, [0.0, 0.0]);
        let c = tr.at(10);
        assert!((c.p[0] - 0.0005).abs() < 1e-12 && c.a[0] == 0.0);
        let c = tr.at(20);
        assert_eq!(c.a[0], 10.0);
        assert!((c.v[0] - 0.05).abs() < 1e-12);
        let c = tr.at(30);
        assert!((c.v[0] - 0.10).abs() < 1e-12 && c.a[0] == 0.0);
        // Asking back in time works too.
        assert_eq!(tr.at(0).p[0], 0.0);
    }

    #[test]
    fn free_motion_stops_and_stays_near_start() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(3);
        let ticks = 60_000;
        let mut tr = Trajectory::free_motion(0.001, ticks, &mut rng, &[]);
        let mut max_r: f64 = 0.0;
        let mut max_v: f64 = 0.0;
        let mut moving = 0;
        for k in 0..ticks {
            let c = tr.at(k);
            max_r = max_r.max(c.p[0].hypot(c.p[1]));
            let v = c.v[0].hypot(c.v[1]);
            max_v = max_v.max(v);
            if v > 1e-6 {
                moving += 1;
            }
        }
        assert!(max_r < 0.075, "{max_r}");
        assert!(max_v <= 0.1 + 1e-9 && max_v > 0.05, "{max_v}");
        assert!(moving > ticks / 4 && moving < ticks, "{moving}");
        // Every move ends at rest.
        let end = tr.pieces.last().unwrap();
        let c = tr.at(end.tick);
        assert!(c.v[0].hypot(c.v[1]) < 1e-9);
    }
}
