//! The fingertip's receive side: validates the controller's phase, context and tip state
//! frames, rejects bad ones with a reason (counted for the status frame), and keeps the
//! latest good values with their age so stale context is never used.
//!
//! Parameters live in [`Receiver`], everything that changes in [`RxState`]. A rejected
//! frame changes nothing but the count of its reason.
//!
//! # Counter rule
//! A protected frame's counter must be 1..=`max_counter_delta` ahead of the last accepted
//! frame of the same message (the gap, minus one, is counted as lost frames); 0 ahead is a
//! repetition and anything further is out of order or a replay: both are rejected as
//! [`RejectReason::Sequence`]. When the message is stale (nothing accepted within its
//! timeout, or nothing yet) any counter is accepted: the receiver resynchronizes.
//!
//! # Stale rule
//! Context and tip state are stale when none was accepted within the context timeout; the
//! phase, within the phase timeout. [`Receiver::inputs`] then withholds the values, and
//! the caller marks the channels they feed as faulty, so the detector judges no event
//! that depends on them. [`Receiver::poll`], called once per tick, latches staleness and
//! counts stale episodes.

use core::fmt;

use super::codec::{ContextMsg, DecodeError, Message, PhaseMsg, TipStateMsg};
use super::{Id, MessageKind, NodeId};
use detector_core::{MAX_PHASES, Signal, Tick};

/// Why a received frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RejectReason {
    /// Not the length of its message (including remote frames, passed with no data).
    WrongLength,
    /// Not one of this node's three receive identifiers (phase, context, tip state).
    UnknownId,
    /// The CRC-8 does not match (corrupted, or sent under another identifier).
    BadCrc,
    /// The counter did not advance by 1..=`max_counter_delta`: a repeated, out-of-order or
    /// replayed frame.
    Sequence,
    /// A phase index at or above the number of phases configured.
    PhaseNotConfigured,
    /// A value outside its range.
    OutOfRange,
}

/// Number of [`RejectReason`]s.
pub const REJECT_REASONS: usize = 6;

impl RejectReason {
    /// Every reason, in index order.
    pub const ALL: [RejectReason; REJECT_REASONS] = [
        RejectReason::WrongLength,
        RejectReason::UnknownId,
        RejectReason::BadCrc,
        RejectReason::Sequence,
        RejectReason::PhaseNotConfigured,
        RejectReason::OutOfRange,
    ];

    /// The reason's index in [`RejectReason::ALL`] and in [`RejectCounts`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// A short name.
    pub const fn name(self) -> &'static str {
        match self {
            RejectReason::WrongLength => "wrong length",
            RejectReason::UnknownId => "unknown identifier",
            RejectReason::BadCrc => "bad CRC",
            RejectReason::Sequence => "counter not advancing",
            RejectReason::PhaseNotConfigured => "phase not configured",
            RejectReason::OutOfRange => "value out of range",
        }
    }

    /// The reason a decoding error amounts to.
    pub const fn from_decode(e: &DecodeError) -> RejectReason {
        match e {
            DecodeError::UnknownId => RejectReason::UnknownId,
            DecodeError::WrongLength { .. } => RejectReason::WrongLength,
            DecodeError::BadCrc { .. } => RejectReason::BadCrc,
            DecodeError::OutOfRange { .. } => RejectReason::OutOfRange,
        }
    }
}

impl fmt::Display for RejectReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Rejected frames by reason, since boot, saturating at `u32::MAX`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RejectCounts([u32; REJECT_REASONS]);

impl RejectCounts {
    /// Frames rejected for `reason`.
    pub fn get(&self, reason: RejectReason) -> u32 {
        self.0.get(reason.index()).copied().unwrap_or(0)
    }

    /// Frames rejected for any reason (saturating).
    pub fn total(&self) -> u32 {
        self.0.iter().fold(0u32, |a, &b| a.saturating_add(b))
    }

    /// All counts, by [`RejectReason::index`].
    pub const fn as_array(&self) -> &[u32; REJECT_REASONS] {
        &self.0
    }

    fn bump(&mut self, reason: RejectReason) {
        if let Some(c) = self.0.get_mut(reason.index()) {
            *c = c.saturating_add(1);
        }
    }
}

/// The receive counters for the status frame, since boot, saturating.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxCounts {
    rejected: RejectCounts,
    lost_frames: u32,
    stale_episodes: u32,
}

impl RxCounts {
    /// Rejected frames by reason.
    pub const fn rejected(&self) -> &RejectCounts {
        &self.rejected
    }

    /// Controller frames lost, from the gaps in accepted frames' counters.
    pub const fn lost_frames(&self) -> u32 {
        self.lost_frames
    }

    /// Times the context or the tip state went from fresh to stale (each counts).
    pub const fn stale_episodes(&self) -> u32 {
        self.stale_episodes
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Slot<T> {
    /// The last accepted message and the tick it arrived.
    last: Option<(T, Tick)>,
    /// Latched by `poll` once stale, cleared by the next accepted frame; guards against
    /// the tick counter wrapping during a very long silence.
    stale: bool,
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Slot {
            last: None,
            stale: true,
        }
    }
}

impl<T: Copy> Slot<T> {
    fn is_stale(&self, now: Tick, timeout: Tick) -> bool {
        match self.last {
            None => true,
            Some((_, at)) => self.stale || now.wrapping_sub(at) > timeout,
        }
    }

    fn value(&self) -> Option<T> {
        self.last.map(|(m, _)| m)
    }
}

/// What the receiver knows of the controller: the last accepted frame of each message
/// and when it arrived. Changed only by accepted frames and by [`Receiver::poll`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxLink {
    phase: Slot<PhaseMsg>,
    context: Slot<ContextMsg>,
    tip_state: Slot<TipStateMsg>,
}

impl RxLink {
    /// The last accepted phase command, stale or not; `None` before the first.
    pub fn phase(&self) -> Option<PhaseMsg> {
        self.phase.value()
    }

    /// The last accepted context, stale or not (use [`Receiver::inputs`] to act on it).
    pub fn context(&self) -> Option<ContextMsg> {
        self.context.value()
    }

    /// The last accepted tip state, stale or not (use [`Receiver::inputs`] to act on it).
    pub fn tip_state(&self) -> Option<TipStateMsg> {
        self.tip_state.value()
    }
}

/// Everything the receiver changes: the link state and the counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxState {
    link: RxLink,
    counts: RxCounts,
}

impl RxState {
    /// A receiver's state at boot: nothing received, everything stale.
    pub fn new() -> RxState {
        RxState::default()
    }

    /// What is known of the controller.
    pub const fn link(&self) -> &RxLink {
        &self.link
    }

    /// The counters.
    pub const fn counts(&self) -> &RxCounts {
        &self.counts
    }
}

/// A frame the receiver accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Accepted {
    /// A phase command.
    Phase {
        /// The command.
        command: PhaseMsg,
        /// Whether phase or sequence differ from the previous command (or there was
        /// none): the caller switches the detector to the phase.
        changed: bool,
    },
    /// A context frame.
    Context(ContextMsg),
    /// A tip state frame.
    TipState(TipStateMsg),
}

/// Which of the controller's messages are fresh (accepted within their timeout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Freshness {
    /// The phase command is fresh.
    pub phase: bool,
    /// The context (desired velocity and acceleration) is fresh.
    pub context: bool,
    /// The tip state (position error) is fresh.
    pub tip_state: bool,
}

/// The controller's inputs to the detector at a tick: `None` where the message is stale
/// or was never received, so the caller flags the channels faulty.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControllerInputs {
    /// Desired tip velocity (x, y), m/s: channels `vel_des_x`, `vel_des_y`.
    pub vel_des: Option<[Signal; 2]>,
    /// Desired tip acceleration (x, y), m/s²: channels `acc_des_x`, `acc_des_y`.
    pub acc_des: Option<[Signal; 2]>,
    /// Tip position error (x, y), m: channels `pos_err_x`, `pos_err_y`.
    pub pos_err: Option<[Signal; 2]>,
}

/// A receiver parameter is invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RxConfigError {
    /// The number of configured phases must be within 1..=8.
    PhaseCount(u8),
    /// A timeout must be within 1..=2³¹−1 ticks.
    Timeout(Tick),
    /// The largest counter step accepted must be within 1..=14.
    MaxCounterDelta(u8),
}

impl fmt::Display for RxConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RxConfigError::PhaseCount(n) => write!(f, "phase count {n} is not within 1..=8"),
            RxConfigError::Timeout(t) => write!(f, "timeout {t} ticks is not within 1..2^31"),
            RxConfigError::MaxCounterDelta(d) => {
                write!(f, "max counter delta {d} is not within 1..=14")
            }
        }
    }
}

/// The fingertip's receive logic: its parameters. See the [module docs](crate::rx).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Receiver {
    node: NodeId,
    phase_count: u8,
    context_timeout: Tick,
    phase_timeout: Tick,
    max_counter_delta: u8,
}

impl Receiver {
    /// The default largest counter step accepted: up to two frames lost in a row.
    pub const DEFAULT_MAX_COUNTER_DELTA: u8 = 3;

    /// A receiver for node `node`, whose configuration has `phase_count` phases.
    /// Context and tip state go stale `context_timeout` ticks after the last accepted
    /// frame, the phase after `phase_timeout` ticks (e.g. 100 and 500 ticks: 20 ms and
    /// 100 ms at 5 kHz).
    pub const fn new(
        node: NodeId,
        phase_count: u8,
        context_timeout: Tick,
        phase_timeout: Tick,
    ) -> Result<Receiver, RxConfigError> {
        if phase_count == 0 || phase_count as usize > MAX_PHASES {
            return Err(RxConfigError::PhaseCount(phase_count));
        }
        if context_timeout == 0 || context_timeout > i32::MAX as u32 {
            return Err(RxConfigError::Timeout(context_timeout));
        }
        if phase_timeout == 0 || phase_timeout > i32::MAX as u32 {
            return Err(RxConfigError::Timeout(phase_timeout));
        }
        Ok(Receiver {
            node,
            phase_count,
            context_timeout,
            phase_timeout,
            max_counter_delta: Receiver::DEFAULT_MAX_COUNTER_DELTA,
        })
    }

    /// The same receiver accepting counter steps up to `delta` (1..=14).
    pub const fn with_max_counter_delta(mut self, delta: u8) -> Result<Receiver, RxConfigError> {
        if delta == 0 || delta > 14 {
            return Err(RxConfigError::MaxCounterDelta(delta));
        }
        self.max_counter_delta = delta;
        Ok(self)
    }

    /// The node this receiver listens for.
    pub const fn node(&self) -> NodeId {
        self.node
    }

    /// Handles one received frame at tick `now`: accepts it (updating the state) or
    /// rejects it with a reason (counting it, changing nothing else). Never panics.
    pub fn receive(
        &self,
        state: &mut RxState,
        now: Tick,
        id: Id,
        data: &[u8],
    ) -> Result<Accepted, RejectReason> {
        match self.check(&state.link, now, id, data) {
            Ok((accepted, lost)) => {
                state.counts.lost_frames = state.counts.lost_frames.saturating_add(lost);
                let link = &mut state.link;
                match accepted {
                    Accepted::Phase { command, .. } => {
                        link.phase = Slot {
                            last: Some((command, now)),
                            stale: false,
                        }
                    }
                    Accepted::Context(m) => {
                        link.context = Slot {
                            last: Some((m, now)),
                            stale: false,
                        }
                    }
                    Accepted::TipState(m) => {
                        link.tip_state = Slot {
                            last: Some((m, now)),
                            stale: false,
                        }
                    }
                }
                Ok(accepted)
            }
            Err(reason) => {
                state.counts.rejected.bump(reason);
                Err(reason)
            }
        }
    }

    /// Validation without side effects: the accepted frame and the frames lost before it.
    fn check(
        &self,
        link: &RxLink,
        now: Tick,
        id: Id,
        data: &[u8],
    ) -> Result<(Accepted, u32), RejectReason> {
        match MessageKind::from_id(id) {
            Some((MessageKind::Phase | MessageKind::Context | MessageKind::TipState, node))
                if node == self.node => {}
            _ => return Err(RejectReason::UnknownId),
        }
        let (_, message) = Message::decode(id, data).map_err(|e| RejectReason::from_decode(&e))?;
        let lost = match message {
            Message::Phase(m) => {
                if m.phase >= self.phase_count {
                    return Err(RejectReason::PhaseNotConfigured);
                }
                let lost = self.sequence(&link.phase, now, self.phase_timeout, m.counter)?;
                let changed = link
                    .phase
                    .value()
                    .is_none_or(|p| (p.phase, p.sequence) != (m.phase, m.sequence));
                return Ok((
                    Accepted::Phase {
                        command: m,
                        changed,
                    },
                    lost,
                ));
            }
            Message::Context(m) => (
                Accepted::Context(m),
                self.sequence(&link.context, now, self.context_timeout, m.counter)?,
            ),
            Message::TipState(m) => (
                Accepted::TipState(m),
                self.sequence(&link.tip_state, now, self.context_timeout, m.counter)?,
            ),
            // Unreachable: the identifier was checked above.
            _ => return Err(RejectReason::UnknownId),
        };
        Ok(lost)
    }

    /// The counter rule: frames lost before this one, or a rejection.
    fn sequence<T: Copy + HasCounter>(
        &self,
        slot: &Slot<T>,
        now: Tick,
        timeout: Tick,
        counter: super::Counter,
    ) -> Result<u32, RejectReason> {
        if slot.is_stale(now, timeout) {
            return Ok(0);
        }
        let Some((last, _)) = slot.last else {
            return Ok(0);
        };
        let delta = last.counter().delta_to(counter);
        if delta == 0 || delta > self.max_counter_delta {
            Err(RejectReason::Sequence)
        } else {
            Ok(u32::from(delta - 1))
        }
    }

    /// Which messages are fresh at `now`. Pure.
    pub fn freshness(&self, state: &RxState, now: Tick) -> Freshness {
        let l = &state.link;
        Freshness {
            phase: !l.phase.is_stale(now, self.phase_timeout),
            context: !l.context.is_stale(now, self.context_timeout),
            tip_state: !l.tip_state.is_stale(now, self.context_timeout),
        }
    }

    /// Whether the context (desired velocity and acceleration) is stale at `now`.
    pub fn is_context_stale(&self, state: &RxState, now: Tick) -> bool {
        !self.freshness(state, now).context
    }

    /// Once per tick: latches staleness and counts each context or tip state going from
    /// fresh to stale as an episode. Returns the freshness at `now`.
    pub fn poll(&self, state: &mut RxState, now: Tick) -> Freshness {
        let f = self.freshness(state, now);
        let l = &mut state.link;
        l.phase.stale = !f.phase;
        let mut episodes = 0u32;
        if !f.context && !l.context.stale {
            episodes += 1;
        }
        if !f.tip_state && !l.tip_state.stale {
            episodes += 1;
        }
        l.context.stale = !f.context;
        l.tip_state.stale = !f.tip_state;
        state.counts.stale_episodes = state.counts.stale_episodes.saturating_add(episodes);
        f
    }

    /// The controller's inputs at `now`, withheld where stale.
    pub fn inputs(&self, state: &RxState, now: Tick) -> ControllerInputs {
        let f = self.freshness(state, now);
        let l = &state.link;
        let ctx = l.context.value().filter(|_| f.context);
        ControllerInputs {
            vel_des: ctx.map(|c| c.vel_des_signals()),
            acc_des: ctx.map(|c| c.acc_des_signals()),
            pos_err: l
                .tip_state
                .value()
                .filter(|_| f.tip_state)
                .map(|t| t.pos_err_signals()),
        }
    }
}

trait HasCounter {
    fn counter(&self) -> super::Counter;
}

impl HasCounter for PhaseMsg {
    fn counter(&self) -> super::Counter {
        self.counter
    }
}

impl HasCounter for ContextMsg {
    fn counter(&self) -> super::Counter {
        self.counter
    }
}

impl HasCounter for TipStateMsg {
    fn counter(&self) -> super::Counter {
        self.counter
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Counter, StandardId};

    const NODE: u8 = 4;

    fn rx() -> Receiver {
        Receiver::new(NodeId::new(NODE).unwrap(), 3, 100, 500).unwrap()
    }

    fn node() -> NodeId {
        NodeId::new(NODE).unwrap()
    }

    fn ctx(counter: u8, vx: i16) -> (Id, heapless::Vec<u8, 8>) {
        let f = ContextMsg {
            counter: Counter::new(counter).unwrap(),
            vel_des: [vx, 0],
            acc_des: [0, 0],
        }
        .encode(node())
        .unwrap();
        (Id::Standard(f.id()), f.data().iter().copied().collect())
    }

    fn phase(counter: u8, p: u8, seq: u8) -> (Id, heapless::Vec<u8, 8>) {
        let f = PhaseMsg {
            counter: Counter::new(counter).unwrap(),
            phase: p,
            sequence: seq,
        }
        .encode(node())
        .unwrap();
        (Id::Standard(f.id()), f.data().iter().copied().collect())
    }

    #[test]
    fn accepts_a_good_sequence_and_counts_lost_frames() {
        let r = rx();
        let mut s = RxState::new();
        for (t, c) in [(0u32, 5u8), (10, 6), (20, 8), (30, 11)] {
            let (id, d) = ctx(c, i16::from(c));
            assert!(matches!(
                r.receive(&mut s, t, id, &d),
                Ok(Accepted::Context(_))
            ));
        }
        assert_eq!(s.counts().lost_frames(), 1 + 2);
        assert_eq!(s.link().context().unwrap().vel_des[0], 11);
    }

    #[test]
    fn rejects_repeats_and_jumps_without_changing_state() {
        let r = rx();
        let mut s = RxState::new();
        let (id, d) = ctx(5, 1);
        r.receive(&mut s, 0, id, &d).unwrap();
        let before = *s.link();
        for c in [5u8, 9, 4] {
            let (id, d) = ctx(c, 2);
            assert_eq!(r.receive(&mut s, 1, id, &d), Err(RejectReason::Sequence));
        }
        assert_eq!(*s.link(), before);
        assert_eq!(s.counts().rejected().get(RejectReason::Sequence), 3);
        // After the timeout any counter resynchronizes.
        let (id, d) = ctx(5, 3);
        assert!(r.receive(&mut s, 101, id, &d).is_ok());
    }

    #[test]
    fn rejects_each_kind_of_bad_frame() {
        let r = rx();
        let mut s = RxState::new();
        let (id, d) = ctx(0, 0);
        assert_eq!(
            r.receive(&mut s, 0, id, &d[..7]),
            Err(RejectReason::WrongLength)
        );
        let mut bad = d.clone();
        bad[3] ^= 0x40;
        assert_eq!(r.receive(&mut s, 0, id, &bad), Err(RejectReason::BadCrc));
        let other = Id::Standard(MessageKind::Context.id(NodeId::new(5).unwrap()));
        assert_eq!(
            r.receive(&mut s, 0, other, &d),
            Err(RejectReason::UnknownId)
        );
        let ev = Id::Standard(MessageKind::Event.id(node()));
        assert_eq!(r.receive(&mut s, 0, ev, &d), Err(RejectReason::UnknownId));
        let ext = Id::Extended(crate::ExtendedId::new(0x0A4).unwrap());
        assert_eq!(r.receive(&mut s, 0, ext, &d), Err(RejectReason::UnknownId));
        let (pid, pd) = phase(0, 3, 0);
        assert_eq!(
            r.receive(&mut s, 0, pid, &pd),
            Err(RejectReason::PhaseNotConfigured)
        );
        // Phase 9 with a correct CRC: out of range.
        let mut raw = [0u8, 0, 9, 0];
        raw[0] = crate::e2e::crc(MessageKind::Phase.id(node()), &raw).unwrap();
        assert_eq!(
            r.receive(&mut s, 0, pid, &raw),
            Err(RejectReason::OutOfRange)
        );
        let counts = s.counts().rejected();
        assert_eq!(counts.total(), 7);
        assert_eq!(counts.get(RejectReason::UnknownId), 3);
        assert_eq!(*s.link(), RxLink::default());
        let _ = StandardId::ZERO;
    }

    #[test]
    fn context_goes_stale_and_is_withheld() {
        let r = rx();
        let mut s = RxState::new();
        assert!(r.is_context_stale(&s, 0));
        assert_eq!(r.inputs(&s, 0), ControllerInputs::default());
        let (id, d) = ctx(1, 500);
        r.receive(&mut s, 1000, id, &d).unwrap();
        assert!(r.poll(&mut s, 1100).context);
        let v = r.inputs(&s, 1100).vel_des.unwrap();
        assert!((v[0].to_f64() - 0.05).abs() < 1e-4);
        assert!(!r.poll(&mut s, 1101).context);
        assert!(r.is_context_stale(&s, 1101));
        assert_eq!(r.inputs(&s, 1101).vel_des, None);
        assert_eq!(s.counts().stale_episodes(), 1);
        // Still stale, no second episode; the latch holds even if the tick wraps round.
        r.poll(&mut s, 5000);
        assert!(r.is_context_stale(&s, 1050u32.wrapping_add(u32::MAX)));
        assert_eq!(s.counts().stale_episodes(), 1);
        let (id, d) = ctx(9, 1);
        r.receive(&mut s, 6000, id, &d).unwrap();
        assert!(!r.is_context_stale(&s, 6000));
    }

    #[test]
    fn phase_change_is_reported_once() {
        let r = rx();
        let mut s = RxState::new();
        let changed = |a: Result<Accepted, RejectReason>| match a {
            Ok(Accepted::Phase { changed, .. }) => changed,
            other => panic!("{other:?}"),
        };
        let (id, d) = phase(0, 1, 7);
        assert!(changed(r.receive(&mut s, 0, id, &d)));
        let (id, d) = phase(1, 1, 7);
        assert!(!changed(r.receive(&mut s, 10, id, &d)));
        let (id, d) = phase(2, 1, 8);
        assert!(changed(r.receive(&mut s, 20, id, &d)));
    }

    #[test]
    fn parameters_are_validated() {
        let n = node();
        assert_eq!(Receiver::new(n, 0, 1, 1), Err(RxConfigError::PhaseCount(0)));
        assert_eq!(Receiver::new(n, 9, 1, 1), Err(RxConfigError::PhaseCount(9)));
        assert_eq!(Receiver::new(n, 1, 0, 1), Err(RxConfigError::Timeout(0)));
        assert_eq!(
            rx().with_max_counter_delta(15),
            Err(RxConfigError::MaxCounterDelta(15))
        );
    }
}
