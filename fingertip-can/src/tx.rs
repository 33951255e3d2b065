//! The fingertip's transmit side: turns each tick's detector [`Output`] into the frames
//! to send, in priority order.
//!
//! - One [`EventMsg`] per decision, at once, each with the next event counter.
//! - Every `stream_decimation` ticks a sample of the confidence stream: on CAN FD one
//!   [`StreamMsg`] with every event, on classic CAN one [`StreamPageMsg`] per event of the
//!   current phase; nothing when the phase evaluates no event (or the detector is out of
//!   service). Each event's level is the highest it
//!   reached since the previous sample, so a level raised and dropped between two samples
//!   still shows in one.
//! - Every `heartbeat_period` ticks the status: page 0 (health), then one of pages
//!   1..=10 in turn, so the whole status goes round every ten periods.
//!
//! The first call sends a stream sample and a heartbeat at once (so the reset reason is
//! on the bus right after boot). Pure logic: parameters in [`Transmitter`], everything
//! that changes in [`TxState`].

use core::fmt;

use heapless::Vec;

use super::codec::{EventMsg, FaultFlags, LevelState, NodeIdSource, PROTOCOL_VERSION};
use super::codec::{ResetReason, STATUS_PAGES, StatusMsg, StatusPage, StreamMsg, StreamPageMsg};
use super::rx::{Receiver, RejectReason, RxCounts, RxState};
use super::{BusFormat, CanFrame, Counter, NodeId};
use detector_core::{EventId, Level, MAX_EVENTS, Output, Tick};

/// Default ticks per confidence-stream sample on CAN FD: 20, i.e. 250 samples/s at the
/// default 5 kHz (see `docs/can-protocol.md` for the bus load).
pub const DEFAULT_STREAM_DECIMATION: u16 = 20;

/// Default ticks per confidence-stream sample on classic CAN: 100, i.e. 50 samples/s at
/// 5 kHz. At 250 samples/s five fingertips' stream pages alone would take half of a
/// 1 Mbit/s classic bus; at 50 samples/s the controller's context fits at up to 253 Hz.
pub const DEFAULT_CLASSIC_STREAM_DECIMATION: u16 = 100;

/// Default heartbeat period in milliseconds (two status frames per period).
pub const DEFAULT_HEARTBEAT_MS: u32 = 50;

/// Most frames one tick can produce: two decisions per event, a stream page per event
/// (classic CAN; one frame on CAN FD), two status pages.
pub const MAX_TX_FRAMES: usize = 2 * MAX_EVENTS + MAX_EVENTS + 2;

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
    /// Longest time from a sample's conversion to the end of its tick, 0.1 µs.
    pub worst_lateness: u16,
    /// Ticks that ended after their deadline.
    pub late_ticks: u32,
    /// Longest tick computation seen, in 0.1 µs.
    pub worst_tick: u16,
    /// Scans the detector lost.
    pub lost_scans: u32,
    /// The detector rate in Hz.
    pub tick_rate_hz: u16,
    /// Where the node id came from.
    pub node_source: NodeIdSource,
    /// CAN error events.
    pub bus_errors: u32,
    /// Frames that could not be queued for sending, or were flushed.
    pub tx_dropped: u32,
    /// Checksum of the active configuration.
    pub config_checksum: u32,
    /// The receiver's counters.
    pub rx: RxCounts,
    /// The firmware's version: major, minor, patch.
    pub firmware: [u8; 3],
    /// The first 32 bits of the firmware's commit (0 unknown).
    pub build: u32,
    /// What runs the detector.
    pub mode: crate::service::Mode,
    /// The active detector's name, UTF-8, zero-padded.
    pub detector_name: [u8; crate::service::NAME_MAX],
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

    /// Status page `page` (`0..STATUS_PAGES`) at uptime `uptime` on a bus of `format`;
    /// `None` past the last.
    pub fn page(&self, page: u8, uptime: Tick, format: BusFormat) -> Option<StatusPage> {
        let rej = |r: RejectReason| sat16(self.rx.rejected().get(r));
        Some(match page {
            0 => StatusPage::Health {
                reset: self.reset,
                phase: self.phase,
                faults: self.faults,
                phase_seq: self.phase_seq,
            },
            1 => StatusPage::Uptime { uptime },
            2 => StatusPage::Identity {
                tick_rate_hz: self.tick_rate_hz,
                protocol: PROTOCOL_VERSION,
                format,
                node_source: self.node_source,
            },
            3 => StatusPage::Lateness {
                worst: self.worst_lateness,
                late_ticks: sat16(self.late_ticks),
            },
            4 => StatusPage::Compute {
                worst_tick: self.worst_tick,
                lost_scans: sat16(self.lost_scans),
            },
            5 => StatusPage::Link {
                stale_episodes: sat16(self.rx.stale_episodes()),
                lost_frames: sat16(self.rx.lost_frames()),
            },
            6 => StatusPage::Bus {
                bus_errors: sat16(self.bus_errors),
                tx_dropped: sat16(self.tx_dropped),
            },
            7 => StatusPage::RejectsFrame {
                wrong_length: rej(RejectReason::WrongLength),
                bad_crc: rej(RejectReason::BadCrc),
            },
            8 => StatusPage::RejectsContent {
                sequence: rej(RejectReason::Sequence),
                out_of_range: rej(RejectReason::OutOfRange),
            },
            9 => StatusPage::RejectsRoute {
                unknown_id: rej(RejectReason::UnknownId),
                phase_not_configured: rej(RejectReason::PhaseNotConfigured),
            },
            11 => StatusPage::Firmware {
                version: self.firmware,
                mode: self.mode,
            },
            12 => StatusPage::Build { hash: self.build },
            13..=16 => {
                let part = page - 13;
                let mut bytes = [0u8; 4];
                let at = usize::from(part) * 4;
                if let Some(b) = self.detector_name.get(at..at + 4) {
                    bytes.copy_from_slice(b);
                }
                StatusPage::DetectorName { part, bytes }
            }
            10 => StatusPage::Config {
                checksum: self.config_checksum,
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
    stream_counter: Counter,
    status_counter: Counter,
    sample: u8,
    latched_alert: u8,
    latched_confirm: u8,
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
    format: BusFormat,
    stream_decimation: u16,
    heartbeat_period: Tick,
}

impl Transmitter {
    /// A transmitter for node `node` on a bus of `format`, sending a stream sample every
    /// `stream_decimation` ticks and a heartbeat every `heartbeat_period` ticks.
    pub const fn new(
        node: NodeId,
        format: BusFormat,
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
            format,
            stream_decimation,
            heartbeat_period,
        })
    }

    /// The defaults for a detector running at `rate_hz`: the format's stream decimation
    /// ([`BusFormat::default_stream_decimation`]) and a [`DEFAULT_HEARTBEAT_MS`] heartbeat.
    pub const fn with_defaults(
        node: NodeId,
        format: BusFormat,
        rate_hz: u32,
    ) -> Result<Transmitter, TxConfigError> {
        if rate_hz == 0 || rate_hz > u16::MAX as u32 {
            return Err(TxConfigError::Rate(rate_hz));
        }
        let hb = (rate_hz * DEFAULT_HEARTBEAT_MS).div_ceil(1000);
        Transmitter::new(node, format, format.default_stream_decimation(), hb)
    }

    /// The same transmitter for node `node`.
    pub const fn for_node(self, node: NodeId) -> Transmitter {
        Transmitter { node, ..self }
    }

    /// The node.
    pub const fn node(&self) -> NodeId {
        self.node
    }

    /// The bus format.
    pub const fn format(&self) -> BusFormat {
        self.format
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
    /// event frames first, then the stream, then status pages.
    pub fn tick(
        &self,
        state: &mut TxState,
        now: Tick,
        output: &Output,
        status: &Status,
    ) -> TxFrames {
        let mut frames = TxFrames::new();
        state.latched_alert |= output.alerting;
        state.latched_confirm |= output.confirmed;
        for d in &output.decisions {
            let bit = 1u8.checked_shl(u32::from(d.event.0)).unwrap_or(0);
            state.latched_alert |= bit;
            if d.level == Level::Confirm {
                state.latched_confirm |= bit;
            }
            let frame = EventMsg::from_decision(state.event_counter, d).encode(self.node);
            state.event_counter = state.event_counter.next();
            self.push(state, &mut frames, frame.ok());
        }
        let first = !state.started;
        state.started = true;
        if first || reached(now, state.next_stream) {
            state.next_stream = now.wrapping_add(u32::from(self.stream_decimation));
            self.stream(state, &mut frames, output);
            state.latched_alert = output.alerting;
            state.latched_confirm = output.confirmed;
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
                let frame = status.page(p, now, self.format).and_then(|page| {
                    StatusMsg {
                        counter: state.status_counter,
                        page,
                    }
                    .encode(self.node)
                    .ok()
                });
                state.status_counter = state.status_counter.next();
                self.push(state, &mut frames, frame);
            }
        }
        frames
    }

    /// One stream sample: a frame on CAN FD, a page per evaluated event on classic CAN;
    /// nothing when no event is evaluated.
    fn stream(&self, state: &mut TxState, frames: &mut TxFrames, output: &Output) {
        if output.evaluated == 0 {
            return;
        }
        let (alert, confirm) = (state.latched_alert, state.latched_confirm);
        let level = |e: usize| LevelState::from_masks(alert, confirm, e);
        match self.format {
            BusFormat::Fd => {
                let mut m = StreamMsg {
                    counter: state.stream_counter,
                    evaluated: output.evaluated,
                    unjudgeable: output.unjudgeable & output.evaluated,
                    confidences: output.confidences,
                    ..StreamMsg::default()
                };
                for (e, l) in m.levels.iter_mut().enumerate() {
                    *l = level(e);
                }
                state.stream_counter = state.stream_counter.next();
                self.push(state, frames, m.encode(self.node).ok());
            }
            BusFormat::Classic => {
                for e in (0..MAX_EVENTS).filter(|e| output.evaluated & (1 << e) != 0) {
                    let m = StreamPageMsg {
                        counter: state.stream_counter,
                        sample: state.sample,
                        event: EventId(e as u8),
                        unjudgeable: output.unjudgeable & (1 << e) != 0,
                        level: level(e),
                        confidence: output.confidences.get(e).copied().unwrap_or_default(),
                    };
                    state.stream_counter = state.stream_counter.next();
                    self.push(state, frames, m.encode(self.node).ok());
                }
                state.sample = state.sample.wrapping_add(1);
            }
        }
    }

    fn push(&self, state: &mut TxState, frames: &mut TxFrames, frame: Option<CanFrame>) {
        let pushed = frame
            .and_then(|f| f.in_format(self.format))
            .is_some_and(|f| frames.push(f).is_ok());
        if !pushed {
            state.dropped = state.dropped.saturating_add(1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Id, Message, MessageKind};
    use detector_core::{Confidence, Decision};

    fn tx(format: BusFormat, dec: u16, hb: Tick) -> Transmitter {
        Transmitter::new(NodeId::new(2).unwrap(), format, dec, hb).unwrap()
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
        let t = tx(BusFormat::Fd, 5, 20);
        let mut s = TxState::new();
        let out = output(0b0000_0111);
        let status = Status::default();
        let mut stream_ticks = std::vec::Vec::new();
        let mut pages = std::vec::Vec::new();
        for now in 1000..1220u32 {
            for f in t.tick(&mut s, now, &out, &status) {
                assert!(f.is_fd(), "every frame of a CAN FD bus is CAN FD");
                match decode(&f) {
                    Message::Stream(m) => {
                        assert_eq!(m.counter.get() as usize, stream_ticks.len());
                        assert_eq!(m.evaluated, 0b111);
                        assert_eq!(m.confidences[2].to_bits(), 3000);
                        stream_ticks.push(now);
                    }
                    Message::Status(p) => pages.push((now, p.page.page(), p.counter.get())),
                    m => panic!("{m:?}"),
                }
            }
        }
        assert_eq!(stream_ticks.len(), 44);
        assert!(stream_ticks.windows(2).all(|w| w[1] - w[0] == 5));
        let want: std::vec::Vec<(u32, u8)> = (0..11u32)
            .flat_map(|k| {
                let p = (k % u32::from(STATUS_PAGES - 1)) as u8 + 1;
                [(1000 + 20 * k, 0), (1000 + 20 * k, p)]
            })
            .collect();
        assert_eq!(
            pages
                .iter()
                .map(|p| (p.0, p.1))
                .collect::<std::vec::Vec<_>>(),
            want
        );
        // One counter for every status frame, whatever its page.
        assert!(pages.iter().enumerate().all(|(i, p)| usize::from(p.2) == i));
    }

    fn decision(e: u8, level: Level, tick: Tick) -> Decision {
        Decision {
            event: EventId(e),
            level,
            confidence: Confidence::ONE,
            onset: tick.wrapping_sub(40),
            tick,
        }
    }

    #[test]
    fn events_go_first_with_advancing_counters() {
        for format in [BusFormat::Fd, BusFormat::Classic] {
            let t = tx(format, 1, 1000);
            let mut s = TxState::new();
            let mut out = output(0b1100_0001);
            for (i, e) in [0u8, 6, 7].into_iter().enumerate() {
                let level = if i == 0 { Level::Alert } else { Level::Confirm };
                out.decisions.push(decision(e, level, 50)).unwrap();
            }
            let frames = t.tick(&mut s, 50, &out, &Status::default());
            let ids: std::vec::Vec<u16> = frames.iter().map(|f| f.id().as_raw()).collect();
            assert!(ids.windows(2).all(|w| w[0] <= w[1]), "{ids:X?}");
            let kinds: std::vec::Vec<MessageKind> =
                frames.iter().map(|f| decode(f).kind()).collect();
            let (e, st) = (MessageKind::Event, MessageKind::Status);
            match format {
                BusFormat::Fd => assert_eq!(kinds, [e, e, e, MessageKind::Stream, st, st]),
                BusFormat::Classic => {
                    let p = MessageKind::StreamPage;
                    assert_eq!(kinds, [e, e, e, p, p, p, st, st]);
                    assert!(frames.iter().all(|f| !f.is_fd()));
                }
            }
            for (i, f) in frames.iter().take(3).enumerate() {
                let Message::Event(m) = decode(f) else {
                    panic!()
                };
                assert_eq!((m.counter.get(), m.onset_age), (i as u8, 40));
            }
            assert_eq!(s.next_event_counter().get(), 3);
            assert_eq!(s.dropped(), 0);
        }
    }

    #[test]
    fn a_level_raised_between_samples_is_in_the_next_one() {
        for format in [BusFormat::Fd, BusFormat::Classic] {
            let t = tx(format, 10, 1000);
            let mut s = TxState::new();
            let levels = |frames: &TxFrames| -> std::vec::Vec<LevelState> {
                frames
                    .iter()
                    .filter_map(|f| match decode(f) {
                        Message::Stream(m) => Some(m.levels[1]),
                        Message::StreamPage(p) if p.event == EventId(1) => Some(p.level),
                        _ => None,
                    })
                    .collect()
            };
            let quiet = output(0b10);
            assert_eq!(
                levels(&t.tick(&mut s, 0, &quiet, &Status::default())),
                [LevelState::None]
            );
            // Confirmed at tick 3 (both levels at once), down again by tick 6.
            let mut up = output(0b10);
            up.decisions.push(decision(1, Level::Alert, 3)).unwrap();
            up.decisions.push(decision(1, Level::Confirm, 3)).unwrap();
            up.alerting = 0b10;
            up.confirmed = 0b10;
            assert!(levels(&t.tick(&mut s, 3, &up, &Status::default())).is_empty());
            t.tick(&mut s, 6, &quiet, &Status::default());
            assert_eq!(
                levels(&t.tick(&mut s, 10, &quiet, &Status::default())),
                [LevelState::Confirm]
            );
            // Reported once: the next sample has it down.
            assert_eq!(
                levels(&t.tick(&mut s, 20, &quiet, &Status::default())),
                [LevelState::None]
            );
        }
    }

    #[test]
    fn classic_pages_share_their_sample_number() {
        let t = tx(BusFormat::Classic, 1, 1000);
        let mut s = TxState::new();
        let mut samples = std::vec::Vec::new();
        for now in 0..3 {
            for f in t.tick(&mut s, now, &output(0b1010_0100), &Status::default()) {
                if let Message::StreamPage(p) = decode(&f) {
                    samples.push((p.sample, p.event.0, p.counter.get()));
                }
            }
        }
        let want: std::vec::Vec<(u8, u8, u8)> = (0..3u8)
            .flat_map(|k| [(k, 2, 3 * k), (k, 5, 3 * k + 1), (k, 7, 3 * k + 2)])
            .collect();
        assert_eq!(samples, want);
        // Nothing evaluated: no page, the sample number stays.
        let frames = t.tick(&mut s, 3, &Output::default(), &Status::default());
        assert!(
            frames
                .iter()
                .all(|f| decode(f).kind() != MessageKind::StreamPage)
        );
    }

    #[test]
    fn no_stream_when_nothing_is_evaluated() {
        for format in [BusFormat::Fd, BusFormat::Classic] {
            let t = tx(format, 1, 1000);
            let mut s = TxState::new();
            let frames = t.tick(&mut s, 0, &Output::default(), &Status::default());
            assert!(
                frames
                    .iter()
                    .all(|f| decode(f).kind() == MessageKind::Status)
            );
            // The next sample is number 0: nothing was counted.
            let frames = t.tick(&mut s, 1, &output(0b1), &Status::default());
            let first = frames.iter().map(decode).find_map(|m| match m {
                Message::Stream(m) => Some(m.counter.get()),
                Message::StreamPage(p) => Some(p.sample),
                _ => None,
            });
            assert_eq!(first, Some(0));
        }
    }

    #[test]
    fn status_reports_the_receiver() {
        let node = NodeId::new(2).unwrap();
        let rx = Receiver::new(node, 2, 10, 10).unwrap();
        let mut rs = RxState::new();
        let _ = rx.receive(&mut rs, 0, Id::Standard(MessageKind::Event.id(node)), &[]);
        let mut st = Status {
            late_ticks: 70_000,
            ..Status::default()
        };
        st.update_from_rx(&rx, &rs, 0);
        assert!(st.faults.contains(FaultFlags::CONTEXT_STALE));
        assert_eq!(
            st.page(9, 0, BusFormat::Fd),
            Some(StatusPage::RejectsRoute {
                unknown_id: 1,
                phase_not_configured: 0
            })
        );
        assert!(matches!(
            st.page(3, 0, BusFormat::Fd),
            Some(StatusPage::Lateness {
                late_ticks: 65535,
                ..
            })
        ));
        assert!(matches!(
            st.page(2, 0, BusFormat::Classic),
            Some(StatusPage::Identity {
                format: BusFormat::Classic,
                protocol: PROTOCOL_VERSION,
                ..
            })
        ));
        assert_eq!(st.page(STATUS_PAGES, 0, BusFormat::Fd), None);
    }

    #[test]
    fn defaults_and_bad_parameters() {
        let n = NodeId::new(0).unwrap();
        let t = Transmitter::with_defaults(n, BusFormat::Fd, 5000).unwrap();
        assert_eq!(t.stream_decimation(), 20);
        assert_eq!(t.heartbeat_period(), 250);
        let c = Transmitter::with_defaults(n, BusFormat::Classic, 5000).unwrap();
        assert_eq!(c.stream_decimation(), 100);
        assert_eq!(c.heartbeat_period(), 250);
        assert_eq!(
            Transmitter::new(n, BusFormat::Fd, 0, 1),
            Err(TxConfigError::StreamDecimation(0))
        );
        assert_eq!(
            Transmitter::with_defaults(n, BusFormat::Fd, 0),
            Err(TxConfigError::Rate(0))
        );
    }
}
