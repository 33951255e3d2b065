//! A fingertip's firmware on the PC, for the tests that run it (included with `#[path]`):
//! the board's engine with the built-in detector, its service channel's end, its flight
//! recorder, ticking every 200 µs, fed a simulated run as its sensors and its controller
//! would feed it.
#![allow(dead_code)]
#![allow(clippy::unwrap_used, reason = "test code: a panic is the failure")]

// The firmware's mutexes take critical sections: std's implementation on the PC.
use critical_section as _;

use detector_core::{Confidence, Decision, Detector, MAX_EVENTS, Signal};
use fingertip_can::{
    BusFormat, ContextGroup, ContextMsg, ContextSlot, Counter, NodeId, NodeIdSource, ResetReason,
};
use firmware::boot::{self, ApproachTick};
use firmware::engine::{BoardInfo, Health, Service};
use firmware::flash_sim::SimFlash;
use firmware::load::Loader;
use firmware::nvm::Nvm;
use firmware::recorder::RecorderCell;
use firmware::sampling::AdcSample;
use firmware::service_end::{Mailbox, Requests, ServiceEnd};
use firmware::shared::RxShared;

/// The detector's tick, µs.
pub const TICK_US: u64 = 200;

/// A fingertip's firmware on the PC: what the board's tasks run.
pub struct Fingertip {
    /// The engine with the built-in detector (or its fallback).
    pub service: Service<'static, ApproachTick>,
    /// The service channel's receiving end.
    pub end: ServiceEnd,
    /// What carries requests out, on a simulated flash.
    pub requests: Requests<'static, 'static, &'static mut SimFlash>,
    /// Where the service channel and the detector task meet.
    pub mailbox: &'static Mailbox<'static>,
    /// The flight recorder.
    pub recorder: &'static RecorderCell,
    /// The receive state the CAN receive task and the engine share.
    pub rx: RxShared,
    /// The next tick.
    pub tick: u32,
    /// When the next tick runs, µs.
    pub next_tick_us: u64,
    /// The CRC-32 of the detector in service and of the one staged, at every tick.
    pub seen: Vec<(u32, Option<u32>)>,
    /// What the sensors and the controller give, if not zeros: row `k` at tick `k`.
    pub feed: Option<Feed>,
    /// The next context frame's counter.
    pub counter: u8,
    /// Each tick's event confidences and the levels raised (with their ticks and
    /// onsets), by tick.
    pub outputs: Vec<([Confidence; MAX_EVENTS], Vec<Decision>)>,
}

/// A simulated run fed to the fingertip as its sensors and the controller would: the
/// calibrated analog channels every tick, the controller's context frame (raw, as sent)
/// at the tick its values arrive in the run (the simulator holds them from their arrival,
/// after the controller's latency), and every fifth tick at least. The last row is held
/// after the end.
pub struct Feed {
    /// The board's ten channels, by tick.
    pub rows: Vec<[f64; 10]>,
}

/// The channels a controller's context frame carries, in a feed row's order after the four
/// analog ones: each with its step in the frame (0.1 mm/s, 2 mm/s², 1 µm) and its largest
/// raw value.
pub const FRAMED: [(&str, f64, i16); 6] = [
    ("vel_des_x", 1e-4, 4095),
    ("vel_des_y", 1e-4, 4095),
    ("acc_des_x", 2e-3, 4095),
    ("acc_des_y", 2e-3, 4095),
    ("pos_err_x", 1e-6, 32767),
    ("pos_err_y", 1e-6, 32767),
];

/// `v` in a frame's raw steps of `step`, within ±`max`.
fn raw(v: f64, step: f64, max: i16) -> i16 {
    (v / step).round().clamp(-f64::from(max), f64::from(max)) as i16
}

/// `trace` with its context channels as the controller's frames carry them, rounded to
/// their steps, and its phases: what the board's detector reads of it.
pub fn framed(trace: &fingertip::trace::Trace) -> fingertip::trace::Trace {
    let channels = trace
        .channel_names()
        .iter()
        .map(|n| {
            let column = trace.column(n).unwrap();
            let values = match FRAMED.iter().find(|(f, ..)| f == n) {
                Some(&(_, step, max)) => column
                    .iter()
                    .map(|&v| f64::from(raw(v, step, max)) * step)
                    .collect(),
                None => column.to_vec(),
            };
            (n.clone(), values)
        })
        .collect();
    let out = fingertip::trace::Trace::from_columns(trace.name(), trace.time().to_vec(), channels)
        .unwrap();
    match trace.phase() {
        Some(phase) => out.with_phase(phase.clone()).unwrap(),
        None => out,
    }
}

impl Feed {
    /// The ten board channels of `traces`, one after the other.
    pub fn new(traces: &[fingertip::trace::Trace]) -> Feed {
        let analog = ["force_x", "force_y", "skin_accel", "stress_rate"];
        let names: [&str; 10] = std::array::from_fn(|k| match k {
            0..4 => analog[k],
            _ => FRAMED[k - 4].0,
        });
        let mut rows = Vec::new();
        for t in traces {
            let columns = names.map(|n| t.column(n).unwrap());
            rows.extend((0..t.len()).map(|k| columns.map(|c| c[k])));
        }
        Feed { rows }
    }

    /// The row of `tick`, the last one after the end.
    pub fn row(&self, tick: u32) -> &[f64; 10] {
        &self.rows[(tick as usize).min(self.rows.len() - 1)]
    }
}

impl Default for Fingertip {
    fn default() -> Self {
        Fingertip::new()
    }
}

impl Fingertip {
    /// A fingertip with the built-in detector, fed zeros and no context.
    pub fn new() -> Fingertip {
        let board = BoardInfo {
            node: NodeId::new(3).unwrap(),
            node_source: NodeIdSource::Straps,
            format: BusFormat::Fd,
            reset: ResetReason::PowerOn,
            clock_fallback: false,
        };
        let active: &'static mut Detector = Box::leak(Box::new(Detector::empty()));
        let spare: &'static mut Detector = Box::leak(Box::new(Detector::empty()));
        let service = boot::start(active, boot::DETECTOR_IMAGE, ApproachTick, board);
        let mailbox: &'static Mailbox<'static> = Box::leak(Box::new(Mailbox::new()));
        let loader = Loader::new(spare, boot::RATE_HZ as f32);
        let recorder: &'static RecorderCell = Box::leak(Box::new(RecorderCell::new()));
        Fingertip {
            service,
            end: ServiceEnd::new(),
            requests: Requests::new(
                loader,
                mailbox,
                recorder,
                Nvm::new(Box::leak(Box::new(SimFlash::new()))),
            ),
            recorder,
            mailbox,
            rx: RxShared::new(),
            tick: 0,
            next_tick_us: 0,
            seen: Vec::new(),
            feed: None,
            counter: 0,
            outputs: Vec::new(),
        }
    }

    /// Fed from `feed`.
    pub fn fed(feed: Feed) -> Fingertip {
        Fingertip {
            feed: Some(feed),
            ..Fingertip::new()
        }
    }

    /// The analog sample of the tick, and the controller's frame at its control cycles.
    pub fn inputs(&mut self) -> AdcSample {
        let mut sample = AdcSample {
            tick: self.tick,
            ..AdcSample::default()
        };
        let Some(feed) = &self.feed else {
            return sample;
        };
        let row = feed.row(self.tick);
        for (v, &si) in sample.values.iter_mut().zip(&row[..4]) {
            *v = Signal::from_f64(si);
        }
        let arrived = self.tick == 0 || feed.row(self.tick - 1)[4..] != row[4..];
        if arrived || self.tick.is_multiple_of(5) {
            let framed = |k: usize| {
                let (_, step, max) = FRAMED[k];
                raw(row[4 + k], step, max)
            };
            let node = NodeId::new(3).unwrap();
            let mut m = ContextMsg {
                counter: Counter(self.counter),
                time_us: self.tick.wrapping_mul(200),
                ..ContextMsg::default()
            };
            m.slots[ContextGroup::slot_of(node)] = Some(ContextSlot {
                vel_des: [framed(0), framed(1)],
                acc_des: [framed(2), framed(3)],
                pos_err: [framed(4), framed(5)],
            });
            let frame = m.encode(ContextGroup::of(node)).unwrap();
            self.counter = self.counter.wrapping_add(1);
            let r = self.service.receiver().unwrap();
            self.rx
                .with(|s| r.receive(s, self.tick, frame.id().into(), frame.data()))
                .unwrap();
        }
        sample
    }

    /// Runs the detector's ticks up to `now_us`.
    pub fn run_to(&mut self, now_us: u64) {
        while self.next_tick_us <= now_us {
            self.mailbox.serve(&mut self.service);
            let sample = self.inputs();
            let r = self.service.tick(&sample, &self.rx, &Health::default());
            self.recorder.record(&self.service);
            self.outputs
                .push((r.output.confidences, r.output.decisions.to_vec()));
            let Service::Running(e) = &self.service else {
                panic!("the built-in detector runs")
            };
            self.seen.push((e.in_service().1, e.staged_crc()));
            self.tick += 1;
            self.next_tick_us += TICK_US;
        }
    }
}
