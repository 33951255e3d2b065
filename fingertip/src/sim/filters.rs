//! Digital models of the analog filters in front of the fingertip's ADC.
//!
//! The simulator integrates the physics at an internal rate well above the detector rate.
//! Each analog channel passes, at that internal rate, through the sensor's own dynamics
//! (the accelerometer's AC coupling) and an anti-alias low-pass filter, and is then sampled
//! at the detector rate, as the ADC samples the real analog front end.

use std::f64::consts::PI;

/// The anti-alias filter's cutoff as a fraction of the output (detector) sampling rate:
/// 0.3, i.e. 1.5 kHz at the default 5 kHz. A 4th-order Butterworth response falls 24 dB
/// per octave: at the Nyquist frequency (1.67 times the cutoff) it attenuates by about
/// 18 dB, at twice the cutoff by 24 dB, and a tone at the sampling rate itself (which
/// aliases onto DC) by about 42 dB.
pub const ANTI_ALIAS_CUTOFF_RATIO: f64 = 0.3;

/// The coefficients of a second-order IIR section (transposed direct form II), normalized
/// by `a0`.
#[derive(Clone, Copy, Debug)]
struct Biquad {
    b0: f64,
    b1: f64,
    b2: f64,
    a1: f64,
    a2: f64,
}

impl Biquad {
    /// A low-pass section with quality factor `q` and cutoff `fc` at sampling rate `fs`
    /// (bilinear transform, prewarped at the cutoff).
    fn low_pass(fc: f64, fs: f64, q: f64) -> Biquad {
        let w0 = 2.0 * PI * fc / fs;
        let (sin, cos) = w0.sin_cos();
        let alpha = sin / (2.0 * q);
        let a0 = 1.0 + alpha;
        let b1 = (1.0 - cos) / a0;
        Biquad {
            b0: b1 / 2.0,
            b1,
            b2: b1 / 2.0,
            a1: -2.0 * cos / a0,
            a2: (1.0 - alpha) / a0,
        }
    }
}

/// The anti-alias filter: a 4th-order Butterworth low-pass (two biquad sections) run at
/// the internal rate, with its cutoff at [`ANTI_ALIAS_CUTOFF_RATIO`] times the output rate.
/// It filters `L` channels at once (the simulator's four analog channels share one
/// filter design), lane by lane, so that the channels' arithmetic runs side by side.
#[derive(Clone, Debug)]
pub struct AntiAliasFilter<const L: usize = 1> {
    sections: [Biquad; 2],
    /// Each section's two state variables, per lane.
    s1: [[f64; L]; 2],
    s2: [[f64; L]; 2],
}

impl<const L: usize> AntiAliasFilter<L> {
    /// A filter running at `input_rate_hz` for sampling at `output_rate_hz`.
    pub fn new(input_rate_hz: f64, output_rate_hz: f64) -> AntiAliasFilter<L> {
        let fc = ANTI_ALIAS_CUTOFF_RATIO * output_rate_hz;
        // Quality factors of the 4th-order Butterworth sections: 1 / (2 cos(pi/8)) and
        // 1 / (2 cos(3 pi/8)).
        let q1 = 1.0 / (2.0 * (PI / 8.0).cos());
        let q2 = 1.0 / (2.0 * (3.0 * PI / 8.0).cos());
        AntiAliasFilter {
            sections: [
                Biquad::low_pass(fc, input_rate_hz, q1),
                Biquad::low_pass(fc, input_rate_hz, q2),
            ],
            s1: [[0.0; L]; 2],
            s2: [[0.0; L]; 2],
        }
    }

    /// Filters one input sample per lane.
    #[inline]
    pub fn process(&mut self, x: [f64; L]) -> [f64; L] {
        let mut v = x;
        for (k, c) in self.sections.iter().enumerate() {
            let (s1, s2) = (&mut self.s1[k], &mut self.s2[k]);
            for lane in 0..L {
                let y = c.b0 * v[lane] + s1[lane];
                s1[lane] = c.b1 * v[lane] - c.a1 * y + s2[lane];
                s2[lane] = c.b2 * v[lane] - c.a2 * y;
                v[lane] = y;
            }
        }
        v
    }

    /// Puts every lane in the steady state of its constant input `x`.
    pub fn settle(&mut self, x: [f64; L]) {
        // In steady state y = x (unit DC gain); solve the state equations for s1, s2.
        for (k, c) in self.sections.iter().enumerate() {
            for ((s1, s2), x) in self.s1[k].iter_mut().zip(&mut self.s2[k]).zip(x) {
                *s2 = c.b2 * x - c.a2 * x;
                *s1 = c.b1 * x - c.a1 * x + *s2;
            }
        }
    }
}

/// A first-order high-pass filter (an RC coupling), bilinear transform.
#[derive(Clone, Copy, Debug)]
pub struct HighPass1 {
    b0: f64,
    a1: f64,
    x1: f64,
    y1: f64,
}

impl HighPass1 {
    /// A high-pass with corner `fc` at sampling rate `fs`.
    pub fn new(fc: f64, fs: f64) -> HighPass1 {
        let k = (PI * fc / fs).tan();
        HighPass1 {
            b0: 1.0 / (1.0 + k),
            a1: (k - 1.0) / (k + 1.0),
            x1: 0.0,
            y1: 0.0,
        }
    }

    /// Puts the filter in the steady state of its constant input `x` (output 0).
    pub fn settle(&mut self, x: f64) {
        self.x1 = x;
        self.y1 = 0.0;
    }

    /// The next output for input `x`.
    #[inline]
    pub fn process(&mut self, x: f64) -> f64 {
        let y = self.b0 * (x - self.x1) - self.a1 * self.y1;
        self.x1 = x;
        self.y1 = y;
        y
    }
}

/// Low-pass filters `input`, sampled at `input_rate_hz`, with the simulator's anti-alias
/// filter and keeps every `factor`-th sample (the first one included), giving a signal at
/// `input_rate_hz / factor`. This is exactly what the simulator does to every analog
/// channel before the ADC. A `factor` of 0 is treated as 1.
pub fn decimate(input: &[f64], input_rate_hz: f64, factor: usize) -> Vec<f64> {
    let factor = factor.max(1);
    let mut f = AntiAliasFilter::<1>::new(input_rate_hz, input_rate_hz / factor as f64);
    input
        .iter()
        .enumerate()
        .filter_map(|(i, &x)| {
            let [y] = f.process([x]);
            (i % factor == 0).then_some(y)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tone_gain(freq: f64, fs: f64, fc_rate: f64) -> f64 {
        let mut f = AntiAliasFilter::<1>::new(fs, fc_rate);
        let n = (fs * 0.2) as usize;
        let mut peak: f64 = 0.0;
        for i in 0..n {
            let [y] = f.process([(2.0 * PI * freq * i as f64 / fs).sin()]);
            if i > n / 2 {
                peak = peak.max(y.abs());
            }
        }
        peak
    }

    #[test]
    fn butterworth_response() {
        // Pass band flat, -3 dB at the cutoff, 24 dB per octave above.
        assert!((tone_gain(100.0, 50_000.0, 5000.0) - 1.0).abs() < 0.01);
        let g = tone_gain(1500.0, 50_000.0, 5000.0);
        assert!((g - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.02, "{g}");
        let g = tone_gain(3000.0, 50_000.0, 5000.0);
        assert!(g < 0.065, "{g}");
        let g = tone_gain(5000.0, 50_000.0, 5000.0);
        assert!(g < 0.01, "{g}");
    }

    /// Lanes share the design, not the state: each is the one-lane filter of its input.
    #[test]
    fn lanes_filter_independently() {
        let mut four = AntiAliasFilter::<4>::new(50_000.0, 5000.0);
        let mut ones: [AntiAliasFilter; 4] =
            std::array::from_fn(|_| AntiAliasFilter::new(50_000.0, 5000.0));
        for i in 0..500 {
            let x: [f64; 4] = std::array::from_fn(|k| ((i * (k + 1)) as f64 * 0.37).sin());
            let y = four.process(x);
            for k in 0..4 {
                assert_eq!(y[k], ones[k].process([x[k]])[0]);
            }
        }
    }

    #[test]
    fn settle_gives_steady_output() {
        let mut f = AntiAliasFilter::<2>::new(50_000.0, 5000.0);
        f.settle([3.5, -1.0]);
        for _ in 0..10 {
            let [a, b] = f.process([3.5, -1.0]);
            assert!((a - 3.5).abs() < 1e-9 && (b + 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn high_pass_blocks_dc_passes_ac() {
        let fs = 50_000.0;
        let mut h = HighPass1::new(15.0, fs);
        let mut last = 0.0;
        for i in 0..(fs as usize) {
            last = h.process(1.0 + (2.0 * PI * 500.0 * i as f64 / fs).sin());
        }
        // After one second the DC part is gone; the 500 Hz part remains.
        assert!(last.abs() <= 1.01);
        let mut peak: f64 = 0.0;
        for i in 0..1000 {
            peak = peak.max(
                h.process(1.0 + (2.0 * PI * 500.0 * i as f64 / fs).sin())
                    .abs(),
            );
        }
        assert!(peak > 0.98 && peak < 1.02, "{peak}");
    }
}
