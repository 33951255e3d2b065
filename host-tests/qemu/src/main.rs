//! The QEMU program: the approach detector on an emulated Cortex-M4 (`mps2-an386`).
//!
//! It loads the embedded detector image, replays the embedded trace three times and prints, over
//! semihosting, one `key=value` line per result (the host test parses them):
//!
//! 1. through [`fingertip_tick`], the tick generated for the configuration at build time
//!    (one call per tick, as the firmware does), timing each call;
//! 2. through its four stage functions ([`fingertip_update_features`],
//!    [`fingertip_term_confidences`], [`fingertip_combine`], [`fingertip_decide`]), timing
//!    each;
//! 3. through [`fingertip_tick_interpreted`], the interpreter (`Detector` as a `DetectorTick`),
//!    timing each call.
//!
//! The three digests must equal the one the PC computes with the interpreter.
//!
//! Instructions are counted with QEMU's `-icount`: the virtual clock advances exactly
//! 2^shift ns per instruction and SysTick (25 MHz core clock) reads it, so a SysTick
//! difference divided by the counts-per-instruction ratio (calibrated at start against a
//! block of 4096 `nop`s) is an exact instruction count. Run it with
//! `-icount shift=10,align=off,sleep=off` (25.6 counts per instruction); without `-icount`
//! the figures are wall-clock noise.
//!
//! On the PC this file builds a small program that runs the same replay (no counts), so
//! `cargo run -p fingertip-qemu` shows what the target should print.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod target {
    use core::panic::PanicInfo;
    use core::sync::atomic::{Ordering, compiler_fence};

    use cortex_m::peripheral::SYST;
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::{ExceptionFrame, entry, exception};
    use cortex_m_semihosting::{debug, hprintln};
    use detector_core::{ChannelMask, Detector, DetectorTick, Inputs, Output, State, Tick};
    use fingertip_qemu::digest::{Crc32, Digest};
    use fingertip_qemu::replay::{Position, SegmentLine, SegmentReport, replay};
    use fingertip_qemu::trace::Trace;
    use fingertip_qemu::{ApproachTick, CONFIG_SOURCE, IMAGE, TRACE, TRACE_SOURCE};

    /// One whole tick as the firmware runs it: the tick generated for the configuration.
    /// A root of the forbidden-helper check.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_tick(
        _detector: &Detector,
        state: &mut State,
        now: Tick,
        inputs: &Inputs,
        out: &mut Output,
    ) {
        ApproachTick.tick_into(state, now, inputs, out);
    }

    /// One whole tick through the interpreter, `Detector::tick_into`, for comparison. A
    /// root of the forbidden-helper check.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_tick_interpreted(
        detector: &Detector,
        state: &mut State,
        now: Tick,
        inputs: &Inputs,
        out: &mut Output,
    ) {
        DetectorTick::tick_into(detector, state, now, inputs, out);
    }

    /// Stage 1 alone: samples in, features updated.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_update_features(state: &mut State, inputs: &Inputs) {
        ApproachTick.update_features(state, inputs);
    }

    /// Stage 2 alone: every term's confidence distribution function.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_term_confidences(state: &mut State, faults: ChannelMask, out: &mut Output) {
        ApproachTick.term_confidences(state, faults, out);
    }

    /// Stage 3 alone: eq. 14 per event.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_combine(state: &State, out: &mut Output) {
        ApproachTick.combine(state, out);
    }

    /// Stage 4 alone: decision levels and onsets.
    #[unsafe(no_mangle)]
    #[inline(never)]
    pub fn fingertip_decide(state: &mut State, now: Tick, out: &mut Output) {
        ApproachTick.decide(state, now, out);
    }

    /// Calibration: exactly `N` instructions between call and return, besides the call
    /// overhead shared with [`nops_0`].
    #[inline(never)]
    fn nops_4096() {
        // SAFETY: `nop`s touch no register, flag or memory.
        unsafe {
            core::arch::asm!(
                ".rept 4096",
                "nop",
                ".endr",
                options(nomem, nostack, preserves_flags)
            )
        }
    }

    #[inline(never)]
    fn nops_256() {
        // SAFETY: as above.
        unsafe {
            core::arch::asm!(
                ".rept 256",
                "nop",
                ".endr",
                options(nomem, nostack, preserves_flags)
            )
        }
    }

    #[inline(never)]
    fn nops_0() {
        // SAFETY: an empty block, kept so the call is not optimized away.
        unsafe { core::arch::asm!("", options(nomem, nostack, preserves_flags)) }
    }

    /// Times a call through a function pointer, so that every calibration block is
    /// measured by the very same instructions and only the block differs.
    #[inline(never)]
    fn measure(f: fn()) -> u32 {
        timed(f).1
    }

    /// SysTick counts down from 2^24 - 1 and wraps; a measurement must stay below one
    /// period (655 360 instructions at 25.6 counts per instruction).
    #[inline(always)]
    fn timed<R>(f: impl FnOnce() -> R) -> (R, u32) {
        compiler_fence(Ordering::SeqCst);
        let t0 = SYST::get_current();
        compiler_fence(Ordering::SeqCst);
        let r = f();
        compiler_fence(Ordering::SeqCst);
        let t1 = SYST::get_current();
        compiler_fence(Ordering::SeqCst);
        (r, t0.wrapping_sub(t1) & 0x00FF_FFFF)
    }

    /// Converts SysTick counts to instructions.
    struct Meter {
        /// SysTick counts for `nops` instructions.
        counts: u64,
        nops: u64,
        /// Instructions of an empty measurement (two SysTick reads).
        overhead: u32,
    }

    impl Meter {
        fn calibrate() -> Meter {
            let big = measure(nops_4096);
            let empty = measure(nops_0);
            let mut m = Meter {
                counts: u64::from(big.saturating_sub(empty)).max(1),
                nops: 4096,
                overhead: 0,
            };
            let ((), bare) = timed(|| ());
            m.overhead = m.raw(bare);
            m
        }

        fn raw(&self, counts: u32) -> u32 {
            ((u64::from(counts) * self.nops + self.counts / 2) / self.counts) as u32
        }

        fn insns(&self, counts: u32) -> u32 {
            self.raw(counts).saturating_sub(self.overhead)
        }
    }

    #[derive(Clone, Copy)]
    struct Stats {
        sum: u64,
        n: u32,
        min: u32,
        max: u32,
        max_at: Position,
    }

    impl Stats {
        const fn new() -> Stats {
            Stats {
                sum: 0,
                n: 0,
                min: u32::MAX,
                max: 0,
                max_at: Position {
                    segment: 0,
                    record: 0,
                },
            }
        }

        fn add(&mut self, v: u32, at: Position) {
            self.sum += u64::from(v);
            self.n += 1;
            self.min = self.min.min(v);
            if v > self.max {
                self.max = v;
                self.max_at = at;
            }
        }

        fn print(&self, name: &str) {
            let hundredths = self.sum * 100 / u64::from(self.n.max(1));
            hprintln!(
                "insns {}: mean={}.{:02} min={} max={} max_at={}:{} n={}",
                name,
                hundredths / 100,
                hundredths % 100,
                if self.n == 0 { 0 } else { self.min },
                self.max,
                self.max_at.segment,
                self.max_at.record,
                self.n
            );
        }
    }

    /// Replays the trace through a whole-tick function, counting each call's instructions
    /// into `stats`.
    fn timed_replay<'a>(
        detector: &Detector,
        trace: &Trace<'a>,
        meter: &Meter,
        tick: fn(&Detector, &mut State, Tick, &Inputs, &mut Output),
        stats: &mut Stats,
        on_segment: impl FnMut(&SegmentReport<'a>),
    ) -> Digest {
        let mut out = Output::default();
        replay(
            detector,
            trace,
            |state, now, inputs, at| {
                let ((), c) = timed(|| tick(detector, state, now, inputs, &mut out));
                stats.add(meter.insns(c), at);
                out.clone()
            },
            on_segment,
        )
    }

    fn fail(what: &dyn core::fmt::Display) -> ! {
        hprintln!("error: {}", what);
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }

    #[entry]
    fn main() -> ! {
        let Some(mut p) = cortex_m::Peripherals::take() else {
            fail(&"peripherals taken twice")
        };
        p.SYST.set_clock_source(SystClkSource::Core);
        p.SYST.set_reload(0x00FF_FFFF);
        p.SYST.clear_current();
        p.SYST.enable_counter();

        let detector = match fingertip_qemu::detector() {
            Ok(d) => d,
            Err(e) => fail(&e),
        };
        let trace = match Trace::parse(TRACE) {
            Ok(t) => t,
            Err(e) => fail(&e),
        };
        let mut image_crc = Crc32::new();
        image_crc.update(IMAGE);
        hprintln!(
            "fingertip-qemu config={} image_crc={:08x} trace={} segments={} ticks={} channels={} features={} events={} state_in_ram={} state_saved={}",
            CONFIG_SOURCE,
            image_crc.value(),
            TRACE_SOURCE,
            trace.segment_count(),
            trace.ticks(),
            detector.channels().len(),
            detector.features().len(),
            detector.events().len(),
            State::SIZE,
            State::SAVED_BYTES
        );

        let meter = Meter::calibrate();
        // A self-check of the method: a block of 256 `nop`s must count as 256.
        let check = meter
            .raw(measure(nops_256))
            .wrapping_sub(meter.raw(measure(nops_0)));
        hprintln!(
            "calibration nops={} counts={} overhead={} check256={}",
            meter.nops,
            meter.counts,
            meter.overhead,
            check
        );

        let mut tick = Stats::new();
        let digest = timed_replay(&detector, &trace, &meter, fingertip_tick, &mut tick, |r| {
            hprintln!(
                "{}",
                SegmentLine {
                    report: r,
                    detector: &detector
                }
            );
        });
        hprintln!("digest tick: {}", digest);

        let mut stages = [Stats::new(); 5];
        let staged = replay(
            &detector,
            &trace,
            |state, now, inputs, at| {
                let mut out = Output::default();
                let ((), a) = timed(|| fingertip_update_features(state, inputs));
                let ((), b) = timed(|| fingertip_term_confidences(state, inputs.faults, &mut out));
                let ((), c) = timed(|| fingertip_combine(state, &mut out));
                let ((), d) = timed(|| fingertip_decide(state, now, &mut out));
                let parts = [a, b, c, d].map(|c| meter.insns(c));
                for (s, v) in stages.iter_mut().zip(parts) {
                    s.add(v, at);
                }
                stages[4].add(parts.iter().sum(), at);
                out
            },
            |_| {},
        );
        hprintln!("digest stages: {}", staged);

        let mut interpreted = Stats::new();
        let digest = timed_replay(
            &detector,
            &trace,
            &meter,
            fingertip_tick_interpreted,
            &mut interpreted,
            |_| {},
        );
        hprintln!("digest interpreted: {}", digest);

        // A flight recorder saves the detector's state once per segment: its cost, the
        // same for any state (every field is written).
        let mut saved = [0u8; State::SAVED_BYTES];
        let state = detector.new_state();
        let mut save = Stats::new();
        for record in 0..8 {
            let ((), c) = timed(|| state.save(core::hint::black_box(&mut saved)));
            save.add(meter.insns(c), Position { segment: 0, record });
        }
        core::hint::black_box(&saved);

        tick.print("tick");
        interpreted.print("interpreted");
        save.print("state_save");
        for (s, name) in
            stages
                .iter()
                .zip(["features", "confidences", "combine", "decide", "stages_sum"])
        {
            s.print(name);
        }
        hprintln!("done");
        debug::exit(debug::EXIT_SUCCESS);
        #[allow(clippy::empty_loop)]
        loop {}
    }

    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        hprintln!("error: hard fault at pc={:#010x}", frame.pc());
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }

    /// Reports the location and exits with a failure. Written without `core::fmt`: a panic
    /// path is reachable from the tick (a division the compiler cannot prove nonzero), and
    /// formatting would put indirect calls on it, which the host test's call-graph check
    /// cannot follow.
    #[panic_handler]
    fn panic(info: &PanicInfo) -> ! {
        if let Ok(mut out) = cortex_m_semihosting::hio::hstdout() {
            let _ = out.write_all(b"error: panic");
            if let Some(l) = info.location() {
                let _ = out.write_all(b" at ");
                let _ = out.write_all(l.file().as_bytes());
                let _ = out.write_all(b":");
                // The line number in decimal, most significant digit first.
                let mut digits = [b'0'; 10];
                let mut n = l.line();
                let mut len = 0;
                for d in digits.iter_mut().rev() {
                    *d = b'0' + (n % 10) as u8;
                    n /= 10;
                    len += 1;
                    if n == 0 {
                        break;
                    }
                }
                if let Some(text) = digits.get(digits.len() - len..) {
                    let _ = out.write_all(text);
                }
            }
            let _ = out.write_all(b"\n");
        }
        debug::exit(debug::EXIT_FAILURE);
        #[allow(clippy::empty_loop)]
        loop {}
    }
}

#[cfg(not(target_os = "none"))]
fn main() -> std::process::ExitCode {
    use fingertip_qemu::replay::{SegmentLine, plain_tick, replay, staged_tick};
    use fingertip_qemu::trace::Trace;

    let detector = match fingertip_qemu::detector() {
        Ok(d) => d,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    let trace = match Trace::parse(fingertip_qemu::TRACE) {
        Ok(t) => t,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    println!(
        "fingertip-qemu (host) config={} trace={} segments={} ticks={}",
        fingertip_qemu::CONFIG_SOURCE,
        fingertip_qemu::TRACE_SOURCE,
        trace.segment_count(),
        trace.ticks()
    );
    let mut tick = plain_tick(&detector);
    let digest = replay(
        &detector,
        &trace,
        |s, n, i, p| tick(s, n, i, p),
        |r| {
            println!(
                "{}",
                SegmentLine {
                    report: r,
                    detector: &detector
                }
            )
        },
    );
    println!("digest tick: {digest}");
    let staged = replay(
        &detector,
        &trace,
        |s, n, i, _| staged_tick(&detector, s, n, i),
        |_| {},
    );
    println!("digest stages: {staged}");
    std::process::ExitCode::SUCCESS
}
