//! The service channel end to end, in one process: the tool's client
//! (`fingertip::can_tools::service`) on one side, the firmware's end (`firmware::service_end`:
//! reassembly, the loader, the mailbox, the engine ticking every 200 µs) on the other,
//! joined by a model of a CAN FD bus at 1 and 5 Mbit/s that loses or corrupts frames.
//!
//! The bus: one frame at a time, the lowest identifier first when both ends wait, each
//! frame on the bus for `busload`'s worst-case time; the fingertip answers a frame 20 µs
//! after it ends (its receive task). The figures (`--nocapture`): the time a 5 kB image
//! takes from the request's first frame to the response's end.
//!
//! The properties: an image loads whole, its CRC-32 reported; the detector in service
//! keeps running during the transfer and the loaded one takes over at the phase boundary;
//! the loss or corruption of any single frame of a transfer, each in turn, either is
//! retried to the same result or fails, and at no tick does anything but the old or the
//! new detector run, nor anything but the new one wait staged.

#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

use std::collections::VecDeque;

#[path = "board_support.rs"]
mod board;

use board::{Feed, Fingertip, TICK_US};
use detector_core::Detector;
use embassy_futures::block_on;
use fingertip::can_tools::busload::fd_frame_bits;
use fingertip::can_tools::service::{Client, Link};
use fingertip_can::service::{ErrorCode, Key, Mode, Request, Response, crc32};
use firmware::boot;
use firmware::engine::Service;
use firmware::nvm::{BootImage, Slot};

/// The fingertip's reaction to a frame, µs.
const REACTION_US: u64 = 20;

/// A frame's worst-case time on the bus at 1 and 5 Mbit/s, µs.
fn frame_us(len: usize) -> f64 {
    fd_frame_bits(len).micros(1_000_000, 5_000_000)
}

/// What happens to the frames of an exchange, counted from 0 in the order they take the
/// bus (both directions).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Fault {
    None,
    Lose(usize),
    /// Flip bit `1` of frame `0`'s data.
    Corrupt(usize, usize),
}

/// The bus between the tool and one fingertip.
struct Bus {
    now_us: f64,
    fingertip: Fingertip,
    /// Frames from the tool, waiting for the bus.
    down: VecDeque<Vec<u8>>,
    /// Frames from the fingertip, waiting, and when each may go (µs).
    up: VecDeque<(Vec<u8>, f64)>,
    /// Frames the tool has received, waiting to be read.
    inbox: VecDeque<Vec<u8>>,
    /// Frames that took the bus so far.
    frames: usize,
    fault: Fault,
    bus_us: f64,
    /// When the last frame from the fingertip ended, µs.
    answered_us: f64,
}

impl Bus {
    fn new(fingertip: Fingertip) -> Bus {
        Bus {
            now_us: 0.0,
            fingertip,
            down: VecDeque::new(),
            up: VecDeque::new(),
            inbox: VecDeque::new(),
            frames: 0,
            fault: Fault::None,
            bus_us: 0.0,
            answered_us: 0.0,
        }
    }

    /// The next frame to take the bus at the present time, lowest identifier first (the
    /// request identifier, 0x683, beats the response, 0x693).
    fn next_frame(&mut self) -> Option<(bool, Vec<u8>)> {
        if let Some(f) = self.down.pop_front() {
            return Some((true, f));
        }
        match self.up.front() {
            Some((_, at)) if *at <= self.now_us => self.up.pop_front().map(|(f, _)| (false, f)),
            _ => None,
        }
    }

    /// Carries frames until `until_us` or until the tool has one to read.
    fn run(&mut self, until_us: f64) {
        while self.inbox.is_empty() && self.now_us < until_us {
            let Some((down, mut data)) = self.next_frame() else {
                // Idle until the fingertip's next answer, tick, or the deadline.
                let next = self
                    .up
                    .front()
                    .map_or(until_us, |(_, at)| *at)
                    .min(until_us);
                let tick = self.fingertip.next_tick_us as f64;
                self.now_us = self.now_us.max(next.min(tick.max(self.now_us)));
                self.fingertip.run_to(self.now_us as u64);
                if next <= self.now_us && self.up.is_empty() && next >= until_us {
                    break;
                }
                continue;
            };
            let k = self.frames;
            self.frames += 1;
            let t = frame_us(data.len());
            self.now_us += t;
            self.bus_us += t;
            self.fingertip.run_to(self.now_us as u64);
            match self.fault {
                Fault::Lose(n) if n == k => continue,
                Fault::Corrupt(n, bit) if n == k => {
                    let i = bit / 8 % data.len();
                    data[i] ^= 1 << (bit % 8);
                }
                _ => {}
            }
            if down {
                let now = self.now_us as u64;
                let f = &mut self.fingertip;
                if let Some(answer) = block_on(f.end.on_frame(&data, now, &mut f.requests)) {
                    self.up
                        .push_back((answer.data().to_vec(), self.now_us + REACTION_US as f64));
                }
            } else {
                self.answered_us = self.now_us;
                self.inbox.push_back(data);
            }
        }
    }
}

impl Link for Bus {
    fn send(&mut self, data: &[u8]) -> std::io::Result<()> {
        self.down.push_back(data.to_vec());
        Ok(())
    }

    fn recv(&mut self, until_us: u64) -> std::io::Result<Option<Vec<u8>>> {
        self.run(until_us as f64);
        if self.inbox.is_empty() && self.now_us < until_us as f64 {
            self.now_us = until_us as f64;
            self.fingertip.run_to(until_us);
        }
        Ok(self.inbox.pop_front())
    }

    fn now_us(&mut self) -> u64 {
        self.now_us.ceil() as u64
    }
}

/// A valid detector for the board whose image is about 5 kB: every board channel, 16
/// features and 8 events of 8 phases with long names, many distinct confidence functions.
fn image_5k() -> Vec<u8> {
    let channels = [
        "force_x",
        "force_y",
        "skin_accel",
        "stress_rate",
        "pos_err_x",
        "pos_err_y",
        "vel_des_x",
        "vel_des_y",
        "acc_des_x",
        "acc_des_y",
    ];
    let mut t = String::from("rate_hz = 5000.0\n");
    for c in channels {
        t += &format!("[[channel]]\nname = \"{c}\"\nunit = \"x\"\n");
    }
    for f in 0..16 {
        let input = channels[f % channels.len()];
        t += &format!(
            "[[feature]]\nname = \"feature_number_{f:02}_xxxxx\"\nstage = {{ low_pass = {{ input = \"{input}\", cutoff_hz = {} }} }}\n",
            10 + f
        );
    }
    for e in 0..8 {
        t += &format!("[[event]]\nname = \"event_number_{e}_xxxxxxxxx\"\nsensor = [\n");
        for k in 0..8 {
            let f = (e + k) % 16;
            t += &format!(
                "  {{ feature = \"feature_number_{f:02}_xxxxx\", weight = 0.125, cdf = {{ flat_bell = {{ low = {}.0, plateau_low = {}.5, plateau_high = {}.0, high = {}.0 }} }} }},\n",
                e * 10 + k,
                e * 10 + k + 1,
                e * 10 + k + 4,
                e * 10 + k + 5
            );
        }
        t += "]\nalert = { on = 0.5, off = 0.3 }\nconfirm = { on = 0.75, off = 0.5 }\n";
    }
    for p in 0..8 {
        t += &format!(
            "[[phase]]\nname = \"phase_number_{p}_xxxxxxxxx\"\nevents = [\"event_number_{p}_xxxxxxxxx\"]\n"
        );
    }
    let config = detector_build::Config::from_toml(&t).unwrap();
    detector_build::compile(&config).unwrap().image()
}

/// Loads `image` through `bus` (its first attempt hit by `fault`), then runs 10 ms more.
fn load(bus: Bus, image: &[u8], fault: Fault) -> (Client<Bus>, Result<Response, String>) {
    let mut bus = bus;
    bus.fault = fault;
    let mut client = Client::new(bus);
    let r = client
        .request(&Request::Load { name: "big", image })
        .map_err(|e| e.to_string());
    let link = client.link();
    let end = link.now_us + 10_000.0;
    link.run(end);
    (client, r)
}

/// The largest valid image, padded to 5,000 bytes: refused for its trailing bytes, after
/// the whole transfer.
fn padded_5k() -> Vec<u8> {
    let mut image = image_5k();
    image.resize(5000, 0);
    image
}

#[test]
fn a_5000_byte_image_crosses_in_well_under_100_ms() {
    let image = padded_5k();
    let (mut client, r) = load(Bus::new(Fingertip::new()), &image, Fault::None);
    let Ok(Response::Error(ErrorCode::Image, text)) = r else {
        panic!("{r:?}")
    };
    assert!(text.contains("bytes follow"), "{text}");
    let bus = client.link();
    println!(
        "a 5000-byte image: {} frames, {:.2} ms of bus time, answered at {:.2} ms",
        bus.frames,
        bus.bus_us / 1000.0,
        bus.answered_us / 1000.0
    );
    assert!(bus.answered_us < 100_000.0);
}

#[test]
fn an_image_loads_whole_and_takes_over_at_activation() {
    let image = image_5k();
    assert!(image.len() > 4000, "{} bytes", image.len());
    let (mut client, r) = load(Bus::new(Fingertip::new()), &image, Fault::None);
    assert_eq!(r, Ok(Response::Staged(crc32(&image))));
    assert_eq!(client.attempts, 1);
    let bus = client.link();
    // The first frame left at 0: the response's end is the load time.
    let seen = &bus.fingertip.seen;
    let staged_at = seen.iter().position(|s| s.1.is_some()).unwrap();
    let built_in = boot::CONFIG_CHECKSUM;
    assert!(
        seen.iter().all(|s| s.0 == built_in),
        "the old detector runs on"
    );
    println!(
        "a {}-byte image: {} frames, {:.2} ms of bus time, answered at {:.2} ms, staged at tick {}",
        image.len(),
        bus.frames,
        bus.bus_us / 1000.0,
        bus.answered_us / 1000.0,
        staged_at,
    );
    assert!(bus.bus_us < 20_000.0, "{} µs", bus.bus_us);
    assert!((staged_at as u64) * TICK_US < 100_000);
    // Identify reports both; activation puts the new one in service at the next tick.
    let Ok(Response::Identity(id)) = client.request(&Request::Identify) else {
        panic!()
    };
    assert_eq!((id.mode, id.detector_crc), (Mode::BuiltIn, built_in));
    assert_eq!(id.staged_crc, Some(crc32(&image)));
    assert_eq!(id.build, firmware::version::BUILD_HASH);
    assert_eq!(
        client.request(&Request::Activate).unwrap(),
        Response::Active(crc32(&image))
    );
    let link = client.link();
    let before = link.fingertip.seen.len();
    let end = link.now_us + 1000.0;
    link.run(end);
    let after = &link.fingertip.seen[before..];
    assert_eq!(after[0].0, crc32(&image), "in service at the next tick");
    let Ok(Response::Identity(id)) = client.request(&Request::Identify) else {
        panic!()
    };
    assert_eq!((id.mode, id.detector_name.as_str()), (Mode::Loaded, "big"));
    assert_eq!(id.staged_crc, None);
    // The ticks never stopped: one per 200 µs of the whole exchange.
    let link = client.link();
    assert_eq!(
        link.fingertip.seen.len() as u64,
        link.fingertip.next_tick_us / TICK_US
    );
}

#[test]
fn a_bad_image_is_refused_by_name_and_nothing_is_staged() {
    let mut image = boot::DETECTOR_IMAGE.to_vec();
    image[4] = 0x7F; // the rate section's tag, after the magic
    let (mut client, r) = load(Bus::new(Fingertip::new()), &image, Fault::None);
    let Ok(Response::Error(ErrorCode::Image, text)) = r else {
        panic!("{r:?}")
    };
    assert!(text.contains("section"), "{text}");
    assert!(client.link().fingertip.seen.iter().all(|s| s.1.is_none()));
    assert!(matches!(
        client.request(&Request::Activate).unwrap(),
        Response::Error(ErrorCode::NothingStaged, _)
    ));
}

#[test]
fn any_frame_lost_or_corrupted_is_retried_or_fails_and_nothing_half_loaded_runs() {
    let image = image_5k();
    let crc = crc32(&image);
    let built_in = boot::CONFIG_CHECKSUM;
    let (mut clean, _) = load(Bus::new(Fingertip::new()), &image, Fault::None);
    let frames = clean.link().frames;
    let mut retried = 0;
    for k in 0..frames {
        for fault in [Fault::Lose(k), Fault::Corrupt(k, 8 + 13 * k)] {
            let (mut client, r) = load(Bus::new(Fingertip::new()), &image, fault);
            match r {
                Ok(Response::Staged(c)) => assert_eq!(c, crc, "{fault:?}"),
                other => panic!("{fault:?}: {other:?}"),
            }
            if client.attempts > 1 {
                retried += 1;
            }
            let seen = &client.link().fingertip.seen;
            assert!(
                seen.iter()
                    .all(|&(active, staged)| active == built_in && staged.is_none_or(|s| s == crc)),
                "{fault:?}"
            );
        }
    }
    println!(
        "{frames} frames per transfer, {retried} of {} faults retried",
        2 * frames
    );
    assert!(retried >= frames, "most faults must need a retry");
}

/// Sends `request` and returns the answer, the exchange retried as needed.
fn ask(client: &mut Client<Bus>, request: Request<'_>) -> Response {
    client.request(&request).unwrap()
}

#[test]
fn flash_writes_wait_for_the_service_state_and_outlast_a_reboot() {
    let image = image_5k();
    let mut client = Client::new(Bus::new(Fingertip::new()));
    let key = Key::parse("force_x.gain").unwrap();
    let gain = (20.0f32 / 4096.0).to_le_bytes();
    // Outside the service state: refused, nothing written.
    let save = Request::Save {
        name: "fitted",
        image: &image,
    };
    assert!(matches!(
        ask(&mut client, save),
        Response::Error(ErrorCode::NotInService, _)
    ));
    assert!(matches!(
        ask(&mut client, Request::WriteKey(key, gain)),
        Response::Error(ErrorCode::NotInService, _)
    ));
    assert!(matches!(
        ask(&mut client, Request::ReadKey(key)),
        Response::Error(ErrorCode::Key, _)
    ));
    // In it: the detector out of service (heartbeats say so), then the writes.
    assert_eq!(ask(&mut client, Request::EnterService), Response::Done);
    let link = client.link();
    let end = link.now_us + 1000.0;
    link.run(end);
    let Service::Running(e) = &link.fingertip.service else {
        panic!()
    };
    assert!(e.in_service_state());
    assert!(
        e.status()
            .faults
            .contains(fingertip_can::FaultFlags::SERVICE)
    );
    let Response::Saved {
        crc,
        slot,
        stall_ms,
    } = ask(&mut client, save)
    else {
        panic!()
    };
    assert_eq!((crc, slot), (crc32(&image), 1));
    // A 4.4 kB image: 5 pages erased and 560 double words at most.
    assert!((120..=200).contains(&stall_ms), "{stall_ms} ms");
    assert_eq!(
        ask(&mut client, Request::WriteKey(key, gain)),
        Response::Written
    );
    assert!(matches!(
        ask(&mut client, Request::WriteKey(Key::NodeId, 15u32.to_le_bytes())),
        Response::Error(ErrorCode::Key, text) if text.contains("node_id 15")
    ));
    assert!(matches!(
        ask(&mut client, Request::WriteKey(key, 0.0f32.to_le_bytes())),
        Response::Error(ErrorCode::Key, text) if text.contains("gain")
    ));
    assert_eq!(
        ask(&mut client, Request::ReadKey(key)),
        Response::Value(gain)
    );
    assert_eq!(ask(&mut client, Request::LeaveService), Response::Done);
    let link = client.link();
    let end = link.now_us + 1000.0;
    link.run(end);
    let Service::Running(e) = &link.fingertip.service else {
        panic!()
    };
    assert!(!e.in_service_state());
    // After a reboot the flash holds the saved detector in slot A.
    let nvm = link.fingertip.requests.nvm();
    let mut buf = vec![0u8; firmware::nvm::SLOT_IMAGE_MAX];
    let Ok(BootImage::Slot(Slot::A, h)) = block_on(nvm.boot_image(&mut buf)) else {
        panic!()
    };
    assert_eq!((h.crc, h.name.as_str()), (crc32(&image), "fitted"));
    assert_eq!(block_on(nvm.read_key(key.raw())), Ok(Some(gain)));
}

/// A fingertip fed 0.4 s of free motion, then a hard contact at 8 cm/s: its recorder
/// freezes 50 ms after the first confirmation, its run started long before.
fn fed_fingertip() -> Fingertip {
    use fingertip::sim::{Scenario, SimOptions, simulate};
    let sim = |scenario: Scenario, duration_s: Option<f64>| {
        let opts = SimOptions {
            seed: 11,
            randomize: true,
            duration_s,
            ..SimOptions::default()
        };
        simulate(&scenario, &opts).unwrap()
    };
    let free = sim(Scenario::FreeMotion, Some(0.4));
    let contact = sim(Scenario::ContactHard8, None);
    Fingertip::fed(Feed::new(&[free, contact]))
}

/// A bus whose fingertip has run through its feed and 100 ms more.
fn after_the_feed(fingertip: Fingertip) -> Bus {
    let ticks = fingertip.feed.as_ref().unwrap().rows.len() as u64 + 500;
    let mut bus = Bus::new(fingertip);
    bus.fingertip.run_to(ticks * TICK_US);
    bus.now_us = (ticks * TICK_US) as f64;
    bus
}

#[test]
fn a_flight_recording_read_over_the_bus_replays_on_the_pc_as_the_chip_ran() {
    use fingertip::can_tools::recording::{self, RecordingError};
    use fingertip_can::service::{PAGE_MAX, RecordingCause};

    let mut client = Client::new(after_the_feed(fed_fingertip()));
    let (start_us, bus_before) = (client.link().now_us, client.link().bus_us);
    let rec = recording::fetch(&mut client).unwrap();
    let info = rec.info;
    let bus = client.link();
    println!(
        "a flight recording of {} ticks ({} channels): {} bytes in {} pages, {:.1} ms of bus time, read in {:.1} ms",
        info.rows,
        info.channels,
        info.bytes,
        (info.bytes as usize).div_ceil(PAGE_MAX),
        (bus.bus_us - bus_before) / 1000.0,
        (bus.now_us - start_us) / 1000.0
    );
    assert!(info.frozen);
    let Some(RecordingCause::Confirmed(event)) = info.cause else {
        panic!("frozen by {:?}", info.cause)
    };
    assert!(
        info.first_tick > 1000,
        "the run started long before the recording"
    );
    assert!(
        info.trigger_tick - info.first_tick >= 250,
        "at least 50 ms before the confirmation"
    );
    assert_eq!(
        info.first_tick + info.rows - 1 - info.trigger_tick,
        250,
        "50 ms after it"
    );

    // What the tool writes, read back.
    let mut d = Detector::empty();
    boot::load_detector(&mut d, boot::DETECTOR_IMAGE).unwrap();
    let crc = crc32(boot::DETECTOR_IMAGE);
    let text = rec.to_trace(&d, crc, "recording.csv").unwrap().to_csv();
    let trace = fingertip::trace::Trace::parse(&text, "recording.csv").unwrap();
    let decisions = rec.check_replay(&d, &trace).unwrap();
    assert!(
        decisions
            .iter()
            .any(|r| r.is_confirm() && r.event == d.events()[usize::from(event)].as_str())
    );

    // Tick by tick, the PC's confidences and confirmations are the chip's.
    let chip = &client.link().fingertip.outputs;
    let mut rows = 0;
    fingertip::replay::replay(&d, &trace, |row, _, out| {
        let tick = info.first_tick as usize + row;
        assert_eq!(
            (out.confidences, out.decisions.to_vec()),
            chip[tick].clone(),
            "tick {tick}"
        );
        rows += 1;
    })
    .unwrap();
    assert_eq!(rows, info.rows);

    // Another detector's configuration is refused, naming both CRCs.
    let other = rec.to_trace(&d, crc ^ 1, "x").unwrap_err();
    assert!(matches!(other, RecordingError::Detector { .. }), "{other}");
    assert!(other.to_string().contains(&format!("{crc:#010x}")));

    // Re-armed, the recorder records again and has nothing to read.
    assert_eq!(
        client.request(&Request::RecordingRearm).unwrap(),
        Response::Done
    );
    let again = recording::fetch(&mut client).unwrap_err();
    assert!(matches!(again, RecordingError::NotFrozen { .. }), "{again}");
}

#[test]
fn a_page_lost_or_corrupted_on_the_bus_is_read_again() {
    use fingertip::can_tools::recording;

    let clean = recording::fetch(&mut Client::new(after_the_feed(fed_fingertip()))).unwrap();
    for fault in [
        Fault::Lose(9),
        Fault::Corrupt(12, 200),
        Fault::Corrupt(31, 17),
    ] {
        let mut bus = after_the_feed(fed_fingertip());
        bus.fault = match fault {
            Fault::Lose(n) => Fault::Lose(bus.frames + n),
            Fault::Corrupt(n, bit) => Fault::Corrupt(bus.frames + n, bit),
            Fault::None => Fault::None,
        };
        let mut client = Client::new(bus);
        assert_eq!(recording::fetch(&mut client).unwrap(), clean, "{fault:?}");
    }
}

#[test]
fn recordings_are_collected_one_after_another_as_they_freeze() {
    use fingertip::can_tools::recording::{self, RecordingError};
    use fingertip::sim::{Scenario, SimOptions, simulate};

    // Two contacts 0.8 s apart (the contact's confirmation holds 0.5 s after it ends).
    let sim = |scenario: Scenario, seed: u64, duration_s: Option<f64>| {
        let opts = SimOptions {
            seed,
            randomize: true,
            duration_s,
            ..SimOptions::default()
        };
        simulate(&scenario, &opts).unwrap()
    };
    let feed = Feed::new(&[
        sim(Scenario::FreeMotion, 1, Some(0.3)),
        sim(Scenario::ContactHard8, 2, None),
        sim(Scenario::FreeMotion, 3, Some(0.8)),
        sim(Scenario::ContactHard5, 4, None),
    ]);
    let end_us = (feed.rows.len() as u64 + 1000) * TICK_US;
    let mut client = Client::new(Bus::new(Fingertip::fed(feed)));
    let mut d = Detector::empty();
    boot::load_detector(&mut d, boot::DETECTOR_IMAGE).unwrap();
    let crc = crc32(boot::DETECTOR_IMAGE);
    let mut triggers = Vec::new();
    while let Some(info) = recording::wait_frozen(&mut client, 20_000, Some(end_us)).unwrap() {
        let rec = recording::fetch(&mut client).unwrap();
        assert_eq!(rec.info, info);
        let trace = rec.to_trace(&d, crc, "collected").unwrap();
        rec.check_replay(&d, &trace).unwrap();
        triggers.push((info.trigger_tick, info.cause));
        assert_eq!(
            client.request(&Request::RecordingRearm).unwrap(),
            Response::Done
        );
    }
    assert_eq!(triggers.len(), 2, "{triggers:?}");
    assert!(triggers[1].0 > triggers[0].0 + 4000, "{triggers:?}");
    // Nothing more to read.
    let e = recording::fetch(&mut client).unwrap_err();
    assert!(matches!(e, RecordingError::NotFrozen { .. }), "{e}");
}
