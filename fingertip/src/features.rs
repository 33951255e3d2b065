//! What each feature does around labelled events: `fingertip features --traces`.
//!
//! Every recording is replayed and each tick's feature values are sorted into the event
//! they fall in (the first `window` after a labelled onset) or into "outside" (ticks in no
//! event's window: not labelled, and more than `after` past the last event's end); ticks
//! later in an event, or in its tail, are left out. For each (feature, event) pair the best
//! single threshold between the event's values and the outside ones says how well the
//! feature alone separates them ([`Separation`]).

use std::path::{Path, PathBuf};

use detector_core::Detector;
use rayon::prelude::*;

use crate::replay::{StreamError, Streamed, replay_stream};
use crate::trace::TraceReader;

/// The most values kept per feature outside events: beyond twice as many, every other one
/// is dropped and the stride doubles, so memory stays bounded for a corpus of any length.
const OUTSIDE_CAP: usize = 1 << 18;

/// Feature values inside events and outside them, per feature.
#[derive(Clone, Debug, Default)]
pub struct FeatureSamples {
    /// The features, in the configuration's order.
    pub features: Vec<String>,
    /// The events, in the configuration's order.
    pub events: Vec<String>,
    /// `inside[event][feature]`: every value in the first `window` after each onset.
    pub inside: Vec<Vec<Vec<f64>>>,
    /// `peaks[event][feature]`: the least and the greatest value in the first `window` of
    /// each labelled occurrence of the event, one pair per occurrence.
    pub peaks: Vec<Vec<Vec<(f64, f64)>>>,
    /// `outside[feature]`: values outside every event, one tick in `outside_stride`.
    pub outside: Vec<Vec<f64>>,
    /// How many outside ticks each kept value stands for (a power of two).
    pub outside_stride: usize,
    /// Outside ticks seen.
    outside_seen: usize,
}

impl FeatureSamples {
    /// No samples yet, for `detector`'s features and events.
    pub fn new(detector: &Detector) -> FeatureSamples {
        let features: Vec<String> = detector.features().iter().map(|n| n.to_string()).collect();
        let events: Vec<String> = detector.events().iter().map(|n| n.to_string()).collect();
        FeatureSamples {
            inside: vec![vec![Vec::new(); features.len()]; events.len()],
            peaks: vec![vec![Vec::new(); features.len()]; events.len()],
            outside: vec![Vec::new(); features.len()],
            outside_stride: 1,
            outside_seen: 0,
            features,
            events,
        }
    }

    fn push_outside(&mut self, values: &[f64]) {
        if self.outside_seen.is_multiple_of(self.outside_stride) {
            for (column, v) in self.outside.iter_mut().zip(values) {
                column.push(*v);
            }
            self.keep_within_cap();
        }
        self.outside_seen += 1;
    }

    /// Keeps every other outside value, stride doubled, while there are twice the cap.
    fn keep_within_cap(&mut self) {
        while self
            .outside
            .first()
            .is_some_and(|c| c.len() >= 2 * OUTSIDE_CAP)
        {
            self.thin_outside(2);
        }
    }

    /// Keeps one outside value in `step`.
    fn thin_outside(&mut self, step: usize) {
        if step > 1 {
            for column in &mut self.outside {
                *column = column.iter().copied().step_by(step).collect();
            }
            self.outside_stride *= step;
        }
    }

    /// Adds another recording's samples; the outside ones are thinned to the coarser of
    /// the two strides, and further while over the cap. Appends in place: merging many
    /// recordings one by one costs what their values do.
    pub fn merge(&mut self, other: FeatureSamples) {
        for (mine, theirs) in self.inside.iter_mut().zip(other.inside) {
            for (m, t) in mine.iter_mut().zip(theirs) {
                m.extend(t);
            }
        }
        for (mine, theirs) in self.peaks.iter_mut().zip(other.peaks) {
            for (m, t) in mine.iter_mut().zip(theirs) {
                m.extend(t);
            }
        }
        let stride = self.outside_stride.max(other.outside_stride);
        self.thin_outside(stride / self.outside_stride);
        let their_step = stride / other.outside_stride;
        for (mine, theirs) in self.outside.iter_mut().zip(other.outside) {
            mine.extend(theirs.into_iter().step_by(their_step));
        }
        self.outside_seen += other.outside_seen;
        self.keep_within_cap();
    }

    /// Outside ticks seen, kept or not.
    pub fn outside_ticks(&self) -> usize {
        self.outside_seen
    }
}

/// Replays one recording and sorts its ticks' feature values: a labelled row within
/// `window_s` of its event's onset goes to that event, an unlabelled row more than
/// `after_s` past the last event's end goes outside. Returns the replay's outcome too (the
/// detector's decisions on the recording). Outside values are kept one tick in
/// `outside_stride` (a power of two) from the start: the ones a merge into samples at that
/// stride would keep, without holding the others meanwhile.
fn sample_recording(
    detector: &Detector,
    file: &Path,
    window_s: f64,
    after_s: f64,
    outside_stride: usize,
) -> Result<(FeatureSamples, Streamed), StreamError> {
    let mut samples = FeatureSamples::new(detector);
    samples.outside_stride = outside_stride.max(1);
    let mut values = vec![0.0; samples.features.len()];
    let reader = TraceReader::open(file)?;
    // The labelled occurrence whose peaks are being taken, by its index among the labelled.
    let mut occurrence = None;
    let streamed = replay_stream(detector, reader, |tick| {
        for (k, v) in values.iter_mut().enumerate() {
            *v = tick.state.feature(k).map_or(0.0, |x| x.to_f64());
        }
        match tick.labelled.last() {
            Some(event) if tick.in_event => {
                let index = samples.events.iter().position(|e| *e == event.event);
                if let Some(e) = index
                    && tick.t - event.onset_s <= window_s
                {
                    for (column, v) in samples.inside[e].iter_mut().zip(&values) {
                        column.push(*v);
                    }
                    let fresh =
                        occurrence.replace(tick.labelled.len()) != Some(tick.labelled.len());
                    for (column, &v) in samples.peaks[e].iter_mut().zip(&values) {
                        match column.last_mut() {
                            Some((low, high)) if !fresh => {
                                *low = low.min(v);
                                *high = high.max(v);
                            }
                            _ => column.push((v, v)),
                        }
                    }
                }
            }
            Some(event) if tick.t <= event.end_s + after_s => {}
            _ => samples.push_outside(&values),
        }
    })?;
    Ok((samples, streamed))
}

/// Samples every recording (its ticks sorted as this module says) into each of `sets`
/// sets of samples that `member(set, i)` says holds recording i of `files`, and returns
/// the sets with what `each` made of every recording's replay, in file order. Each set's
/// samples are exactly those of sampling its recordings one by one and merging them in
/// file order ([`FeatureSamples::merge`]), whatever the number of threads; an error is the
/// first failing file's.
///
/// The recordings are replayed in parallel a few at a time (each chunk waits for its
/// slowest), each keeping outside values at the finest stride of the sets it goes to so
/// far: the values those merges would keep, the others never held. So the outside values
/// held are bounded whatever the corpus's length (the cap for each set and each recording
/// in flight); the values inside events grow with the events labelled.
pub fn sample_sets<R: Send>(
    detector: &Detector,
    files: &[PathBuf],
    window_s: f64,
    after_s: f64,
    sets: usize,
    member: impl Fn(usize, usize) -> bool,
    each: impl Fn(&Path, &Streamed) -> R + Sync,
) -> Result<(Vec<FeatureSamples>, Vec<R>), StreamError> {
    let mut merged: Vec<FeatureSamples> =
        (0..sets).map(|_| FeatureSamples::new(detector)).collect();
    let mut results = Vec::with_capacity(files.len());
    let at_once = 2 * rayon::current_num_threads();
    for (c, chunk) in files.chunks(at_once).enumerate() {
        let first = c * at_once;
        // A set's stride only grows, so the stride now is at most the one at its merge.
        let strides: Vec<usize> = (first..first + chunk.len())
            .map(|i| {
                (0..sets)
                    .filter(|&set| member(set, i))
                    .map(|set| merged[set].outside_stride)
                    .min()
                    .unwrap_or(1)
            })
            .collect();
        let sampled: Vec<Result<(FeatureSamples, R), StreamError>> = chunk
            .par_iter()
            .zip(strides)
            .map(|(f, stride)| {
                let (samples, streamed) = sample_recording(detector, f, window_s, after_s, stride)?;
                Ok((samples, each(f, &streamed)))
            })
            .collect();
        for (i, one) in (first..).zip(sampled) {
            let (samples, result) = one?;
            for (set, into) in merged.iter_mut().enumerate() {
                if member(set, i) {
                    into.merge(samples.clone());
                }
            }
            results.push(result);
        }
    }
    Ok((merged, results))
}

/// How well one feature alone tells one event from the time outside events: the single
/// threshold that does it best.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Separation {
    /// The feature.
    pub feature: String,
    /// The event.
    pub event: String,
    /// Values in the event, and outside (kept ones).
    pub n_event: usize,
    /// Kept values outside events.
    pub n_outside: usize,
    /// The median in the event and outside.
    pub event_median: f64,
    /// The median outside events.
    pub outside_median: f64,
    /// The best threshold.
    pub threshold: f64,
    /// Whether the event lies above it (else below).
    pub above: bool,
    /// Balanced accuracy at that threshold, (true-positive rate + true-negative rate) / 2,
    /// in [0.5, 1]: 0.5 means the feature alone says nothing, 1 that it separates fully.
    pub balanced_accuracy: f64,
}

/// The median of sorted values (0 when empty).
fn median(sorted: &[f64]) -> f64 {
    match sorted.len() {
        0 => 0.0,
        n if n % 2 == 1 => sorted[n / 2],
        n => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
    }
}

/// The best single threshold between `event` and `outside` values (both sorted): every
/// value is tried as the boundary, in both directions.
pub fn best_threshold(event: &[f64], outside: &[f64]) -> (f64, bool, f64) {
    if event.is_empty() || outside.is_empty() {
        return (0.0, true, 0.5);
    }
    let (ne, no) = (event.len() as f64, outside.len() as f64);
    let mut best = (0.0, true, 0.5);
    // Walk the merged values: at each distinct value v, the fraction of each set that is
    // at or below v.
    let (mut i, mut j) = (0, 0);
    while i < event.len() || j < outside.len() {
        let v = match (event.get(i), outside.get(j)) {
            (Some(&a), Some(&b)) => a.min(b),
            (Some(&a), None) => a,
            (None, Some(&b)) => b,
            (None, None) => break,
        };
        while event.get(i).is_some_and(|&x| x <= v) {
            i += 1;
        }
        while outside.get(j).is_some_and(|&x| x <= v) {
            j += 1;
        }
        let (event_below, outside_below) = (i as f64 / ne, j as f64 / no);
        // Event above v: hits are the event's values above, correct rejections the
        // outside ones at or below.
        let above = ((1.0 - event_below) + outside_below) / 2.0;
        let below = (event_below + (1.0 - outside_below)) / 2.0;
        if above > best.2 {
            best = (v, true, above);
        }
        if below > best.2 {
            best = (v, false, below);
        }
    }
    best
}

/// Every (feature, event) pair with values in the event, feature by feature.
pub fn separations(samples: &FeatureSamples) -> Vec<Separation> {
    let sorted = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s
    };
    let outside: Vec<Vec<f64>> = samples.outside.iter().map(|v| sorted(v)).collect();
    let mut out = Vec::new();
    for (f, feature) in samples.features.iter().enumerate() {
        for (e, event) in samples.events.iter().enumerate() {
            let inside = sorted(&samples.inside[e][f]);
            if inside.is_empty() {
                continue;
            }
            let (threshold, above, balanced_accuracy) = best_threshold(&inside, &outside[f]);
            out.push(Separation {
                feature: feature.clone(),
                event: event.clone(),
                n_event: inside.len(),
                n_outside: outside[f].len(),
                event_median: median(&inside),
                outside_median: median(&outside[f]),
                threshold,
                above,
                balanced_accuracy,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_best_threshold_separates_what_can_be_separated() {
        // Fully apart, the event above.
        let (t, above, acc) = best_threshold(&[5.0, 6.0, 7.0], &[1.0, 2.0, 3.0]);
        assert_eq!((t, above, acc), (3.0, true, 1.0));
        // Fully apart, the event below.
        let (t, above, acc) = best_threshold(&[-3.0, -2.0], &[0.0, 1.0, 2.0]);
        assert_eq!((t, above, acc), (-2.0, false, 1.0));
        // The same values: nothing better than chance.
        let (_, _, acc) = best_threshold(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]);
        assert_eq!(acc, 0.5);
        // One outside value among the event's: 3 of 4 outside below 4.5, all event above.
        let (t, above, acc) = best_threshold(&[5.0, 6.0], &[1.0, 2.0, 3.0, 5.5]);
        assert_eq!((t, above), (3.0, true));
        assert!((acc - (1.0 + 0.75) / 2.0).abs() < 1e-12);
        assert_eq!(best_threshold(&[], &[1.0]).2, 0.5);
    }

    #[test]
    fn outside_values_thin_evenly_and_merge_at_the_coarser_stride() {
        let mut a = FeatureSamples {
            features: vec!["f".into()],
            outside: vec![Vec::new()],
            outside_stride: 1,
            ..FeatureSamples::default()
        };
        for k in 0..(2 * OUTSIDE_CAP + 10) {
            a.push_outside(&[k as f64]);
        }
        assert_eq!(a.outside_stride, 2);
        assert_eq!(a.outside_ticks(), 2 * OUTSIDE_CAP + 10);
        assert!(a.outside[0].iter().all(|v| (*v as usize).is_multiple_of(2)));
        assert_eq!(a.outside[0].len(), OUTSIDE_CAP + 5);
        let b = FeatureSamples {
            features: vec!["f".into()],
            outside: vec![vec![1.0, 2.0, 3.0, 4.0]],
            outside_stride: 1,
            outside_seen: 4,
            ..FeatureSamples::default()
        };
        a.merge(b);
        assert_eq!(a.outside_stride, 2);
        assert_eq!(a.outside[0].len(), OUTSIDE_CAP + 5 + 2);
        assert_eq!(a.outside[0][OUTSIDE_CAP + 5..], [1.0, 3.0]);
    }

    /// Many short recordings merged one by one stay within the cap, every value standing
    /// for the same number of ticks.
    #[test]
    fn merging_many_recordings_stays_within_the_cap() {
        let short = |start: usize| FeatureSamples {
            features: vec!["f".into()],
            outside: vec![(start..start + 1000).map(|k| k as f64).collect()],
            outside_stride: 1,
            outside_seen: 1000,
            ..FeatureSamples::default()
        };
        let mut all = short(0);
        let recordings = 5 * OUTSIDE_CAP / 1000;
        for r in 1..recordings {
            all.merge(short(r * 1000));
        }
        assert_eq!(all.outside_ticks(), recordings * 1000);
        assert!(all.outside[0].len() < 2 * OUTSIDE_CAP);
        assert_eq!(all.outside_stride, 4);
        assert!(all.outside[0].windows(2).all(|w| w[1] - w[0] == 4.0));
    }

    /// [`sample_sets`] gives, for every set, what sampling each of its recordings whole and
    /// merging them in file order gives, with one thread or several: on recordings long
    /// enough that the sets thin their outside values, in sets that overlap.
    #[test]
    fn sample_sets_merge_as_whole_recordings_in_file_order() {
        use crate::sim::{self, Scenario, SimOptions};
        let dir = std::env::temp_dir().join(format!("sample-sets-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch directory");
        let mut files = Vec::new();
        for (k, (scenario, duration_s)) in [
            (Scenario::FreeMotion, Some(70.0)),
            (Scenario::ContactHard8, None),
            (Scenario::FreeMotion, Some(40.0)),
            (Scenario::LinkCollision8, None),
            (Scenario::FreeMotion, Some(70.0)),
        ]
        .into_iter()
        .enumerate()
        {
            let opts = SimOptions {
                seed: 40 + k as u64,
                randomize: true,
                duration_s,
                ..SimOptions::default()
            };
            let path = dir.join(format!("{k}.csv"));
            sim::simulate(&scenario, &opts)
                .expect("simulates")
                .write(&path)
                .expect("writes");
            files.push(path);
        }
        let config = detector_build::Config::from_toml(crate::APPROACH_TOML).expect("parses");
        let detector = detector_build::build(&config).expect("builds");
        let (window_s, after_s) = (0.02, 0.1);
        // Two folds' training sets and the whole corpus.
        let member = |set: usize, i: usize| set == 2 || i % 2 != set;
        let expected: Vec<FeatureSamples> = (0..3)
            .map(|set| {
                let mut all = FeatureSamples::new(&detector);
                for (i, f) in files.iter().enumerate() {
                    if member(set, i) {
                        let (s, _) =
                            sample_recording(&detector, f, window_s, after_s, 1).expect("samples");
                        all.merge(s);
                    }
                }
                all
            })
            .collect();
        assert!(expected[2].outside_stride > 1, "the whole corpus thins");
        for threads in [1, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            let (sets, rows) = pool
                .install(|| {
                    sample_sets(&detector, &files, window_s, after_s, 3, member, |_, s| {
                        s.rows
                    })
                })
                .expect("samples");
            assert_eq!(rows.len(), files.len());
            for (got, want) in sets.iter().zip(&expected) {
                assert_eq!(got.outside_stride, want.outside_stride, "{threads} threads");
                assert_eq!(got.outside_ticks(), want.outside_ticks());
                assert_eq!(got.outside, want.outside);
                assert_eq!(got.inside, want.inside);
                assert_eq!(got.peaks, want.peaks);
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A recording sampled from the start at the stride of the samples it is merged into
    /// (as [`sample_sets`] does) merges into exactly what sampling it at stride 1 would:
    /// for a short recording, a longer one, and one long enough to thin itself further.
    #[test]
    fn sampling_at_the_sets_stride_merges_as_sampling_every_tick() {
        let recording = |stride: usize, ticks: usize| {
            let mut r = FeatureSamples {
                features: vec!["f".into()],
                outside: vec![Vec::new()],
                outside_stride: stride,
                ..FeatureSamples::default()
            };
            for k in 0..ticks {
                r.push_outside(&[k as f64]);
            }
            r
        };
        for ticks in [1001, 3 * OUTSIDE_CAP + 3, 9 * OUTSIDE_CAP + 3] {
            // A set of samples already at stride 4, from many short recordings.
            let mut set = recording(1, 1000);
            while set.outside_stride < 4 {
                set.merge(recording(1, 1000));
            }
            let mut every_tick = set.clone();
            every_tick.merge(recording(1, ticks));
            let mut at_stride = set.clone();
            let hinted = recording(set.outside_stride, ticks);
            // Fewer values held, except where the recording alone thins to the stride.
            let alone = recording(1, ticks);
            assert!(
                hinted.outside[0].len() < alone.outside[0].len()
                    || alone.outside_stride >= hinted.outside_stride
            );
            at_stride.merge(hinted);
            assert_eq!(at_stride.outside, every_tick.outside);
            assert_eq!(at_stride.outside_stride, every_tick.outside_stride);
            assert_eq!(at_stride.outside_ticks(), every_tick.outside_ticks());
        }
    }
}
