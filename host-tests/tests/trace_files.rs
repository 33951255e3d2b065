//! Trace files on disk: simulated traces round-trip, recorded data with other channels
//! loads, and bad files give one clear line.

use fingertip::sim::{self, Scenario, SimOptions};
use fingertip::trace::Trace;
use std::path::PathBuf;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("trace-files-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temporary directory");
    d
}

#[test]
fn simulated_trace_round_trips_through_a_file() {
    let dir = temp_dir("rt");
    for s in [Scenario::ContactSoft2, Scenario::DisturbanceLarge5] {
        let tr = sim::simulate(
            &s,
            &SimOptions {
                seed: 11,
                randomize: true,
                ..SimOptions::default()
            },
        )
        .unwrap();
        let path = dir.join(format!("{s}.csv"));
        tr.write(&path).unwrap();
        let mut back = Trace::read(&path).unwrap();
        assert_eq!(back.name(), path.display().to_string());
        back.set_name(tr.name());
        assert_eq!(back, tr, "{s}");
        assert_eq!(back.truth_onset(), tr.truth_onset());
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn recorded_data_with_other_channels_loads() {
    // A user's recording: metadata, other channel names, no phase or truth, time not
    // starting at zero, Windows line ends.
    let text = "# recorded: 2026-11-20 bench 3\r\n\
                # units: mV\r\n\
                t,strain_a,strain_b,mic\r\n\
                12.0000,0.1,0.2,-5\r\n\
                12.0010,0.1,0.25,-4\r\n\
                12.0020,0.15,0.2,-6\r\n";
    let tr = Trace::parse(text, "bench3.csv").unwrap();
    assert!((tr.rate_hz() - 1000.0).abs() < 1e-6);
    assert_eq!(tr.channel_names(), ["strain_a", "strain_b", "mic"]);
    assert_eq!(tr.meta("recorded"), Some("2026-11-20 bench 3"));
    assert!(tr.phase().is_none() && tr.truth_onset().is_none());
}

#[test]
fn bad_file_names_file_line_and_column() {
    let dir = temp_dir("bad");
    let path = dir.join("bad.csv");
    std::fs::write(&path, "# meta: 1\nt,force_x\n0,1\n0.0002,x1\n").unwrap();
    let e = Trace::read(&path).unwrap_err().to_string();
    assert_eq!(
        e,
        format!(
            "{}: line 4, column 2 `force_x`: `x1` is not a number",
            path.display()
        )
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

mod never_panics {
    use fingertip::trace::Trace;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn on_arbitrary_text(text in "\\PC*") {
            let _ = Trace::parse(&text, "fuzz.csv");
        }

        #[test]
        fn on_csv_like_text(
            lines in proptest::collection::vec(
                "(#.*|t|[a-z_]{0,4}|[-+0-9.eE]{0,6}|NaN|inf|,| )*",
                0..8,
            )
        ) {
            let text = lines.join("\n");
            if let Err(e) = Trace::parse(&text, "fuzz.csv") {
                let m = e.to_string();
                prop_assert!(!m.contains('\n'));
                prop_assert!(m.starts_with("fuzz.csv"));
            }
        }
    }
}
