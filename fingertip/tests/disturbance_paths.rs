//! The default detector's disturbance paths, each for the evidence it was added for. On the
//! encoders: a blow on link 1 moves the joints, which the encoders read, while the
//! fingertip on its foam hardly feels it; the path judges the position error swinging off
//! the path and back (`err_shake_steady`, on the swings back), not an arm falling steadily
//! behind its command, which a stall or an object taking part of the speed does, nor one
//! being stopped over tens of ms, whose error's growth steepens without turning back, nor
//! one held off its path beyond what its swing explains (`err_shake_free`), as a post that
//! yields holds a link while the blocked joint moves the tip ahead along the approach, nor
//! one that has not been struck lately (`err_shake_struck`), as a drive that bumps the tip
//! off its path and back over tens of ms moves it. On
//! the force sensor: the vibration's jump weighs a twentieth while the commanded speed
//! changes (`shake_judged`) and a tenth while the finger moves slower than 12 mm/s along
//! the approach (`shake_moving`), where an arm whose loops differentiate their encoders
//! jolts itself; a vibration held for tens of ms is judged only while the finger moves
//! along the approach at 12 mm/s or more (`burst_moving`), where those loops do not shake
//! it in bursts. Every path is judged while the arm is not held back (`lag`) beyond what a
//! struck vibration swings it by (`lag_unshaken`), whichever way the finger moves along the
//! approach. The confirmation waits 8 ms for a struck arm to show it is held (a heavy arm's
//! loss reaches its position error late), or 5 ms once the arm has lately swung back onto
//! its path, which a held arm does not do (83 of 100 knocks on link 2 when this was
//! written; a swing back is remembered for about 16 ms, as a push held down as a collision
//! may have swung back before its confidence rises).

use detector_core::Detector;
use fingertip::APPROACH_TOML;
use fingertip::sim::{Scenario, SimOptions};
use fingertip::trace::Trace;

mod support;
use support::{
    STIFF_OBSTACLES, confirmed, confirmed_at, confirming_where_right, default_with,
    default_with_each, detector, force_noise, minutes_read_only_by, padded_posts, right,
    right_within, runs, steady_motion, times, trace_of,
};

/// The default's encoder term, as written in `configs/approach.toml`.
const ENCODER_TERM: &str = "    { feature = \"err_shake_struck\", weight = 1.0, cdf = { sigmoid = { low = 0.08, high = 0.45 } } },\n";
/// The same term whether or not the arm has been struck lately.
const UNSTRUCK_TERM: &str = "    { feature = \"err_shake_free\", weight = 1.0, cdf = { sigmoid = { low = 0.08, high = 0.45 } } },\n";
/// The same term on the swing back whether or not the tip is held off its path.
const UNHELD_TERM: &str = "    { feature = \"err_shake_steady\", weight = 1.0, cdf = { sigmoid = { low = 0.08, high = 0.45 } } },\n";
/// The swing's input: the error's growth above 30 Hz.
const WOBBLE_INPUT: &str = "stage = { abs = { input = \"err_wobble\" } }";
/// The same swing taken from the error's growth itself, a steady growth included.
const GROWTH_INPUT: &str = "stage = { abs = { input = \"err_growth\" } }";
/// The averaged swing, on the swings back onto the path only.
const BACK_INPUT: &str =
    "stage = { low_pass = { input = \"err_back\", cutoff_hz = 12.0, warm_up_ms = 0.2 } }";
/// The same average on the swing's size, either way.
const SIZE_INPUT: &str =
    "stage = { low_pass = { input = \"err_swing\", cutoff_hz = 12.0, warm_up_ms = 0.2 } }";

#[test]
fn the_encoders_find_knocks_on_link_1_that_the_fingertip_hardly_feels() {
    let fingertip_only = default_with(ENCODER_TERM, "");
    let default = detector(APPROACH_TOML);
    let s = Scenario::KnockLink1;
    let knocks = runs(s, 1..1001, &SimOptions::default());
    let count = |d: &Detector| right(d, s, &knocks).iter().filter(|&&r| r).count();
    let (with_encoders, without) = (count(&default), count(&fingertip_only));
    // 914 and 901 of the 1,000 when this was written.
    assert!(
        with_encoders >= without + 10,
        "the encoder path finds fewer than 10 knocks on link 1 more ({with_encoders} right with it, {without} without): the test no longer shows its part"
    );
}

/// How many disturbances `detector` confirms on `trace`.
fn disturbances(detector: &Detector, trace: &Trace) -> usize {
    confirmed(detector, trace)
        .iter()
        .filter(|e| *e == "disturbance")
        .count()
}

/// The default's lag: how far the error's growth exceeds a tenth of the commanded travel,
/// the finger's speed along the approach either way.
const LAG: &str =
    "stage = { difference = { a = \"off_growth\", b = \"speed_along\", gain = 0.13263 } }";
/// The same lag on the signed commanded velocity, whose tenth turns into a bonus while the
/// finger moves away from the pad.
const SIGNED_LAG: &str =
    "stage = { difference = { a = \"off_growth\", b = \"vel_des_x\", gain = 0.13263 } }";
/// The default's judge of an arm held back: the lag less nine tenths of its allowance
/// while the arm has not swung back onto its path.
const HELD_BACK: &str =
    "stage = { difference = { a = \"lag\", b = \"speed_unswung\", gain = -0.119367 } }";
/// The lag itself, its tenth allowed whether or not the arm has swung back.
const LAG_ANY_TIME: &str = "stage = { raw = { input = \"lag\" } }";

/// From 150 ms on, the arm swings ±5 µm at 60 Hz about its 10 µm tracking error [µm].
fn shaken_error_um(t: f64) -> f64 {
    10.0 + if t < 0.15 {
        0.0
    } else {
        5.0 * (2.0 * std::f64::consts::PI * 60.0 * (t - 0.15)).sin()
    }
}

/// The default with `written` in its configuration `instead` (see [`default_with`]), and
/// its encoder term on the swing back whether or not the tip is held off its path or the
/// arm struck: an arm that falls behind or is being stopped also moves off its path
/// without swinging, which either gate alone would keep from reading as shaken.
fn ungated_with(written: &str, instead: &str) -> Detector {
    default_with_each(&[(ENCODER_TERM, UNHELD_TERM), (written, instead)])
}

/// Minutes of free motion on drives that bump the tip 10-30 µm off its path and back over
/// 50-100 ms (base seeds 100 and 300, `plant.drive_bump=1e-5..3e-5`): a bump's way back
/// swings the arm back onto its path as a knock's does, and without the struck gate each
/// minute confirms a disturbance (at 5.2 and 39.0 s when this was written).
const BUMPED_MINUTES: [u64; 2] = [3_626_650_549_393_848_585, 10_879_951_648_181_544_962];

#[test]
fn a_drive_that_bumps_the_tip_off_its_path_and_back_is_no_disturbance() {
    minutes_read_only_by(
        &BUMPED_MINUTES,
        "plant.drive_bump=1e-5..3e-5",
        &default_with(ENCODER_TERM, UNSTRUCK_TERM),
        "without the struck gate",
        "disturbance",
    );
}

#[test]
fn an_arm_shaken_off_its_path_is_a_disturbance_and_one_falling_behind_is_not() {
    let default = detector(APPROACH_TOML);
    let growth = ungated_with(WOBBLE_INPUT, GROWTH_INPUT);
    let shaken = steady_motion(0.020, shaken_error_um);
    assert_eq!(disturbances(&default, &shaken), 1, "a shaken arm");
    let fingertip_only = default_with(ENCODER_TERM, "");
    assert_eq!(
        disturbances(&fingertip_only, &shaken),
        0,
        "the fingertip's paths read the shaken arm: the test no longer shows the encoders' part"
    );
    // From 150 ms on, it falls behind its command at 1 mm/s (a twentieth of its speed,
    // under a tenth: not a link collision either).
    let stalled = steady_motion(0.020, |t| 10.0 + 1000.0 * (t - 0.15).max(0.0));
    assert_eq!(disturbances(&default, &stalled), 0, "an arm falling behind");
    assert!(
        disturbances(&growth, &stalled) > 0,
        "the error's growth itself, a steady one included, reads no disturbance either: the test no longer shows the high-pass's part"
    );
}

#[test]
fn an_arm_being_stopped_over_tens_of_ms_is_no_disturbance() {
    let default = detector(APPROACH_TOML);
    let either_way = ungated_with(BACK_INPUT, SIZE_INPUT);
    // From 150 ms on, an obstacle that gives before it holds takes a growing part of the
    // commanded 20 mm/s away, up to 4 mm/s after 30 ms, and keeps it: the error's growth
    // steepens for 30 ms and never turns back.
    let stopping = steady_motion(0.020, |t| {
        let (ramp, dt) = (0.03, (t - 0.15).max(0.0));
        let lost_um_s = 4000.0;
        10.0 + if dt < ramp {
            lost_um_s * dt * dt / (2.0 * ramp)
        } else {
            lost_um_s * (ramp / 2.0 + dt - ramp)
        }
    });
    assert_eq!(disturbances(&default, &stopping), 0, "an arm being stopped");
    assert!(
        disturbances(&either_way, &stopping) > 0,
        "the swing's size either way reads no disturbance either: the test no longer shows the swings back's part"
    );
}

/// `duration_s` of randomized free motion from `seed`, the arm's joint loops taking their
/// velocity from the encoders through a 250 Hz low-pass.
fn free_motion_on_encoder_velocity(seed: u64, duration_s: f64) -> Trace {
    let opts = SimOptions {
        duration_s: Some(duration_s),
        velocity_filter_hz: 250.0,
        ..SimOptions::default()
    };
    runs(Scenario::FreeMotion, [seed], &opts).remove(0)
}

/// The default's jump while the commanded speed changes: a gate leaking a twentieth.
const JUMP_LEAK: &str = "unless = { feature = \"speed_unsettled\", above = 3.0 }, leak = 0.05 }";
/// The default's jump while the finger moves slowly along the approach: a second gate
/// leaking a tenth.
const SLOW_LEAK: &str = "unless = { feature = \"speed_along\", below = 12.0 }, leak = 0.1 }";

/// The default with its leaking gate `gate`, as written in `configs/approach.toml`, passing
/// the fraction `leak` of the jump.
fn with_leak(gate: &str, leak: &str) -> Detector {
    let (condition, _) = gate.split_once("leak = ").expect("a leaking gate");
    default_with(gate, &format!("{condition}leak = {leak} }}"))
}

/// The arm's jolt in `tr` is confirmed as a disturbance by `heavier`, which weighs the jump
/// more, not by the default.
fn assert_jolt_left_alone(heavier: &Detector, tr: &Trace) {
    assert_eq!(
        disturbances(heavier, tr),
        1,
        "the jump weighed more no longer confirms the jolt: the run no longer shows it"
    );
    assert_eq!(
        disturbances(&detector(APPROACH_TOML), tr),
        0,
        "the jolt is confirmed as a disturbance"
    );
}

#[test]
fn an_arm_jolting_itself_after_a_change_of_speed_is_no_disturbance() {
    // Free motion on loops that take their velocity from the encoders through 250 Hz: 50
    // ms after a ramp of the commanded speed ends (at 48 mm/s along x), the fingertip
    // reads a jolt of 18 cN as the position error jumps by 6 um.
    let tr = free_motion_on_encoder_velocity(3_626_650_549_393_848_380, 4.4);
    assert_jolt_left_alone(&with_leak(JUMP_LEAK, "1.0"), &tr);
}

#[test]
fn a_strong_jolt_just_after_a_change_of_speed_is_no_disturbance() {
    // Free motion on loops that take their velocity from the encoders through 250 Hz,
    // moving at 65 mm/s along the approach just after a change of speed (remembered as 18
    // mm/s): the force's energy jumps 100-120 cN^2 above four times its usual level, which
    // a tenth weighs above the path's level (10-12) and a twentieth below it, 5.06 s into
    // the run.
    let tr = free_motion_on_encoder_velocity(3_626_650_549_393_848_442, 5.1);
    assert_jolt_left_alone(&with_leak(JUMP_LEAK, "0.1"), &tr);
}

#[test]
fn an_arm_jolting_itself_while_it_moves_slowly_along_the_approach_is_no_disturbance() {
    // Free motion on loops that take their velocity from the encoders through 250 Hz,
    // moving at 7.9 mm/s along the approach with its change of speed remembered below 3
    // mm/s: the force's energy jumps 30-37 cN^2 above four times its usual level, which a
    // tenth weighs below the path's level, 10.91 s into the run.
    let tr = free_motion_on_encoder_velocity(3_626_650_549_393_848_380, 11.0);
    assert_jolt_left_alone(&with_leak(SLOW_LEAK, "1.0"), &tr);
}

/// The default's vibration term: the burst path judged while the finger moves along the
/// approach.
const BURST_TERM: &str = "{ feature = \"burst_moving\", weight = 1.0";

/// The default with the burst path judged at any speed along the approach.
fn burst_at_any_speed() -> Detector {
    default_with(
        BURST_TERM,
        &BURST_TERM.replace("burst_moving", "burst_steady"),
    )
}

#[test]
fn an_arm_shaking_itself_while_it_moves_slowly_along_the_approach_is_no_disturbance() {
    // Free motion on loops that take their velocity from the encoders through 250 Hz,
    // cruising at 7.9 mm/s away from the object and 9.3 mm/s across: the arm shakes
    // itself, and the force's energy over 10 ms climbs above twice its usual level for
    // tens of ms, 3.7 s into the run.
    let tr = free_motion_on_encoder_velocity(3_626_650_549_393_848_582, 3.9);
    assert_eq!(
        disturbances(&burst_at_any_speed(), &tr),
        1,
        "the burst path at any speed no longer confirms the arm's own shaking: the run no longer shows it"
    );
    assert_eq!(
        disturbances(&detector(APPROACH_TOML), &tr),
        0,
        "the arm's own shaking is confirmed as a disturbance"
    );
}

/// 500 ms of steady motion at `along_mm_s` along the approach and 20 mm/s across it, the
/// force sensor's noise 1.5 cN RMS, and from 300 ms on a vibration of 4 cN at 80 Hz for
/// 60 ms: its 8 cN^2 are twice the noise's energy and more than the 4 cN^2 above it that
/// this path confirms from, and less than four times it plus the 2-10 cN^2 the jump judges
/// from.
fn burst_while_moving(along_mm_s: f64) -> Trace {
    let t = times(2500);
    let mut noise = force_noise(7);
    let force_x = t
        .iter()
        .map(|&s| {
            let burst = if (0.3..0.36).contains(&s) {
                0.04 * (2.0 * std::f64::consts::PI * 80.0 * (s - 0.3)).sin()
            } else {
                0.0
            };
            burst + noise()
        })
        .collect();
    let along = vec![along_mm_s * 1e-3; t.len()];
    let across = vec![0.020; t.len()];
    trace_of(
        "a vibration burst",
        t,
        vec![
            ("force_x", force_x),
            ("vel_des_x", along),
            ("vel_des_y", across),
        ],
    )
}

#[test]
fn a_small_vibration_is_judged_while_the_finger_moves_along_the_approach() {
    let default = detector(APPROACH_TOML);
    let any_speed = burst_at_any_speed();
    let moving = burst_while_moving(20.0);
    assert_eq!(
        disturbances(&default, &moving),
        1,
        "at 20 mm/s along the approach"
    );
    // Slower along the approach the burst path is shut, and the jump alone does not reach
    // a vibration this small: the trade for not reading the arm's own bursts.
    let slow = burst_while_moving(5.0);
    assert_eq!(
        disturbances(&default, &slow),
        0,
        "at 5 mm/s along the approach"
    );
    assert_eq!(
        disturbances(&any_speed, &slow),
        1,
        "the burst path at any speed misses the burst at 5 mm/s: the test no longer shows the gate's part"
    );
}

#[test]
fn an_arm_shaken_while_the_finger_moves_away_from_the_pad_is_a_disturbance() {
    // A disturbance is judged while the arm is not held back: its lag, the error's growth
    // beyond a tenth of the commanded travel. Moving away at 5 cm/s, the same swing.
    let away = steady_motion(-0.050, shaken_error_um);
    assert_eq!(
        disturbances(&detector(APPROACH_TOML), &away),
        1,
        "an arm shaken while the finger moves away"
    );
    let signed = default_with(LAG, SIGNED_LAG);
    assert_eq!(
        disturbances(&signed, &away),
        0,
        "the lag on the signed velocity finds the disturbance too: the test no longer shows what the allowance's sign does"
    );
}

/// The default's judge of an arm held back, as the disturbance's context reads it.
const HELD_CONTEXT: &str = "{ feature = \"lag_unshaken\", cdf";
/// The same context on the lag itself, whatever the arm's shaking swings it by.
const LAG_CONTEXT: &str = "{ feature = \"lag\", cdf";

/// Bursts on link 2 of the tuning seeds (base seed 100, run seeds as `fingertip evaluate`
/// names them) that swing the arm off its usual path and back at each period: the default
/// confirms each 5.6-13.6 ms after the onset, and with the context on the lag itself each
/// 14.6-66.4 ms after, its dwell started again at each swing off the path (26.2-66.4 ms
/// when the swing back was judged only at the ticks the confidence is up, before the early
/// dwell remembered it).
const SWINGING_BURSTS: [u64; 6] = [
    14_820_112_127_734_872_099,
    14_820_112_127_734_872_254,
    14_820_112_127_734_872_351,
    14_820_112_127_734_872_795,
    14_820_112_127_734_872_835,
    14_820_112_127_734_873_041,
];

/// Checks that the default confirms a disturbance on each of the knocks on link 2 `seeds`
/// (run seeds of the tuning seeds, as `fingertip evaluate` names them) within 20 ms of its
/// onset, and at least `by_s` sooner than `changed` (`what` it is) does.
fn knocks_confirmed_sooner_than(seeds: &[u64], changed: &Detector, by_s: f64, what: &str) {
    let s = Scenario::KnockLink2;
    let knocks = runs(s, seeds.iter().copied(), &SimOptions::default());
    let default = detector(APPROACH_TOML);
    assert_eq!(
        right_within(&default, s, &knocks, 0.020),
        knocks.len(),
        "knocks on link 2 confirmed within 20 ms"
    );
    for (seed, k) in seeds.iter().zip(&knocks) {
        let at = |d: &Detector| confirmed_at(d, k, "disturbance").expect("a disturbance");
        let (by_default, by_changed) = (at(&default), at(changed));
        assert!(
            by_default <= by_changed - by_s,
            "knock on link 2 {seed}: confirmed at {by_default:.4} s, {what} at {by_changed:.4} s: the test no longer shows the difference"
        );
    }
}

#[test]
fn a_burst_that_shakes_the_arm_is_confirmed_while_it_lasts() {
    knocks_confirmed_sooner_than(
        &SWINGING_BURSTS,
        &default_with(HELD_CONTEXT, LAG_CONTEXT),
        0.0015,
        "with the context on the lag itself",
    );
}

/// The default's swing taken away from the lag: half the swing back's recent peak, above
/// four times the usual swing.
const PEAK_EXCESS: &str =
    "stage = { difference = { a = \"back_lately\", b = \"err_swing_usual\", gain = 4.0 } }";
/// The same swing on the swing back's 13 ms average, above twice the usual (`err_shake`).
const AVERAGED_EXCESS: &str = "stage = { positive = { input = \"err_shake\" } }";
/// The default's share of the peak swing taken away.
const HALF_PEAK: &str =
    "stage = { difference = { a = \"held_back\", b = \"swing_struck\", gain = 0.5 } }";
/// Three times the averaged swing: the averaged swing back's peak twice over.
const THRICE_AVERAGED: &str =
    "stage = { difference = { a = \"held_back\", b = \"swing_struck\", gain = 3.0 } }";

/// Bursts on link 2 of the tuning seeds (base seed 100, run seeds as `fingertip evaluate`
/// names them) whose first swings lift the lag over the threshold: the swing back's 13 ms
/// average builds up over them, and the disturbance's dwell started again at each swing
/// off the path, confirmed 16.4-22.6 ms after the onset; on the swing back's recent peak,
/// 5.6-10.2 ms.
const FIRST_SWINGS: [u64; 4] = [
    14_820_112_127_734_872_387,
    14_820_112_127_734_872_893,
    14_820_112_127_734_872_216,
    14_820_112_127_734_872_906,
];

#[test]
fn a_bursts_first_swings_are_taken_away_from_the_lag_as_they_come() {
    knocks_confirmed_sooner_than(
        &FIRST_SWINGS,
        &default_with_each(&[(PEAK_EXCESS, AVERAGED_EXCESS), (HALF_PEAK, THRICE_AVERAGED)]),
        0.005,
        "with the averaged swing back taken away",
    );
}

/// The default's gate on the swing taken away: only while the force sensor has just jumped.
const STRUCK_GATE: &str =
    "input = \"swing_excess\", unless = { feature = \"shake\", below = 30.0 }";
/// The same swing taken away at any time.
const NO_STRUCK_GATE: &str =
    "input = \"swing_excess\", unless = { feature = \"shake\", below = -30000.0 }";

/// Link collisions on link 1 of the tuning seeds (base seeds 100 and 300), whose arm reads
/// a swing back as it stops (the tip catches up along the approach where the pad is turned
/// towards joint 1) while the force sensor barely jumps: with the swing taken away at any
/// time, each confirmed a disturbance (picked again when the swing taken away became half
/// its recent peak).
const SWUNG_COLLISIONS: [(Scenario, u64); 9] = [
    (Scenario::LinkCollision8, 14_820_092_336_525_572_204),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_535),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_921),
    (Scenario::LinkCollision8, 14_820_092_336_525_573_000),
    (Scenario::LinkCollision8, 7_566_788_862_157_613_468),
    (Scenario::LinkCollision8, 7_566_788_862_157_613_651),
    (Scenario::LinkCollision8, 7_566_788_862_157_613_853),
    (Scenario::LinkCollision8, 7_566_788_862_157_613_862),
    (Scenario::LinkCollision2, 7_566_800_956_785_519_163),
];

#[test]
fn a_collision_swinging_its_arm_back_unstruck_is_no_disturbance() {
    let read_as_disturbances = confirming_where_right(
        &default_with(STRUCK_GATE, NO_STRUCK_GATE),
        &SWUNG_COLLISIONS,
        &SimOptions::default(),
        "disturbance",
    );
    assert!(
        read_as_disturbances >= 7,
        "the swing taken away at any time reads only {read_as_disturbances} of the {} collisions as disturbances: the test no longer shows the gate's part",
        SWUNG_COLLISIONS.len()
    );
}

/// The default's disturbance dwell: 8 ms ...
const DISTURBANCE_DWELL: &str = "dwell_ms = 8.0, hold_ms = 150.0";
/// ... or 5 once the arm has lately swung back onto its path (an early dwell, on the swing
/// back of the last 16 ms or so).
const BACK_LATELY: &str = ", early = { feature = \"back_lately\", above = 3.0, dwell_ms = 5.0 }";
/// The same early dwell on the swing back at the ticks the confidence is up only.
const BACK_NOW: &str = ", early = { feature = \"err_back\", above = 3.0, dwell_ms = 5.0 }";

/// Link collisions of the tuning seeds (base seed 100, run seeds as `fingertip evaluate`
/// names them; stiff obstacles, [`STIFF_OBSTACLES`]) on arms of 1-4 kg, struck on link 2: the link
/// rings the fingertip at once and the heavy arm's loss reaches the position error only
/// after 5 ms. With the disturbance confirmed after a fixed 5 ms, each was read as a
/// disturbance 4.9-5.1 ms after the onset (with the lag's tenth allowed at any time, as
/// then: the allowance held back until the arm swings back holds them down itself).
const HEAVY_COLLISIONS: [(Scenario, u64); 8] = [
    (Scenario::LinkCollision8, 14_820_092_336_525_572_149),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_140),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_117),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_125),
    (Scenario::LinkCollision2, 14_820_084_639_944_177_710),
    (Scenario::LinkCollision2, 14_820_084_639_944_177_669),
    (Scenario::LinkCollision2, 14_820_084_639_944_177_671),
    (Scenario::LinkCollision2, 14_820_084_639_944_177_778),
];

#[test]
fn a_heavy_arms_collision_is_given_the_disturbances_longer_wait() {
    let heavy = SimOptions {
        ranges: vec![
            "plant.arm_mass=1..4".parse().expect("a range"),
            STIFF_OBSTACLES.parse().expect("a range"),
        ],
        ..SimOptions::default()
    };
    let read_as_disturbances = confirming_where_right(
        // With the lag's tenth allowed at any time: a link held by an obstacle and not
        // swung back holds the disturbance down through that allowance alone.
        &default_with_each(&[
            (HELD_BACK, LAG_ANY_TIME),
            (DISTURBANCE_DWELL, "dwell_ms = 5.0, hold_ms = 150.0"),
            (BACK_LATELY, ""),
        ]),
        &HEAVY_COLLISIONS,
        &heavy,
        "disturbance",
    );
    assert!(
        read_as_disturbances >= 6,
        "with a fixed 5 ms dwell only {read_as_disturbances} of the {} heavy arms' collisions read as disturbances: the test no longer shows the longer wait's part",
        HEAVY_COLLISIONS.len()
    );
}

#[test]
fn a_knock_whose_arm_swings_back_is_confirmed_before_the_longer_wait_ends() {
    let fixed = default_with(BACK_LATELY, "");
    let default = detector(APPROACH_TOML);
    let knocks = runs(Scenario::KnockLink2, 1..101, &SimOptions::default());
    let (mut sooner, mut later) = (0, 0);
    for k in &knocks {
        let at = |d: &Detector| confirmed_at(d, k, "disturbance");
        if let (Some(early), Some(waited)) = (at(&default), at(&fixed)) {
            sooner += usize::from(early <= waited - 0.002);
            later += usize::from(early > waited);
        }
    }
    assert_eq!(later, 0, "the early dwell confirmed {later} knocks later");
    assert!(
        sooner >= 60,
        "only {sooner} of 100 knocks on link 2 are confirmed at least 2 ms before a fixed 8 ms dwell ends: the test no longer shows the early end's part"
    );
}

/// Bursts on link 2 of the tuning seeds (base seed 100, run seeds as `fingertip evaluate`
/// names them) that push the arm against the approach: the confidence is held down while
/// the arm reads as held back (`lag_unshaken`), and the arm swings back onto its path
/// before it is let up. Judged on the swing back at the ticks the confidence is up only,
/// each waited the full 8 ms, confirmed 3-10 ms later.
const SWUNG_BACK_FIRST: [u64; 6] = [
    14_820_112_127_734_872_468,
    14_820_112_127_734_873_060,
    14_820_112_127_734_872_147,
    14_820_112_127_734_872_297,
    14_820_112_127_734_872_320,
    14_820_112_127_734_872_839,
];

#[test]
fn a_knock_whose_arm_swung_back_before_its_confidence_rose_is_confirmed_early() {
    knocks_confirmed_sooner_than(
        &SWUNG_BACK_FIRST,
        &default_with(BACK_LATELY, BACK_NOW),
        0.002,
        "with the swing back judged at the confidence's ticks only",
    );
}

#[test]
fn a_knock_on_a_finger_held_still_is_a_disturbance_and_never_a_collision() {
    // A finger held still (about 0.07 mm/s) in the approach phase: nothing can be driven
    // into an obstacle, so every blow is a disturbance. The paths on the vibration weigh
    // less there (a tenth for the jump, none for the averaged burst, where hunting loops
    // shake an arm at rest); the encoders' path and the jump still find knocks on link 2.
    let still = SimOptions {
        ranges: vec!["motion.speed_factor=0.001..0.002".parse().expect("a range")],
        ..SimOptions::default()
    };
    let default = detector(APPROACH_TOML);
    let mut right_on_link2 = 0;
    for s in [Scenario::KnockLink2, Scenario::KnockLink1] {
        for (seed, k) in (1..101).zip(runs(s, 1..101, &still)) {
            let events = confirmed(&default, &k);
            assert!(
                !events.iter().any(|e| e == "link_collision"),
                "{} seed {seed}: a knock on a finger held still confirmed a link collision ({events:?})",
                s.name()
            );
            if s == Scenario::KnockLink2 {
                right_on_link2 += usize::from(events == ["disturbance"]);
            }
        }
    }
    // 100 of 100 when this was written.
    assert!(
        right_on_link2 >= 90,
        "only {right_on_link2} of 100 knocks on link 2 of a finger held still are confirmed as one disturbance and nothing else"
    );
}

/// Runs of the tuning seeds (base seed 100, `--range obstacle.stiffness=2e3..1.5e4`: a
/// padded post, a person's arm) in which link 1 strikes a post that yields, where the pad
/// is turned towards joint 1: the blocked joint moves the tip ahead along the approach,
/// ever faster, which the swing back reads as the arm catching up. Without the gate on the
/// tip held off its path, each confirmed a disturbance 31-64 ms after the collision (with
/// the lag's tenth allowed at any time, as then: the allowance held back until the arm
/// swings back holds most of them down itself).
const YIELDING_POSTS: [(Scenario, u64); 8] = [
    (Scenario::LinkCollision8, 14_820_092_336_525_572_145),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_138),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_114),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_099),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_214),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_180),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_347),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_478),
];

#[test]
fn a_link_held_by_a_post_that_yields_is_no_arm_swung_back() {
    let read_as_disturbances = confirming_where_right(
        &ungated_with(HELD_BACK, LAG_ANY_TIME),
        &YIELDING_POSTS,
        &padded_posts(),
        "disturbance",
    );
    assert!(
        read_as_disturbances >= 6,
        "without the gate, only {read_as_disturbances} of the {} collisions with a post that yields confirm a disturbance: the test no longer shows the gate's part",
        YIELDING_POSTS.len()
    );
}

/// Link collisions at 8 cm/s of the tuning seeds (base seed 100, `--range
/// obstacle.stiffness=2e3..1.5e4`) in which a post that yields takes 1.5-15 % of the speed
/// away, under a tenth of it for most, while the struck link shakes the fingertip. With a
/// tenth of the travel allowed at any time, each was read as a disturbance 9-14 ms after
/// the collision.
const HOLDING_POSTS: [(Scenario, u64); 8] = [
    (Scenario::LinkCollision8, 14_820_092_336_525_572_134),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_136),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_119),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_098),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_221),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_199),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_193),
    (Scenario::LinkCollision8, 14_820_092_336_525_572_204),
];

#[test]
fn a_post_that_yields_holds_the_disturbance_until_the_arm_swings_back() {
    let read_as_disturbances = confirming_where_right(
        &default_with(HELD_BACK, LAG_ANY_TIME),
        &HOLDING_POSTS,
        &padded_posts(),
        "disturbance",
    );
    // All 8 when this was written.
    assert!(
        read_as_disturbances >= 6,
        "with a tenth of the travel allowed at any time, only {read_as_disturbances} of the {} collisions with a post that yields confirm a disturbance: the test no longer shows the allowance's part",
        HOLDING_POSTS.len()
    );
}
