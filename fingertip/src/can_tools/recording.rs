//! A fingertip's flight recording, read out over the service channel (`fingertip
//! fetch-recording`) and written as a trace that replays on the PC as the chip ran.
//!
//! The fingertip keeps the detector's inputs tick by tick as the core read them (each
//! channel's sample in its working unit, 16.16 bits), the phase and the channels withheld,
//! with the detector's state saved before the first of them ([`detector_core::State::save`]).
//! The readout is that state, then one row per tick: the phase (`u8`), the withheld
//! channels (`u16`), each channel's sample (`i32`), little-endian. As a trace: the time
//! column is the tick over the rate, each channel's sample in SI (its bits / 2¹⁶ / the
//! channel's scale: the replay's conversion gives the same bits back), a `phase` column,
//! a `withheld` column, and the state and first tick in the metadata, so that
//! [`crate::replay`] starts where the chip did.

use detector_core::{Detector, State};
use fingertip_can::service::{RecordingCause, RecordingInfo, Request, Response};

use super::service::{Client, ClientError, Link};
use crate::replay::{DecisionRecord, FIRST_TICK_KEY, STATE_KEY, WITHHELD_COLUMN};
use crate::trace::{Labels, Trace, TraceError};

/// Bytes of a row before its samples: phase, withheld channels.
const ROW_HEAD: usize = 3;

/// One tick of a recording.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordedRow {
    /// The phase's index in the detector's configuration.
    pub phase: u8,
    /// The channels withheld (bit `i` for channel `i`).
    pub withheld: u16,
    /// Each channel's sample, 16.16 bits in its working unit.
    pub samples: Vec<i32>,
}

/// A frozen recording as read out.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Recording {
    /// What the fingertip reported of it.
    pub info: RecordingInfo,
    /// The detector's state before the first row ([`State::SAVED_BYTES`]).
    pub saved: Vec<u8>,
    /// One row per tick from `info.first_tick` on.
    pub rows: Vec<RecordedRow>,
}

/// Why a recording could not be fetched or written.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The exchange failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// It answered something else than the request's response.
    #[error("unexpected answer to {request}: {answer}")]
    Unexpected {
        /// The request.
        request: &'static str,
        /// The answer.
        answer: String,
    },
    /// Nothing is frozen to read.
    #[error(
        "nothing frozen to read: the recorder holds {rows} ticks and waits for a confirmation or a fault (then 50 ms more)"
    )]
    NotFrozen {
        /// Rows held so far.
        rows: u32,
    },
    /// A page came back for another offset than asked, or empty before the end.
    #[error("the readout broke off at byte {at} of {bytes}: {why}")]
    Readout {
        /// Where.
        at: u32,
        /// The readout's length.
        bytes: u32,
        /// What came instead.
        why: String,
    },
    /// The readout's length is not a saved state and whole rows.
    #[error(
        "the readout is {bytes} bytes: not a saved state ({state} bytes) and {rows} rows of {row} bytes"
    )]
    Length {
        /// Its length.
        bytes: usize,
        /// A saved state's length.
        state: usize,
        /// The rows reported.
        rows: u32,
        /// A row's length.
        row: usize,
    },
    /// The recording is of another detector than the configuration's.
    #[error(
        "the recording was made by the detector whose image has CRC-32 {recorded:#010x}; the configuration builds {config:#010x} (give the configuration the fingertip ran)"
    )]
    Detector {
        /// The recording's.
        recorded: u32,
        /// The configuration's.
        config: u32,
    },
    /// The trace could not be made.
    #[error(transparent)]
    Trace(#[from] TraceError),
    /// The trace does not replay.
    #[error(transparent)]
    Replay(#[from] crate::replay::ReplayError),
    /// The PC's replay does not confirm what froze the recording, at its tick.
    #[error(
        "the PC's replay differs from the fingertip: {event} was confirmed at tick {tick} there, but the replay confirms {replayed}"
    )]
    Diverged {
        /// The event the fingertip confirmed.
        event: String,
        /// At its tick.
        tick: u32,
        /// What the replay confirmed.
        replayed: String,
    },
}

/// What the fingertip's recorder holds.
pub fn info<L: Link>(client: &mut Client<L>) -> Result<RecordingInfo, RecordingError> {
    match client.ask(&Request::RecordingInfo)? {
        Response::Recording(i) => Ok(i),
        other => Err(RecordingError::Unexpected {
            request: "recording info",
            answer: format!("{other:?}"),
        }),
    }
}

/// Waits until the fingertip's recorder holds a frozen recording, asking every `poll_us`
/// µs on the link's clock; `None` once `until_us` has passed without one.
pub fn wait_frozen<L: Link>(
    client: &mut Client<L>,
    poll_us: u64,
    until_us: Option<u64>,
) -> Result<Option<RecordingInfo>, RecordingError> {
    loop {
        let i = info(client)?;
        if i.frozen {
            return Ok(Some(i));
        }
        let link = client.link();
        let next = link.now_us() + poll_us;
        if until_us.is_some_and(|u| next > u) {
            return Ok(None);
        }
        // Nothing else is asked meanwhile: a frame that arrives is a stray answer.
        while link.now_us() < next {
            link.recv(next).map_err(ClientError::from)?;
        }
    }
}

/// Reads the frozen recording out, page by page (each page checked by its CRC-32 and
/// retried by the client when lost or corrupted).
pub fn fetch<L: Link>(client: &mut Client<L>) -> Result<Recording, RecordingError> {
    let info = info(client)?;
    if !info.frozen {
        return Err(RecordingError::NotFrozen { rows: info.rows });
    }
    let mut bytes = Vec::with_capacity(info.bytes as usize);
    while (bytes.len() as u32) < info.bytes {
        let at = bytes.len() as u32;
        let broke = |why: String| RecordingError::Readout {
            at,
            bytes: info.bytes,
            why,
        };
        match client.ask(&Request::RecordingRead(at))? {
            Response::Page { offset, data } if offset == at && !data.is_empty() => {
                bytes.extend_from_slice(&data);
            }
            Response::Page { offset, data } => {
                return Err(broke(format!("{} bytes from byte {offset}", data.len())));
            }
            other => return Err(broke(format!("{other:?}"))),
        }
    }
    parse(info, &bytes)
}

/// The recording in a readout of `bytes`, as `info` describes it.
pub fn parse(info: RecordingInfo, bytes: &[u8]) -> Result<Recording, RecordingError> {
    let n = usize::from(info.channels);
    let row = ROW_HEAD + 4 * n;
    let length = || RecordingError::Length {
        bytes: bytes.len(),
        state: State::SAVED_BYTES,
        rows: info.rows,
        row,
    };
    let (saved, rest) = bytes
        .split_at_checked(State::SAVED_BYTES)
        .ok_or_else(length)?;
    if rest.len() != info.rows as usize * row {
        return Err(length());
    }
    let rows = rest
        .chunks_exact(row)
        .map(|r| RecordedRow {
            phase: r[0],
            withheld: u16::from_le_bytes([r[1], r[2]]),
            samples: r[ROW_HEAD..]
                .chunks_exact(4)
                .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
        })
        .collect();
    Ok(Recording {
        info,
        saved: saved.to_vec(),
        rows,
    })
}

impl Recording {
    /// The recording as a trace for `detector` (the configuration the fingertip ran,
    /// whose image's CRC-32 is `image_crc`), named `name`.
    pub fn to_trace(
        &self,
        detector: &Detector,
        image_crc: u32,
        name: &str,
    ) -> Result<Trace, RecordingError> {
        if image_crc != self.info.detector_crc {
            return Err(RecordingError::Detector {
                recorded: self.info.detector_crc,
                config: image_crc,
            });
        }
        let rate = f64::from(self.info.rate_hz);
        let first = self.info.first_tick;
        let t = (0..self.rows.len())
            // Ticks counted on past a wrap of the fingertip's counter: time keeps rising.
            .map(|k| (f64::from(first) + k as f64) / rate)
            .collect();
        let mut columns: Vec<(String, Vec<f64>)> = detector
            .channels()
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let scale = f64::from(detector.channel_scales().get(k).copied().unwrap_or(1.0));
                let values = self
                    .rows
                    .iter()
                    .map(|r| f64::from(r.samples.get(k).copied().unwrap_or(0)) / 65536.0 / scale)
                    .collect();
                (c.to_string(), values)
            })
            .collect();
        columns.push((
            WITHHELD_COLUMN.to_string(),
            self.rows.iter().map(|r| f64::from(r.withheld)).collect(),
        ));
        let mut phase = Labels::new();
        for r in &self.rows {
            phase.push(
                detector
                    .phases()
                    .get(usize::from(r.phase))
                    .map_or("?", |p| p.as_str()),
            );
        }
        let mut trace = Trace::from_columns(name, t, columns)?.with_phase(phase)?;
        let cause = match self.info.cause {
            Some(RecordingCause::Confirmed(e)) => format!(
                "{} confirmed",
                detector
                    .events()
                    .get(usize::from(e))
                    .map_or("?", |n| n.as_str())
            ),
            Some(RecordingCause::Fault(mask)) => format!("channels withheld: {mask:#06x}"),
            None => "none".to_string(),
        };
        for (key, value) in [
            (
                "description",
                "flight recording read out of a fingertip".to_string(),
            ),
            ("trigger", cause),
            ("trigger_tick", self.info.trigger_tick.to_string()),
            ("detector_crc", format!("{:#010x}", self.info.detector_crc)),
            ("rate_hz", self.info.rate_hz.to_string()),
            (FIRST_TICK_KEY, first.to_string()),
            (STATE_KEY, hex::encode(&self.saved)),
        ] {
            trace.push_metadata(key, &value)?;
        }
        Ok(trace)
    }

    /// Replays `trace` (this recording's, from [`Recording::to_trace`]) through
    /// `detector` and checks that it confirms what froze the recording at the tick the
    /// fingertip did; returns every level the replay raised.
    pub fn check_replay(
        &self,
        detector: &Detector,
        trace: &Trace,
    ) -> Result<Vec<DecisionRecord>, RecordingError> {
        let decisions = crate::replay::replay(detector, trace, |_, _, _| {})?;
        if let Some(RecordingCause::Confirmed(e)) = self.info.cause {
            let event = detector
                .events()
                .get(usize::from(e))
                .map_or("?", |n| n.as_str());
            let rate = f64::from(self.info.rate_hz);
            // The fingertip's tick, wrapped as its counter wraps.
            let tick_of = |t_s: f64| (t_s * rate).round() as u64 as u32;
            let confirms: Vec<&DecisionRecord> =
                decisions.iter().filter(|d| d.is_confirm()).collect();
            let same = confirms
                .iter()
                .any(|d| d.event == event && tick_of(d.t_s) == self.info.trigger_tick);
            if !same {
                let replayed = if confirms.is_empty() {
                    "nothing".to_string()
                } else {
                    confirms
                        .iter()
                        .map(|d| format!("{} at tick {}", d.event, tick_of(d.t_s)))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                return Err(RecordingError::Diverged {
                    event: event.to_string(),
                    tick: self.info.trigger_tick,
                    replayed,
                });
            }
        }
        Ok(decisions)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn default_detector() -> Detector {
        let config = detector_build::Config::from_toml(crate::APPROACH_TOML).expect("parses");
        detector_build::build(&config).expect("builds")
    }

    /// A readout of `rows` quiet rows after a fresh state, for the default's channels.
    fn readout(d: &Detector, first_tick: u32, rows: u32) -> (RecordingInfo, Vec<u8>) {
        let channels = d.channels().len();
        let mut bytes = vec![0u8; State::SAVED_BYTES];
        d.new_state()
            .save((&mut bytes[..]).try_into().expect("the saved length"));
        for k in 0..rows {
            bytes.extend_from_slice(&[0, 0, 0]);
            for c in 0..channels {
                let v = if c == 0 { k as i32 * 7 } else { 0 };
                bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let info = RecordingInfo {
            frozen: true,
            cause: None,
            trigger_tick: 0,
            first_tick,
            rows,
            channels: channels as u8,
            rate_hz: 5000,
            detector_crc: 0x1234_5678,
            bytes: bytes.len() as u32,
        };
        (info, bytes)
    }

    #[test]
    fn a_recording_across_the_tick_counters_wrap_keeps_its_time_rising() {
        let d = default_detector();
        let (info, bytes) = readout(&d, u32::MAX - 9, 40);
        let rec = parse(info, &bytes).expect("whole");
        assert_eq!(rec.rows.len(), 40);
        assert_eq!(rec.rows[3].samples[0], 21);
        let trace = rec.to_trace(&d, 0x1234_5678, "wrap").expect("a trace");
        assert!(trace.time().windows(2).all(|w| w[1] > w[0]));
        let text = trace.to_csv();
        let read = Trace::parse(&text, "wrap.csv").expect("reads back");
        // The samples come back to the same bits.
        let force = read.column("force_x").expect("the first channel");
        assert_eq!(d.sample_from_si(0, force[3]).to_bits(), 21);
        rec.check_replay(&d, &read).expect("replays");
    }

    #[test]
    fn a_readout_that_is_not_a_state_and_whole_rows_is_refused_naming_its_length() {
        let d = default_detector();
        let (info, bytes) = readout(&d, 100, 5);
        let e = parse(info, &bytes[..bytes.len() - 1]).unwrap_err();
        assert!(
            e.to_string()
                .contains(&format!("{} bytes: not a saved state", bytes.len() - 1)),
            "{e}"
        );
        let e = parse(info, &bytes[..100]).unwrap_err();
        assert!(matches!(e, RecordingError::Length { .. }), "{e}");
    }
}
