//! The fingertip detector's PC tool, as a library: the simulator, the trace format,
//! replay, scoring, plots, the identification of self-motion cancellations and the CAN
//! tools behind the `fingertip` command.

pub mod can_tools;
pub mod corpus;
pub mod features;
pub mod fit;
pub mod identify;
pub mod output;
pub mod plot;
pub mod replay;
pub mod score;
pub mod sim;
pub mod trace;

/// The paper's approach-phase detector, `configs/approach.toml`: the default configuration
/// of every tool, and the firmware's (built from the same file).
pub const APPROACH_TOML: &str = include_str!("../../configs/approach.toml");

/// The default detector's tick, generated from `configs/approach.toml` at build time as
/// the firmware's is: replays run it instead of the interpreter whenever the detector they
/// were given is the default one.
pub mod builtin {
    use std::sync::OnceLock;

    use detector_core::Detector;

    mod generated {
        #![allow(missing_docs, clippy::all)]
        include!(concat!(env!("OUT_DIR"), "/approach_tick.rs"));
    }
    pub use generated::ApproachTick;

    /// Whether `detector` is the default detector, which [`ApproachTick`] runs.
    pub fn is_default(detector: &Detector) -> bool {
        static DEFAULT: OnceLock<Option<Detector>> = OnceLock::new();
        DEFAULT
            .get_or_init(|| {
                detector_build::Config::from_toml(super::APPROACH_TOML)
                    .ok()
                    .and_then(|c| detector_build::build(&c).ok())
            })
            .as_ref()
            .is_some_and(|d| d == detector)
    }
}

/// A number as a person reads it in a message: plain in the everyday range, in scientific
/// notation far outside it, so that a huge input is never echoed with 300 digits.
pub fn readable(v: f64) -> String {
    if v == 0.0 || (1e-3..1e7).contains(&v.abs()) || !v.is_finite() {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Appends `num / 2^shift` with `decimals` digits after the point, rounded to nearest with
/// ties to even on its exact value, a minus sign on every negative `num`: what
/// `format!("{:.decimals$}", num as f64 / 2^shift)` prints, without going through a float,
/// for `shift` ≤ 32 and `decimals` ≤ 9 (more are taken as 9). The tools write fixed-point
/// values (confidences, features) this way, millions per second.
pub fn write_binary_fraction(out: &mut Vec<u8>, num: i32, shift: u32, decimals: u32) {
    let decimals = decimals.min(9);
    // Below 2³¹ · 10⁹ < 2⁶²: the arithmetic fits in 64 bits.
    let unit = 10u64.pow(decimals);
    let scaled = u64::from(num.unsigned_abs()) * unit;
    let mut q = scaled >> shift;
    let twice_rest = (scaled - (q << shift)) << 1;
    let den = 1u64 << shift;
    if twice_rest > den || (twice_rest == den && q & 1 == 1) {
        q += 1;
    }
    if num < 0 {
        out.push(b'-');
    }
    // Written from the last character: the fraction's digits, the point, the integer's
    // digits (at least one).
    let mut text = [0u8; 48];
    let mut at = text.len();
    let mut put = |c: u8| {
        at -= 1;
        text[at] = c;
        at
    };
    let mut fraction = q % unit;
    for _ in 0..decimals {
        put(b'0' + (fraction % 10) as u8);
        fraction /= 10;
    }
    if decimals > 0 {
        put(b'.');
    }
    let mut integer = q / unit;
    let mut start = put(b'0' + (integer % 10) as u8);
    integer /= 10;
    while integer > 0 {
        start = put(b'0' + (integer % 10) as u8);
        integer /= 10;
    }
    out.extend_from_slice(&text[start..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn printed(num: i32, shift: u32, decimals: u32) -> String {
        let mut out = Vec::new();
        write_binary_fraction(&mut out, num, shift, decimals);
        String::from_utf8(out).unwrap_or_default()
    }

    /// Every confidence, and signals at the range ends, around zero, on ties and at random,
    /// against the float formatter.
    #[test]
    fn binary_fractions_print_as_floats_do() {
        for bits in 0..=32768 {
            let want = format!("{:.5}", f64::from(bits) / 32768.0);
            assert_eq!(printed(bits, 15, 5), want, "{bits}");
        }
        let mut values = vec![
            0,
            1,
            -1,
            32,
            -32,
            33,
            -33,
            65536,
            -65536,
            i32::MAX,
            i32::MIN,
        ];
        let mut seed = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..200_000 {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            values.push((seed as i32) >> (seed >> 59));
        }
        for num in values {
            for (shift, decimals) in [(16, 6), (16, 0), (16, 2), (15, 5), (0, 3), (32, 9)] {
                let want = format!(
                    "{:.*}",
                    decimals as usize,
                    f64::from(num) / 2f64.powi(shift)
                );
                assert_eq!(
                    printed(num, shift as u32, decimals),
                    want,
                    "{num} {shift} {decimals}"
                );
            }
        }
    }
}
