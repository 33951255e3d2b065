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
//! Two detectors take turns: the one in service and a spare. A load goes into the spare;
//! the engine takes it at its phase boundary and sends the one it replaced back as the
//! next spare. While a loaded detector waits for its boundary there is no spare, and a
//! second load is refused as busy.

use core::cell::RefCell;

use detector_core::Detector;
use detector_core::DetectorTick;
use embassy_sync::blocking_mutex::Mutex;
use fingertip_can::service::{DetectorName, ErrorCode, Identity, Mode, Request, Response, detail};
use fingertip_can::transfer::{MAX_MESSAGE, Payload, Reassembler, Received, SINGLE_MAX, Sender};

use crate::engine::{Engine, Service};
use crate::load::{LoadError, Loader, Staged};
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
}

struct Inner<'d> {
    /// Loaded, for the engine to stage.
    posted: Option<Staged<'d>>,
    /// Replaced by the engine, for the loader.
    retired: Option<&'d mut Detector>,
    activate: bool,
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
            published: Published {
                mode: Mode::BuiltIn,
                crc: 0,
                name: DetectorName::new(),
                staged: None,
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

/// Carries out requests: the receive side's handler.
pub struct Requests<'m, 'd> {
    loader: Loader<'d>,
    mailbox: &'m Mailbox<'d>,
}

impl<'m, 'd> Requests<'m, 'd> {
    /// Requests served with `loader`'s spare detector, meeting the detector task in
    /// `mailbox`.
    pub fn new(loader: Loader<'d>, mailbox: &'m Mailbox<'d>) -> Requests<'m, 'd> {
        Requests { loader, mailbox }
    }

    /// Carries out one request.
    pub fn handle(&mut self, request: Request<'_>) -> Response {
        let error = |code, args| Response::Error(code, detail(args));
        match request {
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
            Request::Load { name, image } => {
                let crc = crate::checksum::crc32(image);
                let (retired, mode, waiting) = self.mailbox.with(|i| {
                    let waiting = i.posted.as_ref().map(|s| s.crc).or(i.published.staged);
                    (i.retired.take(), i.published.mode, waiting)
                });
                // The same image again (the tool retries when the answer was lost): it
                // is already staged.
                if waiting == Some(crc) {
                    return Response::Staged(crc);
                }
                if let Some(d) = retired {
                    self.loader.give_back(d);
                }
                if mode == Mode::Fallback {
                    return error(
                        ErrorCode::Busy,
                        format_args!("the detector is out of service (fallback)"),
                    );
                }
                match self.loader.stage(name, image) {
                    Ok(staged) => {
                        self.mailbox.with(|i| i.posted = Some(staged));
                        Response::Staged(crc)
                    }
                    Err(e) => {
                        let code = match e {
                            LoadError::Busy => ErrorCode::Busy,
                            LoadError::Name => ErrorCode::Malformed,
                            LoadError::Image(_) | LoadError::Rate(_) => ErrorCode::Image,
                            LoadError::Channel(_) => ErrorCode::Channel,
                        };
                        error(code, format_args!("{e}"))
                    }
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
                    None => error(
                        ErrorCode::NothingStaged,
                        format_args!("load a detector first"),
                    ),
                }
            }
            Request::ReadKey(k) | Request::WriteKey(k, _) => error(
                ErrorCode::Store,
                format_args!("no key-value store on this firmware: {k}"),
            ),
        }
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
    pub fn on_frame(
        &mut self,
        data: &[u8],
        now_us: u64,
        requests: &mut Requests<'_, '_>,
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
                    Ok(r) => requests.handle(r),
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
        for r in [identity, error] {
            let frame = respond(0x10, &r, 0).expect("fits a single frame");
            assert!(frame.data().len() <= 64);
        }
    }
}
