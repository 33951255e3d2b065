//! The tool's end of the service channel (`fingertip_can::service`): a request to one
//! fingertip, sent as a segmented transfer on its request identifier, and the response
//! read back from its response identifier, retried when a frame is lost or corrupted.
//!
//! The exchange runs over any [`Link`]: a SocketCAN interface ([`SocketLink`], Linux) for
//! `fingertip load` and `fingertip calibrate`, or a simulated bus in the tests, where the
//! firmware's own end of the channel answers.

use fingertip_can::service::{Request, Response, ServiceError};
use fingertip_can::transfer::{
    MAX_MESSAGE, Reassembler, Received, Sender, TIMEOUT_US, TransferError,
};

/// How long the tool waits for a response after its request's last frame, µs: the
/// fingertip checks an image in a few milliseconds.
pub const RESPONSE_TIMEOUT_US: u64 = 500_000;
/// Attempts per request before the tool gives up.
pub const ATTEMPTS: u32 = 3;

/// One fingertip's request and response identifiers on a bus, as the tool sees them.
pub trait Link {
    /// Sends a frame (CAN FD, bit-rate switching) with these data bytes on the request
    /// identifier.
    fn send(&mut self, data: &[u8]) -> std::io::Result<()>;
    /// The data of the next frame on the response identifier, waiting until `until_us`
    /// at most; `None` when none came.
    fn recv(&mut self, until_us: u64) -> std::io::Result<Option<Vec<u8>>>;
    /// The link's clock, µs.
    fn now_us(&mut self) -> u64;
}

/// Why a request failed.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// The request cannot be encoded (too long).
    #[error("the request cannot be sent: {0}")]
    Request(ServiceError),
    /// Every attempt failed; the last one's reason.
    #[error("no answer after {attempts} attempts: {last}")]
    NoAnswer {
        /// Attempts made.
        attempts: u32,
        /// What went wrong the last time.
        last: String,
    },
    /// The bus interface failed.
    #[error("CAN interface: {0}")]
    Io(#[from] std::io::Error),
    /// The fingertip answered with an error response ([`Client::ask`]).
    #[error("the fingertip refused: {}: {text}", code.name())]
    Refused {
        /// Why.
        code: fingertip_can::service::ErrorCode,
        /// Its words.
        text: String,
    },
}

/// Sends requests over a [`Link`] and reads their responses.
pub struct Client<L: Link> {
    link: L,
    /// Attempts made by all requests so far (a retry counts one).
    pub attempts: u32,
}

impl<L: Link> Client<L> {
    /// A client on `link`.
    pub fn new(link: L) -> Client<L> {
        Client { link, attempts: 0 }
    }

    /// The link.
    pub fn link(&mut self) -> &mut L {
        &mut self.link
    }

    /// Sends `request` and returns the fingertip's response (which may be an error
    /// response: that is an answer, not a failure). A transfer broken by a lost or
    /// corrupted frame, a corrupted response or silence is retried, [`ATTEMPTS`] times
    /// in all.
    pub fn request(&mut self, request: &Request<'_>) -> Result<Response, ClientError> {
        let mut buf = vec![0u8; MAX_MESSAGE];
        let n = request.encode(&mut buf).map_err(ClientError::Request)?;
        let message = &buf[..n];
        let code = message[0];
        let mut last = String::new();
        for attempt in 1..=ATTEMPTS {
            self.attempts += 1;
            match self.attempt(message, code)? {
                Ok(Response::Error(fingertip_can::service::ErrorCode::Corrupt, _)) => {
                    last = "the fingertip received the request corrupted".into();
                }
                Ok(r) => return Ok(r),
                Err(e) => last = e,
            }
            if attempt == ATTEMPTS {
                break;
            }
            self.settle()?;
        }
        Err(ClientError::NoAnswer {
            attempts: ATTEMPTS,
            last,
        })
    }

    /// [`Client::request`], with an error response as [`ClientError::Refused`].
    pub fn ask(&mut self, request: &Request<'_>) -> Result<Response, ClientError> {
        match self.request(request)? {
            Response::Error(code, text) => Err(ClientError::Refused {
                code,
                text: text.to_string(),
            }),
            r => Ok(r),
        }
    }

    /// After a broken attempt: waits until the fingertip has been silent for longer than
    /// its transfer timeout, so that it has dropped whatever it was reassembling and
    /// answered whatever it had, before the request goes again.
    fn settle(&mut self) -> Result<(), std::io::Error> {
        let quiet = TIMEOUT_US + TIMEOUT_US / 5;
        let mut until = self.link.now_us() + quiet;
        while self.link.now_us() < until {
            if self.link.recv(until)?.is_some() {
                until = self.link.now_us() + quiet;
            }
        }
        Ok(())
    }

    /// One attempt: the outer error is the interface's, the inner what broke the
    /// exchange.
    fn attempt(
        &mut self,
        message: &[u8],
        code: u8,
    ) -> Result<Result<Response, String>, std::io::Error> {
        let now = self.link.now_us();
        let (mut sender, first) = match Sender::new(message, now) {
            Ok(s) => s,
            Err(e) => return Ok(Err(e.to_string())),
        };
        self.link.send(first.data())?;
        let mut rx = Reassembler::<MAX_MESSAGE>::new(0, 0);
        let mut deadline = now + RESPONSE_TIMEOUT_US;
        loop {
            let now = self.link.now_us();
            // Consecutive frames as the flow control allows.
            loop {
                match sender.poll(now) {
                    Ok(Some(f)) => self.link.send(f.data())?,
                    Ok(None) => break,
                    Err(e) => return Ok(Err(e.to_string())),
                }
            }
            let until = if sender.is_done() {
                deadline
            } else {
                sender.next_at().min(deadline)
            };
            let Some(data) = self.link.recv(until.max(now))? else {
                if self.link.now_us() >= deadline {
                    return Ok(Err(TransferError::Timeout.to_string()));
                }
                continue;
            };
            let now = self.link.now_us();
            if !sender.is_done() {
                if let Err(e) = sender.on_flow(&data, now) {
                    return Ok(Err(e.to_string()));
                }
                continue;
            }
            match rx.on_frame(&data, now) {
                Received::Complete => {
                    return Ok(Response::decode(code, rx.message()).map_err(|e| e.to_string()));
                }
                Received::Flow(f) => {
                    self.link.send(f.data())?;
                    deadline = now + RESPONSE_TIMEOUT_US;
                }
                Received::Pending => deadline = now + RESPONSE_TIMEOUT_US,
                Received::Failed(e, _) => return Ok(Err(e.to_string())),
            }
        }
    }
}

/// A fingertip's service identifiers on a SocketCAN interface (CAN FD).
#[cfg(target_os = "linux")]
pub struct SocketLink {
    socket: socketcan::CanFdSocket,
    request: socketcan::StandardId,
    response: u16,
    start: std::time::Instant,
}

#[cfg(target_os = "linux")]
impl SocketLink {
    /// Opens `iface` for node `node`'s service channel.
    pub fn open(iface: &str, node: fingertip_can::NodeId) -> std::io::Result<SocketLink> {
        use socketcan::Socket;
        let socket = socketcan::CanFdSocket::open(iface)?;
        let request = socketcan::StandardId::new(fingertip_can::service_request_id(node).as_raw())
            .ok_or_else(|| std::io::Error::other("request identifier"))?;
        Ok(SocketLink {
            socket,
            request,
            response: fingertip_can::service_response_id(node).as_raw(),
            start: std::time::Instant::now(),
        })
    }
}

#[cfg(target_os = "linux")]
impl Link for SocketLink {
    fn send(&mut self, data: &[u8]) -> std::io::Result<()> {
        use socketcan::{EmbeddedFrame, Socket};
        let frame = socketcan::CanFdFrame::new(self.request, data)
            .ok_or_else(|| std::io::Error::other("not a CAN FD length"))?;
        let mut frame = frame;
        frame.set_brs(true);
        self.socket.write_frame(&frame)
    }

    fn recv(&mut self, until_us: u64) -> std::io::Result<Option<Vec<u8>>> {
        use socketcan::{CanAnyFrame, EmbeddedFrame, Socket};
        loop {
            let now = self.now_us();
            if now >= until_us {
                return Ok(None);
            }
            let wait = std::time::Duration::from_micros(until_us - now);
            let frame = match self.socket.read_frame_timeout(wait) {
                Ok(f) => f,
                Err(e)
                    if e.kind() == std::io::ErrorKind::WouldBlock
                        || e.kind() == std::io::ErrorKind::TimedOut =>
                {
                    return Ok(None);
                }
                Err(e) => return Err(e),
            };
            let (id, data) = match &frame {
                CanAnyFrame::Normal(f) => (f.id(), f.data().to_vec()),
                CanAnyFrame::Fd(f) => (f.id(), f.data().to_vec()),
                _ => continue,
            };
            if id
                == socketcan::Id::Standard(
                    socketcan::StandardId::new(self.response)
                        .ok_or_else(|| std::io::Error::other("response identifier"))?,
                )
            {
                return Ok(Some(data));
            }
        }
    }

    fn now_us(&mut self) -> u64 {
        self.start.elapsed().as_micros() as u64
    }
}
