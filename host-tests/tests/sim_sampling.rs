//! Sampling: the anti-alias filter before decimation, the detector rate as a parameter,
//! the channels' full scales, and bad options.

use fingertip::sim::{self, CHANNELS, ParamRange, Scenario, SimError, SimOptions};
use std::f64::consts::TAU;

fn tone(freq: f64, rate: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| (TAU * freq * i as f64 / rate).sin())
        .collect()
}

/// Peak of the second half (after the filter's transient).
fn settled_peak(x: &[f64]) -> f64 {
    x[x.len() / 2..].iter().fold(0.0, |m, v| m.max(v.abs()))
}

#[test]
fn anti_alias_decimation_attenuates_a_tone_above_nyquist() {
    let rate = 50_000.0;
    let n = 50_000;
    // 5 kHz out: Nyquist 2.5 kHz. A 3.5 kHz tone would alias to 1.5 kHz.
    let above = sim::decimate(&tone(3500.0, rate, n), rate, 10);
    assert_eq!(above.len(), 5000);
    let naive: Vec<f64> = tone(3500.0, rate, n).into_iter().step_by(10).collect();
    assert!(
        settled_peak(&naive) > 0.9,
        "without the filter the alias is full size"
    );
    assert!(
        settled_peak(&above) < 0.1,
        "alias: {}",
        settled_peak(&above)
    );
    // Further above, it is gone.
    let far = sim::decimate(&tone(7000.0, rate, n), rate, 10);
    assert!(settled_peak(&far) < 0.01, "{}", settled_peak(&far));
    // In band, the tone passes.
    let inside = sim::decimate(&tone(300.0, rate, n), rate, 10);
    assert!(
        (settled_peak(&inside) - 1.0).abs() < 0.02,
        "{}",
        settled_peak(&inside)
    );
}

#[test]
fn detector_rate_is_a_parameter() {
    for rate in [1000.0, 2000.0, 5000.0, 8000.0] {
        let tr = sim::simulate(
            &Scenario::ContactHard5,
            &SimOptions {
                rate_hz: rate,
                ..SimOptions::default()
            },
        )
        .unwrap();
        assert!((tr.rate_hz() - rate).abs() < 1e-6 * rate, "{rate}");
        assert_eq!(tr.len(), (0.150 * rate).round() as usize + 1);
        let (row, _) = tr.truth_onset().unwrap();
        assert!((tr.time()[row] - 0.020).abs() <= 1.0 / rate + 1e-6);
        // The internal rate resolves the stiffest mode (0.35 rad of its phase per step at
        // most), is a multiple of the detector rate, and at least twice it.
        let internal: f64 = tr.meta("internal_rate_hz").unwrap().parse().unwrap();
        let stiffest: f64 = tr.meta("stiffest_mode_hz").unwrap().parse().unwrap();
        assert!(
            stiffest > 1000.0,
            "a hard contact's skin mode: {stiffest} Hz"
        );
        assert!(
            internal >= std::f64::consts::TAU * stiffest / 0.35,
            "{internal}"
        );
        assert!(internal >= sim::MIN_INTERNAL_RATE_HZ && internal >= 2.0 * rate);
        assert_eq!((internal / rate).fract(), 0.0);
    }
}

#[test]
fn analog_channels_are_12_bit_within_full_scale() {
    let tr = sim::simulate(
        &Scenario::ContactHard8,
        &SimOptions {
            seed: 3,
            randomize: true,
            ..SimOptions::default()
        },
    )
    .unwrap();
    assert_eq!(
        tr.channel_names(),
        CHANNELS.iter().map(|c| c.name).collect::<Vec<_>>()
    );
    for c in CHANNELS.iter() {
        let Some(adc) = c.adc else { continue };
        let lsb = 2.0 * adc.full_scale / 4096.0;
        for &v in tr.column(c.name).unwrap() {
            let code = v / lsb;
            assert!((code - code.round()).abs() < 1e-9, "{}: {v}", c.name);
            assert!(
                (-2048.0..=2047.0).contains(&code.round()),
                "{}: {v}",
                c.name
            );
        }
        assert_eq!(
            tr.meta(&format!("full_scale.{}", c.name)),
            Some(adc.full_scale.to_string().as_str())
        );
    }
}

#[test]
fn bad_options_are_errors_not_panics() {
    let bad = [
        SimOptions {
            rate_hz: 0.0,
            ..SimOptions::default()
        },
        SimOptions {
            rate_hz: f64::NAN,
            ..SimOptions::default()
        },
        SimOptions {
            rate_hz: 1e9,
            ..SimOptions::default()
        },
        SimOptions {
            controller_rate_hz: -1.0,
            ..SimOptions::default()
        },
        SimOptions {
            controller_rate_hz: 250.0,
            ..SimOptions::default()
        },
        SimOptions {
            duration_s: Some(-1.0),
            ..SimOptions::default()
        },
        SimOptions {
            duration_s: Some(f64::INFINITY),
            ..SimOptions::default()
        },
        SimOptions {
            duration_s: Some(1e6),
            ..SimOptions::default()
        },
        SimOptions {
            lead_in_s: -0.001,
            ..SimOptions::default()
        },
        SimOptions {
            lead_in_s: 11.0,
            ..SimOptions::default()
        },
        SimOptions {
            lead_in_s: f64::NAN,
            ..SimOptions::default()
        },
        SimOptions {
            noise_factor: -0.5,
            ..SimOptions::default()
        },
        SimOptions {
            noise_factor: 11.0,
            ..SimOptions::default()
        },
        SimOptions {
            noise_factor: f64::INFINITY,
            ..SimOptions::default()
        },
        SimOptions {
            encoder_resolution_um: 0.0,
            ..SimOptions::default()
        },
        SimOptions {
            encoder_resolution_um: 200.0,
            ..SimOptions::default()
        },
        SimOptions {
            encoder_resolution_um: f64::NAN,
            ..SimOptions::default()
        },
        SimOptions {
            film_highpass_hz: -1.0,
            ..SimOptions::default()
        },
        SimOptions {
            film_highpass_hz: 11.0,
            ..SimOptions::default()
        },
        SimOptions {
            film_highpass_hz: f64::NAN,
            ..SimOptions::default()
        },
        SimOptions {
            velocity_filter_hz: -1.0,
            ..SimOptions::default()
        },
        SimOptions {
            velocity_filter_hz: 2001.0,
            ..SimOptions::default()
        },
        SimOptions {
            velocity_filter_hz: f64::NAN,
            ..SimOptions::default()
        },
    ];
    for o in bad {
        let e = sim::simulate(&Scenario::ContactHard8, &o).unwrap_err();
        assert!(matches!(e, SimError::BadOption { .. }), "{e}");
        assert!(!e.to_string().contains('\n'));
    }
}

#[test]
fn duration_option_sets_the_length() {
    let tr = sim::simulate(
        &Scenario::FreeMotion,
        &SimOptions {
            duration_s: Some(0.5),
            ..SimOptions::default()
        },
    )
    .unwrap();
    assert_eq!(tr.len(), 2501);
    // A run cut before its event has no truth onset.
    let tr = sim::simulate(
        &Scenario::ContactHard8,
        &SimOptions {
            duration_s: Some(0.01),
            ..SimOptions::default()
        },
    )
    .unwrap();
    assert!(tr.truth_onset().is_none());
}

/// A range that cannot be drawn from is refused with the reason, before any work: an
/// unknown parameter, bounds out of order or not finite, a sign the parameter cannot take,
/// bounds beyond ten times the envelope's (or a reach of its own, for a parameter the
/// envelope does not draw), or a range on a run that draws nothing.
#[test]
fn bad_ranges_are_errors_not_panics() {
    let range = |name: &str, min: f64, max: f64| ParamRange {
        name: name.to_string(),
        min,
        max,
    };
    for (r, randomize, reason) in [
        (
            range("plant.bogus", 1.0, 2.0),
            true,
            "not a simulator parameter",
        ),
        (
            range("arm_mass", 0.3, 0.4),
            true,
            "not a simulator parameter",
        ),
        (range("plant.arm_mass", 0.4, 0.3), true, "min <= max"),
        (range("plant.arm_mass", f64::NAN, 0.3), true, "finite"),
        (range("plant.arm_mass", 0.0, 0.3), true, "above 0"),
        (range("plant.drive_ripple", -0.01, 0.05), true, "0 or more"),
        (range("plant.pad_angle", -0.1, 0.5), true, "above 0"),
        (range("plant.arm_mass", 0.3, 5.1), true, "within +-5"),
        (
            range("plant.drive_bump", 0.0, 2e-4),
            true,
            "within +-0.0001",
        ),
        (
            range("plant.feedforward_error", -1.6, 0.0),
            true,
            "within +-1.5",
        ),
        (range("plant.arm_mass", 0.3, 0.4), false, "draws none"),
    ] {
        let opts = SimOptions {
            randomize,
            ranges: vec![r.clone()],
            ..SimOptions::default()
        };
        let e = sim::simulate(&Scenario::ContactHard8, &opts).unwrap_err();
        assert!(matches!(e, SimError::BadRange(_)), "{r}: {e}");
        let text = e.to_string();
        assert!(text.contains(reason), "{r}: {text}");
        assert!(!text.contains('\n'));
    }
}

/// A range replaces the envelope's for the parameter it names, every other draw staying as
/// it was, and the trace records it; a free-motion parameter's range reaches its
/// trajectory.
#[test]
fn ranges_replace_the_envelope() {
    let run = |scenario: Scenario, ranges: Vec<ParamRange>| {
        sim::simulate(
            &scenario,
            &SimOptions {
                seed: 7,
                randomize: true,
                duration_s: (scenario == Scenario::FreeMotion).then_some(2.0),
                ranges,
                ..SimOptions::default()
            },
        )
        .expect("simulate")
    };
    let value = |t: &fingertip::trace::Trace, name: &str| -> f64 {
        t.meta(&format!("param.{name}"))
            .expect("recorded")
            .parse()
            .expect("a number")
    };
    let envelope = run(Scenario::LinkCollision8, vec![]);
    let slow = run(
        Scenario::LinkCollision8,
        vec![ParamRange {
            name: "plant.control_bandwidth".into(),
            min: 5.0,
            max: 6.0,
        }],
    );
    let bw = value(&slow, "plant.control_bandwidth");
    assert!((5.0..=6.0).contains(&bw), "{bw}");
    assert!(value(&envelope, "plant.control_bandwidth") >= 10.0);
    assert_eq!(slow.meta("range.plant.control_bandwidth"), Some("5..6"));
    assert_eq!(envelope.meta("range.plant.control_bandwidth"), None);
    // The other parameters are drawn as before.
    for name in [
        "plant.arm_mass",
        "plant.control_damping_ratio",
        "obstacle.stiffness",
    ] {
        assert_eq!(value(&slow, name), value(&envelope, name), "{name}");
    }
    // Pinned to one value, a free-motion stretch cruises no faster than it.
    let pinned = run(
        Scenario::FreeMotion,
        vec![
            ParamRange {
                name: "free_motion.cruise_speed".into(),
                min: 0.01,
                max: 0.01,
            },
            ParamRange {
                name: "free_motion.speed".into(),
                min: 0.01,
                max: 0.01,
            },
        ],
    );
    let vx = pinned.column("vel_des_x").expect("vel_des_x");
    let vy = pinned.column("vel_des_y").expect("vel_des_y");
    let fastest = vx
        .iter()
        .zip(vy)
        .map(|(x, y)| x.hypot(*y))
        .fold(0.0, f64::max);
    assert!(fastest > 0.005 && fastest < 0.0101, "{fastest}");
}

/// Every parameter drawn at the ends of what a range may reach (from a tenth of its
/// envelope's lower bound, or 0, up to it; from its upper bound to ten times it, or to
/// its reach where the envelope does not draw it) gives a trace whose channels are
/// finite: no panic, no NaN.
#[test]
fn every_parameter_at_the_ends_of_its_reach_runs() {
    for p in sim::params::all_specs() {
        let name = format!("{}.{}", p.group, p.name);
        let scenario = match p.group {
            "soft_object" => Scenario::ContactSoft5,
            "braking" => Scenario::ContactBraking,
            "very_soft_object" => Scenario::ContactVerySoft1,
            "movable_object" => Scenario::ObjectMoves5,
            "obstacle" => Scenario::LinkCollision8,
            "large_disturbance" => Scenario::DisturbanceLarge5,
            "small_disturbance" => Scenario::DisturbanceSmall5,
            "knock" => Scenario::KnockLink1,
            "sudden_accel" => Scenario::SuddenAccelMoving5,
            "free_motion" => Scenario::FreeMotion,
            _ => Scenario::ContactHard5,
        };
        let reach = p.reach();
        let low = if p.min > 0.0 {
            p.min / sim::params::RANGE_REACH
        } else if p.min >= 0.0 || p.draw == sim::params::Draw::EitherSign {
            0.0
        } else {
            -reach
        };
        for (min, max) in [(low, p.min), (p.max, reach)] {
            let r = ParamRange {
                name: name.clone(),
                min,
                max,
            };
            let t = sim::simulate(
                &scenario,
                &SimOptions {
                    seed: 3,
                    randomize: true,
                    duration_s: (scenario == Scenario::FreeMotion).then_some(1.0),
                    ranges: vec![r.clone()],
                    ..SimOptions::default()
                },
            )
            .unwrap_or_else(|e| panic!("{r}: {e}"));
            for c in CHANNELS {
                let col = t.column(c.name).expect("channel");
                assert!(col.iter().all(|v| v.is_finite()), "{r}: {}", c.name);
            }
        }
    }
}
