//! The fingertip's receive side: validates the controller's phase and context frames,
//! rejects bad ones with a reason (counted for the status frame), counts the frames lost,
//! and keeps the latest good values with their age so stale context is never used.
//!
//! Parameters live in [`Receiver`], everything that changes in [`RxState`]. A rejected
//! frame changes nothing but the count of its reason.
//!
//! # Counter rule (AUTOSAR E2E profile 5 style)
//! Each identifier the fingertip listens to (its phase, its group's broadcast context, its
//! classic context parts) has its own counter track. A frame with a good CRC is checked
//! against the last frame accepted on its identifier:
//!
//! - the counter did not move (0 ahead): a repetition, rejected ([`RejectReason::Sequence`]);
//! - while the track is fresh (its last frame accepted within the message's timeout), a
//!   context frame whose controller time does not advance is an old frame, rejected
//!   ([`RejectReason::Sequence`]);
//! - anything else is accepted at once, resynchronizing the counter: a frame `k + 1`
//!   ahead counts `k` frames lost. No good frame is ever rejected because frames before it
//!   were lost.
//!
//! After a silence longer than the timeout, a context frame whose time went back (the
//! controller restarted) is accepted without counting any loss. The 8-bit counter wraps
//! after 256 frames (256 ms at 1 kHz), far beyond any timeout, so a gap of up to 255
//! frames is counted exactly.
//!
//! # Stale rule
//! The fingertip's velocity, acceleration and position error (its slot of the broadcast
//! context, or the three classic parts) are stale when none was accepted within the
//! context timeout; the phase, within the phase timeout. A context frame whose slot for
//! this fingertip is not filled is accepted (its counter tracked) but refreshes nothing.
//! [`Receiver::inputs`] withholds stale values, and the caller marks the channels they
//! feed as faulty, so the detector judges no event that depends on them.
//! [`Receiver::poll`], called once per tick, latches staleness (so a tick counter that
//! wraps during a very long silence cannot make old context look fresh) and counts stale
//! episodes.

use core::fmt;

use super::codec::{ContextPart, ContextPartMsg, ContextSlot, DecodeError, Message, PhaseMsg};
use super::{Address, ContextGroup, Counter, Id, MessageKind, NodeId};
use detector_core::{MAX_PHASES, Tick};

/// Why a received frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RejectReason {
    /// Not the length of its message (including remote frames, passed with no data).
    WrongLength,
    /// Not one of this node's receive identifiers (its phase, its group's context, its
    /// context parts).
    UnknownId,
    /// The CRC-16 does not match (corrupted, or sent under another identifier).
    BadCrc,
    /// A repetition (the counter did not move), or an old context frame (its controller
    /// time did not advance).
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
            RejectReason::Sequence => "repeated or old frame",
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

/// The last frame accepted on one identifier.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Last {
    counter: Counter,
    /// The controller's time, for the frames that carry it.
    time: Option<u32>,
    /// When it arrived.
    at: Tick,
}

/// A counter track: the last frame accepted on one identifier, and whether it has aged
/// past its timeout (latched by `poll`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Track {
    last: Option<Last>,
    stale: bool,
}

impl Default for Track {
    fn default() -> Self {
        Track {
            last: None,
            stale: true,
        }
    }
}

impl Track {
    fn is_fresh(&self, now: Tick, timeout: Tick) -> bool {
        !self.stale && self.last.is_some_and(|l| now.wrapping_sub(l.at) <= timeout)
    }

    fn latch(&mut self, now: Tick, timeout: Tick) {
        self.stale = !self.is_fresh(now, timeout);
    }

    /// The counter rule: frames lost before this one, or a rejection.
    fn check(
        &self,
        now: Tick,
        timeout: Tick,
        counter: Counter,
        time: Option<u32>,
    ) -> Result<u32, RejectReason> {
        let Some(last) = self.last else {
            return Ok(0);
        };
        let delta = last.counter.delta_to(counter);
        if delta == 0 {
            return Err(RejectReason::Sequence);
        }
        let advanced = match (time, last.time) {
            (Some(t), Some(lt)) => t.wrapping_sub(lt) as i32 > 0,
            _ => true,
        };
        match (self.is_fresh(now, timeout), advanced) {
            (true, false) => Err(RejectReason::Sequence),
            // A controller that restarted: nothing to count.
            (false, false) => Ok(0),
            (_, true) => Ok(u32::from(delta - 1)),
        }
    }

    fn accept(&mut self, now: Tick, counter: Counter, time: Option<u32>) {
        *self = Track {
            last: Some(Last {
                counter,
                time,
                at: now,
            }),
            stale: false,
        };
    }
}

/// A value and when it arrived, with the staleness latched by `poll`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
struct Held<T> {
    value: Option<(T, Tick)>,
    stale: bool,
}

impl<T> Default for Held<T> {
    fn default() -> Self {
        Held {
            value: None,
            stale: true,
        }
    }
}

impl<T: Copy> Held<T> {
    fn is_fresh(&self, now: Tick, timeout: Tick) -> bool {
        !self.stale
            && self
                .value
                .is_some_and(|(_, at)| now.wrapping_sub(at) <= timeout)
    }

    fn get(&self) -> Option<T> {
        self.value.map(|(v, _)| v)
    }

    fn set(&mut self, value: T, now: Tick) {
        *self = Held {
            value: Some((value, now)),
            stale: false,
        };
    }

    fn fresh(&self, now: Tick, timeout: Tick) -> Option<T> {
        self.get().filter(|_| self.is_fresh(now, timeout))
    }
}

/// What the receiver knows of the controller: the last accepted frames and values, and
/// when they arrived. Changed only by accepted frames and by [`Receiver::poll`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RxLink {
    phase_track: Track,
    context_track: Track,
    part_track: Track,
    phase: Held<PhaseMsg>,
    parts: [Held<[i16; 2]>; 3],
    controller_time: Option<u32>,
}

impl RxLink {
    /// The last accepted phase command, stale or not; `None` before the first.
    pub fn phase(&self) -> Option<PhaseMsg> {
        self.phase.get()
    }

    /// The last accepted value of a context part, stale or not (use
    /// [`Receiver::inputs`] to act on it).
    pub fn part(&self, part: ContextPart) -> Option<[i16; 2]> {
        self.parts.get(part as usize).and_then(Held::get)
    }

    /// The controller's time (µs) in the last accepted broadcast context frame.
    pub const fn controller_time(&self) -> Option<u32> {
        self.controller_time
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
    /// A broadcast context frame of this fingertip's group.
    Context {
        /// The frame's counter.
        counter: Counter,
        /// This fingertip's slot; `None` when the controller left it empty.
        slot: Option<ContextSlot>,
        /// The controller's time, µs.
        time_us: u32,
    },
    /// One part of this fingertip's context (classic CAN).
    ContextPart(ContextPartMsg),
}

/// A received frame that passed [`Receiver::decode`]'s checks, waiting for
/// [`Receiver::accept`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Decoded(Accepted);

/// Which of the controller's messages are fresh (accepted within their timeout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Freshness {
    /// The phase command is fresh.
    pub phase: bool,
    /// The desired velocity and acceleration are fresh.
    pub context: bool,
    /// The tip position error is fresh.
    pub tip_state: bool,
}

/// The controller's inputs to the detector at a tick, as the frames carry them (raw, in
/// steps of [`ContextPart::scale`]: the caller converts them to the detector's units in
/// one rounding): `None` where the value is stale or was never received, so the caller
/// flags the channels faulty.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControllerInputs {
    /// Desired tip velocity (x, y), steps of 0.1 mm/s: channels `vel_des_x`, `vel_des_y`.
    pub vel_des: Option<[i16; 2]>,
    /// Desired tip acceleration (x, y), steps of 2 mm/s²: channels `acc_des_x`,
    /// `acc_des_y`.
    pub acc_des: Option<[i16; 2]>,
    /// Tip position error (x, y), steps of 1 µm: channels `pos_err_x`, `pos_err_y`.
    pub pos_err: Option<[i16; 2]>,
}

/// A receiver parameter is invalid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RxConfigError {
    /// The number of configured phases must be within 1..=8.
    PhaseCount(u8),
    /// A timeout must be within 1..=2³¹−1 ticks.
    Timeout(Tick),
}

impl fmt::Display for RxConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RxConfigError::PhaseCount(n) => write!(f, "phase count {n} is not within 1..=8"),
            RxConfigError::Timeout(t) => write!(f, "timeout {t} ticks is not within 1..2^31"),
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
}

impl Receiver {
    /// A receiver for node `node`, whose configuration has `phase_count` phases.
    /// Context goes stale `context_timeout` ticks after its last good frame, the phase
    /// after `phase_timeout` ticks (e.g. 100 and 500 ticks: 20 ms and 100 ms at 5 kHz).
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
        })
    }

    /// The node this receiver listens for.
    pub const fn node(&self) -> NodeId {
        self.node
    }

    /// The raw identifiers it accepts: its phase, its group's broadcast context, its
    /// classic context parts (for the CAN controller's acceptance filter).
    pub const fn identifiers(&self) -> [u16; 3] {
        [
            MessageKind::Phase.raw_id(self.node),
            MessageKind::Context.raw_id(self.node),
            MessageKind::ContextPart.raw_id(self.node),
        ]
    }

    /// Handles one received frame at tick `now`: accepts it (updating the state) or
    /// rejects it with a reason (counting it, changing nothing else). Never panics.
    /// [`decode`](Receiver::decode) then [`accept`](Receiver::accept).
    pub fn receive(
        &self,
        state: &mut RxState,
        now: Tick,
        id: Id,
        data: &[u8],
    ) -> Result<Accepted, RejectReason> {
        self.accept(state, now, self.decode(id, data))
    }

    /// The checks of a received frame that need no state: the identifier, the length, the
    /// CRC, every value's range, the phase configured. Pure: the firmware runs it before
    /// taking the lock on the state, where only [`accept`](Receiver::accept)'s few checks
    /// run.
    pub fn decode(&self, id: Id, data: &[u8]) -> Result<Decoded, RejectReason> {
        let group = ContextGroup::of(self.node);
        match MessageKind::from_id(id) {
            Some((MessageKind::Phase | MessageKind::ContextPart, Address::Node(n)))
                if n == self.node => {}
            Some((MessageKind::Context, Address::Group(g))) if g == group => {}
            _ => return Err(RejectReason::UnknownId),
        }
        let (_, message) = Message::decode(id, data).map_err(|e| RejectReason::from_decode(&e))?;
        Ok(Decoded(match message {
            Message::Phase(m) if m.phase >= self.phase_count => {
                return Err(RejectReason::PhaseNotConfigured);
            }
            Message::Phase(command) => Accepted::Phase {
                command,
                changed: true,
            },
            Message::Context(m) => Accepted::Context {
                counter: m.counter,
                slot: m.slot_of(group, self.node),
                time_us: m.time_us,
            },
            Message::ContextPart(m) => Accepted::ContextPart(m),
            // Unreachable: the identifier was checked above.
            _ => return Err(RejectReason::UnknownId),
        }))
    }

    /// Takes a frame [`decode`](Receiver::decode) passed (or the reason it did not) into
    /// the state at tick `now`: the counter rule, then the new values; a rejection is
    /// counted and changes nothing else.
    pub fn accept(
        &self,
        state: &mut RxState,
        now: Tick,
        decoded: Result<Decoded, RejectReason>,
    ) -> Result<Accepted, RejectReason> {
        match decoded.and_then(|d| self.sequence(&state.link, now, d.0)) {
            Ok((accepted, lost)) => {
                state.counts.lost_frames = state.counts.lost_frames.saturating_add(lost);
                self.apply(&mut state.link, now, &accepted);
                Ok(accepted)
            }
            Err(reason) => {
                state.counts.rejected.bump(reason);
                Err(reason)
            }
        }
    }

    fn apply(&self, link: &mut RxLink, now: Tick, accepted: &Accepted) {
        match *accepted {
            Accepted::Phase { command, .. } => {
                link.phase_track.accept(now, command.counter, None);
                link.phase.set(command, now);
            }
            Accepted::Context {
                counter,
                slot,
                time_us,
            } => {
                link.context_track.accept(now, counter, Some(time_us));
                if let Some(s) = slot {
                    for part in ContextPart::ALL {
                        if let Some(h) = link.parts.get_mut(part as usize) {
                            h.set(s.part(part), now);
                        }
                    }
                }
                link.controller_time = Some(time_us);
            }
            Accepted::ContextPart(m) => {
                link.part_track.accept(now, m.counter, None);
                if let Some(h) = link.parts.get_mut(m.part as usize) {
                    h.set(m.value, now);
                }
            }
        }
    }

    /// The counter rule for a decoded frame: the frame (a phase command's change worked
    /// out) and the frames lost before it.
    fn sequence(
        &self,
        link: &RxLink,
        now: Tick,
        frame: Accepted,
    ) -> Result<(Accepted, u32), RejectReason> {
        match frame {
            Accepted::Phase { command, .. } => {
                let lost =
                    link.phase_track
                        .check(now, self.phase_timeout, command.counter, None)?;
                let changed = link
                    .phase
                    .get()
                    .is_none_or(|p| (p.phase, p.sequence) != (command.phase, command.sequence));
                Ok((Accepted::Phase { command, changed }, lost))
            }
            Accepted::Context {
                counter, time_us, ..
            } => {
                let lost =
                    link.context_track
                        .check(now, self.context_timeout, counter, Some(time_us))?;
                Ok((frame, lost))
            }
            Accepted::ContextPart(m) => {
                let lost = link
                    .part_track
                    .check(now, self.context_timeout, m.counter, None)?;
                Ok((frame, lost))
            }
        }
    }

    /// Which messages are fresh at `now`. Pure.
    pub fn freshness(&self, state: &RxState, now: Tick) -> Freshness {
        let l = &state.link;
        let fresh = |p: ContextPart| {
            l.parts
                .get(p as usize)
                .is_some_and(|h| h.is_fresh(now, self.context_timeout))
        };
        Freshness {
            phase: l.phase.is_fresh(now, self.phase_timeout),
            context: fresh(ContextPart::Velocity) && fresh(ContextPart::Acceleration),
            tip_state: fresh(ContextPart::PositionError),
        }
    }

    /// Whether the context (desired velocity and acceleration) is stale at `now`.
    pub fn is_context_stale(&self, state: &RxState, now: Tick) -> bool {
        !self.freshness(state, now).context
    }

    /// Once per tick: latches staleness and counts each context or tip state going from
    /// fresh to stale as an episode. Returns the freshness at `now`.
    pub fn poll(&self, state: &mut RxState, now: Tick) -> Freshness {
        let before = self.latched(&state.link);
        let f = self.freshness(state, now);
        let l = &mut state.link;
        l.phase.stale = !f.phase;
        for h in l.parts.iter_mut() {
            h.stale = !h.is_fresh(now, self.context_timeout);
        }
        l.phase_track.latch(now, self.phase_timeout);
        l.context_track.latch(now, self.context_timeout);
        l.part_track.latch(now, self.context_timeout);
        let episodes =
            u32::from(before.context && !f.context) + u32::from(before.tip_state && !f.tip_state);
        state.counts.stale_episodes = state.counts.stale_episodes.saturating_add(episodes);
        f
    }

    /// The freshness as last latched (values accepted since count as fresh).
    fn latched(&self, l: &RxLink) -> Freshness {
        let up = |p: ContextPart| l.parts.get(p as usize).is_some_and(|h| !h.stale);
        Freshness {
            phase: !l.phase.stale,
            context: up(ContextPart::Velocity) && up(ContextPart::Acceleration),
            tip_state: up(ContextPart::PositionError),
        }
    }

    /// The controller's inputs at `now`, withheld where stale.
    pub fn inputs(&self, state: &RxState, now: Tick) -> ControllerInputs {
        let part = |p: ContextPart| {
            state
                .link
                .parts
                .get(p as usize)
                .and_then(|h| h.fresh(now, self.context_timeout))
        };
        let f = self.freshness(state, now);
        ControllerInputs {
            vel_des: part(ContextPart::Velocity).filter(|_| f.context),
            acc_des: part(ContextPart::Acceleration).filter(|_| f.context),
            pos_err: part(ContextPart::PositionError),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::ContextMsg;
    use crate::{CanFrame, StandardId};

    const NODE: u8 = 7;

    fn node() -> NodeId {
        NodeId::new(NODE).unwrap()
    }

    fn rx() -> Receiver {
        Receiver::new(node(), 3, 100, 500).unwrap()
    }

    fn slot(vx: i16) -> ContextSlot {
        ContextSlot {
            vel_des: [vx, 0],
            acc_des: [0, 0],
            pos_err: [0, 0],
        }
    }

    /// A broadcast context frame of node 7's group (nodes 5..=9) with node 7's slot filled.
    fn ctx(counter: u8, time_us: u32, vx: i16) -> CanFrame {
        let mut m = ContextMsg {
            counter: Counter(counter),
            time_us,
            ..ContextMsg::default()
        };
        m.slots[2] = Some(slot(vx));
        m.encode(ContextGroup::of(node())).unwrap()
    }

    fn phase(counter: u8, p: u8, seq: u8) -> CanFrame {
        PhaseMsg {
            counter: Counter(counter),
            phase: p,
            sequence: seq,
        }
        .encode(node())
        .unwrap()
    }

    fn give(
        r: &Receiver,
        s: &mut RxState,
        now: Tick,
        f: &CanFrame,
    ) -> Result<Accepted, RejectReason> {
        r.receive(s, now, Id::Standard(f.id()), f.data())
    }

    #[test]
    fn accepts_a_good_sequence_and_counts_lost_frames() {
        let r = rx();
        let mut s = RxState::new();
        for (t, c) in [(0u32, 5u8), (5, 6), (10, 8), (15, 11)] {
            assert!(matches!(
                give(&r, &mut s, t, &ctx(c, 1000 * u32::from(c), i16::from(c))),
                Ok(Accepted::Context { slot: Some(_), .. })
            ));
        }
        assert_eq!(s.counts().lost_frames(), 1 + 2);
        assert_eq!(s.link().part(ContextPart::Velocity), Some([11, 0]));
        assert_eq!(s.link().controller_time(), Some(11_000));
    }

    #[test]
    fn resynchronizes_on_the_first_good_frame_after_a_loss() {
        let r = rx();
        let mut s = RxState::new();
        give(&r, &mut s, 0, &ctx(250, 0, 1)).unwrap();
        // 40 frames lost across the counter's wrap: accepted at once, every loss counted,
        // and the frames after it too.
        for (k, c) in [35u8, 36, 37].into_iter().enumerate() {
            let t = 41 + k as u32;
            give(&r, &mut s, t, &ctx(c, 1000 * t, 2)).unwrap();
        }
        assert_eq!(s.counts().lost_frames(), 40);
        assert_eq!(s.counts().rejected().total(), 0);
    }

    #[test]
    fn rejects_repetitions_and_old_frames_without_changing_state() {
        let r = rx();
        let mut s = RxState::new();
        give(&r, &mut s, 0, &ctx(5, 5000, 1)).unwrap();
        let before = *s.link();
        // The same frame again; a newer counter with an older time (an old frame).
        for f in [ctx(5, 5000, 1), ctx(6, 4000, 2), ctx(7, 5000, 3)] {
            assert_eq!(give(&r, &mut s, 1, &f), Err(RejectReason::Sequence));
        }
        assert_eq!(*s.link(), before);
        assert_eq!(s.counts().rejected().get(RejectReason::Sequence), 3);
        // After the timeout a controller that restarted (time back at 0) is accepted,
        // with nothing counted lost.
        r.poll(&mut s, 101);
        give(&r, &mut s, 101, &ctx(9, 0, 3)).unwrap();
        assert_eq!(s.counts().lost_frames(), 0);
        // ... but still not the very same frame twice.
        assert_eq!(
            give(&r, &mut s, 400, &ctx(9, 0, 3)),
            Err(RejectReason::Sequence)
        );
    }

    #[test]
    fn rejects_each_kind_of_bad_frame() {
        let r = rx();
        let mut s = RxState::new();
        let f = ctx(0, 0, 0);
        let id = Id::Standard(f.id());
        assert_eq!(
            r.receive(&mut s, 0, id, &f.data()[..48]),
            Err(RejectReason::WrongLength)
        );
        let mut bad = f.data().to_vec();
        bad[20] ^= 0x40;
        assert_eq!(r.receive(&mut s, 0, id, &bad), Err(RejectReason::BadCrc));
        // Another group's context, another node's phase, an event, an extended identifier.
        let other = MessageKind::Context.id(NodeId::new(2).unwrap());
        assert_eq!(
            r.receive(&mut s, 0, Id::Standard(other), f.data()),
            Err(RejectReason::UnknownId)
        );
        let p = PhaseMsg {
            counter: Counter(0),
            phase: 0,
            sequence: 0,
        }
        .encode(NodeId::new(8).unwrap())
        .unwrap();
        assert_eq!(give(&r, &mut s, 0, &p), Err(RejectReason::UnknownId));
        let ev = Id::Standard(MessageKind::Event.id(node()));
        assert_eq!(
            r.receive(&mut s, 0, ev, &[0; 8]),
            Err(RejectReason::UnknownId)
        );
        let ext = Id::Extended(crate::ExtendedId::new(0x144).unwrap());
        assert_eq!(
            r.receive(&mut s, 0, ext, &[0; 5]),
            Err(RejectReason::UnknownId)
        );
        assert_eq!(
            give(&r, &mut s, 0, &phase(0, 3, 0)),
            Err(RejectReason::PhaseNotConfigured)
        );
        // Phase 9 with a correct CRC: out of range.
        let pid = MessageKind::Phase.id(node());
        let mut raw = [0u8, 0, 0, 9, 0];
        crate::e2e::seal(pid, &mut raw);
        assert_eq!(
            r.receive(&mut s, 0, Id::Standard(pid), &raw),
            Err(RejectReason::OutOfRange)
        );
        let counts = s.counts().rejected();
        assert_eq!(counts.total(), 8);
        assert_eq!(counts.get(RejectReason::UnknownId), 4);
        assert_eq!(*s.link(), RxLink::default());
        let _ = StandardId::ZERO;
    }

    #[test]
    fn context_goes_stale_and_is_withheld() {
        let r = rx();
        let mut s = RxState::new();
        assert!(r.is_context_stale(&s, 0));
        assert_eq!(r.inputs(&s, 0), ControllerInputs::default());
        give(&r, &mut s, 1000, &ctx(1, 0, 500)).unwrap();
        assert!(r.poll(&mut s, 1100).context);
        let v = r.inputs(&s, 1100).vel_des.unwrap();
        assert_eq!(v[0], 500, "0.05 m/s in steps of 0.1 mm/s");
        assert!(r.inputs(&s, 1100).pos_err.is_some());
        assert!(!r.poll(&mut s, 1101).context);
        assert!(r.is_context_stale(&s, 1101));
        assert_eq!(r.inputs(&s, 1101), ControllerInputs::default());
        assert_eq!(s.counts().stale_episodes(), 2, "context and tip state");
        // Still stale, no new episode; the latch holds even if the tick wraps round.
        r.poll(&mut s, 5000);
        assert!(r.is_context_stale(&s, 1050u32.wrapping_add(u32::MAX)));
        assert_eq!(s.counts().stale_episodes(), 2);
        give(&r, &mut s, 6000, &ctx(9, 10, 1)).unwrap();
        assert!(!r.is_context_stale(&s, 6000));
    }

    #[test]
    fn an_empty_slot_keeps_the_counter_but_refreshes_nothing() {
        let r = rx();
        let mut s = RxState::new();
        give(&r, &mut s, 0, &ctx(1, 0, 5)).unwrap();
        let empty = ContextMsg {
            counter: Counter(2),
            time_us: 1000,
            ..ContextMsg::default()
        }
        .encode(ContextGroup::of(node()))
        .unwrap();
        assert!(matches!(
            give(&r, &mut s, 90, &empty),
            Ok(Accepted::Context { slot: None, .. })
        ));
        assert!(r.poll(&mut s, 100).context);
        assert!(
            !r.poll(&mut s, 101).context,
            "aged from the frame that filled it"
        );
        give(&r, &mut s, 102, &ctx(3, 2000, 5)).unwrap();
        assert_eq!(s.counts().lost_frames(), 0);
    }

    #[test]
    fn classic_parts_refresh_each_their_own() {
        let r = rx();
        let mut s = RxState::new();
        let part = |c: u8, part: ContextPart, v: i16| {
            ContextPartMsg {
                counter: Counter(c),
                part,
                value: [v, -v],
            }
            .encode(node())
            .unwrap()
        };
        give(&r, &mut s, 0, &part(0, ContextPart::Velocity, 500)).unwrap();
        give(&r, &mut s, 0, &part(1, ContextPart::Acceleration, 5)).unwrap();
        let f = r.poll(&mut s, 0);
        assert!(f.context && !f.tip_state);
        give(&r, &mut s, 1, &part(3, ContextPart::PositionError, 7)).unwrap();
        assert_eq!(s.counts().lost_frames(), 1);
        let i = r.inputs(&s, 1);
        assert!(i.vel_des.is_some() && i.acc_des.is_some() && i.pos_err.is_some());
        // Velocity keeps coming, acceleration does not: the context is stale as a whole.
        for t in [60u32, 101] {
            give(&r, &mut s, t, &part(4 + t as u8, ContextPart::Velocity, 1)).unwrap();
        }
        assert!(!r.poll(&mut s, 101).context);
        assert_eq!(r.inputs(&s, 101).vel_des, None);
    }

    #[test]
    fn phase_change_is_reported_once() {
        let r = rx();
        let mut s = RxState::new();
        let changed = |a: Result<Accepted, RejectReason>| match a {
            Ok(Accepted::Phase { changed, .. }) => changed,
            other => panic!("{other:?}"),
        };
        assert!(changed(give(&r, &mut s, 0, &phase(0, 1, 7))));
        assert!(!changed(give(&r, &mut s, 10, &phase(1, 1, 7))));
        assert!(changed(give(&r, &mut s, 20, &phase(2, 1, 8))));
        assert_eq!(
            give(&r, &mut s, 30, &phase(2, 1, 8)),
            Err(RejectReason::Sequence)
        );
    }

    #[test]
    fn parameters_are_validated() {
        let n = node();
        assert_eq!(Receiver::new(n, 0, 1, 1), Err(RxConfigError::PhaseCount(0)));
        assert_eq!(Receiver::new(n, 9, 1, 1), Err(RxConfigError::PhaseCount(9)));
        assert_eq!(Receiver::new(n, 1, 0, 1), Err(RxConfigError::Timeout(0)));
        assert_eq!(rx().identifiers(), [0x147, 0x121, 0x137]);
    }
}
