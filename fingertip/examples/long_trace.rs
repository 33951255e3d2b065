//! Writes a long event-free trace ([`fingertip::sim::long`]) to standard output, for
//! measuring how a replay of a whole working day behaves (memory, ticks per second):
//!
//! ```sh
//! cargo run --release -p fingertip --example long_trace -- 10 > day.csv   # 10 hours
//! /usr/bin/time -v fingertip replay day.csv
//! ```
//!
//! The argument is the length in hours (default 1).

use std::io::{BufWriter, Write};

use fingertip::sim::long::{RATE_HZ, write_long_recording};

fn main() -> std::io::Result<()> {
    let hours: f64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .filter(|h: &f64| h.is_finite() && *h > 0.0)
        .unwrap_or(1.0);
    let mut out = BufWriter::with_capacity(1 << 20, std::io::stdout().lock());
    write_long_recording(&mut out, (hours * 3600.0 * RATE_HZ) as u64)?;
    out.flush()
}
