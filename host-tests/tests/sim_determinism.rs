//! Every run is seeded: the same scenario, options and seed give an identical trace.

use fingertip::sim::{self, Scenario, SimOptions};

fn opts(seed: u64, randomize: bool) -> SimOptions {
    SimOptions {
        seed,
        randomize,
        ..SimOptions::default()
    }
}

#[test]
fn same_seed_same_trace() {
    for s in Scenario::single_event() {
        for randomize in [false, true] {
            let a = sim::simulate(s, &opts(42, randomize)).unwrap();
            let b = sim::simulate(s, &opts(42, randomize)).unwrap();
            assert_eq!(a, b, "{s}");
            assert_eq!(a.to_csv(), b.to_csv(), "{s}");
        }
    }
    let free = SimOptions {
        duration_s: Some(2.0),
        ..opts(9, true)
    };
    let a = sim::simulate(&Scenario::FreeMotion, &free).unwrap();
    let b = sim::simulate(&Scenario::FreeMotion, &free).unwrap();
    assert_eq!(a, b);
}

#[test]
fn other_seed_other_trace() {
    for s in Scenario::all() {
        let a = sim::simulate(s, &opts(1, true)).unwrap();
        let b = sim::simulate(s, &opts(2, true)).unwrap();
        assert_ne!(a.column("force_x"), b.column("force_x"), "{s}");
    }
    // Nominal runs share their physics; only the noise differs.
    let a = sim::simulate(&Scenario::ContactHard8, &opts(1, false)).unwrap();
    let b = sim::simulate(&Scenario::ContactHard8, &opts(2, false)).unwrap();
    assert_ne!(a.column("skin_accel"), b.column("skin_accel"));
    assert_eq!(a.meta(sim::META_ONSET), b.meta(sim::META_ONSET));
    assert_eq!(a.column("vel_des_x"), b.column("vel_des_x"));
}

#[test]
fn randomized_runs_draw_parameters_nominal_runs_do_not() {
    let param = |seed, randomize, key: &str| {
        sim::simulate(&Scenario::ContactSoft5, &opts(seed, randomize))
            .unwrap()
            .meta(key)
            .unwrap()
            .to_string()
    };
    let key = "param.soft_object.stiffness";
    assert_eq!(param(1, false, key), "2000");
    assert_eq!(param(2, false, key), "2000");
    assert_ne!(param(1, true, key), param(2, true, key));
    assert_ne!(param(1, true, "param.plant.skin_mass"), "0.002");
}

#[test]
fn equal_seeds_of_different_scenarios_are_independent() {
    let a = sim::simulate(&Scenario::ContactHard5, &opts(5, true)).unwrap();
    let b = sim::simulate(&Scenario::ContactSoft5, &opts(5, true)).unwrap();
    assert_ne!(
        a.meta("param.plant.foam_stiffness"),
        b.meta("param.plant.foam_stiffness")
    );
}

#[test]
fn scenario_names_and_expected_events() {
    assert_eq!(Scenario::all().len(), 20);
    assert_eq!(Scenario::table1().len(), 13);
    assert_eq!(Scenario::single_event().len(), 19);
    assert!(!Scenario::single_event().contains(&Scenario::FreeMotion));
    let expected = [
        ("contact_hard_8", Some("contact")),
        ("contact_hard_5", Some("contact")),
        ("contact_hard_2", Some("contact")),
        ("contact_soft_8", Some("contact")),
        ("contact_soft_5", Some("contact")),
        ("contact_soft_2", Some("contact")),
        ("object_moves_5", Some("contact")),
        ("link_collision_8", Some("link_collision")),
        ("link_collision_2", Some("link_collision")),
        ("disturbance_large_5", Some("disturbance")),
        ("disturbance_small_5", Some("disturbance")),
        ("sudden_accel_standstill", None),
        ("sudden_accel_moving_5", None),
        ("contact_braking", Some("contact")),
        ("contact_very_soft_1", Some("contact")),
        ("disturbance_slow_2", Some("disturbance")),
        ("knock_link1", Some("disturbance")),
        ("knock_link2", Some("disturbance")),
        ("knock_pad", Some("disturbance")),
        ("free_motion", None),
    ];
    for (s, (name, event)) in Scenario::all().iter().zip(expected) {
        assert_eq!(s.name(), name);
        assert_eq!(s.expected(), event, "{name}");
        assert_eq!(Scenario::from_name(name), Some(*s));
        assert_eq!(name.parse::<Scenario>().unwrap(), *s);
        assert_eq!(s.to_string(), name);
        let tr = sim::simulate(
            s,
            &SimOptions {
                duration_s: Some(0.2),
                ..opts(0, false)
            },
        )
        .unwrap();
        assert_eq!(tr.meta(sim::META_SCENARIO), Some(name));
        assert_eq!(tr.meta(sim::META_EXPECTED), Some(event.unwrap_or("none")));
    }
    let e = "contact_hard_9"
        .parse::<Scenario>()
        .unwrap_err()
        .to_string();
    assert!(e.contains("contact_hard_9"), "{e}");
    for s in Scenario::all() {
        assert!(e.contains(s.name()), "{e} does not list {s}");
    }
}

/// Every randomized run of every single-event scenario falls in a bin of its scenario's
/// binning, every bin gets runs, and the bin holds the run's own parameter.
#[test]
fn every_run_falls_in_a_bin_of_what_matters_most() {
    use fingertip::sim::Split;
    for s in Scenario::single_event() {
        let binning = s.binning().expect("single-event scenarios are binned");
        let labels = binning.labels();
        let mut seen = vec![0usize; labels.len()];
        for seed in 0..60 {
            let tr = sim::simulate(s, &opts(seed, true)).unwrap();
            let bin = s
                .run_bin(&tr)
                .unwrap_or_else(|| panic!("{s} seed {seed}: no bin"));
            seen[bin.bin] += 1;
            assert!(bin.value.is_finite() && bin.value > 0.0, "{s}: {bin:?}");
            if let Split::Edges(edges) = binning.split {
                // Inside the edges, in its own range; beyond them, in the outer bin.
                let (lo, hi) = (edges[bin.bin], edges[bin.bin + 1]);
                let last = edges.len() - 2;
                let placed = (lo..=hi).contains(&bin.value)
                    || (bin.bin == 0 && bin.value < lo)
                    || (bin.bin == last && bin.value > hi);
                assert!(placed, "{s}: {} in {}", bin.value, labels[bin.bin]);
            }
        }
        assert!(seen.iter().all(|&n| n > 0), "{s}: {labels:?} got {seen:?}");
    }
    assert!(Scenario::FreeMotion.binning().is_none());
}

/// A lead-in delays a run's event by exactly that much with the same drawn parameters, the
/// motion running all along and the trace recording it; free motion, which has no event,
/// is the same run with or without one.
#[test]
fn a_lead_in_delays_the_event_and_nothing_else() {
    let lead_in = 0.25;
    for s in [
        Scenario::ContactVerySoft1,
        Scenario::DisturbanceSlow2,
        Scenario::LinkCollision8,
        Scenario::SuddenAccelMoving5,
    ] {
        let cold = sim::simulate(&s, &opts(5, true)).unwrap();
        let led = sim::simulate(
            &s,
            &SimOptions {
                lead_in_s: lead_in,
                ..opts(5, true)
            },
        )
        .unwrap();
        let num = |t: &fingertip::trace::Trace, key: &str| -> f64 {
            t.meta(key).unwrap().parse().unwrap()
        };
        assert_eq!(
            cold.meta("param.motion.onset"),
            led.meta("param.motion.onset"),
            "{s}"
        );
        assert_eq!(cold.meta("lead_in_s"), None, "{s}");
        assert_eq!(num(&led, "lead_in_s"), lead_in, "{s}");
        let longer = led.len() as f64 - cold.len() as f64 - lead_in * 5000.0;
        assert!(
            longer.abs() <= 1.0,
            "{s}: {longer} rows more than the lead-in"
        );
        // When the event is due (a sudden acceleration's: when its command steps).
        let scheduled = |t: &fingertip::trace::Trace| {
            let key = ["scheduled_onset_s", "command_onset_s"]
                .into_iter()
                .find(|k| t.meta(k).is_some())
                .unwrap();
            num(t, key)
        };
        assert!(
            (scheduled(&led) - scheduled(&cold) - lead_in).abs() < 2e-3,
            "{s}: scheduled {} then {}",
            scheduled(&cold),
            scheduled(&led)
        );
        // The physical onset within 2 ms of it: where the arm is then, behind its command by
        // a following error that its noise moves by some µm, is all that differs.
        if s.expected().is_some() {
            let (cold_row, _) = cold.truth_onset().unwrap();
            let (led_row, _) = led.truth_onset().unwrap();
            let shift = led_row as f64 - cold_row as f64 - lead_in * 5000.0;
            assert!(
                shift.abs() <= 10.0,
                "{s}: the event moved by {shift} rows more"
            );
        }
        // The finger cruises through the lead-in as it did before its event.
        assert_eq!(
            cold.column("vel_des_x").unwrap()[0],
            led.column("vel_des_x").unwrap()[0]
        );
    }
    let free = |lead_in_s| {
        sim::simulate(
            &Scenario::FreeMotion,
            &SimOptions {
                duration_s: Some(1.0),
                lead_in_s,
                ..opts(3, true)
            },
        )
        .unwrap()
    };
    assert_eq!(free(0.0), free(lead_in));
}

/// A noise factor scales the sensors' white noise and nothing else: the same drawn plant,
/// the same motion and event, the force sensor's noise about that many times larger around
/// the same reading, and the trace recording it.
#[test]
fn a_noise_factor_scales_the_noise_and_nothing_else() {
    let run = |noise_factor| {
        sim::simulate(
            &Scenario::ContactSoft5,
            &SimOptions {
                noise_factor,
                ..opts(8, true)
            },
        )
        .unwrap()
    };
    let (base, loud, silent) = (run(1.0), run(3.0), run(0.0));
    assert_eq!(base.meta("noise_factor"), None);
    assert_eq!(loud.meta("noise_factor"), Some("3"));
    assert_eq!(base.meta("onset_s"), loud.meta("onset_s"));
    assert_eq!(
        base.meta("param.plant.skin_mass"),
        loud.meta("param.plant.skin_mass")
    );
    let scale = |t: &fingertip::trace::Trace| -> f64 {
        t.meta("param.sensors.noise_scale")
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!((scale(&loud) / scale(&base) - 3.0).abs() < 1e-9);
    assert_eq!(scale(&silent), 0.0);
    assert_eq!(base.column("vel_des_x"), loud.column("vel_des_x"));
    // Before the contact, the force sensor reads the same motion: the readings' spread
    // around the noise-free run's grows with the factor.
    let (on, _) = base.truth_onset().unwrap();
    let spread = |t: &fingertip::trace::Trace| {
        let (x, clean) = (
            t.column("force_x").unwrap(),
            silent.column("force_x").unwrap(),
        );
        let sq: f64 = (0..on).map(|k| (x[k] - clean[k]).powi(2)).sum();
        (sq / on as f64).sqrt()
    };
    let ratio = spread(&loud) / spread(&base);
    assert!((2.5..3.5).contains(&ratio), "noise grew {ratio} times");
}

/// An encoder resolution is what the controller reads the tip's position in: while the
/// finger cruises, each context message's position error moves by the commanded travel
/// less a whole number of encoder steps, 20 µm ones when asked for; the default is the
/// envelope's 1 µm run, unrecorded, and the trace records another.
#[test]
fn an_encoder_resolution_quantizes_what_the_controller_reads() {
    let run = |encoder_resolution_um| {
        sim::simulate(
            &Scenario::ContactHard8,
            &SimOptions {
                encoder_resolution_um,
                ..opts(4, false)
            },
        )
        .unwrap()
    };
    let (fine, coarse) = (run(1.0), run(20.0));
    assert_eq!(
        fine,
        sim::simulate(&Scenario::ContactHard8, &opts(4, false)).unwrap()
    );
    assert_eq!(fine.meta("encoder_resolution_um"), None);
    assert_eq!(coarse.meta("encoder_resolution_um"), Some("20"));
    // Steps of the controller's reading over one context period (5 rows at 5 kHz), in
    // 20 µm steps, before the contact.
    let steps = |t: &fingertip::trace::Trace| -> Vec<f64> {
        let (e, v) = (
            t.column("pos_err_x").unwrap(),
            t.column("vel_des_x").unwrap(),
        );
        let (on, _) = t.truth_onset().unwrap();
        (20..on - 5)
            .map(|k| (v[k] * 1e-3 - (e[k + 5] - e[k])) / 20e-6)
            .collect()
    };
    let off_grid = |s: &[f64]| s.iter().map(|x| (x - x.round()).abs()).fold(0.0, f64::max);
    assert!(off_grid(&steps(&coarse)) < 1e-3, "{:?}", steps(&coarse));
    assert!(off_grid(&steps(&fine)) > 0.02, "{:?}", steps(&fine));
}

/// An AC-coupled film reads a steady rate of loading as one that dies away: on the nominal
/// very soft contact (the film loaded at a steady rate for as long as the finger presses
/// on), the film's reading above what it read before the contact holds without the
/// coupling and has all but died 200 ms on with a corner of 2 Hz (1 / (2 pi f) = 80 ms),
/// where the other channels read exactly what they read without it; the trace records
/// the corner.
#[test]
fn an_ac_coupled_film_reads_a_steady_load_as_a_dying_rate() {
    let run = |film_highpass_hz| {
        sim::simulate(
            &Scenario::ContactVerySoft1,
            &SimOptions {
                film_highpass_hz,
                duration_s: Some(0.3),
                ..opts(7, false)
            },
        )
        .unwrap()
    };
    let (dc, ac) = (run(0.0), run(2.0));
    assert_eq!(dc.meta("film_highpass_hz"), None);
    assert_eq!(ac.meta("film_highpass_hz"), Some("2"));
    for channel in ["force_x", "force_y", "skin_accel", "pos_err_x", "vel_des_x"] {
        assert_eq!(dc.column(channel), ac.column(channel), "{channel}");
    }
    let onset: f64 = dc.meta("onset_s").unwrap().parse().unwrap();
    let rate = dc.rate_hz();
    let row = |t: f64| (t * rate).round() as usize;
    // The film's mean over 40 ms (two periods of mains hum) from `from` s after the onset,
    // above its mean before the onset.
    let rise = |t: &fingertip::trace::Trace, from: f64| {
        let film = t.column("stress_rate").unwrap();
        let mean = |a: usize, b: usize| film[a..b].iter().sum::<f64>() / (b - a) as f64;
        mean(row(onset + from), row(onset + from + 0.04)) - mean(0, row(onset))
    };
    let (dc_early, dc_late) = (rise(&dc, 0.01), rise(&dc, 0.2));
    let (ac_early, ac_late) = (rise(&ac, 0.01), rise(&ac, 0.2));
    assert!(
        dc_early > 0.3 && dc_late > 0.7 * dc_early,
        "{dc_early} {dc_late}"
    );
    assert!(
        ac_early > 0.3 && ac_late < 0.3 * ac_early,
        "{ac_early} {ac_late}"
    );
}
