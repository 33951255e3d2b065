//! Trace files: the one format for simulated and recorded fingertip data.
//!
//! A trace is a CSV file (see `docs/trace-format.md` for the full description):
//!
//! ```text
//! # scenario: contact_hard_8
//! # rate_hz: 5000
//! t,force_x,force_y,skin_accel,stress_rate,phase,truth
//! 0,0.009765625,0,-0.244140625,0.9765625,approach,
//! 0.0002,0,-0.009765625,0.48828125,0,approach,
//! ...
//! 0.02,-0.029296875,0,12.6953125,160.15625,approach,contact
//! ```
//!
//! - Lines whose first non-blank character is `#` are comments and may appear anywhere,
//!   before the header included. A comment of the form `# key: value` is kept as metadata.
//! - Blank lines are ignored.
//! - The first other line is the header: comma-separated column names, unique and
//!   non-empty. Column `t` (time in seconds) is required.
//! - Columns `phase` and `truth` are optional text columns; every other column is a
//!   numeric input channel, in SI units, of any name.
//! - Every following line is one row with exactly one cell per column. Numeric cells must
//!   be finite decimal numbers. Cells are trimmed of surrounding blanks; quoting is not
//!   supported, so text cells cannot hold commas.
//! - Time increases strictly and uniformly: every step is within
//!   [`TIME_STEP_TOLERANCE`] of the mean period. The rate is derived from it.
//!
//! Every error is one line naming the file, the 1-based line number in the file and the
//! column (see [`TraceError`]).

use std::fmt::Write as _;
use std::fs;
use std::io::{self, BufRead};
use std::path::Path;

/// The name of the time column.
pub const TIME_COLUMN: &str = "t";
/// The name of the optional phase column.
pub const PHASE_COLUMN: &str = "phase";
/// The name of the optional ground-truth column.
pub const TRUTH_COLUMN: &str = "truth";
/// How far a time step may stray from the mean period, as a fraction of that period.
pub const TIME_STEP_TOLERANCE: f64 = 0.01;

/// Why a trace could not be read, built or written.
///
/// Its `Display` is always a single line naming the file and, where it applies, the
/// 1-based line number in the file and the column.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TraceError {
    /// The file could not be read (missing, unreadable).
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: String,
        /// The underlying error.
        #[source]
        source: io::Error,
    },
    /// The file is not UTF-8 text.
    #[error("{file}: line {line}, byte {offset}: not UTF-8 text{hint}")]
    NotUtf8 {
        /// The file.
        file: String,
        /// The line of the first byte that is not UTF-8 (1-based).
        line: usize,
        /// Its offset from the start of the file (0-based).
        offset: usize,
        /// What the file looks like instead, if that can be told.
        hint: &'static str,
    },
    /// The file could not be written; no file was left at the destination.
    #[error("cannot write: {0}")]
    Write(#[source] crate::output::OutputError),
    /// The file holds nothing but blank and comment lines.
    #[error("{file}: empty: no header row (a trace needs a header naming its columns, `t` first)")]
    NoHeader {
        /// The file.
        file: String,
    },
    /// The header has no `t` column.
    #[error("{file}: line {line}: the header has no column `t` (time in seconds)")]
    MissingTime {
        /// The file.
        file: String,
        /// The header's line number (1-based).
        line: usize,
    },
    /// A column name appears twice.
    #[error("{file}: line {line}, column {column}: duplicate column name `{name}`")]
    DuplicateColumn {
        /// The file.
        file: String,
        /// The header's line number (1-based).
        line: usize,
        /// The 1-based position of the second occurrence.
        column: usize,
        /// The repeated name.
        name: String,
    },
    /// A column name is empty (for example a trailing comma in the header).
    #[error("{file}: line {line}, column {column}: empty column name")]
    EmptyColumnName {
        /// The file.
        file: String,
        /// The header's line number (1-based).
        line: usize,
        /// The 1-based position of the empty name.
        column: usize,
    },
    /// A name, label or metadata entry holds a character the format cannot carry.
    #[error("{file}: {what} `{text}` is not allowed: {reason}")]
    InvalidText {
        /// The file.
        file: String,
        /// What the text is (channel name, phase label, ...).
        what: &'static str,
        /// The offending text (escaped).
        text: String,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// The header is followed by no data row.
    #[error("{file}: empty: no data rows after the header on line {line}")]
    NoRows {
        /// The file.
        file: String,
        /// The header's line number (1-based).
        line: usize,
    },
    /// Only one data row: the sampling rate cannot be derived.
    #[error("{file}: line {line}: only one data row; at least two are needed to derive the rate")]
    SingleRow {
        /// The file.
        file: String,
        /// The line of the only row (1-based).
        line: usize,
    },
    /// A row has more or fewer cells than the header has columns.
    #[error("{file}: line {line}: {found} cells, but the header has {expected} columns")]
    CellCount {
        /// The file.
        file: String,
        /// The row's line number (1-based).
        line: usize,
        /// The number of columns in the header.
        expected: usize,
        /// The number of cells on the row.
        found: usize,
    },
    /// A cell of a numeric column is not a number.
    #[error("{file}: line {line}, column {column} `{name}`: `{cell}` is not a number")]
    NotANumber {
        /// The file.
        file: String,
        /// The row's line number (1-based).
        line: usize,
        /// The 1-based column position.
        column: usize,
        /// The column's name.
        name: String,
        /// The cell as written (shortened if long).
        cell: String,
    },
    /// A cell of a numeric column is NaN or infinite.
    #[error(
        "{file}: line {line}, column {column} `{name}`: `{cell}` is not finite (NaN and infinities are not allowed)"
    )]
    NotFinite {
        /// The file.
        file: String,
        /// The row's line number (1-based).
        line: usize,
        /// The 1-based column position.
        column: usize,
        /// The column's name.
        name: String,
        /// The cell as written (shortened if long).
        cell: String,
    },
    /// Time does not increase from one row to the next.
    #[error(
        "{file}: line {line}, column {column} `t`: time {} s does not increase (previous row: {} s)",
        crate::readable(*t),
        crate::readable(*previous)
    )]
    TimeNotIncreasing {
        /// The file.
        file: String,
        /// The row's line number (1-based).
        line: usize,
        /// The 1-based position of the `t` column.
        column: usize,
        /// The time on this row.
        t: f64,
        /// The time on the previous row.
        previous: f64,
    },
    /// A time step differs from the mean period by more than [`TIME_STEP_TOLERANCE`].
    #[error(
        "{file}: line {line}, column {column} `t`: time step {} s differs from the trace's mean period {} s by more than 1% (time must be uniform)",
        crate::readable(*step),
        crate::readable(*period)
    )]
    TimeNotUniform {
        /// The file.
        file: String,
        /// The row's line number (1-based).
        line: usize,
        /// The 1-based position of the `t` column.
        column: usize,
        /// The step from the previous row to this one.
        step: f64,
        /// The mean period over the whole trace.
        period: f64,
    },
    /// A column given to a constructor does not have one value per time sample.
    #[error("{file}: column `{name}` has {found} values, but time has {expected}")]
    LengthMismatch {
        /// The trace's name.
        file: String,
        /// The column.
        name: String,
        /// The number of time samples.
        expected: usize,
        /// The number of values in the column.
        found: usize,
    },
}

/// A trace: uniformly sampled named channels, with optional phase and ground truth.
///
/// Built by [`Trace::parse`], [`Trace::read`] or [`Trace::from_columns`], it always holds at
/// least two rows, strictly increasing uniform time, finite values, unique channel names,
/// and one value per row in every column.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    name: String,
    t: Vec<f64>,
    rate_hz: f64,
    channel_names: Vec<String>,
    data: Vec<Vec<f64>>,
    phase: Option<Labels>,
    truth: Option<Labels>,
    metadata: Vec<(String, String)>,
    lines: LineMap,
}

/// The file line each row was read from, for messages. Not part of the trace's data: two
/// traces with the same rows are equal wherever their rows were read from.
#[derive(Clone, Debug, Default)]
struct LineMap(Vec<u32>);

impl PartialEq for LineMap {
    fn eq(&self, _: &LineMap) -> bool {
        true
    }
}

/// A text column (phase or truth): one label per row, stored compactly as an index into
/// the distinct labels (a trace has few distinct phases and events but many rows).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Labels {
    distinct: Vec<String>,
    rows: Vec<u32>,
}

impl Labels {
    /// An empty column.
    pub fn new() -> Labels {
        Labels::default()
    }

    /// `n` rows of the same label.
    pub fn uniform(label: &str, n: usize) -> Labels {
        Labels {
            distinct: vec![label.to_string()],
            rows: vec![0; n],
        }
    }

    /// `before` on rows `..switch`, `after` on rows `switch..n`.
    pub fn switch_at(before: &str, after: &str, switch: usize, n: usize) -> Labels {
        let switch = switch.min(n);
        if before == after || switch == n {
            return Labels::uniform(before, n);
        }
        if switch == 0 {
            return Labels::uniform(after, n);
        }
        let mut rows = vec![0; switch];
        rows.resize(n, 1);
        Labels {
            distinct: vec![before.to_string(), after.to_string()],
            rows,
        }
    }

    /// Appends a row.
    pub fn push(&mut self, label: &str) {
        let i = match self.distinct.iter().rposition(|d| d == label) {
            Some(i) => i,
            None => {
                self.distinct.push(label.to_string());
                self.distinct.len() - 1
            }
        };
        // A trace cannot hold 2^32 distinct labels in memory anyway.
        self.rows.push(i as u32);
    }

    /// The number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The label of a row (`None` past the end).
    pub fn get(&self, row: usize) -> Option<&str> {
        self.rows
            .get(row)
            .map(|&i| self.distinct[i as usize].as_str())
    }

    /// The labels row by row.
    pub fn iter(&self) -> impl Iterator<Item = &String> + '_ {
        self.rows.iter().map(|&i| &self.distinct[i as usize])
    }

    /// The distinct labels, in order of first appearance.
    pub fn distinct(&self) -> &[String] {
        &self.distinct
    }
}

impl<S: AsRef<str>> FromIterator<S> for Labels {
    fn from_iter<I: IntoIterator<Item = S>>(iter: I) -> Labels {
        let mut l = Labels::new();
        for s in iter {
            l.push(s.as_ref());
        }
        l
    }
}

impl Trace {
    /// Builds a trace from a time column and named channel columns.
    ///
    /// `name` is used in error messages (a file name or a scenario name). Checks everything
    /// [`Trace::parse`] checks; lines in errors are those the trace would have when written
    /// without metadata (header on line 1).
    pub fn from_columns(
        name: &str,
        t: Vec<f64>,
        channels: Vec<(String, Vec<f64>)>,
    ) -> Result<Trace, TraceError> {
        let mut seen: Vec<&str> = vec![TIME_COLUMN];
        for (i, (ch, values)) in channels.iter().enumerate() {
            check_column_name(name, ch)?;
            if ch == PHASE_COLUMN || ch == TRUTH_COLUMN || seen.contains(&ch.as_str()) {
                return Err(TraceError::DuplicateColumn {
                    file: name.to_string(),
                    line: 1,
                    column: i + 2,
                    name: ch.clone(),
                });
            }
            seen.push(ch);
            if values.len() != t.len() {
                return Err(TraceError::LengthMismatch {
                    file: name.to_string(),
                    name: ch.clone(),
                    expected: t.len(),
                    found: values.len(),
                });
            }
            if let Some(row) = values.iter().position(|v| !v.is_finite()) {
                return Err(TraceError::NotFinite {
                    file: name.to_string(),
                    line: row + 2,
                    column: i + 2,
                    name: ch.clone(),
                    cell: values[row].to_string(),
                });
            }
        }
        let rate_hz = check_time(name, &t, |row| row + 2, 1)?;
        let (channel_names, data) = channels.into_iter().unzip();
        Ok(Trace {
            name: name.to_string(),
            t,
            rate_hz,
            channel_names,
            data,
            phase: None,
            truth: None,
            metadata: Vec::new(),
            lines: LineMap::default(),
        })
    }

    /// Adds a phase column (one phase name per row).
    pub fn with_phase(mut self, phase: Labels) -> Result<Trace, TraceError> {
        self.check_labels(PHASE_COLUMN, &phase, "phase label")?;
        self.phase = Some(phase);
        Ok(self)
    }

    /// Adds a truth column (the true event's name from its onset on, empty otherwise).
    pub fn with_truth(mut self, truth: Labels) -> Result<Trace, TraceError> {
        self.check_labels(TRUTH_COLUMN, &truth, "truth label")?;
        self.truth = Some(truth);
        Ok(self)
    }

    /// Adds a metadata entry, written as a `# key: value` comment before the header.
    ///
    /// The key must be non-empty and hold no blank, `:` or `,`; the value may not hold a
    /// line break and is trimmed.
    pub fn push_metadata(&mut self, key: &str, value: &str) -> Result<(), TraceError> {
        if key.is_empty()
            || key.starts_with('#')
            || key
                .chars()
                .any(|c| c.is_whitespace() || c == ':' || c == ',')
        {
            return Err(TraceError::InvalidText {
                file: self.name.clone(),
                what: "metadata key",
                text: shorten(key),
                reason: "a key is non-empty and holds no blank, `#` first, `:` or `,`",
            });
        }
        if value.contains(['\n', '\r']) {
            return Err(TraceError::InvalidText {
                file: self.name.clone(),
                what: "metadata value",
                text: shorten(value),
                reason: "a value holds no line break",
            });
        }
        self.metadata
            .push((key.to_string(), value.trim().to_string()));
        Ok(())
    }

    /// Reads a trace file.
    pub fn read(path: impl AsRef<Path>) -> Result<Trace, TraceError> {
        Trace::collect(TraceReader::open(path)?)
    }

    /// Parses trace text; `name` (usually the file name) prefixes every error message.
    pub fn parse(text: &str, name: &str) -> Result<Trace, TraceError> {
        Trace::collect(TraceReader::new(text.as_bytes(), name)?)
    }

    /// Reads every row of `reader` into a trace and checks that time is uniform.
    fn collect<R: BufRead>(mut reader: TraceReader<R>) -> Result<Trace, TraceError> {
        let mut t = Vec::new();
        let mut data: Vec<Vec<f64>> = vec![Vec::new(); reader.channel_names().len()];
        let mut phase = reader.has_phase().then(Labels::new);
        let mut truth = reader.has_truth().then(Labels::new);
        let mut lines = Vec::new();
        while let Some(row) = reader.next_row()? {
            t.push(row.t);
            for (column, v) in data.iter_mut().zip(row.values) {
                column.push(*v);
            }
            if let (Some(labels), Some(p)) = (phase.as_mut(), row.phase) {
                labels.push(p);
            }
            if let (Some(labels), Some(p)) = (truth.as_mut(), row.truth) {
                labels.push(p);
            }
            lines.push(row.line as u32);
        }
        let name = reader.name.clone();
        if t.is_empty() {
            return Err(TraceError::NoRows {
                file: name,
                line: reader.header_line,
            });
        }
        let rate_hz = check_time(&name, &t, |row| lines[row] as usize, reader.t_col + 1)?;
        Ok(Trace {
            name,
            t,
            rate_hz,
            channel_names: reader.channel_names().to_vec(),
            data,
            phase,
            truth,
            metadata: std::mem::take(&mut reader.metadata),
            lines: LineMap(lines),
        })
    }

    /// The file line of row `row` (0-based): where it was read from, or, for a trace built
    /// in memory, where it would be written without metadata (header on line 1). Every
    /// message about a row names its line.
    pub fn line_of(&self, row: usize) -> usize {
        self.lines.0.get(row).map_or(row + 2, |&l| l as usize)
    }

    /// Writes the trace as CSV text: metadata comments, header, rows.
    ///
    /// Numbers are written in the shortest form that reads back to the same `f64`, so
    /// writing and reading again gives an equal trace (up to its name).
    pub fn to_csv(&self) -> String {
        let mut out = String::with_capacity(self.len() * (12 * (self.data.len() + 1) + 16));
        for (k, v) in &self.metadata {
            // Writing to a String cannot fail.
            let _ = writeln!(out, "# {k}: {v}");
        }
        out.push_str(TIME_COLUMN);
        for name in &self.channel_names {
            out.push(',');
            out.push_str(name);
        }
        if self.phase.is_some() {
            out.push(',');
            out.push_str(PHASE_COLUMN);
        }
        if self.truth.is_some() {
            out.push(',');
            out.push_str(TRUTH_COLUMN);
        }
        out.push('\n');
        for row in 0..self.len() {
            let _ = write!(out, "{}", self.t[row]);
            for col in &self.data {
                let _ = write!(out, ",{}", col[row]);
            }
            if let Some(p) = &self.phase {
                out.push(',');
                out.push_str(p.get(row).unwrap_or(""));
            }
            if let Some(p) = &self.truth {
                out.push(',');
                out.push_str(p.get(row).unwrap_or(""));
            }
            out.push('\n');
        }
        out
    }

    /// Writes the trace to a file as one [`OutputPlan`](crate::output::OutputPlan) output:
    /// checked first, staged beside the destination, then moved into place. On any failure
    /// the staging file is removed and the destination is left untouched.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), TraceError> {
        use crate::output::{Kind, OutputPlan};
        let plan =
            OutputPlan::new(&[], &[(path.as_ref(), Kind::File)]).map_err(TraceError::Write)?;
        plan.write(0, self.to_csv().as_bytes())
            .map_err(TraceError::Write)?;
        plan.commit().map_err(TraceError::Write)
    }

    /// The name errors are reported under (the file name for a trace that was read).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Renames the trace (the name errors are reported under).
    pub fn set_name(&mut self, name: &str) {
        self.name = name.to_string();
    }

    /// The number of rows (always at least 2).
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Always false: a trace has at least two rows. Present for API symmetry with `len`.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The sampling rate in Hz, derived from the time column: (rows - 1) / (t_last - t_first).
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// The time column in seconds.
    pub fn time(&self) -> &[f64] {
        &self.t
    }

    /// The names of the numeric input channels, in file order (not `t`, `phase`, `truth`).
    pub fn channel_names(&self) -> &[String] {
        &self.channel_names
    }

    /// A numeric column by name: an input channel, or `t` for time.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        if name == TIME_COLUMN {
            return Some(&self.t);
        }
        self.channel_names
            .iter()
            .position(|c| c == name)
            .map(|i| self.data[i].as_slice())
    }

    /// The phase column, if the trace has one.
    pub fn phase(&self) -> Option<&Labels> {
        self.phase.as_ref()
    }

    /// The truth column, if the trace has one.
    pub fn truth(&self) -> Option<&Labels> {
        self.truth.as_ref()
    }

    /// The first row whose truth cell is not empty, with the event named there.
    pub fn truth_onset(&self) -> Option<(usize, &str)> {
        self.truth
            .as_ref()?
            .iter()
            .enumerate()
            .find(|(_, s)| !s.is_empty())
            .map(|(i, s)| (i, s.as_str()))
    }

    /// The metadata entries (`# key: value` comments), in file order.
    pub fn metadata(&self) -> &[(String, String)] {
        &self.metadata
    }

    /// The value of the first metadata entry with this key.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn check_labels(
        &self,
        column: &str,
        labels: &Labels,
        what: &'static str,
    ) -> Result<(), TraceError> {
        if labels.len() != self.len() {
            return Err(TraceError::LengthMismatch {
                file: self.name.clone(),
                name: column.to_string(),
                expected: self.len(),
                found: labels.len(),
            });
        }
        for label in labels.distinct() {
            if label.contains([',', '\n', '\r']) || label.trim() != label {
                return Err(TraceError::InvalidText {
                    file: self.name.clone(),
                    what,
                    text: shorten(label),
                    reason: "a label holds no comma or line break and no blank at either end",
                });
            }
        }
        Ok(())
    }
}

/// A trace read row by row, for recordings of any length: the metadata and header are
/// read and checked when it is made, then each [`TraceReader::next_row`] reads, checks and
/// hands out one row without keeping it. Rows are checked as [`Trace::parse`] checks them
/// (cells, numbers, time strictly increasing); whether time is uniform is for the caller
/// to judge, row by row or at the end.
pub struct TraceReader<R> {
    input: R,
    name: String,
    /// The last line read (1-based) and the bytes read before it.
    line: usize,
    offset: usize,
    /// Text read in blocks: `buf[start..end]` is not yet split into lines, `buf[..start]`
    /// holds the last line handed out; `base` bytes of the file come before `buf`.
    buf: Vec<u8>,
    start: usize,
    end: usize,
    base: usize,
    at_end: bool,
    metadata: Vec<(String, String)>,
    columns: Vec<String>,
    header_line: usize,
    t_col: usize,
    phase_col: Option<usize>,
    truth_col: Option<usize>,
    /// The numeric input columns, in file order.
    numeric: Vec<usize>,
    channel_names: Vec<String>,
    values: Vec<f64>,
    phase: String,
    truth: String,
    previous_t: Option<f64>,
}

/// One row handed out by a [`TraceReader`].
#[derive(Debug)]
pub struct Row<'a> {
    /// The file line it was read from.
    pub line: usize,
    /// Time (s).
    pub t: f64,
    /// The input channels' values, in [`TraceReader::channel_names`] order.
    pub values: &'a [f64],
    /// The phase cell, when the trace has a phase column.
    pub phase: Option<&'a str>,
    /// The truth cell, when the trace has a truth column.
    pub truth: Option<&'a str>,
}

/// The bytes a [`TraceReader`] reads at a time (a longer line grows its buffer).
const BLOCK: usize = 1 << 18;

const UTF16_HINT: &str = " (it looks like UTF-16, which is not supported: save it as UTF-8)";
const OTHER_HINT: &str = " (a binary file, or text in another encoding: save it as UTF-8)";

impl TraceReader<io::BufReader<fs::File>> {
    /// Opens a trace file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, TraceError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let f = fs::File::open(path).map_err(|source| TraceError::Read {
            file: file.clone(),
            source,
        })?;
        TraceReader::new(io::BufReader::with_capacity(1 << 16, f), &file)
    }
}

impl<R: BufRead> TraceReader<R> {
    /// Reads the metadata and header from `input`; `name` prefixes every error message.
    pub fn new(mut input: R, name: &str) -> Result<Self, TraceError> {
        let file = name.to_string();
        // UTF-16 shows a byte-order mark, or ASCII with a NUL beside every character.
        let head = input.fill_buf().map_err(|source| TraceError::Read {
            file: file.clone(),
            source,
        })?;
        let head = &head[..head.len().min(64)];
        let nul_at = |parity: usize| head.iter().skip(parity).step_by(2).all(|&b| b == 0);
        if head.starts_with(&[0xff, 0xfe])
            || head.starts_with(&[0xfe, 0xff])
            || (head.len() >= 8 && (nul_at(0) || nul_at(1)))
        {
            return Err(TraceError::NotUtf8 {
                file,
                line: 1,
                offset: 0,
                hint: UTF16_HINT,
            });
        }
        let mut reader = TraceReader {
            input,
            name: file,
            line: 0,
            offset: 0,
            buf: vec![0; BLOCK],
            start: 0,
            end: 0,
            base: 0,
            at_end: false,
            metadata: Vec::new(),
            columns: Vec::new(),
            header_line: 0,
            t_col: 0,
            phase_col: None,
            truth_col: None,
            numeric: Vec::new(),
            channel_names: Vec::new(),
            values: Vec::new(),
            phase: String::new(),
            truth: String::new(),
            previous_t: None,
        };
        let Some(range) = reader.next_line()? else {
            return Err(TraceError::NoHeader { file: reader.name });
        };
        let header = String::from_utf8_lossy(&reader.buf[range]).into_owned();
        reader.header_line = reader.line;
        reader.columns = header.split(',').map(|s| s.trim().to_string()).collect();
        reader.check_header()?;
        Ok(reader)
    }

    fn check_header(&mut self) -> Result<(), TraceError> {
        let (file, line, columns) = (&self.name, self.header_line, &self.columns);
        for (i, col) in columns.iter().enumerate() {
            if col.is_empty() {
                return Err(TraceError::EmptyColumnName {
                    file: file.clone(),
                    line,
                    column: i + 1,
                });
            }
            if columns[..i].contains(col) {
                return Err(TraceError::DuplicateColumn {
                    file: file.clone(),
                    line,
                    column: i + 1,
                    name: col.clone(),
                });
            }
        }
        let Some(t_col) = columns.iter().position(|c| c == TIME_COLUMN) else {
            return Err(TraceError::MissingTime {
                file: file.clone(),
                line,
            });
        };
        self.t_col = t_col;
        self.phase_col = columns.iter().position(|c| c == PHASE_COLUMN);
        self.truth_col = columns.iter().position(|c| c == TRUTH_COLUMN);
        self.numeric = (0..columns.len())
            .filter(|&c| Some(c) != self.phase_col && Some(c) != self.truth_col && c != t_col)
            .collect();
        self.channel_names = self.numeric.iter().map(|&c| columns[c].clone()).collect();
        self.values = vec![0.0; self.numeric.len()];
        Ok(())
    }

    /// The next line that is neither blank nor a comment (comments holding `key: value`
    /// are kept as metadata): its trimmed text's byte range in the line buffer; `None` at
    /// the end.
    fn next_line(&mut self) -> Result<Option<std::ops::Range<usize>>, TraceError> {
        loop {
            let Some(raw) = self.raw_line()? else {
                return Ok(None);
            };
            self.offset = self.base + raw.start;
            self.line += 1;
            let bytes = &self.buf[raw.clone()];
            let nul = memchr::memchr(0, bytes);
            // Recordings are ASCII text, trimmed as bytes; any other line is checked as UTF-8
            // and trimmed as text.
            let (lead, trimmed) = if nul.is_none() && bytes.is_ascii() {
                let rest = bytes.trim_ascii_start();
                (bytes.len() - rest.len(), rest.trim_ascii_end())
            } else {
                let text = match (nul, std::str::from_utf8(bytes)) {
                    (None, Ok(text)) => text,
                    (nul, other) => {
                        let bad = other.err().map(|e| e.valid_up_to());
                        let at = nul.into_iter().chain(bad).min().unwrap_or(0);
                        return Err(TraceError::NotUtf8 {
                            file: self.name.clone(),
                            line: self.line,
                            offset: self.offset + at,
                            hint: OTHER_HINT,
                        });
                    }
                };
                let bom = if self.line == 1 && text.starts_with('\u{feff}') {
                    '\u{feff}'.len_utf8()
                } else {
                    0
                };
                let body = &text[bom..];
                let rest = body.trim_start();
                (bom + body.len() - rest.len(), rest.trim_end().as_bytes())
            };
            if trimmed.is_empty() {
                continue;
            }
            if let Some(comment) = trimmed.strip_prefix(b"#") {
                if let Some(kv) = parse_metadata(&String::from_utf8_lossy(comment)) {
                    self.metadata.push(kv);
                }
                continue;
            }
            let start = raw.start + lead;
            return Ok(Some(start..start + trimmed.len()));
        }
    }

    /// The next line as it is in the file, its newline included: its range in `buf`,
    /// reading another block when the text in hand holds no whole line; `None` at the end.
    fn raw_line(&mut self) -> Result<Option<std::ops::Range<usize>>, TraceError> {
        let mut searched = self.start;
        loop {
            if let Some(n) = memchr::memchr(b'\n', &self.buf[searched..self.end]) {
                let line = self.start..searched + n + 1;
                self.start = line.end;
                return Ok(Some(line));
            }
            if self.at_end {
                if self.start == self.end {
                    return Ok(None);
                }
                let line = self.start..self.end;
                self.start = self.end;
                return Ok(Some(line));
            }
            // Keep the unsplit tail, at the front; grow only for a line longer than a block.
            searched = self.end - self.start;
            self.buf.copy_within(self.start..self.end, 0);
            self.base += self.start;
            self.end -= self.start;
            self.start = 0;
            if self.end == self.buf.len() {
                self.buf.resize(self.buf.len() * 2, 0);
            }
            let n = loop {
                match self.input.read(&mut self.buf[self.end..]) {
                    Ok(n) => break n,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(source) => {
                        return Err(TraceError::Read {
                            file: self.name.clone(),
                            source,
                        });
                    }
                }
            };
            self.end += n;
            self.at_end = n == 0;
        }
    }

    /// The next row, checked; `None` after the last one.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, TraceError> {
        let Some(range) = self.next_line()? else {
            return Ok(None);
        };
        let line = self.line;
        let text = &self.buf[range];
        let file = &self.name;
        let columns = &self.columns;
        let mut t = f64::NAN;
        let mut k = 0;
        self.phase.clear();
        self.truth.clear();
        // `rest` is the text after the cells read so far; `None` once the last was read.
        let mut rest = Some(text);
        for (c, column) in columns.iter().enumerate() {
            let Some(r) = rest else {
                return Err(TraceError::CellCount {
                    file: file.clone(),
                    line,
                    expected: columns.len(),
                    found: c,
                });
            };
            let label = if Some(c) == self.phase_col {
                Some(&mut self.phase)
            } else if Some(c) == self.truth_col {
                Some(&mut self.truth)
            } else {
                None
            };
            let value = match label {
                Some(label) => {
                    let (cell, tail) = next_cell(r);
                    label.push_str(&String::from_utf8_lossy(cell));
                    rest = tail;
                    continue;
                }
                // Most cells are plain decimals, read in one pass; the rest are split off
                // and read by the general parser.
                None => match plain_decimal(r) {
                    Some((v, n)) => {
                        rest = r.get(n + 1..);
                        v
                    }
                    None => {
                        let (cell, tail) = next_cell(r);
                        rest = tail;
                        parse_number(file, line, c, column, &String::from_utf8_lossy(cell))?
                    }
                },
            };
            if c == self.t_col {
                t = value;
            } else if let Some(v) = self.values.get_mut(k) {
                *v = value;
                k += 1;
            }
        }
        if let Some(r) = rest {
            return Err(TraceError::CellCount {
                file: file.clone(),
                line,
                expected: columns.len(),
                found: columns.len() + 1 + memchr::memchr_iter(b',', r).count(),
            });
        }
        if let Some(previous) = self.previous_t
            && t <= previous
        {
            return Err(TraceError::TimeNotIncreasing {
                file: file.clone(),
                line,
                column: self.t_col + 1,
                t,
                previous,
            });
        }
        self.previous_t = Some(t);
        Ok(Some(Row {
            line,
            t,
            values: &self.values,
            phase: self.phase_col.map(|_| self.phase.as_str()),
            truth: self.truth_col.map(|_| self.truth.as_str()),
        }))
    }

    /// The input channels' names, in file order.
    pub fn channel_names(&self) -> &[String] {
        &self.channel_names
    }

    /// Whether the trace has a phase column.
    pub fn has_phase(&self) -> bool {
        self.phase_col.is_some()
    }

    /// Whether the trace has a truth column.
    pub fn has_truth(&self) -> bool {
        self.truth_col.is_some()
    }

    /// The name errors are reported under.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The header's file line.
    pub fn header_line(&self) -> usize {
        self.header_line
    }

    /// The metadata read so far.
    pub fn metadata(&self) -> &[(String, String)] {
        &self.metadata
    }
}

/// Rows a [`ReadAhead`] hands over at a time: large enough that the hand-over costs little
/// per row, small enough that a few batches in flight stay well under a megabyte.
const BATCH_ROWS: usize = 1024;
/// Batches read ahead of the consumer.
const BATCHES_AHEAD: usize = 4;

/// A [`TraceReader`] that parses on a thread of its own, a few batches of rows ahead of the
/// consumer, so reading the text and using the rows run on two cores. It hands out the
/// same rows, checked the same way, and stops at the same error; memory stays a few
/// batches whatever the length.
///
/// Made inside a [`std::thread::scope`] by [`ReadAhead::spawn`]; when it is dropped the
/// parsing thread stops at its next batch.
pub struct ReadAhead {
    batches: std::sync::mpsc::Receiver<Result<Batch, TraceError>>,
    /// Emptied batches sent back for reuse.
    spent: std::sync::mpsc::SyncSender<Batch>,
    batch: Batch,
    next: usize,
    phase: String,
    truth: String,
    name: String,
    channel_names: Vec<String>,
    metadata: Vec<(String, String)>,
    header_line: usize,
    has_phase: bool,
    has_truth: bool,
}

/// Rows parsed ahead: line, time and values of each, and the labels where they change.
#[derive(Default)]
struct Batch {
    lines: Vec<usize>,
    t: Vec<f64>,
    values: Vec<f64>,
    /// `(row in the batch, label)` wherever the phase differs from the row before.
    phase: Vec<(usize, String)>,
    truth: Vec<(usize, String)>,
}

impl Batch {
    fn clear(&mut self) {
        self.lines.clear();
        self.t.clear();
        self.values.clear();
        self.phase.clear();
        self.truth.clear();
    }

    /// Fills the batch from `reader` (up to [`BATCH_ROWS`]); `last` holds the phase and
    /// truth of the row before. Returns the error that stopped it, if any.
    fn fill<R: BufRead>(
        &mut self,
        reader: &mut TraceReader<R>,
        last: &mut (String, String),
    ) -> Option<TraceError> {
        self.clear();
        while self.t.len() < BATCH_ROWS {
            match reader.next_row() {
                Ok(Some(row)) => {
                    let i = self.t.len();
                    self.lines.push(row.line);
                    self.t.push(row.t);
                    self.values.extend_from_slice(row.values);
                    for (cell, last, changes) in [
                        (row.phase, &mut last.0, &mut self.phase),
                        (row.truth, &mut last.1, &mut self.truth),
                    ] {
                        if let Some(cell) = cell
                            && cell != last.as_str()
                        {
                            last.clear();
                            last.push_str(cell);
                            changes.push((i, cell.to_string()));
                        }
                    }
                }
                Ok(None) => return None,
                Err(e) => return Some(e),
            }
        }
        None
    }
}

impl ReadAhead {
    /// Moves `reader` to a thread of `scope` that parses its rows ahead.
    pub fn spawn<'scope, R: BufRead + Send + 'scope>(
        scope: &'scope std::thread::Scope<'scope, '_>,
        mut reader: TraceReader<R>,
    ) -> ReadAhead {
        let (to_consumer, batches) = std::sync::mpsc::sync_channel(BATCHES_AHEAD);
        let (spent, to_reuse) = std::sync::mpsc::sync_channel::<Batch>(BATCHES_AHEAD + 2);
        let ahead = ReadAhead {
            batches,
            spent,
            batch: Batch::default(),
            next: 0,
            phase: String::new(),
            truth: String::new(),
            name: reader.name().to_string(),
            channel_names: reader.channel_names().to_vec(),
            metadata: reader.metadata().to_vec(),
            header_line: reader.header_line(),
            has_phase: reader.has_phase(),
            has_truth: reader.has_truth(),
        };
        scope.spawn(move || {
            let mut last = (String::new(), String::new());
            loop {
                let mut batch = to_reuse.try_recv().unwrap_or_default();
                let error = batch.fill(&mut reader, &mut last);
                let end = error.is_some() || batch.t.len() < BATCH_ROWS;
                if !batch.t.is_empty() && to_consumer.send(Ok(batch)).is_err() {
                    return;
                }
                if let Some(e) = error {
                    let _ = to_consumer.send(Err(e));
                }
                if end {
                    return;
                }
            }
        });
        ahead
    }

    /// The `# key: value` comments before the header.
    pub fn metadata(&self) -> &[(String, String)] {
        &self.metadata
    }

    /// The next row, checked; `None` after the last one.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, TraceError> {
        if self.next == self.batch.t.len() {
            let spent = std::mem::take(&mut self.batch);
            // The parser may have ended, or have enough spare batches: then it is dropped.
            let _ = self.spent.try_send(spent);
            match self.batches.recv() {
                Ok(Ok(batch)) => self.batch = batch,
                Ok(Err(e)) => return Err(e),
                // The parser is done: every row was handed out.
                Err(_) => return Ok(None),
            }
            self.next = 0;
        }
        let i = self.next;
        self.next += 1;
        let b = &self.batch;
        for (changes, label) in [(&b.phase, &mut self.phase), (&b.truth, &mut self.truth)] {
            if let Ok(k) = changes.binary_search_by_key(&i, |c| c.0) {
                label.clone_from(&changes[k].1);
            }
        }
        let width = self.channel_names.len();
        Ok(Some(Row {
            line: b.lines[i],
            t: b.t[i],
            values: &b.values[i * width..(i + 1) * width],
            phase: self.has_phase.then_some(self.phase.as_str()),
            truth: self.has_truth.then_some(self.truth.as_str()),
        }))
    }

    /// The input channels' names, in file order.
    pub fn channel_names(&self) -> &[String] {
        &self.channel_names
    }

    /// The name errors are reported under.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The header's file line.
    pub fn header_line(&self) -> usize {
        self.header_line
    }
}

/// The first cell of a row's `text` (UTF-8), trimmed, and the text after its comma (`None`
/// when it is the last cell).
fn next_cell(text: &[u8]) -> (&[u8], Option<&[u8]>) {
    let (cell, tail) = match memchr::memchr(b',', text) {
        Some(i) => (&text[..i], text.get(i + 1..)),
        None => (text, None),
    };
    let blank = |b: Option<&u8>| b.is_some_and(|b| b.is_ascii_whitespace() || !b.is_ascii());
    let cell = if blank(cell.first()) || blank(cell.last()) {
        // A comma is one byte: the cell is whole characters.
        std::str::from_utf8(cell).map_or(cell, |c| c.trim().as_bytes())
    } else {
        cell
    };
    (cell, tail)
}

/// Checks a channel name given to a constructor.
fn check_column_name(file: &str, name: &str) -> Result<(), TraceError> {
    if name.is_empty()
        || name.starts_with('#')
        || name.contains([',', '\n', '\r'])
        || name.trim() != name
    {
        return Err(TraceError::InvalidText {
            file: file.to_string(),
            what: "channel name",
            text: shorten(name),
            reason: "a name is non-empty, holds no comma or line break, does not start with `#` and has no blank at either end",
        });
    }
    Ok(())
}

/// `key: value` from the text of a comment, when it has that form (key without blanks).
fn parse_metadata(comment: &str) -> Option<(String, String)> {
    let (key, value) = comment.split_once(':')?;
    let key = key.trim();
    if key.is_empty() || key.chars().any(|c| c.is_whitespace() || c == ',') {
        return None;
    }
    Some((key.to_string(), value.trim().to_string()))
}

fn parse_number(
    file: &str,
    line: usize,
    col: usize,
    name: &str,
    cell: &str,
) -> Result<f64, TraceError> {
    match cell.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(TraceError::NotFinite {
            file: file.to_string(),
            line,
            column: col + 1,
            name: name.to_string(),
            cell: shorten(cell),
        }),
        Err(_) => Err(TraceError::NotANumber {
            file: file.to_string(),
            line,
            column: col + 1,
            name: name.to_string(),
            cell: shorten(cell),
        }),
    }
}

/// The plain decimal at the start of `text`, up to a comma or the end (`-12.0345`: a sign,
/// at most 19 digits with at most one point, no exponent, no blank), when its digits read
/// as an integer stay below 2⁵³ and it has at most 22 digits after the point: its value and
/// its length in bytes. `None` for anything else, which the general parser then reads.
///
/// Recordings are mostly such numbers, and this reads them several times faster than the
/// general parser, with the same result: the digits and the power of ten are both exact
/// in an `f64`, so the one division rounds the decimal's exact value correctly (Clinger's
/// fast path).
fn plain_decimal(text: &[u8]) -> Option<(f64, usize)> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let (negative, start) = match text.first()? {
        b'-' => (true, 1),
        b'+' => (false, 1),
        _ => (false, 0),
    };
    let mut mantissa: u64 = 0;
    let mut count = 0;
    let mut point = None;
    let mut end = text.len();
    for (i, &b) in text.iter().enumerate().skip(start) {
        match b {
            // More than 19 digits may wrap: they are declined below.
            b'0'..=b'9' => {
                mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(b - b'0'));
                count += 1;
            }
            b'.' if point.is_none() => point = Some(count),
            b',' => {
                end = i;
                break;
            }
            _ => return None,
        }
    }
    let decimals = count - point.unwrap_or(count);
    if count == 0 || count > 19 || mantissa >= 1 << 53 || decimals >= POW10.len() {
        return None;
    }
    let magnitude = mantissa as f64 / POW10[decimals];
    Some((if negative { -magnitude } else { magnitude }, end))
}

fn shorten(cell: &str) -> String {
    const MAX: usize = 40;
    if cell.chars().count() <= MAX {
        cell.escape_debug().to_string()
    } else {
        let head: String = cell.chars().take(MAX).collect();
        format!("{}...", head.escape_debug())
    }
}

/// Checks that time is finite, strictly increasing and uniform; returns the rate in Hz.
/// `line_of(row)` gives the file line of a row for messages, `column` the 1-based column.
fn check_time(
    file: &str,
    t: &[f64],
    line_of: impl Fn(usize) -> usize,
    column: usize,
) -> Result<f64, TraceError> {
    if t.is_empty() {
        return Err(TraceError::NoRows {
            file: file.to_string(),
            line: 1,
        });
    }
    if t.len() == 1 {
        return Err(TraceError::SingleRow {
            file: file.to_string(),
            line: line_of(0),
        });
    }
    for (row, v) in t.iter().enumerate() {
        if !v.is_finite() {
            return Err(TraceError::NotFinite {
                file: file.to_string(),
                line: line_of(row),
                column,
                name: TIME_COLUMN.to_string(),
                cell: v.to_string(),
            });
        }
    }
    for row in 1..t.len() {
        if t[row] <= t[row - 1] {
            return Err(TraceError::TimeNotIncreasing {
                file: file.to_string(),
                line: line_of(row),
                column,
                t: t[row],
                previous: t[row - 1],
            });
        }
    }
    let period = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    for row in 1..t.len() {
        let step = t[row] - t[row - 1];
        if (step - period).abs() > TIME_STEP_TOLERANCE * period {
            return Err(TraceError::TimeNotUniform {
                file: file.to_string(),
                line: line_of(row),
                column,
                step,
                period,
            });
        }
    }
    Ok(1.0 / period)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The plain-decimal fast path reads exactly what `str::parse` reads, or declines:
        /// every digit count, point position and sign, and the limits of 19 digits, 2⁵³
        /// and 22 decimals on both sides.
        #[test]
        fn plain_decimals_read_as_str_parse_does(
            sign in prop::sample::select(vec!["", "-", "+"]),
            digits in "[0-9]{0,21}",
            point in prop::option::of(0usize..=21),
        ) {
            let mut cell = digits.clone();
            if let Some(p) = point {
                cell.insert(p.min(digits.len()), '.');
            }
            let cell = format!("{sign}{cell}");
            let general = cell.parse::<f64>().ok();
            if let Some((fast, n)) = plain_decimal(cell.as_bytes()) {
                prop_assert_eq!(Some(fast.to_bits()), general.map(f64::to_bits), "{}", cell);
                prop_assert_eq!(n, cell.len());
            }
            // A comma ends the number; the cells after it are not read.
            let row = format!("{cell},9,x");
            prop_assert_eq!(plain_decimal(row.as_bytes()), plain_decimal(cell.as_bytes()));
        }
    }

    #[test]
    fn plain_decimal_takes_the_common_cells_and_declines_the_rest() {
        for (cell, want) in [
            ("0", 0.0),
            ("-0.0045", -0.0045),
            ("1234.5678", 1234.5678),
            ("+.5", 0.5),
            ("7.", 7.0),
            ("9007199254740991", 9_007_199_254_740_991.0),
            (".0000000000000000001", 1e-19),
        ] {
            assert_eq!(
                plain_decimal(cell.as_bytes()),
                Some((want, cell.len())),
                "{cell}"
            );
        }
        assert_eq!(plain_decimal(b"-2.5,1,2"), Some((-2.5, 4)));
        for cell in [
            "",
            "-",
            ".",
            ",1",
            "-,1",
            "1e3",
            "1.2.3",
            "9007199254740993",
            "12345678901234567890.",
            "1234567.000000000001",
            "0.0000000000000000000001",
            " 1",
            "1 ,2",
            "inf",
            "NaN",
            "0x10",
        ] {
            assert_eq!(plain_decimal(cell.as_bytes()), None, "{cell}");
        }
    }

    fn parse(text: &str) -> Result<Trace, TraceError> {
        Trace::parse(text, "test.csv")
    }

    fn message(text: &str) -> String {
        let e = parse(text).expect_err("should fail");
        let m = e.to_string();
        assert!(!m.contains('\n'), "one line: {m}");
        assert!(m.starts_with("test.csv: "), "names the file: {m}");
        m
    }

    const GOOD: &str = "# scenario: contact_hard_8\n\
                        # a plain comment\n\
                        t,force_x,phase,truth\n\
                        0,1.5,approach,\n\
                        # comment between rows\n\
                        0.0002,-2,approach,\n\
                        \n\
                        0.0004,3e-3,approach,contact\n\
                        0.0006, 4 ,approach,contact\n";

    #[test]
    fn parses_a_good_trace() {
        let tr = parse(GOOD).unwrap();
        assert_eq!(tr.len(), 4);
        assert!((tr.rate_hz() - 5000.0).abs() < 1e-6);
        assert_eq!(tr.channel_names(), ["force_x"]);
        assert_eq!(tr.column("force_x").unwrap(), [1.5, -2.0, 3e-3, 4.0]);
        assert_eq!(tr.column("t").unwrap()[1], 0.0002);
        assert!(tr.column("phase").is_none());
        assert_eq!(tr.phase().unwrap().get(0), Some("approach"));
        assert_eq!(tr.truth().unwrap().distinct(), ["", "contact"]);
        assert_eq!(tr.truth_onset(), Some((2, "contact")));
        assert_eq!(tr.meta("scenario"), Some("contact_hard_8"));
        assert_eq!(tr.metadata().len(), 1, "plain comments are not metadata");
    }

    #[test]
    fn accepts_any_channel_names_and_order() {
        let tr = parse("pressure_kpa,t,Temp\n1,10,2\n2,10.5,3\n3,11,4\n").unwrap();
        assert_eq!(tr.channel_names(), ["pressure_kpa", "Temp"]);
        assert!((tr.rate_hz() - 2.0).abs() < 1e-12);
        assert!(tr.phase().is_none() && tr.truth().is_none() && tr.truth_onset().is_none());
    }

    #[test]
    fn tolerates_crlf_and_bom() {
        let tr = parse("\u{feff}t,a\r\n0,1\r\n1,2\r\n").unwrap();
        assert_eq!(tr.column("a").unwrap(), [1.0, 2.0]);
    }

    #[test]
    fn error_empty_file() {
        let m = message("");
        assert!(m.contains("no header"), "{m}");
        let m = message("# only: comments\n\n# here\n");
        assert!(m.contains("no header"), "{m}");
    }

    #[test]
    fn error_no_rows() {
        let m = message("# x: y\nt,force_x\n# nothing\n");
        assert!(m.contains("line 2") && m.contains("no data rows"), "{m}");
    }

    #[test]
    fn error_single_row() {
        let m = message("t,a\n0,1\n");
        assert!(
            m.contains("line 2") && m.contains("only one data row"),
            "{m}"
        );
    }

    #[test]
    fn error_missing_time() {
        let m = message("# c\ntime,force_x\n0,1\n1,2\n");
        assert!(m.contains("line 2") && m.contains("no column `t`"), "{m}");
    }

    #[test]
    fn error_duplicate_column() {
        let m = message("t,force_x,force_x\n0,1,2\n1,2,3\n");
        assert!(
            m.contains("line 1, column 3") && m.contains("duplicate column name `force_x`"),
            "{m}"
        );
    }

    #[test]
    fn error_empty_column_name() {
        let m = message("t,force_x,\n0,1,\n1,2,\n");
        assert!(
            m.contains("line 1, column 3") && m.contains("empty column name"),
            "{m}"
        );
    }

    #[test]
    fn error_non_numeric_cell() {
        let m = message("t,force_x,skin_accel\n0,1,2\n# c\n0.1,abc,3\n");
        assert!(
            m.contains("line 4, column 2 `force_x`") && m.contains("`abc` is not a number"),
            "{m}"
        );
        let m = message("t,force_x\n0,1\n0.1,\n");
        assert!(m.contains("line 3, column 2") && m.contains("``"), "{m}");
    }

    #[test]
    fn error_non_finite_cell() {
        for bad in ["NaN", "inf", "-inf", "1e400"] {
            let m = message(&format!("t,force_x\n0,1\n0.1,{bad}\n"));
            assert!(
                m.contains("line 3, column 2 `force_x`") && m.contains("not finite"),
                "{m}"
            );
        }
        let m = message("force_x,t\n0,NaN\n0.1,1\n");
        assert!(
            m.contains("line 2, column 2 `t`") && m.contains("not finite"),
            "{m}"
        );
    }

    #[test]
    fn error_wrong_cell_count() {
        let m = message("t,force_x\n0,1\n0.1,2,3\n");
        assert!(
            m.contains("line 3") && m.contains("3 cells") && m.contains("2 columns"),
            "{m}"
        );
        let m = message("t,force_x\n0\n0.1,2\n");
        assert!(m.contains("line 2") && m.contains("1 cells"), "{m}");
    }

    #[test]
    fn error_decreasing_time() {
        let m = message("t,a\n0,1\n0.2,1\n0.1,1\n0.3,1\n");
        assert!(
            m.contains("line 4, column 1 `t`") && m.contains("does not increase"),
            "{m}"
        );
        let m = message("a,t\n1,0\n1,0\n");
        assert!(m.contains("line 3, column 2 `t`"), "{m}");
    }

    #[test]
    fn error_non_uniform_time() {
        let mut text = String::from("t,a\n");
        for k in 0..100 {
            let t = if k < 50 { k as f64 } else { k as f64 + 0.5 };
            text.push_str(&format!("{t},0\n"));
        }
        let m = message(&text);
        assert!(
            m.contains("line 52, column 1 `t`") && m.contains("uniform"),
            "{m}"
        );
    }

    #[test]
    fn small_time_jitter_is_accepted() {
        let mut text = String::from("t,a\n");
        for k in 0..100 {
            let jitter = if k % 2 == 0 { 0.002 } else { -0.002 };
            text.push_str(&format!("{},0\n", k as f64 + jitter));
        }
        assert!(parse(&text).is_ok());
    }

    #[test]
    fn read_names_the_file_when_missing() {
        let e = Trace::read("/nonexistent/dir/x.csv").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/dir/x.csv: cannot read")
        );
    }

    fn sample() -> Trace {
        let n = 50;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 5000.0).collect();
        let a: Vec<f64> = (0..n).map(|k| (k as f64 * 0.37).sin() * 1e-3).collect();
        let b: Vec<f64> = (0..n).map(|k| -(k as f64) * 1.0e7 + 1.0 / 3.0).collect();
        let mut tr = Trace::from_columns("mem", t, vec![("force_x".into(), a), ("x y".into(), b)])
            .unwrap()
            .with_phase(Labels::uniform("approach", n))
            .unwrap()
            .with_truth(Labels::switch_at("", "contact", 7, n))
            .unwrap();
        tr.push_metadata("scenario", "contact_hard_8").unwrap();
        tr.push_metadata("note", "value: with colon").unwrap();
        tr
    }

    #[test]
    fn labels_switch_at_matches_pushing_rows() {
        for (before, after) in [("", "contact"), ("a", "a")] {
            for switch in [0, 1, 3, 5, 9] {
                let n = 5;
                let pushed: Labels = (0..n)
                    .map(|r| if r < switch { before } else { after })
                    .collect();
                let built = Labels::switch_at(before, after, switch, n);
                assert_eq!(built, pushed, "{before:?} {after:?} {switch}");
                assert_eq!(built.len(), n);
                assert_eq!(built.get(n), None);
            }
        }
    }

    /// Reads up to seven bytes at a time, splitting lines and characters anywhere.
    struct Trickle<'a>(&'a [u8]);

    impl io::Read for Trickle<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            let n = out.len().min(self.0.len()).min(7);
            out[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    /// Every row of `reader` as text, then the error that stopped it, if any.
    fn rows_of(mut next: impl FnMut() -> Result<Option<String>, TraceError>) -> Vec<String> {
        let mut rows = Vec::new();
        loop {
            match next() {
                Ok(Some(row)) => rows.push(row),
                Ok(None) => return rows,
                Err(e) => {
                    rows.push(e.to_string());
                    return rows;
                }
            }
        }
    }

    fn describe(r: Row<'_>) -> String {
        format!(
            "{} {} {:?} {:?} {:?}",
            r.line, r.t, r.values, r.phase, r.truth
        )
    }

    /// The same rows and the same error, at the same line and byte, whether the text comes
    /// whole, a few bytes at a time (lines and characters split between reads, a comment
    /// longer than the reader's block) or through the read-ahead thread.
    #[test]
    fn rows_are_the_same_however_the_text_arrives() {
        let mut text = String::from("\u{feff}# rate_hz: 1000\r\n# ");
        text.push_str(&"long comment ".repeat(40_000));
        text.push_str("\n\nt, a ,phase,truth,b\n");
        for k in 0..3000 {
            let phase = if k < 1700 { "approach" } else { "gräsp" };
            let truth = if k % 1000 > 600 { "contact" } else { "" };
            let a = match k % 4 {
                0 => format!("{}", f64::from(k) * 0.001 - 1.5),
                1 => format!(" {}e-3 ", k),
                2 => format!("+{k}.25"),
                _ => "-0.000000000000000000001".to_string(),
            };
            let end = if k % 3 == 0 { "\r\n" } else { "\n" };
            text.push_str(&format!(
                "{},{a},{phase},{truth},{}{end}",
                f64::from(k) * 0.001,
                -k
            ));
            if k % 500 == 0 {
                text.push_str("  # a comment between rows\n");
            }
        }
        let mut broken = text.clone().into_bytes();
        broken.extend_from_slice(b"3,1,approach,,\xff\n");
        for bytes in [text.as_bytes(), &broken[..]] {
            let mut whole = TraceReader::new(bytes, "f.csv").unwrap();
            let whole = rows_of(|| Ok(whole.next_row()?.map(describe)));
            let slow = io::BufReader::with_capacity(5, Trickle(bytes));
            let mut slow = TraceReader::new(slow, "f.csv").unwrap();
            let slow = rows_of(|| Ok(slow.next_row()?.map(describe)));
            let ahead = std::thread::scope(|scope| {
                let reader = TraceReader::new(bytes, "f.csv").unwrap();
                let mut ahead = ReadAhead::spawn(scope, reader);
                rows_of(|| Ok(ahead.next_row()?.map(describe)))
            });
            assert_eq!(whole.len(), 3000 + usize::from(bytes.len() > text.len()));
            assert_eq!(whole[0], "5 0 [-1.5, 0.0] Some(\"approach\") Some(\"\")");
            assert!(
                whole[2999].ends_with(" Some(\"gräsp\") Some(\"contact\")"),
                "{}",
                whole[2999]
            );
            assert_eq!(slow, whole);
            assert_eq!(ahead, whole);
        }
        let mut broken_reader = TraceReader::new(&broken[..], "f.csv").unwrap();
        let error = rows_of(|| Ok(broken_reader.next_row()?.map(describe)));
        // The header on line 4, 3000 rows, 6 comments between them.
        let last_line = 4 + 3000 + 6 + 1;
        assert_eq!(
            error.last().map(String::as_str),
            Some(&*format!(
                "f.csv: line {last_line}, byte {}: not UTF-8 text (a binary file, or text in another encoding: save it as UTF-8)",
                broken.len() - 2
            ))
        );
    }

    #[test]
    fn round_trip_through_text() {
        let tr = sample();
        let mut back = Trace::parse(&tr.to_csv(), "mem").unwrap();
        assert_eq!(back, tr);
        back.set_name("other");
        assert_ne!(back, tr);
        assert_eq!(back.truth_onset(), Some((7, "contact")));
    }

    #[test]
    fn round_trip_through_file_and_no_temp_left() {
        let dir = std::env::temp_dir().join(format!("trace-rt-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("run.csv");
        let tr = sample();
        tr.write(&path).unwrap();
        let mut back = Trace::read(&path).unwrap();
        back.set_name("mem");
        assert_eq!(back, tr);
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(
            names.len(),
            1,
            "only the trace, no temporary file: {names:?}"
        );
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("trace-fail-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        // The destination is a directory: refused before anything is written.
        let dest = dir.join("occupied");
        fs::create_dir_all(dest.join("inner")).unwrap();
        let e = sample().write(&dest).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        let names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["occupied"], "temporary file removed");
        fs::remove_dir_all(&dir).unwrap();
    }

    /// Files that are not UTF-8 text are refused with the line and byte where the text
    /// stops, and UTF-16 is named; huge cells and numbers are shown short.
    #[test]
    fn encodings_and_huge_values_give_short_clear_messages() {
        let dir = std::env::temp_dir().join(format!("trace-enc-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let good = "t,x\n0,1\n0.001,2\n";
        let utf16le: Vec<u8> = good.encode_utf16().flat_map(u16::to_le_bytes).collect();
        let with_bom: Vec<u8> = [0xff, 0xfe].into_iter().chain(utf16le.clone()).collect();
        let utf16be: Vec<u8> = good.encode_utf16().flat_map(u16::to_be_bytes).collect();
        let latin1: Vec<u8> = b"t,x\n0,1\n0.001,caf\xe9\n".to_vec();
        let png: Vec<u8> = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR".to_vec();
        for (bytes, words) in [
            (&utf16le, &["line 1", "byte 0", "UTF-16"][..]),
            (&with_bom, &["line 1", "byte 0", "UTF-16"][..]),
            (&utf16be, &["line 1", "byte 0", "UTF-16"][..]),
            (&latin1, &["line 3", "byte 17", "another encoding"][..]),
            (&png, &["line 1", "byte 0", "binary"][..]),
        ] {
            let path = dir.join("bad.csv");
            fs::write(&path, bytes).unwrap();
            let m = Trace::read(&path).unwrap_err().to_string();
            for w in words {
                assert!(m.contains(w), "{m:?} lacks {w:?}");
            }
        }
        let huge_cell = format!("t,x\n0,1\n0.001,{}\n", "9".repeat(10_000_000) + "x");
        let m = parse(&huge_cell).unwrap_err().to_string();
        assert!(m.len() < 200 && m.contains("line 3"), "{} bytes", m.len());
        let m = parse("t,x\n1e300,1\n0,2\n").unwrap_err().to_string();
        assert!(m.contains("1e300") && m.len() < 200, "{m}");
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn constructors_reject_bad_input() {
        let t = vec![0.0, 1.0, 2.0];
        let e = Trace::from_columns("m", t.clone(), vec![("a".into(), vec![1.0])]).unwrap_err();
        assert!(matches!(e, TraceError::LengthMismatch { .. }), "{e}");
        let e =
            Trace::from_columns("m", t.clone(), vec![("a,b".into(), vec![1.0; 3])]).unwrap_err();
        assert!(matches!(e, TraceError::InvalidText { .. }), "{e}");
        let e =
            Trace::from_columns("m", t.clone(), vec![("truth".into(), vec![1.0; 3])]).unwrap_err();
        assert!(matches!(e, TraceError::DuplicateColumn { .. }), "{e}");
        let e = Trace::from_columns("m", t.clone(), vec![("a".into(), vec![1.0, f64::NAN, 0.0])])
            .unwrap_err();
        assert!(matches!(e, TraceError::NotFinite { line: 3, .. }), "{e}");
        let e = Trace::from_columns("m", vec![0.0, 2.0, 1.0], vec![]).unwrap_err();
        assert!(matches!(e, TraceError::TimeNotIncreasing { .. }), "{e}");
        let tr = Trace::from_columns("m", t, vec![]).unwrap();
        let e = tr.clone().with_phase(Labels::uniform("a", 2)).unwrap_err();
        assert!(matches!(e, TraceError::LengthMismatch { .. }), "{e}");
        let e = tr
            .clone()
            .with_truth(Labels::uniform("a,b", 3))
            .unwrap_err();
        let e2 = tr
            .clone()
            .with_truth(["x", " y", "z"].into_iter().collect())
            .unwrap_err();
        assert!(matches!(e2, TraceError::InvalidText { .. }), "{e2}");
        assert!(matches!(e, TraceError::InvalidText { .. }), "{e}");
        let mut tr = tr;
        assert!(tr.push_metadata("bad key", "v").is_err());
        assert!(tr.push_metadata("k", "two\nlines").is_err());
    }
}
