//! The fingertip's transmit side: turns each tick's detector [`Output`] into the frames
//! to send, in priority order.
//!
//! - One [`EventMsg`] per decision, at once, each with the next event counter.
//! - Every `stream_decimation` ticks a sample of the confidence stream: one
//!   [`ConfidenceMsg`] page per group of three events holding an event of the current
//!   phase (nothing when the phase evaluates no event), all with the same sequence
//!   number, which advances per sample sent.
//! - Every `heartbeat_period` ticks the status: page 0 (health), then one of pages 1..=5
//!   in turn, so the whole status goes round every five periods.
//!
//! The first call sends a stream sample and a heartbeat at once (so the reset reason is
//! on the bus right after boot). Pure logic: parameters in [`Transmitter`], everything
//! that changes in [`TxState`].

use core::fmt;

use heapless::Vec;

use super::codec::{ConfidenceMsg, EventMsg, FaultFlags, PROTOCOL_VERSION, ResetReason};
use super::codec::{STATUS_PAGES, StatusPage};
use super::rx::{Receiver, RejectReason, RxCounts, RxState};
use super::{CanFrame, Counter, NodeId};
use detector_core::{Confidence, MAX_EVENTS, Output, Tick};

/// Default ticks per confidence-stream sample: 20, i.e. 250 samples/s at the default
/// 5 kHz. Five fingertips with up to three events per phase then load a 1 Mbit/s bus to
/// at most 23% worst case (see `docs/can-protocol.md`).
pub const DEFAULT_STREAM_DECIMATION: u16 = 20;

/// Default heartbeat period in milliseconds (two status frames per period).
pub const DEFAULT_HEARTBEAT_MS: u32 = 50;

/// Most frames one tick can produce: two decisions per event, three stream pages, two
/// status pages.
pub const MAX_TX_FRAMES: usize = 2 * MAX_EVENTS + ConfidenceMsg::PAGES as usize + 2;

/// The frames of one tick, highest priority first.
pub type TxFrames = Vec<CanFrame, MAX_TX_FRAMES>;

/// A transmitter parameter is invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TxConfigError {
    /// The stream decimation must be at least 1 tick.
    StreamDecimation(u16),
    /// The heartbeat period must be within 1..=2³¹−1 ticks.
    HeartbeatPeriod(Tick),
    /// The detector rate must be within 1..=65535 Hz.
    Rate(u32),
}

impl fmt::Display for TxConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TxConfigError::StreamDecimation(d) => {
                write!(f, "stream decimation {d} ticks is not at least 1")
            }
            TxConfigError::HeartbeatPeriod(p) => {
                write!(f, "heartbeat period {p} ticks is not within 1..2^31")
            }
            TxConfigError::Rate(r) => write!(f, "detector rate {r} Hz is not within 1..=65535"),
        }
    }
}

impl core::error::Error for TxConfigError {}

/// What the status heartbeat reports; the firmware keeps it up to date (mostly through
/// [`Status::update_from_rx`]) and the transmitter encodes it. Counters are since boot;
/// they saturate at 65535 on the bus.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Why the fingertip last reset.
    pub reset: ResetReason,
    /// Current faults (the stale bits are set by [`Status::update_from_rx`]).
    pub faults: FaultFlags,
    /// The phase the detector runs, `0..=7`, `None` before the first phase frame.
    pub phase: Option<u8>,
    /// That phase's sequence number.
    pub phase_seq: u8,
    /// Ticks that overran their period.
    pub overruns: u32,
    /// Longest tick computation seen, in 0.1 µs (saturate at 65535).
    pub worst_tick: u16,
    /// The detector rate in Hz.
    pub tick_rate_hz: u16,
    /// CAN error events.
    pub bus_errors: u32,
    /// Frames that could not be queued for sending.
    pub tx_dropped: u32,
    /// Checksum of the active configuration.
    pub config_checksum: u32,
    /// The receiver's counters.
    pub rx: RxCounts,
}

fn sat16(v: u32) -> u16 {
    v.min(u32::from(u16::MAX)) as u16
}

impl Status {
    /// Copies in the receiver's counters, its phase, and its staleness flags at `now`.
    pub fn update_from_rx(&mut self, rx: &Receiver, state: &RxState, now: Tick) {
        let f = rx.freshness(state, now);
        self.faults.set(FaultFlags::CONTEXT_STALE, !f.context);
        self.faults.set(FaultFlags::TIP_STATE_STALE, !f.tip_state);
        self.faults.set(FaultFlags::PHASE_STALE, !f.phase);
        self.rx = *state.counts();
        if let Some(p) = state.link().phase() {
            self.phase = Some(p.phase);
            self.phase_seq = p.sequence;
        }
    }

    /// Status page `page` (`0..STATUS_PAGES`) with uptime `uptime`; `None` past the last.
    pub fn page(&self, page: u8, uptime: Tick) -> Option<StatusPage> {
        let rej = |r: RejectReason| sat16(self.rx.rejected().get(r));
        Some(match page {
            0 => StatusPage::Health {
                reset: self.reset,
                faults: self.faults,
                uptime,
                phase: self.phase,
                phase_seq: self.phase_seq,
            },
            1 => StatusPage::Timing {
                overruns: sat16(self.overruns),
                worst_tick: self.worst_tick,
                tick_rate_hz: self.tick_rate_hz,
                protocol: PROTOCOL_VERSION,
            },
            2 => StatusPage::Link {
                stale_episodes: sat16(self.rx.stale_episodes()),
                lost_frames: sat16(self.rx.lost_frames()),
                bus_errors: sat16(self.bus_errors),
            },
            3 => StatusPage::FrameRejects {
                wrong_length: rej(RejectReason::WrongLength),
                unknown_id: rej(RejectReason::UnknownId),
                bad_crc: rej(RejectReason::BadCrc),
            },
            4 => StatusPage::ContentRejects {
                sequence: rej(RejectReason::Sequence),
                phase_not_configured: rej(RejectReason::PhaseNotConfigured),
                out_of_range: rej(RejectReason::OutOfRange),
            },
            5 => StatusPage::Config {
                checksum: self.config_checksum,
                tx_dropped: sat16(self.tx_dropped),
            },
            _ => return None,
        })
    }
}

/// The transmitter's state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TxState {
    started: bool,
    event_counter: Counter,
    stream_seq: u8,
    next_stream: Tick,
    next_status: Tick,
    next_page: u8,
    dropped: u32,
}

impl TxState {
    /// The state at boot.
    pub fn new() -> TxState {
        TxState::default()
    }

    /// Frames this transmitter could not produce (a decision naming an event of 8 or
    /// more; cannot happen with a core [`Output`]). The firmware adds it to
    /// [`Status::tx_dropped`].
    pub const fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The counter the next event frame will carry.
    pub const fn next_event_counter(&self) -> Counter {
        self.event_counter
    }
}

/// Whether `now` has reached `at` (wrapping; ticks up to 2³¹ apart compare right).
fn reached(now: Tick, at: Tick) -> bool {
    now.wrapping_sub(at) as i32 >= 0
}

/// The fingertip's transmit logic: its parameters. See the [module docs](crate::tx).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Transmitter {
    node: NodeId,
    stream_decimation: u16,
    heartbeat_period: Tick,
}

impl Transmitter {
    /// A transmitter for node `node` sending a confidence sample every
    /// `stream_decimation` ticks and a heartbeat every `heartbeat_period` ticks.
    pub const fn new(
        node: NodeId,
        stream_decimation: u16,
        heartbeat_period: Tick,
    ) -> Result<Transmitter, TxConfigError> {
        if stream_decimation == 0 {
            return Err(TxConfigError::StreamDecimation(stream_decimation));
        }
        if heartbeat_period == 0 || heartbeat_period > i32::MAX as u32 {
            return Err(TxConfigError::HeartbeatPeriod(heartbeat_period));
        }
        Ok(Transmitter {
            node,
            stream_decimation,
            heartbeat_period,
        })
    }

    /// The defaults for a detector running at `rate_hz`:
    /// [`DEFAULT_STREAM_DECIMATION`] and a [`DEFAULT_HEARTBEAT_MS`] heartbeat.
    pub const fn with_defaults(node: NodeId, rate_hz: u32) -> Result<Transmitter, TxConfigError> {
        if rate_hz == 0 || rate_hz > u16::MAX as u32 {
            return Err(TxConfigError::Rate(rate_hz));
        }
        let hb = (rate_hz * DEFAULT_HEARTBEAT_MS).div_ceil(1000);
        Transmitter::new(node, DEFAULT_STREAM_DECIMATION, hb)
    }

    /// The node.
    pub const fn node(&self) -> NodeId {
        self.node
    }

    /// Ticks per confidence-stream sample.
    pub const fn stream_decimation(&self) -> u16 {
        self.stream_decimation
    }

    /// Ticks per heartbeat.
    pub const fn heartbeat_period(&self) -> Tick {
        self.heartbeat_period
    }

    /// The frames to send after the tick `now`, given its output and the current status:
    /// event frames first, then stream pages, then status pages.
    pub fn tick(
        &self,
        state: &mut TxState,
        now: Tick,
        output: &Output,
        status: &Status,
    ) -> TxFrames {
        let mut frames = TxFrames::new();
        for d in &output.decisions {
            match EventMsg::from_decision(state.event_counter, d).encode(self.node) {
                Ok(f) => {
                    state.event_counter = state.event_counter.next();
                    self.push(state, &mut frames, f);
                }
                Err(_) => state.dropped = state.dropped.saturating_add(1),
            }
        }
        let first = !state.started;
        state.started = true;
        if first || reached(now, state.next_stream) {
            state.next_stream = now.wrapping_add(u32::from(self.stream_decimation));
            let mut sent = false;
            for page in 0..ConfidenceMsg::PAGES {
                if let Some(m) = stream_page(output, page, state.stream_seq)
                    && let Ok(f) = m.encode(self.node)
                {
                    sent = true;
                    self.push(state, &mut frames, f);
                }
            }
            if sent {
                state.stream_seq = state.stream_seq.wrapping_add(1);
            }
        }
        if first || reached(now, state.next_status) {
            state.next_status = now.wrapping_add(self.heartbeat_period);
            let page = state.next_page.clamp(1, STATUS_PAGES - 1);
            state.next_page = if page + 1 >= STATUS_PAGES {
                1
            } else {
                page + 1
            };
            for p in [0, page] {
                if let Some(f) = status.page(p, now).and_then(|s| s.encode(self.node).ok()) {
                    self.push(state, &mut frames, f);
                }
            }
        }
        frames
    }

    fn push(&self, state: &mut TxState, frames: &mut TxFrames, f: CanFrame) {
        if frames.push(f).is_err() {
            state.dropped = state.dropped.saturating_add(1);
        }
    }
}

/// Page `page` of a stream sample, or `None` when it holds no event of the phase.
fn stream_page(output: &Output, page: u8, seq: u8) -> Option<ConfidenceMsg> {
    let first = 3 * usize::from(page);
    let slots = ConfidenceMsg::slots(page);
    let mask = ((1u16 << slots) - 1) as u8;
    let evaluated = (output.evaluated >> first) & mask;
    if evaluated == 0 {
        return None;
    }
    let mut confidences = [Confidence::ZERO; 3];
    for (k, c) in confidences.iter_mut().enumerate().take(slots) {
        if evaluated & (1 << k) != 0 {
            *c = output
                .confidences
                .get(first + k)
                .copied()
                .unwrap_or_default();
        }
    }
    Some(ConfidenceMsg {
        seq,
        page,
        evaluated,
        unjudgeable: (output.unjudgeable >> first) & evaluated,
        confidences,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Id, Message, MessageKind};
    use detector_core::{Decision, EventId, Level};

    fn tx(dec: u16, hb: Tick) -> Transmitter {
        Transmitter::new(NodeId::new(2).unwrap(), dec, hb).unwrap()
    }

    fn decode(f: &CanFrame) -> Message {
        Message::decode(Id::Standard(f.id()), f.data()).unwrap().1
    }

    fn output(evaluated: u8) -> Output {
        let mut o = Output {
            evaluated,
            ..Output::default()
        };
        for (i, c) in o.confidences.iter_mut().enumerate() {
            if evaluated & (1 << i) != 0 {
                *c = Confidence::from_bits(1000 * (i as u16 + 1)).unwrap();
            }
        }
        o
    }

    #[test]
    fn decimates_the_stream_and_paces_the_heartbeat() {
        let t = tx(5, 20);
        let mut s = TxState::new();
        let out = output(0b0000_0111);
        let status = Status::default();
        let mut stream_ticks = std::vec::Vec::new();
        let mut pages = std::vec::Vec::new();
        for now in 1000..1100u32 {
            for f in t.tick(&mut s, now, &out, &status) {
                match decode(&f) {
                    Message::Confidence(m) => {
                        assert_eq!(m.seq as usize, stream_ticks.len());
                        assert_eq!(m.evaluated, 0b111);
                        assert_eq!(m.confidences[2].to_bits(), 3000);
                        stream_ticks.push(now);
                    }
                    Message::Status(p) => pages.push((now, p.page())),
                    m => panic!("{m:?}"),
                }
            }
        }
        assert_eq!(stream_ticks.len(), 20);
        assert!(stream_ticks.windows(2).all(|w| w[1] - w[0] == 5));
        let want: std::vec::Vec<(u32, u8)> = [0u32, 20, 40, 60, 80]
            .iter()
            .zip(1u8..)
            .flat_map(|(&t, p)| [(1000 + t, 0), (1000 + t, p)])
            .collect();
        assert_eq!(pages, want);
    }

    #[test]
    fn events_go_first_with_advancing_counters() {
        let t = tx(1, 1000);
        let mut s = TxState::new();
        let mut out = output(0b1100_0001);
        for (i, e) in [0u8, 6, 7].into_iter().enumerate() {
            out.decisions
                .push(Decision {
                    event: EventId(e),
                    level: if i == 0 { Level::Alert } else { Level::Confirm },
                    confidence: Confidence::ONE,
                    onset: 10,
                    tick: 50,
                })
                .unwrap();
        }
        let frames = t.tick(&mut s, 50, &out, &Status::default());
        let kinds: std::vec::Vec<MessageKind> = frames.iter().map(|f| decode(f).kind()).collect();
        let (e, c, st) = (
            MessageKind::Event,
            MessageKind::Confidence,
            MessageKind::Status,
        );
        assert_eq!(kinds, [e, e, e, c, c, st, st]);
        let ids: std::vec::Vec<u16> = frames.iter().map(|f| f.id().as_raw()).collect();
        assert!(ids.windows(2).all(|w| w[0] <= w[1]));
        for (i, f) in frames.iter().take(3).enumerate() {
            let Message::Event(m) = decode(f) else {
                panic!()
            };
            assert_eq!(m.counter.get(), i as u8);
            assert_eq!(m.onset_age, 40);
        }
        let Message::Confidence(p2) = decode(&frames[4]) else {
            panic!()
        };
        assert_eq!((p2.page, p2.evaluated), (2, 0b11));
        assert_eq!(p2.confidences[1].to_bits(), 8000);
        assert_eq!(s.next_event_counter().get(), 3);
    }

    #[test]
    fn no_stream_frames_when_nothing_is_evaluated() {
        let t = tx(1, 1000);
        let mut s = TxState::new();
        let frames = t.tick(&mut s, 0, &Output::default(), &Status::default());
        assert!(
            frames
                .iter()
                .all(|f| decode(f).kind() == MessageKind::Status)
        );
    }

    #[test]
    fn status_reports_the_receiver() {
        let node = NodeId::new(2).unwrap();
        let rx = Receiver::new(node, 2, 10, 10).unwrap();
        let mut rs = RxState::new();
        let _ = rx.receive(&mut rs, 0, Id::Standard(MessageKind::Event.id(node)), &[]);
        let mut st = Status {
            overruns: 70_000,
            ..Status::default()
        };
        st.update_from_rx(&rx, &rs, 0);
        assert!(st.faults.contains(FaultFlags::CONTEXT_STALE));
        assert_eq!(
            st.page(3, 0),
            Some(StatusPage::FrameRejects {
                wrong_length: 0,
                unknown_id: 1,
                bad_crc: 0
            })
        );
        assert!(matches!(
            st.page(1, 0),
            Some(StatusPage::Timing {
                overruns: 65535,
                ..
            })
        ));
        assert_eq!(st.page(STATUS_PAGES, 0), None);
    }

    #[test]
    fn defaults_and_bad_parameters() {
        let n = NodeId::new(0).unwrap();
        let t = Transmitter::with_defaults(n, 5000).unwrap();
        assert_eq!(t.stream_decimation(), 20);
        assert_eq!(t.heartbeat_period(), 250);
        assert_eq!(
            Transmitter::new(n, 0, 1),
            Err(TxConfigError::StreamDecimation(0))
        );
        assert_eq!(
            Transmitter::with_defaults(n, 0),
            Err(TxConfigError::Rate(0))
        );
    }
}
