//! Sampling: the anti-alias filter before decimation, the detector rate as a parameter,
//! the channels' full scales, and bad options.

use fingertip::sim::{self, CHANNELS, Scenario, SimError, SimOptions};
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
