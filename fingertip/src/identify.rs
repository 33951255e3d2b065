//! Identifying a self-motion cancellation (the core's `cancel` stage) from a recording of
//! event-free motion: which gain and cut-off make `gain · low-pass(motion)` explain the
//! most of a sensor.
//!
//! For each cut-off of a logarithmic grid, the motion channel is low-passed exactly as the
//! core does (first order, backward Euler, starting at the first sample) and the gain is the
//! least-squares slope of the sensor on it, both with their means removed (a sensor's
//! offset is not the motion's doing). The fit that explains the largest share of the
//! sensor's variance wins. Rows labelled with an event in the trace's `truth` column are
//! left out: an event is not self-motion.

use crate::trace::Trace;

/// One candidate cancellation, in the trace's units (the sensor's unit per motion unit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    /// The low-pass cut-off (Hz).
    pub cutoff_hz: f64,
    /// The least-squares gain.
    pub gain: f64,
    /// The share of the sensor's variance the prediction explains, in [0, 1].
    pub explained: f64,
    /// The RMS of what is left, in the sensor's unit.
    pub residual_rms: f64,
}

/// Why a cancellation could not be identified.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    /// The trace has no such channel.
    #[error("the trace has no channel `{0}` (it has: {1})")]
    NoChannel(String, String),
    /// Too few event-free rows to fit anything.
    #[error("only {0} event-free rows: at least {MIN_ROWS} are needed")]
    TooShort(usize),
    /// The motion never changes among the event-free rows.
    #[error("`{0}` does not change in the event-free rows: nothing to identify from")]
    NoMotion(String),
}

/// The fewest event-free rows a fit uses.
pub const MIN_ROWS: usize = 100;

/// Cut-offs tried: 24 per decade from 1 Hz to 40 % of the trace's rate.
fn cutoffs(rate_hz: f64) -> Vec<f64> {
    let top = 0.4 * rate_hz;
    (0..)
        .map(|k| 10f64.powf(f64::from(k) / 24.0))
        .take_while(|&f| f <= top)
        .collect()
}

/// Every cut-off's fit of `input` by `gain · low-pass(motion)`, best first.
pub fn identify(trace: &Trace, input: &str, motion: &str) -> Result<Vec<Fit>, IdentifyError> {
    let column = |name: &str| {
        trace.column(name).ok_or_else(|| {
            IdentifyError::NoChannel(name.to_owned(), trace.channel_names().join(", "))
        })
    };
    let x = column(input)?;
    let u = column(motion)?;
    let free: Vec<bool> = (0..trace.len())
        .map(|row| {
            trace
                .truth()
                .and_then(|t| t.get(row))
                .is_none_or(str::is_empty)
        })
        .collect();
    let n = free.iter().filter(|&&f| f).count();
    if n < MIN_ROWS {
        return Err(IdentifyError::TooShort(n));
    }
    let rate = trace.rate_hz();
    let mut fits: Vec<Fit> = cutoffs(rate)
        .into_iter()
        .map(|cutoff_hz| fit(x, &low_pass(u, rate, cutoff_hz), &free, cutoff_hz))
        .collect();
    if fits.iter().all(|f| f.gain == 0.0) {
        return Err(IdentifyError::NoMotion(motion.to_owned()));
    }
    fits.sort_by(|a, b| b.explained.total_cmp(&a.explained));
    Ok(fits)
}

/// The core's first-order low-pass over a whole column, in `f64`.
fn low_pass(u: &[f64], rate_hz: f64, cutoff_hz: f64) -> Vec<f64> {
    let alpha = 1.0 / (1.0 + rate_hz / (2.0 * std::f64::consts::PI * cutoff_hz));
    let mut y = u.first().copied().unwrap_or(0.0);
    u.iter()
        .map(|&v| {
            y += alpha * (v - y);
            y
        })
        .collect()
}

/// The least-squares fit of `x` by `gain · y` over the `free` rows, means removed.
fn fit(x: &[f64], y: &[f64], free: &[bool], cutoff_hz: f64) -> Fit {
    let rows = || {
        x.iter()
            .zip(y)
            .zip(free)
            .filter(|(_, f)| **f)
            .map(|((a, b), _)| (*a, *b))
    };
    let n = rows().count() as f64;
    let (sx, sy) = rows().fold((0.0, 0.0), |(sx, sy), (a, b)| (sx + a, sy + b));
    let (mx, my) = (sx / n, sy / n);
    let (sxy, syy, sxx) = rows().fold((0.0, 0.0, 0.0), |(sxy, syy, sxx), (a, b)| {
        let (da, db) = (a - mx, b - my);
        (sxy + da * db, syy + db * db, sxx + da * da)
    });
    let gain = if syy > 0.0 { sxy / syy } else { 0.0 };
    // Residual sum of squares of the best line: sxx − gain · sxy.
    let rss = (sxx - gain * sxy).max(0.0);
    Fit {
        cutoff_hz,
        gain,
        explained: if sxx > 0.0 { 1.0 - rss / sxx } else { 0.0 },
        residual_rms: (rss / n).sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Labels;

    /// A trace of `input = gain · low-pass(motion at cutoff) + offset + wobble`, the motion a
    /// random staircase, the wobble independent of it.
    fn synthetic(gain: f64, cutoff_hz: f64, rows: usize) -> Trace {
        let rate = 5000.0;
        let motion: Vec<f64> = (0..rows)
            .map(|k| [0.0, 2.0, -1.5, 0.5, 3.0, -2.5, 0.0, 1.0][(k / 700) % 8])
            .collect();
        let y = low_pass(&motion, rate, cutoff_hz);
        let input: Vec<f64> = y
            .iter()
            .enumerate()
            .map(|(k, v)| gain * v + 0.3 + 0.05 * gain.abs() * ((k as f64) * 0.77).sin())
            .collect();
        let t = (0..rows).map(|k| k as f64 / rate).collect();
        Trace::from_columns(
            "synthetic",
            t,
            vec![("f".into(), input), ("a".into(), motion)],
        )
        .expect("valid")
    }

    #[test]
    fn recovers_gain_and_cutoff() {
        for (gain, cutoff) in [(-0.04, 100.0), (2.5, 10.0)] {
            let fits = identify(&synthetic(gain, cutoff, 20_000), "f", "a").expect("fits");
            let best = fits[0];
            assert!(
                (best.gain - gain).abs() < 0.02 * gain.abs(),
                "{best:?} for {gain}"
            );
            assert!(
                (best.cutoff_hz / cutoff).log10().abs() < 1.0 / 24.0 + 1e-9,
                "{best:?} for {cutoff} Hz"
            );
            assert!(best.explained > 0.99, "{best:?}");
            assert!(fits.windows(2).all(|w| w[0].explained >= w[1].explained));
        }
    }

    #[test]
    fn event_rows_are_left_out_and_bad_input_is_named() {
        // An event that adds a large unrelated force in the second half is not fitted.
        let rows = 20_000;
        let mut trace = synthetic(-0.04, 100.0, rows);
        let with_event: Vec<f64> = trace
            .column("f")
            .expect("f")
            .iter()
            .enumerate()
            .map(|(k, v)| {
                if k >= rows / 2 {
                    v - 5.0 * (k as f64 * 1e-3)
                } else {
                    *v
                }
            })
            .collect();
        let t = trace.time().to_vec();
        let a = trace.column("a").expect("a").to_vec();
        trace = Trace::from_columns("event", t, vec![("f".into(), with_event), ("a".into(), a)])
            .expect("valid")
            .with_truth(Labels::switch_at("", "contact", rows / 2, rows))
            .expect("labels");
        let best = identify(&trace, "f", "a").expect("fits")[0];
        assert!((best.gain + 0.04).abs() < 0.001, "{best:?}");

        assert!(matches!(
            identify(&trace, "force_z", "a"),
            Err(IdentifyError::NoChannel(name, _)) if name == "force_z"
        ));
        let short = synthetic(1.0, 10.0, 50);
        assert_eq!(identify(&short, "f", "a"), Err(IdentifyError::TooShort(50)));
        let still = Trace::from_columns(
            "still",
            (0..1000).map(|k| f64::from(k) / 5000.0).collect(),
            vec![("f".into(), vec![0.1; 1000]), ("a".into(), vec![0.0; 1000])],
        )
        .expect("valid");
        assert_eq!(
            identify(&still, "f", "a"),
            Err(IdentifyError::NoMotion("a".into()))
        );
    }
}
