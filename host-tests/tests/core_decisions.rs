//! Decisions against their documentation (`LevelSpec`, `EventSpec::onset_level`,
//! `Decision`, `Output`, `Detector::set_phase`): hysteresis, dwell, back-dated onset, phase
//! switches, faults. Every scripted run is checked on the engine and on the `f64` model.
//!
//! The detector runs at 1000 Hz, so a tick is 1 ms. Confidences come from raw features
//! through a sigmoid from 0 to 1, S(t): x = 0 → 0, 0.25 → ⅛, 0.4 → 0.32, 0.5 → ½,
//! 0.75 → ⅞, 1 → 1.

#[path = "reference_support.rs"]
mod support;

use detector_build::{Config, EventSpec};
use detector_core::{Level, Output, StageSpec};
use host_tests::reference::{Model, ModelOutput};
use support::*;

/// One tick of a script: samples of `x y k`, faulty channels, a phase to switch to first.
#[derive(Clone, Copy, Debug, Default)]
struct Tick {
    x: f64,
    y: f64,
    k: f64,
    faults: u32,
    switch: Option<u8>,
}

fn at(x: f64) -> Tick {
    Tick {
        x,
        k: 1.0,
        ..Tick::default()
    }
}

/// Event `e` on channels `x y k`: sensor `fx` (weight `wx`), optionally sensor `fy` (weight
/// `1 − wx`), optionally a context term on `fk`; phases `p0 = {e}`, `p1 = {e}`, `p2 = {}`.
fn detector_config(wx: f32, with_y: bool, with_k: bool, tweak: impl Fn(&mut EventSpec)) -> Config {
    let s = sigmoid(0.0, 1.0);
    let mut sensors = vec![sensor("fx", wx, s)];
    if with_y {
        sensors.push(sensor("fy", 1.0 - wx, s));
    }
    let ctx = if with_k {
        vec![context("fk", s)]
    } else {
        vec![]
    };
    let mut e = event("e", ctx, sensors);
    tweak(&mut e);
    config(
        1000.0,
        &["x", "y", "k"],
        vec![("fx", raw("x")), ("fy", raw("y")), ("fk", raw("k"))],
        vec![e],
        vec![phase("p0", &["e"]), phase("p1", &["e"]), phase("p2", &[])],
    )
}

/// A decision as (tick, level, onset).
type Raised = (u32, Level, u32);

/// Runs a script on the engine and the model; returns the engine's outputs after checking
/// that the model raised the same levels and reports the same sets.
fn run(config: &Config, script: &[Tick]) -> Vec<Output> {
    let det = detector_build::build(config).expect("valid");
    let model = Model::new(config).expect("resolves");
    let mut st = det.new_state();
    let mut ms = model.new_state();
    let mut outs = Vec::new();
    for (t, s) in script.iter().enumerate() {
        if let Some(p) = s.switch {
            det.set_phase(&mut st, det.phase_at(p).expect("phase"));
            model.set_phase(&mut ms, usize::from(p));
        }
        let now = t as u32;
        let o = det.tick(&mut st, now, &inputs_f64(&[s.x, s.y, s.k], s.faults));
        let m: ModelOutput = model.tick(&mut ms, now, &[s.x, s.y, s.k], s.faults);
        let engine: Vec<Raised> = o
            .decisions
            .iter()
            .map(|d| (d.tick, d.level, d.onset))
            .collect();
        let reference: Vec<Raised> = m
            .decided
            .decisions
            .iter()
            .map(|d| (d.tick, d.level, d.onset))
            .collect();
        assert_eq!(engine, reference, "model disagrees at tick {t}");
        assert_eq!(o.alerting, m.decided.alerting, "alerting at tick {t}");
        assert_eq!(o.confirmed, m.decided.confirmed, "confirmed at tick {t}");
        assert_eq!(o.unjudgeable, m.judgement.unjudgeable, "unjudgeable at {t}");
        assert_eq!(o.degraded, m.judgement.degraded, "degraded at tick {t}");
        for d in &o.decisions {
            assert_eq!(d.confidence, o.confidences[0], "decision confidence at {t}");
            assert_eq!(d.tick, now);
        }
        outs.push(o);
    }
    outs
}

/// Every decision of a run as (tick, level, onset).
fn raised(outs: &[Output]) -> Vec<Raised> {
    outs.iter()
        .flat_map(|o| o.decisions.iter().map(|d| (d.tick, d.level, d.onset)))
        .collect()
}

fn alerting(outs: &[Output]) -> Vec<bool> {
    outs.iter().map(|o| o.alerting & 1 != 0).collect()
}

/// Alert on ½ / off ¼: raised at the first tick at or above ½, kept while the confidence
/// stays at or above ¼ (0.32 keeps it), lowered below ¼ (⅛), raised again at ½.
#[test]
fn hysteresis() {
    let c = detector_config(1.0, false, false, |e| {
        e.alert = level(0.5, 0.25, 0.0);
        e.confirm = level(1.0, 1.0, 0.0);
    });
    let xs = [0.0, 0.5, 0.4, 0.4, 0.75, 0.4, 0.25, 0.4, 0.5, 0.0];
    let outs = run(&c, &xs.map(at));
    assert_eq!(
        alerting(&outs),
        [
            false, true, true, true, true, true, false, false, true, false
        ]
    );
    // The confidence never went back to zero between ticks 1 and 8, so the second raise is
    // back-dated to tick 1 too.
    assert_eq!(raised(&outs), [(1, Level::Alert, 1), (8, Level::Alert, 1)]);
}

/// `off` equal to `on`: lowered as soon as the confidence drops below `on`.
#[test]
fn no_hysteresis_when_off_equals_on() {
    let c = detector_config(1.0, false, false, |e| {
        e.alert = level(0.5, 0.5, 0.0);
        e.confirm = level(1.0, 1.0, 0.0);
    });
    let outs = run(&c, &[0.5, 0.4, 0.5].map(at));
    assert_eq!(alerting(&outs), [true, false, true]);
    assert_eq!(raised(&outs), [(0, Level::Alert, 0), (2, Level::Alert, 0)]);
}

/// Confirm with a dwell of 3 ms = 3 ticks at 1000 Hz: raised on the third consecutive tick
/// at or above `on` (⅞ ≥ ¾); a tick below `on` (½) restarts the count even though it is
/// above `off`. The alert (no dwell) comes at the first tick.
#[test]
fn dwell() {
    let c = detector_config(1.0, false, false, |e| {
        e.alert = level(0.5, 0.25, 0.0);
        e.confirm = level(0.75, 0.25, 3.0);
    });
    let xs = [0.0, 0.75, 0.75, 0.5, 0.75, 0.75, 0.75, 0.75];
    let outs = run(&c, &xs.map(at));
    assert_eq!(
        raised(&outs),
        [(1, Level::Alert, 1), (6, Level::Confirm, 1)]
    );
    assert!(outs[7].confirmed & 1 != 0);
    assert!(outs[5].confirmed & 1 == 0);
}

/// Confirm with a hold of 3 ms = 3 ticks: a dip below `off` (⅛ < ½) for 1 or 2 ticks keeps
/// the level up and raises nothing again (one physical event, one confirmation); 3 ticks in
/// a row below `off` lower it, and the next rise is a second confirmation (the onset stays
/// at tick 1: the confidence never returns to 0). Without a hold the same script confirms
/// four times.
#[test]
fn hold_keeps_one_event_one_confirmation() {
    let xs = [0.0, 1.0, 0.25, 1.0, 0.25, 0.25, 1.0, 0.25, 0.25, 0.25, 1.0];
    for (hold_ms, want, up_at_9) in [
        (
            3.0,
            vec![(1, Level::Confirm, 1), (10, Level::Confirm, 1)],
            false,
        ),
        (
            2.0,
            vec![
                (1, Level::Confirm, 1),
                (6, Level::Confirm, 1),
                (10, Level::Confirm, 1),
            ],
            false,
        ),
        (4.0, vec![(1, Level::Confirm, 1)], true),
        (
            0.0,
            vec![
                (1, Level::Confirm, 1),
                (3, Level::Confirm, 1),
                (6, Level::Confirm, 1),
                (10, Level::Confirm, 1),
            ],
            false,
        ),
    ] {
        let c = detector_config(1.0, false, false, |e| {
            e.alert = level(0.5, 0.25, 0.0);
            e.confirm = level(0.75, 0.5, 0.0);
            e.confirm.hold_ms = hold_ms;
        });
        let outs = run(&c, &xs.map(at));
        let confirms: Vec<_> = raised(&outs)
            .into_iter()
            .filter(|r| r.1 == Level::Confirm)
            .collect();
        assert_eq!(confirms, want, "hold {hold_ms} ms");
        assert_eq!(outs[9].confirmed & 1 != 0, up_at_9, "hold {hold_ms} ms");
        assert!(outs[2].confirmed & 1 != 0 || hold_ms == 0.0);
    }
}

/// A dwell of 0 raises at the first tick at or above `on`, like a dwell of one tick.
#[test]
fn zero_dwell_raises_on_the_first_tick() {
    for dwell in [0.0, 1.0] {
        let c = detector_config(1.0, false, false, |e| {
            e.alert = level(0.5, 0.25, dwell);
            e.confirm = level(0.75, 0.5, dwell);
        });
        let outs = run(&c, &[0.0, 1.0].map(at));
        assert_eq!(
            raised(&outs),
            [(1, Level::Alert, 1), (1, Level::Confirm, 1)],
            "dwell {dwell}"
        );
    }
}

/// The onset is the first tick of the current run of confidence above `onset_level`:
/// by default when the confidence left zero (tick 2, at ⅛), with `onset_level` 0.2 when it
/// passed 0.2 (tick 4, at 0.32). A return to zero starts a new run.
#[test]
fn back_dated_onset() {
    let xs = [0.0, 0.0, 0.25, 0.25, 0.4, 0.5, 0.0, 0.25, 0.5];
    for (onset_level, want) in [
        (0.0, [(5, Level::Alert, 2), (8, Level::Alert, 7)]),
        (0.2, [(5, Level::Alert, 4), (8, Level::Alert, 8)]),
    ] {
        let c = detector_config(1.0, false, false, |e| {
            e.alert = level(0.5, 0.45, 0.0);
            e.confirm = level(1.0, 1.0, 0.0);
            e.onset_level = onset_level;
        });
        let outs = run(&c, &xs.map(at));
        assert_eq!(raised(&outs), want, "onset_level {onset_level}");
    }
}

/// Switching to another phase lowers every level and forgets the onset: with the
/// confidence still high, the alert is raised again at the next tick with the onset at that
/// tick; the confirm, with a dwell of 2 ticks, only at the second. Switching to the active
/// phase changes nothing.
#[test]
fn phase_switch_resets_levels_and_onsets() {
    let c = detector_config(1.0, false, false, |e| {
        e.alert = level(0.5, 0.25, 0.0);
        e.confirm = level(0.75, 0.5, 2.0);
    });
    let mut script = [0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0].map(at);
    script[4].switch = Some(1);
    script[6].switch = Some(1);
    let outs = run(&c, &script);
    assert_eq!(
        raised(&outs),
        [
            (1, Level::Alert, 1),
            (2, Level::Confirm, 1),
            (4, Level::Alert, 4),
            (5, Level::Confirm, 4),
        ]
    );
    assert!(outs[7].alerting & 1 != 0 && outs[7].confirmed & 1 != 0);
}

/// Only the active phase's events are evaluated: in `p2` (no events) the event has
/// confidence 0, is not in `evaluated`, and decides nothing; back in `p0` it starts afresh.
#[test]
fn events_outside_the_phase_are_not_evaluated() {
    let c = detector_config(1.0, false, false, |e| {
        e.alert = level(0.5, 0.25, 0.0);
    });
    let mut script = [1.0; 5].map(at);
    script[1].switch = Some(2);
    script[3].switch = Some(0);
    let outs = run(&c, &script);
    assert_eq!(outs[0].evaluated, 1);
    for o in &outs[1..3] {
        assert_eq!(o.evaluated, 0);
        assert_eq!(o.confidences[0].to_bits(), 0);
        assert!(o.decisions.is_empty());
        assert_eq!(o.alerting | o.confirmed, 0);
    }
    assert_eq!(outs[3].evaluated, 1);
    assert_eq!(
        raised(&outs),
        [
            (0, Level::Alert, 0),
            (0, Level::Confirm, 0),
            (3, Level::Alert, 3),
            (3, Level::Confirm, 3),
        ]
    );
}

/// A faulty sensor channel drops its term (counted as 0) and marks the event degraded:
/// sensors x (w ½) and y (w ½) both at 1 give Ψ = 1; with y faulty Ψ = ½.
#[test]
fn a_faulty_sensor_channel_degrades() {
    let c = detector_config(0.5, true, false, |_| {});
    let mut script = [Tick {
        x: 1.0,
        y: 1.0,
        ..Tick::default()
    }; 3];
    script[1].faults = 0b010;
    let outs = run(&c, &script);
    let conf: Vec<u16> = outs.iter().map(|o| o.confidences[0].to_bits()).collect();
    assert_eq!(conf, [32768, 16384, 32768]);
    assert_eq!(
        outs.iter().map(|o| o.degraded).collect::<Vec<_>>(),
        [0, 1, 0]
    );
    assert!(outs.iter().all(|o| o.unjudgeable == 0));
}

/// Every sensor channel faulty, or the context channel faulty: the event is unjudgeable,
/// confidence 0, every level lowered, no decision; it is judged again once the fault
/// clears, and raised afresh with a new onset.
#[test]
fn faults_make_an_event_unjudgeable() {
    let c = detector_config(0.5, true, true, |e| {
        e.alert = level(0.5, 0.25, 0.0);
        e.confirm = level(0.75, 0.5, 0.0);
    });
    let high = Tick {
        x: 1.0,
        y: 1.0,
        k: 1.0,
        ..Tick::default()
    };
    let mut script = [high; 6];
    script[1].faults = 0b011; // both sensors
    script[3].faults = 0b100; // the context channel
    script[4].faults = 0b100;
    let outs = run(&c, &script);
    for t in [1, 3, 4] {
        let o = &outs[t];
        assert_eq!(o.unjudgeable, 1, "tick {t}");
        assert_eq!(o.evaluated, 1, "tick {t}");
        assert_eq!(o.degraded, 0, "tick {t}");
        assert_eq!(o.confidences[0].to_bits(), 0, "tick {t}");
        assert_eq!(o.alerting | o.confirmed, 0, "tick {t}");
        assert!(o.decisions.is_empty(), "tick {t}");
    }
    assert_eq!(
        raised(&outs),
        [
            (0, Level::Alert, 0),
            (0, Level::Confirm, 0),
            (2, Level::Alert, 2),
            (2, Level::Confirm, 2),
            (5, Level::Alert, 5),
            (5, Level::Confirm, 5),
        ]
    );
}

/// A fault reaches a term through a chain of features: a low-pass of a difference of `x`
/// and `k` is lost when `k` is faulty; a fault on a channel no term reads changes nothing.
#[test]
fn faults_follow_feature_chains() {
    let mut c = config(
        1000.0,
        &["x", "y", "k"],
        vec![
            (
                "d",
                StageSpec::Difference {
                    a: name("x"),
                    b: name("k"),
                    gain: 1.0,
                },
            ),
            (
                "lp",
                StageSpec::LowPass {
                    input: name("d"),
                    cutoff_hz: 100.0,
                    warm_up_ms: None,
                    warm_up_until: None,
                    warm_up_longer: None,
                },
            ),
            ("fx", raw("x")),
        ],
        vec![event(
            "e",
            vec![],
            vec![
                sensor("lp", 0.5, sigmoid(-10.0, 10.0)),
                sensor("fx", 0.5, sigmoid(0.0, 1.0)),
            ],
        )],
        vec![phase("p", &["e"])],
    );
    c.events[0].alert = level(0.5, 0.25, 0.0);
    let script = [0b000, 0b100, 0b010, 0b101].map(|faults| Tick {
        x: 1.0,
        faults,
        ..Tick::default()
    });
    let outs = run(&c, &script);
    assert_eq!(
        outs.iter()
            .map(|o| (o.degraded, o.unjudgeable))
            .collect::<Vec<_>>(),
        [(0, 0), (1, 0), (0, 0), (0, 1)]
    );
    let det = detector_build::build(&c).expect("valid");
    let e = det.event("e").expect("event");
    assert_eq!(det.event_channels(e), 0b101);
}

/// `a` excludes `b`: while `a`'s confirm level is up, `b`'s levels are held down whatever its
/// confidence; once `a`'s level has fallen (its confidence below `off` for the 2 ms hold),
/// `b` is raised at once. Without the exclusion `b` is raised as soon as it is confident.
#[test]
fn an_exclusion_holds_the_excluded_event_down_while_the_other_is_confirmed() {
    let s = sigmoid(0.0, 1.0);
    let make = |exclude: bool| {
        let mut a = event("a", vec![], vec![sensor("fx", 1.0, s)]);
        let mut b = event("b", vec![], vec![sensor("fy", 1.0, s)]);
        for e in [&mut a, &mut b] {
            e.confirm = level(0.75, 0.5, 0.0);
            e.confirm.hold_ms = 2.0;
        }
        if exclude {
            a.excludes = vec!["b".into()];
        }
        config(
            1000.0,
            &["x", "y"],
            vec![("fx", raw("x")), ("fy", raw("y"))],
            vec![a, b],
            vec![phase("p", &["a", "b"])],
        )
    };
    let xs = [0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0];
    let ys = [0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    let confirmations = |c: &Config| {
        let det = detector_build::build(c).expect("valid");
        let model = Model::new(c).expect("resolves");
        let (mut st, mut ms) = (det.new_state(), model.new_state());
        let mut got = Vec::new();
        for (t, (&x, &y)) in xs.iter().zip(&ys).enumerate() {
            let o = det.tick(&mut st, t as u32, &inputs_f64(&[x, y], 0));
            let m = model.tick(&mut ms, t as u32, &[x, y], 0);
            assert_eq!(o.confirmed, m.decided.confirmed, "confirmed at tick {t}");
            assert_eq!(o.alerting, m.decided.alerting, "alerting at tick {t}");
            got.extend(
                o.decisions
                    .iter()
                    .filter(|d| d.level == Level::Confirm)
                    .map(|d| (d.tick, d.event.0)),
            );
        }
        got
    };
    assert_eq!(confirmations(&make(false)), [(1, 0), (2, 1)]);
    assert_eq!(confirmations(&make(true)), [(1, 0), (5, 1)]);
}

/// Confirm after 5 ticks, or after 3 once `fy` (channel y, weight 0: it moves no
/// confidence) has been strictly above ½ at a tick of the run: the run starts at tick 1.
/// Shown at tick 1 or 2, the level rises at tick 3 (the run's third tick); shown only at
/// tick 4, at tick 4; shown before the run, at the level and not above it, or while y is
/// faulty (the event degraded), it waits the whole 5 ticks; a run broken by a tick below
/// `on` (tick 3) forgets what was shown in it: the next run (from tick 4) waits 5 ticks
/// unless shown again.
#[test]
fn early_dwell_once_its_feature_has_shown() {
    let c = detector_config(1.0, true, false, |e| {
        e.alert = level(0.5, 0.25, 0.0);
        e.confirm = level(0.75, 0.5, 5.0);
        e.confirm.early = Some(detector_build::EarlySpec {
            feature: name("fy"),
            above: 0.5,
            dwell_ms: 3.0,
        });
    });
    let script = |xs: &[f64], ys: &[(usize, f64)], faulty: &[usize]| -> Vec<Tick> {
        let mut s: Vec<Tick> = xs.iter().map(|&x| at(x)).collect();
        for &(t, y) in ys {
            s[t].y = y;
        }
        for &t in faulty {
            s[t].faults = 0b010;
        }
        s
    };
    let run_of = [0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    let broken = [0.0, 1.0, 1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    for (what, s, want) in [
        ("nothing shown", script(&run_of, &[], &[]), 5),
        ("shown at tick 2", script(&run_of, &[(2, 1.0)], &[]), 3),
        ("shown at tick 1", script(&run_of, &[(1, 1.0)], &[]), 3),
        ("shown at tick 4", script(&run_of, &[(4, 1.0)], &[]), 4),
        ("shown before the run", script(&run_of, &[(0, 1.0)], &[]), 5),
        ("at the level", script(&run_of, &[(2, 0.5)], &[]), 5),
        ("while faulty", script(&run_of, &[(2, 1.0)], &[2]), 5),
        ("in a broken run", script(&broken, &[(2, 1.0)], &[]), 8),
        ("after the break", script(&broken, &[(5, 1.0)], &[]), 6),
    ] {
        let outs = run(&c, &s);
        let confirms: Vec<_> = raised(&outs)
            .into_iter()
            .filter(|r| r.1 == Level::Confirm)
            .collect();
        // The confidence never returns to 0 after tick 1: every onset is tick 1.
        assert_eq!(confirms, [(want, Level::Confirm, 1)], "{what}");
    }
}
