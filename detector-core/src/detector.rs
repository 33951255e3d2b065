//! The interpreter: a [`Detector`] (validated tables, immutable, loaded from an image) and
//! its [`State`] (what changes every tick), kept apart so the same tables can drive
//! several states.
//!
//! A tick runs four stages, each callable alone so a profiler can time them one by one
//! ([`DetectorTick`]): `update_features` → `term_confidences` → `combine` → `decide`;
//! [`DetectorTick::tick_into`] and [`Detector::tick`] run them in order.

use heapless::Vec;

use crate::Name;
use crate::cdf::Cdf;
use crate::feature::{MAX_SLOTS, Stage, StageState, WINDOW_POOL, taps_valid, windows_disjoint};
use crate::image::{ImageError, Reader, Section};
use crate::num::{ChannelMask, Confidence, EventMask, Signal, Tick};
use crate::state::{
    EventId, EventState, Inputs, LevelParams, ONE, Output, PhaseId, State, StateError,
    any_confirmed, clear_psi, decide_event, eq14, eval_psi, load_sample, product, psi_value,
    reset_event, step_feature,
};
use crate::tick::DetectorTick;
use crate::{
    MAX_CHANNELS, MAX_DISTINCT_TERMS as MAX_PSI, MAX_EVENTS, MAX_FEATURES, MAX_PHASES, MAX_TERMS,
};

/// One feature judged by one CDF (the paper's ψ), evaluated once per tick however many
/// terms of however many events name the same pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Psi {
    slot: u8,
    cdf: Cdf,
    /// The channels the feature reads: a fault on any of them makes ψ 0.
    channels: ChannelMask,
    /// The events whose terms use it: it is evaluated when one of them is active.
    events: EventMask,
}

impl Psi {
    /// A ψ used by no event yet; its channels are those `slot` depends on.
    fn new(slot: u8, cdf: Cdf, slot_channels: &[ChannelMask; MAX_SLOTS]) -> Psi {
        Psi {
            slot,
            cdf,
            channels: slot_channels.get(usize::from(slot)).copied().unwrap_or(0),
            events: 0,
        }
    }
}

/// Marks ψ `k` as used by the events in `bit` and gives the channels it reads (none for an
/// index past the table).
fn use_psi(psis: &mut [Psi], k: usize, bit: EventMask) -> ChannelMask {
    psis.get_mut(k).map_or(0, |p| {
        p.events |= bit;
        p.channels
    })
}

/// A sensor term: which ψ, and its weight (Q15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Weighted {
    psi: u8,
    weight: u16,
}

#[derive(Clone, Debug, PartialEq, Eq)]
struct Event {
    /// Context terms, as indices into the detector's ψ table.
    context: Vec<u8, MAX_TERMS>,
    sensor: Vec<Weighted, MAX_TERMS>,
    /// The channels the context terms read, together.
    context_channels: ChannelMask,
    /// The channels the sensor terms read, together.
    sensor_channels: ChannelMask,
    levels: [LevelParams; 2],
    onset_level: u16,
    /// The events whose confirm level, while up, holds this one's down.
    excluded_by: EventMask,
}

impl State {
    /// The term confidences computed for `event` at the last tick: (context terms, sensor
    /// terms), in configuration order. Stale for events outside the active phase.
    pub fn terms(
        &self,
        detector: &Detector,
        event: EventId,
    ) -> Option<(TermConfidences, TermConfidences)> {
        let e = detector.events.get(usize::from(event.0))?;
        let psi = |k: u8| self.psi.get(usize::from(k)).copied().unwrap_or(0);
        Some((
            TermConfidences(e.context.iter().map(|&k| psi(k)).collect()),
            TermConfidences(e.sensor.iter().map(|w| psi(w.psi)).collect()),
        ))
    }
}

/// The confidences of an event's terms of one kind, in configuration order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TermConfidences(Vec<u16, MAX_TERMS>);

impl TermConfidences {
    /// The confidences.
    pub fn iter(&self) -> impl Iterator<Item = Confidence> + '_ {
        self.0
            .iter()
            .map(|&b| Confidence::from_bits_clamped(u32::from(b)))
    }
}

/// A validated detector: compiled features, events, phases and decision levels.
#[derive(Clone, Debug, PartialEq)]
pub struct Detector {
    rate_hz: f32,
    channel_names: Vec<Name, MAX_CHANNELS>,
    channel_scales: Vec<f32, MAX_CHANNELS>,
    feature_names: Vec<Name, MAX_FEATURES>,
    event_names: Vec<Name, MAX_EVENTS>,
    phase_names: Vec<Name, MAX_PHASES>,
    stages: Vec<Stage, MAX_FEATURES>,
    /// Channel dependencies of each slot.
    slot_channels: [ChannelMask; MAX_SLOTS],
    weights: [u32; WINDOW_POOL],
    /// The distinct (feature, CDF) pairs of all events' terms.
    psis: Vec<Psi, MAX_PSI>,
    events: Vec<Event, MAX_EVENTS>,
    phases: Vec<EventMask, MAX_PHASES>,
}

impl Detector {
    /// A detector with nothing configured: no channel, no event, every tick evaluates
    /// nothing. `const`, so a detector can be a static in `.bss` that
    /// [`Detector::load_image`] fills in place.
    pub const fn empty() -> Detector {
        Detector {
            rate_hz: 0.0,
            channel_names: Vec::new(),
            channel_scales: Vec::new(),
            feature_names: Vec::new(),
            event_names: Vec::new(),
            phase_names: Vec::new(),
            stages: Vec::new(),
            slot_channels: [0; MAX_SLOTS],
            weights: [0; WINDOW_POOL],
            psis: Vec::new(),
            events: Vec::new(),
            phases: Vec::new(),
        }
    }

    /// Replaces this detector with the one in `image` (made by `detector_build::Compiled::image`),
    /// in place: the stack holds one event at a time, never a whole detector or
    /// configuration. Every value is checked; on error the detector is left empty (see
    /// [`Detector::empty`]) and the error names what was wrong.
    pub fn load_image(&mut self, image: &[u8]) -> Result<(), ImageError> {
        let result = self.read_image(&mut Reader::new(image));
        if result.is_err() {
            self.clear();
        }
        result
    }

    /// Empties every list and table in place.
    fn clear(&mut self) {
        self.rate_hz = 0.0;
        self.channel_names.clear();
        self.channel_scales.clear();
        self.feature_names.clear();
        self.event_names.clear();
        self.phase_names.clear();
        self.stages.clear();
        self.slot_channels = [0; MAX_SLOTS];
        self.weights = [0; WINDOW_POOL];
        self.psis.clear();
        self.events.clear();
        self.phases.clear();
    }

    fn read_image(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        // Counts are checked against the capacities, so no push below can fail.
        self.clear();
        r.magic()?;
        for section in Section::ORDER {
            r.section(section)?;
            match section {
                Section::Rate => self.read_rate(r)?,
                Section::Channels => self.read_channels(r)?,
                Section::Features => self.read_features(r)?,
                Section::SlotChannels => self
                    .slot_channels
                    .iter_mut()
                    .take(Section::slots_in_use(self.stages.len()))
                    .try_for_each(|m| {
                        *m = r.u32()?;
                        Ok::<_, ImageError>(())
                    })?,
                Section::Taps => self.read_taps(r)?,
                Section::Terms => self.read_terms(r)?,
                Section::Events => self.read_events(r)?,
                Section::Phases => self.read_phases(r)?,
            }
        }
        if self.channel_names.is_empty() || self.events.is_empty() || self.phases.is_empty() {
            return Err(ImageError::Invalid("detector (empty)"));
        }
        r.finish()
    }

    fn read_rate(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        let rate = r.f32()?;
        if !(rate.is_finite() && (10.0..=50_000.0).contains(&rate)) {
            return Err(ImageError::Invalid("detector rate"));
        }
        self.rate_hz = rate;
        Ok(())
    }

    fn read_channels(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        for _ in 0..r.count(MAX_CHANNELS, "channel count")? {
            let name = r.name()?;
            let scale = r.f32()?;
            if !(scale.is_finite() && scale > 0.0) {
                return Err(ImageError::Invalid("channel scale"));
            }
            let _ = self.channel_names.push(name);
            let _ = self.channel_scales.push(scale);
        }
        Ok(())
    }

    fn read_features(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        for k in 0..r.count(MAX_FEATURES, "feature count")? {
            let _ = self.feature_names.push(r.name()?);
            // A feature reads channels and the features declared before it.
            let _ = self.stages.push(Stage::read_image(r, MAX_CHANNELS + k)?);
        }
        if !windows_disjoint(&self.stages) {
            return Err(ImageError::Invalid("window placement"));
        }
        Ok(())
    }

    fn read_taps(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        for t in self.weights.iter_mut() {
            *t = r.u32()?;
        }
        if !self.stages.iter().all(|s| taps_valid(s, &self.weights)) {
            return Err(ImageError::Invalid("STE window taps"));
        }
        Ok(())
    }

    fn read_terms(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        for _ in 0..r.count(MAX_PSI, "CDF count")? {
            let slot = r.below(MAX_SLOTS, "term feature")?;
            let psi = Psi::new(slot, Cdf::read_image(r)?, &self.slot_channels);
            let _ = self.psis.push(psi);
        }
        Ok(())
    }

    fn read_events(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        let count = r.count(MAX_EVENTS, "event count")?;
        for i in 0..count {
            let _ = self.event_names.push(r.name()?);
            let e = self.read_event(r, 1 << i, count)?;
            let _ = self.events.push(e);
        }
        Ok(())
    }

    /// One event's terms and levels; `bit` is its event mask bit, `events` how many events
    /// the image holds.
    fn read_event(
        &mut self,
        r: &mut Reader<'_>,
        bit: EventMask,
        events: usize,
    ) -> Result<Event, ImageError> {
        let psis = self.psis.len();
        let (mut context, mut context_channels) = (Vec::new(), 0);
        for _ in 0..r.count(MAX_TERMS, "context term count")? {
            let k = r.below(psis, "context term CDF")?;
            context_channels |= use_psi(&mut self.psis, usize::from(k), bit);
            let _ = context.push(k);
        }
        let (mut sensor, mut sensor_channels) = (Vec::new(), 0);
        let mut total = 0u32;
        for _ in 0..r.count(MAX_TERMS, "sensor term count")? {
            let k = r.below(psis, "sensor term CDF")?;
            let weight = r.u16()?;
            total += u32::from(weight);
            if total > crate::MAX_WEIGHT_SUM_Q15 {
                return Err(ImageError::Invalid("term weights"));
            }
            sensor_channels |= use_psi(&mut self.psis, usize::from(k), bit);
            let _ = sensor.push(Weighted { psi: k, weight });
        }
        if sensor.is_empty() {
            return Err(ImageError::Invalid("sensor term count"));
        }
        let levels = [LevelParams::read_image(r)?, LevelParams::read_image(r)?];
        // An early dwell watches a feature of the detector that reads only channels the
        // event's terms read, so that a fault it would read degrades the event.
        for early in levels.iter().filter_map(LevelParams::early) {
            let slot = usize::from(early.slot());
            let feature = slot - MAX_CHANNELS;
            let reads = self.slot_channels[slot & (MAX_SLOTS - 1)];
            if feature >= self.stages.len() || reads & !(context_channels | sensor_channels) != 0 {
                return Err(ImageError::Invalid("early dwell's feature"));
            }
        }
        let onset_level = r.u16()?;
        if onset_level >= levels[0].on {
            return Err(ImageError::Invalid("onset level"));
        }
        let excluded_by = r.u8()?;
        // Events that exist (the count is known before any event is read), not itself.
        if u32::from(excluded_by) >> events != 0 || excluded_by & bit != 0 {
            return Err(ImageError::Invalid("event exclusions"));
        }
        Ok(Event {
            context,
            sensor,
            context_channels,
            sensor_channels,
            levels,
            onset_level,
            excluded_by,
        })
    }

    fn read_phases(&mut self, r: &mut Reader<'_>) -> Result<(), ImageError> {
        let events = self.events.len();
        for _ in 0..r.count(MAX_PHASES, "phase count")? {
            let _ = self.phase_names.push(r.name()?);
            let mask = r.u8()?;
            if u32::from(mask) >> events != 0 {
                return Err(ImageError::Invalid("phase events"));
            }
            let _ = self.phases.push(mask);
        }
        Ok(())
    }

    /// A fresh state: features empty, first phase active, no level up.
    pub fn new_state(&self) -> State {
        let mut stages = [StageState::default(); MAX_FEATURES];
        for (st, stage) in stages.iter_mut().zip(&self.stages) {
            *st = stage.fresh_state();
        }
        State {
            values: [0; MAX_SLOTS],
            stages,
            ring: [0; WINDOW_POOL],
            psi: [0; MAX_PSI],
            events: [EventState::default(); MAX_EVENTS],
            phase: 0,
        }
    }

    /// The state saved by [`State::save`] in `bytes`, checked against this detector:
    /// its phase one of the detector's, every feature's running state one its stage can
    /// reach. A tick on the state returned does what it did where it was saved.
    pub fn restore(&self, bytes: &[u8]) -> Result<State, StateError> {
        let state = State::read_saved(bytes)?;
        if usize::from(state.phase) >= self.phase_names.len() {
            return Err(StateError::Phase(state.phase, self.phase_names.len()));
        }
        for (k, (stage, st)) in self.stages.iter().zip(&state.stages).enumerate() {
            if !stage.admits(st, &state.ring) {
                return Err(StateError::Feature(k));
            }
        }
        Ok(state)
    }

    /// The detector rate in Hz.
    pub fn rate_hz(&self) -> f32 {
        self.rate_hz
    }

    /// Channel names, in sample order.
    pub fn channels(&self) -> &[Name] {
        &self.channel_names
    }

    /// Each channel's scale: the detector sees SI value × scale (see
    /// `detector_build::ChannelSpec::scale`).
    pub fn channel_scales(&self) -> &[f32] {
        &self.channel_scales
    }

    /// The sample for channel `index` from its value in SI units: scaled, rounded and
    /// saturated (NaN gives zero).
    #[inline]
    pub fn sample_from_si(&self, index: usize, si: f64) -> Signal {
        let scale = self.channel_scales.get(index).copied().unwrap_or(1.0);
        Signal::from_f64(si * f64::from(scale))
    }

    /// Feature names, in evaluation order.
    pub fn features(&self) -> &[Name] {
        &self.feature_names
    }

    /// Event names, by [`EventId`].
    pub fn events(&self) -> &[Name] {
        &self.event_names
    }

    /// Phase names, by index.
    pub fn phases(&self) -> &[Name] {
        &self.phase_names
    }

    /// The index of a channel by name.
    pub fn channel(&self, name: &str) -> Option<usize> {
        self.channel_names.iter().position(|n| n == name)
    }

    /// An event by name.
    pub fn event(&self, name: &str) -> Option<EventId> {
        self.event_names
            .iter()
            .position(|n| n == name)
            .map(|i| EventId(i as u8))
    }

    /// A phase by name.
    pub fn phase(&self, name: &str) -> Option<PhaseId> {
        self.phase_names
            .iter()
            .position(|n| n == name)
            .map(|i| PhaseId(i as u8))
    }

    /// A phase by index, `None` if this detector has no such phase.
    pub fn phase_at(&self, index: u8) -> Option<PhaseId> {
        (usize::from(index) < self.phases.len()).then_some(PhaseId(index))
    }

    /// The events possible in a phase.
    pub fn phase_events(&self, phase: PhaseId) -> EventMask {
        self.phases.get(usize::from(phase.0)).copied().unwrap_or(0)
    }

    /// An event's alert and confirm levels.
    pub fn event_levels(&self, event: EventId) -> Option<[LevelParams; 2]> {
        self.events.get(usize::from(event.0)).map(|e| e.levels)
    }

    /// The channels an event's features read (context and sensor terms together).
    pub fn event_channels(&self, event: EventId) -> ChannelMask {
        self.events
            .get(usize::from(event.0))
            .map_or(0, |e| e.context_channels | e.sensor_channels)
    }

    /// Switches phase. Switching to another phase lowers every level and forgets onsets;
    /// "switching" to the active phase changes nothing. Features keep running in every
    /// phase, so they are warm in the new one.
    pub fn set_phase(&self, state: &mut State, phase: PhaseId) {
        if state.phase != phase.0 {
            state.phase = phase.0;
            state.events = [EventState::default(); MAX_EVENTS];
        }
    }

    /// One whole tick: features, term confidences, event confidences, decisions.
    /// (The interpreter; [`DetectorTick::tick_into`] writes into a caller's `out`
    /// instead, with no [`Output`] built and copied per tick: the firmware's way.)
    pub fn tick(&self, state: &mut State, now: Tick, inputs: &Inputs) -> Output {
        let mut out = Output::default();
        DetectorTick::tick_into(self, state, now, inputs, &mut out);
        out
    }
}

/// The interpreter: walks the detector's tables, so it runs any detector it has loaded.
/// Terms of different events that judge the same feature with the same CDF are evaluated
/// once; eq. 14's products are rounded to nearest in Q15.
impl DetectorTick for Detector {
    fn image_crc(&self) -> Option<u32> {
        None
    }

    fn update_features(&self, state: &mut State, inputs: &Inputs) {
        for c in 0..self.channel_names.len() {
            load_sample(state, c, inputs);
        }
        for (k, stage) in self.stages.iter().enumerate() {
            step_feature(state, k, stage, &self.weights);
        }
    }

    fn term_confidences(&self, state: &mut State, faults: ChannelMask, out: &mut Output) {
        let active = self.phase_events(PhaseId(state.phase));
        out.evaluated = active;
        for (k, p) in self.psis.iter().enumerate() {
            if p.events & active == 0 {
                continue;
            }
            if p.channels & faults != 0 {
                clear_psi(state, k);
            } else {
                eval_psi(state, k, p.slot, &p.cdf);
            }
        }
        if faults == 0 {
            return;
        }
        for (i, e) in self.events.iter().enumerate() {
            let bit: EventMask = 1 << i;
            if active & bit == 0 || (e.context_channels | e.sensor_channels) & faults == 0 {
                continue;
            }
            let faulty = |k: u8| {
                self.psis
                    .get(usize::from(k))
                    .is_none_or(|p| p.channels & faults != 0)
            };
            if e.context_channels & faults != 0 || e.sensor.iter().all(|t| faulty(t.psi)) {
                out.unjudgeable |= bit;
            } else if e.sensor_channels & faults != 0 {
                out.degraded |= bit;
            }
        }
    }

    fn combine(&self, state: &State, out: &mut Output) {
        let psi = |k: u8| psi_value(state, usize::from(k));
        let judged = out.evaluated & !out.unjudgeable;
        for (i, (e, c)) in self
            .events
            .iter()
            .zip(out.confidences.iter_mut())
            .enumerate()
        {
            if judged & (1 << i) == 0 {
                continue;
            }
            let product = e.context.iter().fold(ONE, |acc, &k| product(acc, psi(k)));
            let sum: u32 = e
                .sensor
                .iter()
                .map(|t| u32::from(t.weight) * psi(t.psi))
                .sum();
            *c = eq14(product, sum);
        }
    }

    fn decide(&self, state: &mut State, now: Tick, out: &mut Output) {
        for (i, e) in self.events.iter().enumerate() {
            let bit: EventMask = 1 << i;
            if out.evaluated & bit == 0 {
                continue;
            }
            if out.unjudgeable & bit != 0 {
                reset_event(state, i);
                continue;
            }
            let c = out.confidences[i & (MAX_EVENTS - 1)];
            let excluded = any_confirmed(state, e.excluded_by);
            decide_event(state, i, &e.levels, e.onset_level, excluded, c, now, out);
        }
    }
}
