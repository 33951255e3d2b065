//! The default detector's contact paths, each for the evidence it was added for. A very
//! soft object at 1 cm/s on a film whose amplifier is AC-coupled: the film reads the
//! steady loading as a rate that dies away, and the contact is found on the force sensor
//! (the paper's "filtered force", `force_push_steady`). Without that path the film's
//! paths alone miss some of the same runs.

use detector_build::Config;
use detector_core::Detector;
use fingertip::score::classify;
use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::{APPROACH_TOML, replay};

/// The default's force-sensor contact term, as written in `configs/approach.toml`.
const FORCE_TERM: &str = "    { feature = \"force_push_steady\", weight = 1.0, cdf = { sigmoid = { low = 1.0, high = 2.5 } } },\n";

fn detector(toml: &str) -> Detector {
    detector_build::build(&Config::from_toml(toml).expect("parses")).expect("builds")
}

/// Which of the randomized very soft contacts on seeds `seeds`, with the film AC-coupled
/// at `film_highpass_hz`, `detector` gets right.
fn right(detector: &Detector, seeds: std::ops::Range<u64>, film_highpass_hz: f64) -> Vec<bool> {
    let s = Scenario::ContactVerySoft1;
    seeds
        .map(|seed| {
            let opts = SimOptions {
                seed,
                randomize: true,
                film_highpass_hz,
                ..SimOptions::default()
            };
            let tr = sim::simulate(&s, &opts).expect("simulates");
            let (on, _) = tr.truth_onset().expect("an event");
            let decisions = replay::replay(detector, &tr, |_, _, _| {}).expect("replays");
            classify(s.expected().map(|e| (e, tr.time()[on])), &decisions).is_right()
        })
        .collect()
}

#[test]
fn an_ac_coupled_film_leaves_very_soft_contacts_to_the_force_sensor() {
    assert!(
        APPROACH_TOML.contains(FORCE_TERM),
        "the default's force term"
    );
    let film_only = detector(&APPROACH_TOML.replacen(FORCE_TERM, "", 1));
    let default = detector(APPROACH_TOML);
    let seeds = 1..41;
    let with_force = right(&default, seeds.clone(), 2.0);
    let film_alone = right(&film_only, seeds.clone(), 2.0);
    assert!(
        with_force.iter().all(|&r| r),
        "the default misses very soft contacts on seeds {:?}",
        seeds
            .clone()
            .zip(&with_force)
            .filter(|(_, r)| !**r)
            .map(|(s, _)| s)
            .collect::<Vec<_>>()
    );
    let missed = film_alone.iter().filter(|&&r| !r).count();
    assert!(
        missed > 0,
        "the film's paths alone find all {} runs: the test no longer shows the force path's part",
        film_alone.len()
    );
    // On a film without coupling (the envelope's), the default finds them too.
    assert!(right(&default, seeds, 0.0).iter().all(|&r| r));
}
