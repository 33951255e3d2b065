//! What the detector-path tests share to build synthetic traces: the simulator's channels
//! from the few a test drives, and the force sensor's noise.

use fingertip::sim::CHANNELS;
use fingertip::trace::Trace;
use rand::rngs::Xoshiro256PlusPlus;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

/// `n` sample times at 5 kHz from zero [s].
pub fn times(n: u32) -> Vec<f64> {
    (0..n).map(|k| f64::from(k) / 5000.0).collect()
}

/// A trace named `name` at times `t`: the channels in `given` as given (in the trace's
/// units), every other channel of the simulator's at zero.
pub fn trace_of(name: &str, t: Vec<f64>, given: Vec<(&str, Vec<f64>)>) -> Trace {
    let zeros = vec![0.0; t.len()];
    let mut channels: Vec<(String, Vec<f64>)> = CHANNELS
        .iter()
        .filter(|c| given.iter().all(|(g, _)| *g != c.name))
        .map(|c| (c.name.to_string(), zeros.clone()))
        .collect();
    channels.extend(given.into_iter().map(|(c, v)| (c.to_string(), v)));
    Trace::from_columns(name, t, channels).expect("a trace")
}

/// The force sensor's white noise, 1.5 cN RMS [N], the same sequence for the same `seed`.
pub fn force_noise(seed: u64) -> impl FnMut() -> f64 {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    move || 0.015 * rng.sample::<f64, _>(StandardNormal)
}
