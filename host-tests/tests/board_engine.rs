//! The board's engine on simulated runs, fed as the board is fed: the calibrated analog
//! samples every tick, the controller's context frames every fifth tick in their raw steps
//! (0.1 mm/s, 2 mm/s², 1 µm). It confirms what the PC's replay of the same run, its
//! context rounded to those steps, confirms, the same event at the same tick: the channels
//! reach the detector in the units its configuration works in (cN, mm, mm/s for the
//! default), converted as the replay converts a trace. The steps themselves can move a
//! confirmation by a tick: the disturbance's judge of an arm held back takes away the
//! arm's swing, averaged to tenths of a µm, and on randomized large disturbance 4 the
//! 1 µm steps confirm it 0.2 ms sooner than the simulator's unrounded error.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

#[path = "board_support.rs"]
mod board;

use board::{Feed, Fingertip, TICK_US};
use detector_core::{Detector, Level};
use fingertip::sim::{Scenario, SimOptions, simulate};
use firmware::boot;

/// The first confirmation: the event's name and its tick.
type First = Option<(String, u32)>;

fn on_the_pc(d: &Detector, trace: &fingertip::trace::Trace) -> First {
    let decisions = fingertip::replay::replay(d, trace, |_, _, _| {}).unwrap();
    decisions
        .iter()
        .find(|r| r.is_confirm())
        .map(|r| (r.event.clone(), (r.t_s * 5000.0).round() as u32))
}

fn on_the_board(d: &Detector, trace: &fingertip::trace::Trace) -> First {
    let mut f = Fingertip::fed(Feed::new(std::slice::from_ref(trace)));
    f.run_to((trace.len() as u64 - 1) * TICK_US);
    f.outputs
        .iter()
        .flat_map(|(_, ds)| ds)
        .find(|x| x.level == Level::Confirm)
        .map(|x| (d.events()[usize::from(x.event.0)].to_string(), x.tick))
}

#[test]
fn the_board_confirms_what_the_pcs_replay_confirms() {
    let mut d = Detector::empty();
    boot::load_detector(&mut d, boot::DETECTOR_IMAGE).unwrap();
    let mut runs = 0;
    for (scenario, seed, randomize) in
        Scenario::table1()
            .iter()
            .map(|s| (*s, 0, false))
            .chain((1..=4).flat_map(|seed| {
                [
                    Scenario::ContactHard8,
                    Scenario::ContactSoft2,
                    Scenario::LinkCollision8,
                    Scenario::DisturbanceLarge5,
                    Scenario::ContactBraking,
                    Scenario::KnockLink1,
                ]
                .map(|s| (s, seed, true))
            }))
    {
        let opts = SimOptions {
            seed,
            randomize,
            ..SimOptions::default()
        };
        let trace = simulate(&scenario, &opts).unwrap();
        let pc = on_the_pc(&d, &board::framed(&trace));
        let chip = on_the_board(&d, &trace);
        let name = format!("{} seed {seed}", scenario.name());
        match (&pc, &chip) {
            (Some((a, ta)), Some((b, tb))) => {
                assert_eq!(a, b, "{name}: {pc:?} on the PC, {chip:?} on the board");
                assert_eq!(ta, tb, "{name}: {pc:?} on the PC, {chip:?} on the board");
            }
            (None, None) => {}
            _ => panic!("{name}: {pc:?} on the PC, {chip:?} on the board"),
        }
        runs += 1;
    }
    assert!(runs > 20);
}
