//! Commanded tip trajectories: piecewise-constant acceleration switching at controller ticks.
//!
//! The robot's controller updates its command once per tick, so every change of commanded
//! acceleration falls on a tick, and the context the fingertip receives (desired velocity
//! and acceleration) is exactly what the controller applies.

use super::params::{FreeMotion, uniform};
use rand::{Rng, RngExt};

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
        if self.pieces[self.cursor].tick > tick {
            self.cursor = 0;
        }
        while self.cursor + 1 < self.pieces.len() && self.pieces[self.cursor + 1].tick <= tick {
            self.cursor += 1;
        }
        let pc = &self.pieces[self.cursor];
        let dt = (tick - pc.tick) as f64 * self.period;
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

    /// Random event-free motion lasting at least `ticks` ticks: pauses and point-to-point
    /// moves with trapezoidal (or triangular) speed profiles, every value drawn from the
    /// ranges of [`FreeMotion`] (acceleration log-uniformly). Moves stay within the
    /// workspace radius of the start point: a move that would leave it heads back towards
    /// the start instead.
    pub(crate) fn free_motion<R: Rng>(period: f64, ticks: u64, rng: &mut R) -> Trajectory {
        let spec = |name: &str| {
            FreeMotion::SPECS
                .iter()
                .find(|s| s.name == name)
                .map(|s| (s.min, s.max))
                .unwrap_or((0.0, 0.0))
        };
        let (pause_p, _) = spec("pause_probability");
        let (pause_lo, pause_hi) = spec("pause");
        let (dist_lo, dist_hi) = spec("distance");
        let (speed_lo, speed_hi) = spec("speed");
        let (acc_lo, acc_hi) = spec("acceleration");
        let (radius, _) = spec("workspace_radius");
        let mut tr = Trajectory::new(period, [0.0; 2]);
        let mut tick: u64 = 0;
        let mut pos = [0.0f64; 2];
        while tick < ticks {
            if rng.random::<f64>() < pause_p {
                tick += ((uniform(rng, pause_lo, pause_hi) / period).round() as u64).max(1);
            }
            let mut angle = uniform(rng, 0.0, std::f64::consts::TAU);
            let dist = uniform(rng, dist_lo, dist_hi);
            let speed = uniform(rng, speed_lo, speed_hi);
            let acc = (uniform(rng, acc_lo.ln(), acc_hi.ln())).exp();
            let target = [pos[0] + dist * angle.cos(), pos[1] + dist * angle.sin()];
            if (target[0] * target[0] + target[1] * target[1]).sqrt() > radius {
                angle = (-pos[1]).atan2(-pos[0]);
            }
            let dir = [angle.cos(), angle.sin()];
            // Trapezoid: accelerate for n_acc ticks, cruise n_cruise ticks, decelerate.
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
            let cruise = ((dist - v * t_acc) / v).max(0.0);
            let n_cruise = (cruise / period).round() as u64;
            tr.set_accel(tick, [a * dir[0], a * dir[1]]);
            tr.set_accel(tick + n_acc, [0.0; 2]);
            tr.set_accel(tick + n_acc + n_cruise, [-a * dir[0], -a * dir[1]]);
            tr.set_accel(tick + 2 * n_acc + n_cruise, [0.0; 2]);
            let travelled = v * t_acc + v * n_cruise as f64 * period;
            pos = [pos[0] + travelled * dir[0], pos[1] + travelled * dir[1]];
            tick += 2 * n_acc + n_cruise;
        }
        tr
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
        let mut tr = Trajectory::free_motion(0.001, ticks, &mut rng);
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
