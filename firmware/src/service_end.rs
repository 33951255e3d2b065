//! The fingertip's end of the service channel ([`fingertip_can::service`]): requests
//! reassembled from the node's request identifier, carried out, and answered on its
//! response identifier.
//!
//! Two tasks share the work, as on the board: the CAN receive side ([`ServiceEnd`] and
//! [`Requests`], on the thread executor) takes the frames, checks and loads a detector
//! image into the spare detector ([`crate::load::Loader`]: milliseconds of work the
//! detector task never waits for) and answers; the detector task, once per tick, hands
//! the engine what was posted for it and publishes what it runs ([`Mailbox::serve`]).
//! They meet in the [`Mailbox`], under a critical section held for a few instructions.
//!
//! Writes of the flash ([`crate::nvm`]: saving a detector to a slot, writing a key)
//! happen only in the service state, which the tool asks for first: the detector task
//! takes the engine out of service at its next tick ([`Engine::set_service`]), and a
//! write is refused until it has (the flash stalls the CPU, ticks included).
//!
//! Two detectors take turns: the one in service and a spare. A load goes into the spare;
//! the engine takes it at its phase boundary and sends the one it replaced back as the
//! next spare. While a loaded detector waits for its boundary there is no spare, and a
//! second load is refused as busy.

use core::cell::RefCell;

use detector_core::Detector;
use detector_core::DetectorTick;
use embassy_sync::blocking_mutex::Mutex;
use embedded_storage_async::nor_flash::NorFlash;
use fingertip_can::service::{
    CrashReport, DetectorName, ErrorCode, Identity, Key, Mode, PAGE_MAX, Request, Response, detail,
};
use fingertip_can::transfer::{MAX_MESSAGE, Payload, Reassembler, Received, SINGLE_MAX, Sender};

use crate::calib::{Calibration, CalibrationError};
use crate::engine::{Engine, Service};
use crate::load::{LoadError, Loader, Staged};
use crate::nvm::Nvm;
use crate::recorder::RecorderCell;
use crate::shared::RawMutex;
use crate::version::VERSION;

/// Consecutive frames the fingertip takes per flow control: with no gap asked for, a
/// block is 16 × 170 µs = 2.7 ms of bus time, and the receive task has the next flow
/// control's round trip to catch up.
pub const BLOCK_SIZE: u8 = 16;

/// What the detector task last published of the detector in service.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
struct Published {
    mode: Mode,
    crc: u32,
    name: DetectorName,
    staged: Option<u32>,
    /// The engine is in the service state.
    service: bool,
}

struct Inner<'d> {
    /// Loaded, for the engine to stage.
    posted: Option<Staged<'d>>,
    /// Replaced by the engine, for the loader.
    retired: Option<&'d mut Detector>,
    activate: bool,
    /// The service state asked for.
    service: bool,
    published: Published,
}

/// Where the receive side and the detector task meet.
pub struct Mailbox<'d>(Mutex<RawMutex, RefCell<Inner<'d>>>);

impl Default for Mailbox<'_> {
    fn default() -> Self {
        Mailbox::new()
    }
}

impl<'d> Mailbox<'d> {
    /// Empty.
    pub const fn new() -> Mailbox<'d> {
        Mailbox(Mutex::new(RefCell::new(Inner {
            posted: None,
            retired: None,
            activate: false,
            service: false,
            published: Published {
                mode: Mode::BuiltIn,
                crc: 0,
                name: DetectorName::new(),
                staged: None,
                service: false,
            },
        })))
    }

    fn with<R>(&self, f: impl FnOnce(&mut Inner<'d>) -> R) -> R {
        self.0.lock(|i| f(&mut i.borrow_mut()))
    }

    /// From the detector task, once per tick before the tick: stages what was posted,
    /// asks for activation, takes back the detector the engine retired, and publishes
    /// what runs. A fallback publishes that nothing does.
    pub fn serve<T: DetectorTick>(&self, service: &mut Service<'d, T>) {
        self.with(|i| match service {
            Service::Running(engine) => i.serve(engine),
            Service::Fallback(f, _) => {
                i.published.mode = Mode::Fallback;
                i.published.crc = f.status().config_checksum;
            }
        });
    }
}

impl<'d> Inner<'d> {
    fn serve<T: DetectorTick>(&mut self, engine: &mut Engine<'d, T>) {
        if let Some(s) = self.posted.take() {
            // Only one detector is ever out of the engine (see the module's header), so a
            // replaced staged one cannot meet another here.
            if let Some(old) = engine.stage(s) {
                self.retired = Some(old.detector);
            }
        }
        if core::mem::take(&mut self.activate) {
            engine.activate();
        }
        if let Some(d) = engine.take_retired() {
            self.retired = Some(d);
        }
        engine.set_service(self.service);
        self.published.service = engine.in_service_state();
        let (mode, crc, name) = engine.in_service();
        let p = &mut self.published;
        p.staged = engine.staged_crc();
        if p.mode != mode || p.crc != crc {
            p.mode = mode;
            p.crc = crc;
            p.name.clone_from(name);
        }
    }
}

/// Carries out requests: the receive side's handler, with the board's flash.
pub struct Requests<'m, 'd, F> {
    loader: Loader<'d>,
    mailbox: &'m Mailbox<'d>,
    recorder: &'m RecorderCell,
    nvm: Nvm<F>,
    last_crash: Option<CrashReport>,
}

/// A failed request's response.
fn error(code: ErrorCode, args: core::fmt::Arguments<'_>) -> Response {
    Response::Error(code, detail(args))
}

/// Whether `value` may be written to `key`: a node id within 0..=14, a calibration
/// parameter within [`Calibration::new`]'s ranges.
fn check_key(key: Key, value: [u8; 4]) -> Result<(), Response> {
    match key {
        Key::NodeId => match u32::from_le_bytes(value) {
            0..=14 => Ok(()),
            v => Err(error(
                ErrorCode::Key,
                format_args!("node_id {v} is not within 0..=14"),
            )),
        },
        Key::Calibration { parameter, .. } => {
            let v = f32::from_le_bytes(value);
            // The parameter alone, the others at values the ranges take.
            let mut p = [1.0, 2048.0, 0.0, 25.0];
            p[parameter as usize] = v;
            // The range, not the value: float formatting would cost the firmware 10 KiB
            // of flash.
            Calibration::new(p[0], p[1], p[2], p[3])
                .map(|_| ())
                .map_err(|e| {
                    let range = match e {
                        CalibrationError::Gain(_) => "finite, non-zero, below 128 per count",
                        CalibrationError::Zero(_) => "within 0..=65535 counts",
                        CalibrationError::Drift(_) => "within ±1000 counts per °C",
                        CalibrationError::Reference(_) => "within ±1000 °C",
                    };
                    error(ErrorCode::Key, format_args!("{key} must be {range}"))
                })
        }
    }
}

impl<'m, 'd, F: NorFlash> Requests<'m, 'd, F> {
    /// Requests served with `loader`'s spare detector, meeting the detector task in
    /// `mailbox`, keeping what must last in `nvm`, reading out the flight `recorder`.
    pub fn new(
        loader: Loader<'d>,
        mailbox: &'m Mailbox<'d>,
        recorder: &'m RecorderCell,
        nvm: Nvm<F>,
    ) -> Requests<'m, 'd, F> {
        Requests {
            loader,
            mailbox,
            recorder,
            nvm,
            last_crash: None,
        }
    }

    /// Answers LastCrash with `crash`, found at boot ([`crate::crash`]).
    pub fn with_last_crash(mut self, crash: Option<CrashReport>) -> Requests<'m, 'd, F> {
        self.last_crash = crash;
        self
    }

    /// The flash.
    pub fn nvm(&mut self) -> &mut Nvm<F> {
        &mut self.nvm
    }

    /// Whether the engine is in the service state (a flash write may go), else the
    /// response refusing one.
    fn writable(&self) -> Result<(), Response> {
        if self.mailbox.with(|i| i.published.service) {
            Ok(())
        } else {
            Err(error(
                ErrorCode::NotInService,
                format_args!("enter the service state first"),
            ))
        }
    }

    /// Checks and stages an image (see [`Loader::stage`]); the same image again is
    /// already staged.
    fn stage(&mut self, name: &str, image: &[u8]) -> Result<u32, Response> {
        let crc = crate::checksum::crc32(image);
        let (retired, mode, waiting) = self.mailbox.with(|i| {
            let waiting = i.posted.as_ref().map(|s| s.crc).or(i.published.staged);
            (i.retired.take(), i.published.mode, waiting)
        });
        if let Some(d) = retired {
            self.loader.give_back(d);
        }
        // The same image again (the tool retries when the answer was lost).
        if waiting == Some(crc) {
            return Ok(crc);
        }
        if mode == Mode::Fallback {
            return Err(error(
                ErrorCode::Busy,
                format_args!("the detector is out of service (fallback)"),
            ));
        }
        match self.loader.stage(name, image) {
            Ok(staged) => {
                self.mailbox.with(|i| i.posted = Some(staged));
                Ok(crc)
            }
            Err(e) => {
                let code = match e {
                    LoadError::Busy => ErrorCode::Busy,
                    LoadError::Name => ErrorCode::Malformed,
                    LoadError::Image(_) | LoadError::Rate(_) => ErrorCode::Image,
                    LoadError::Channel(_) => ErrorCode::Channel,
                };
                Err(error(code, format_args!("{e}")))
            }
        }
    }

    /// Carries out one request.
    pub async fn handle(&mut self, request: Request<'_>) -> Response {
        match self.carry_out(request).await {
            Ok(r) | Err(r) => r,
        }
    }

    async fn carry_out(&mut self, request: Request<'_>) -> Result<Response, Response> {
        Ok(match request {
            Request::Identify => {
                let p = self.mailbox.with(|i| {
                    let mut p = i.published.clone();
                    p.staged = p.staged.or(i.posted.as_ref().map(|s| s.crc));
                    p
                });
                Response::Identity(Identity {
                    version: VERSION,
                    build: crate::version::BUILD_HASH,
                    mode: p.mode,
                    detector_crc: p.crc,
                    detector_name: p.name,
                    staged_crc: p.staged,
                })
            }
            Request::Load { name, image } => Response::Staged(self.stage(name, image)?),
            Request::Save { name, image } => {
                self.writable()?;
                let crc = self.stage(name, image)?;
                let name = DetectorName::try_from(name).unwrap_or_default();
                let (slot, stall_us) = self
                    .nvm
                    .save(&name, image)
                    .await
                    .map_err(|e| error(ErrorCode::Store, format_args!("{e}")))?;
                Response::Saved {
                    crc,
                    slot: slot.raw() as u8,
                    stall_ms: u16::try_from(stall_us.div_ceil(1000)).unwrap_or(u16::MAX),
                }
            }
            Request::Activate => {
                let staged = self.mailbox.with(|i| {
                    let crc = i.posted.as_ref().map(|s| s.crc).or(i.published.staged);
                    i.activate = crc.is_some();
                    crc
                });
                match staged {
                    Some(crc) => Response::Active(crc),
                    None => {
                        return Err(error(
                            ErrorCode::NothingStaged,
                            format_args!("load a detector first"),
                        ));
                    }
                }
            }
            Request::EnterService | Request::LeaveService => {
                let on = request == Request::EnterService;
                self.mailbox.with(|i| i.service = on);
                Response::Done
            }
            Request::LastCrash => Response::Crash(self.last_crash.clone()),
            Request::RecordingInfo => Response::Recording(self.recorder.with(|r| r.info())),
            Request::RecordingRead(offset) => {
                let mut page = [0u8; PAGE_MAX];
                match self.recorder.with(|r| r.read(offset, &mut page)) {
                    Some(n) => Response::Page {
                        offset,
                        data: heapless::Vec::from_slice(page.get(..n).unwrap_or(&[]))
                            .unwrap_or_default(),
                    },
                    None => {
                        return Err(error(
                            ErrorCode::Busy,
                            format_args!("the recording is not frozen yet"),
                        ));
                    }
                }
            }
            Request::RecordingRearm => {
                self.recorder.with(|r| r.rearm());
                Response::Done
            }
            Request::ReadKey(k) => match self.nvm.read_key(k.raw()).await {
                Ok(Some(v)) => Response::Value(v),
                Ok(None) => {
                    return Err(error(
                        ErrorCode::Key,
                        format_args!("`{k}` was never written"),
                    ));
                }
                Err(e) => return Err(error(ErrorCode::Store, format_args!("{e}"))),
            },
            Request::WriteKey(k, v) => {
                self.writable()?;
                check_key(k, v)?;
                self.nvm
                    .write_key(k.raw(), v)
                    .await
                    .map_err(|e| error(ErrorCode::Store, format_args!("{e}")))?;
                Response::Written
            }
        })
    }
}

/// The service channel's receiving end: reassembles requests, has them carried out, and
/// answers each with a single frame (every response fits one).
pub struct ServiceEnd {
    rx: Reassembler<MAX_MESSAGE>,
}

impl Default for ServiceEnd {
    fn default() -> Self {
        ServiceEnd::new()
    }
}

impl ServiceEnd {
    /// Idle.
    pub const fn new() -> ServiceEnd {
        ServiceEnd {
            rx: Reassembler::new(BLOCK_SIZE, 0),
        }
    }

    /// A frame on the node's request identifier at `now_us`: what to send on its
    /// response identifier (a flow control, or the response), if anything.
    pub async fn on_frame<F: NorFlash>(
        &mut self,
        data: &[u8],
        now_us: u64,
        requests: &mut Requests<'_, '_, F>,
    ) -> Option<Payload> {
        match self.rx.on_frame(data, now_us) {
            Received::Pending | Received::Failed(_, None) => None,
            Received::Flow(f) | Received::Failed(_, Some(f)) => Some(f),
            Received::Complete => {
                let message = self.rx.message();
                // A corrupted request cannot be trusted for its code: it is answered under
                // the code it arrived with, which the tool matches against its own.
                let code = message.first().copied().unwrap_or(0);
                let response = match Request::decode(message) {
                    Ok(r) => requests.handle(r).await,
                    Err(e) => {
                        let code = match e {
                            fingertip_can::service::ServiceError::Corrupt => ErrorCode::Corrupt,
                            _ => ErrorCode::Malformed,
                        };
                        Response::Error(code, detail(format_args!("{e}")))
                    }
                };
                respond(code & 0x7F, &response, now_us)
            }
        }
    }

    /// Drops a request whose sender went silent; call now and then.
    pub fn poll(&mut self, now_us: u64) {
        self.rx.poll(now_us);
    }
}

/// The single frame answering request `code` with `response`.
fn respond(code: u8, response: &Response, now_us: u64) -> Option<Payload> {
    let mut buf = [0u8; SINGLE_MAX];
    let n = response.encode(code, &mut buf).ok()?;
    Sender::new(buf.get(..n)?, now_us)
        .ok()
        .map(|(_, frame)| frame)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fingertip_can::service::{DETAIL_MAX, NAME_MAX};

    #[test]
    fn the_longest_responses_fit_one_frame() {
        let long_name = DetectorName::try_from("n".repeat(NAME_MAX).as_str()).unwrap();
        let identity = Response::Identity(Identity {
            version: [255; 3],
            build: u32::MAX,
            mode: Mode::Loaded,
            detector_crc: u32::MAX,
            detector_name: long_name,
            staged_crc: Some(u32::MAX),
        });
        let error = Response::Error(
            ErrorCode::Channel,
            detail(format_args!("{}", "x".repeat(DETAIL_MAX))),
        );
        let mut crash = CrashReport::new(fingertip_can::service::CrashKind::Panic, u32::MAX);
        core::fmt::Write::write_str(&mut crash, &"m".repeat(100)).unwrap();
        for r in [identity, error, Response::Crash(Some(crash))] {
            let frame = respond(0x10, &r, 0).expect("fits a single frame");
            assert!(frame.data().len() <= 64);
        }
    }
}
