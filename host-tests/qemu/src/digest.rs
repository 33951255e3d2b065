//! CRC-32 digests of a replay: inputs, features, term confidences and outputs kept apart,
//! so that a mismatch between the chip and the PC says which stage diverged first.

use detector_core::{Detector, EventId, Inputs, Level, Output, State};

/// CRC-32/ISO-HDLC (the zlib and Ethernet CRC: reflected, polynomial 0x04C11DB7, initial
/// and final XOR 0xFFFFFFFF), four bits at a time from a 16-entry table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crc32(u32);

const NIBBLE: [u32; 16] = {
    let mut t = [0u32; 16];
    let mut i = 0;
    while i < 16 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 4 {
            c = if c & 1 != 0 {
                (c >> 1) ^ 0xEDB8_8320
            } else {
                c >> 1
            };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

impl Default for Crc32 {
    fn default() -> Self {
        Crc32::new()
    }
}

impl Crc32 {
    /// An empty CRC.
    pub const fn new() -> Crc32 {
        Crc32(0xFFFF_FFFF)
    }

    /// Absorbs bytes.
    pub fn update(&mut self, bytes: &[u8]) {
        let mut c = self.0;
        for &b in bytes {
            c ^= u32::from(b);
            c = (c >> 4) ^ NIBBLE[(c & 0xF) as usize];
            c = (c >> 4) ^ NIBBLE[(c & 0xF) as usize];
        }
        self.0 = c;
    }

    /// The CRC of everything absorbed so far.
    pub const fn value(&self) -> u32 {
        !self.0
    }
}

/// What a replay produced: four CRCs and counts. Equal digests on the chip and on the PC
/// mean every feature value, term confidence, event confidence, flag and decision was
/// bit-identical at every tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Digest {
    /// Fault masks and raw samples as fed to the detector.
    pub inputs: Crc32Value,
    /// Every feature's raw 16.16 value after each tick.
    pub features: Crc32Value,
    /// Every event's context and sensor term confidences (Q15) after each tick.
    pub terms: Crc32Value,
    /// Every event confidence, the five event masks, and every decision (event, level,
    /// confidence, onset, tick).
    pub outputs: Crc32Value,
    /// Ticks run.
    pub ticks: u32,
    /// Alert levels raised.
    pub alerts: u32,
    /// Confirm levels raised.
    pub confirms: u32,
    /// Event-ticks with an event unjudgeable.
    pub unjudgeable: u32,
    /// Event-ticks with an event degraded.
    pub degraded: u32,
}

/// A CRC's final value, printed as eight hex digits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Crc32Value(pub u32);

impl core::fmt::Display for Crc32Value {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:08x}", self.0)
    }
}

impl core::fmt::Display for Digest {
    /// One line of `key=value` pairs, the format the QEMU program prints and the host test
    /// parses.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "inputs={} features={} terms={} outputs={} ticks={} alerts={} confirms={} unjudgeable={} degraded={}",
            self.inputs,
            self.features,
            self.terms,
            self.outputs,
            self.ticks,
            self.alerts,
            self.confirms,
            self.unjudgeable,
            self.degraded
        )
    }
}

/// Accumulates a [`Digest`] tick by tick.
#[derive(Clone, Debug, Default)]
pub struct Digester {
    inputs: Crc32,
    features: Crc32,
    terms: Crc32,
    outputs: Crc32,
    counts: Digest,
}

impl Digester {
    /// An empty digest.
    pub fn new() -> Digester {
        Digester::default()
    }

    /// Absorbs one tick: what went in (`channels` samples of `inputs`), the state after
    /// it, and what came out.
    pub fn tick(
        &mut self,
        detector: &Detector,
        channels: usize,
        inputs: &Inputs,
        state: &State,
        out: &Output,
    ) {
        self.inputs.update(&inputs.faults.to_le_bytes());
        for s in inputs.samples.iter().take(channels) {
            self.inputs.update(&s.to_bits().to_le_bytes());
        }
        for k in 0..detector.features().len() {
            let v = state.feature(k).map_or(0, |s| s.to_bits());
            self.features.update(&v.to_le_bytes());
        }
        let events = detector.events().len();
        for i in 0..events {
            if let Some((ctx, sen)) = state.terms(detector, EventId(i as u8)) {
                for c in ctx.iter().chain(sen.iter()) {
                    self.terms.update(&c.to_bits().to_le_bytes());
                }
            }
        }
        for c in out.confidences.iter().take(events) {
            self.outputs.update(&c.to_bits().to_le_bytes());
        }
        self.outputs.update(&[
            out.evaluated,
            out.unjudgeable,
            out.degraded,
            out.alerting,
            out.confirmed,
            out.decisions.len() as u8,
        ]);
        for d in &out.decisions {
            let level = match d.level {
                Level::Alert => 0u8,
                Level::Confirm => 1,
            };
            self.outputs.update(&[d.event.0, level]);
            self.outputs.update(&d.confidence.to_bits().to_le_bytes());
            self.outputs.update(&d.onset.to_le_bytes());
            self.outputs.update(&d.tick.to_le_bytes());
            match d.level {
                Level::Alert => self.counts.alerts += 1,
                Level::Confirm => self.counts.confirms += 1,
            }
        }
        self.counts.ticks += 1;
        self.counts.unjudgeable += out.unjudgeable.count_ones();
        self.counts.degraded += out.degraded.count_ones();
    }

    /// The digest so far.
    pub fn digest(&self) -> Digest {
        Digest {
            inputs: Crc32Value(self.inputs.value()),
            features: Crc32Value(self.features.value()),
            terms: Crc32Value(self.terms.value()),
            outputs: Crc32Value(self.outputs.value()),
            ..self.counts
        }
    }
}
