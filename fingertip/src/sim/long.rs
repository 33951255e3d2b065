//! A synthetic event-free recording of any length, written row by row, for measuring how
//! the tools handle a whole working day (memory, ticks per second): `examples/long_trace.rs`
//! writes it to standard output, `benches/replay.rs` times a replay of it.
//!
//! The channels are those of the approach configuration at 5 kHz: sensor noise and mains
//! hum on the analog ones, a slow back-and-forth motion in the controller's context. About
//! 79 bytes per row.

use std::io::Write;

/// The rate of the recording (Hz), the approach configuration's.
pub const RATE_HZ: f64 = 5000.0;

/// Writes `rows` rows (`rows / 5000` seconds) of the recording, its header first.
pub fn write_long_recording(out: &mut impl Write, rows: u64) -> std::io::Result<()> {
    let rate = RATE_HZ;
    writeln!(
        out,
        "# long_trace: {} s of event-free motion at {rate} Hz",
        rows as f64 / rate
    )?;
    writeln!(
        out,
        "t,force_x,force_y,skin_accel,stress_rate,pos_err_x,pos_err_y,vel_des_x,vel_des_y,acc_des_x,acc_des_y"
    )?;
    // A small linear congruential generator: reproducible noise without a dependency.
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut noise = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let mut line = String::with_capacity(160);
    for k in 0..rows {
        let t = k as f64 / rate;
        let hum = (std::f64::consts::TAU * 50.0 * t).sin();
        let phase = std::f64::consts::TAU * 0.25 * t;
        let (v, a) = (
            0.02 * phase.sin(),
            0.02 * std::f64::consts::TAU * 0.25 * phase.cos(),
        );
        line.clear();
        use std::fmt::Write as _;
        let _ = writeln!(
            line,
            "{t:.4},{:.4},{:.4},{:.3},{:.3},{:.7},{:.7},{v:.5},0,{a:.5},0",
            0.01 * noise() + 0.01 * hum,
            0.01 * noise(),
            0.5 * noise() + 0.2 * hum,
            0.5 * noise(),
            15e-6 + 1e-6 * noise(),
            1e-6 * noise(),
        );
        out.write_all(line.as_bytes())?;
    }
    Ok(())
}
