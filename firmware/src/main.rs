//! The board binary: clocks, peripherals and the embassy tasks around the lib.
//!
//! Tasks, each owning its peripheral and talking through its handle on the [`Shared`]
//! state (what it writes, it owns):
//! - `detector_task`, on an interrupt executor above every other task: TIM6 triggers an
//!   ADC1 scan every detector tick into a DMA ring of two scans; the DMA's interrupt
//!   counts the scans from its position ([`ScanProgress`]) and wakes the task, which reads
//!   the newest scan, calibrates it and runs one [`Service::tick`] on it (the engine, or
//!   the fallback when the embedded detector cannot run); its frames go straight to the
//!   transmit path ([`TxScheduler`]) and into the FDCAN's buffers; it measures each tick's
//!   computation and lateness with the DWT cycle counter;
//! - `temperature`: the TMP117 over I2C2, four times a second; publishes the temperature;
//! - `can_rx`, `can_supervisor`: FDCAN1 (CAN FD at 1 and 5 Mbit/s), the receive path,
//!   bus-off recovery and the flush of stale frames; the FDCAN's interrupt pumps the
//!   transmit path as buffers free up;
//! - `watchdog_task`: refreshes the IWDG while scans arrive and ticks complete.
//!
//! The CAN, temperature and watchdog tasks run on the thread executor, below the
//! detector: none of them can hold a tick back.
//!
//! Everything worth testing lives in the lib; this file is wiring, and `regs` holds its
//! raw register accesses.

#![no_std]
#![no_main]

mod regs;

use core::num::{NonZeroU8, NonZeroU16};

use core::cell::UnsafeCell;
use cortex_m::peripheral::DWT;
use cortex_m::peripheral::SCB;
use cortex_m_rt::{ExceptionFrame, entry, exception};
use defmt::{error, info, warn};

use defmt_rtt as _;
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_executor::{Executor, InterruptExecutor, Spawner};
use embassy_futures::block_on;
use embassy_futures::select::{Either, select};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, RingBufferedAdc, SampleTime};
use embassy_stm32::can::{self, CanConfigurator, CanRx, Properties};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Input, Pull};
use embassy_stm32::i2c::{self, I2c, Master};
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::mode::Async;
use embassy_stm32::peripherals::{ADC1, DMA1_CH1, DMA1_CH2, DMA1_CH3, FDCAN1, I2C2, IWDG, TIM6};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{RoundTo, Timer};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, dma, interrupt};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Delay, Duration, Instant, Ticker};
use static_cell::{ConstStaticCell, StaticCell};

use core::cell::{Cell, RefCell};
use detector_core::Detector;
use detector_core::Tick;
use fingertip_can::service::{CrashKind, CrashReport};
use fingertip_can::{BusFormat, CanFrame, NodeId, Receiver};
use firmware::boot::{self, ApproachTick};
use firmware::crash::CrashRecord;
use firmware::engine::{BoardInfo, Service, TickRunner};
use firmware::load::Loader;
use firmware::node_id::{self, NodeIdError};
use firmware::nvm::{BootImage, Nvm, SLOT_IMAGE_MAX};
use firmware::recorder::RecorderCell;
use firmware::sampling::{DMA_LEN, DMA_SCANS, FrontEnd, SCAN_LEN, ScanPicker, ScanProgress};
use firmware::service_end::{Mailbox, Requests, ServiceEnd};
use firmware::shared::{
    BusHandle, CanRxHandle, DetectorHandle, Handles, RawMutex, SamplerHandle, Shared,
    TemperatureHandle, WatchdogHandle,
};
use firmware::supervise::{BusAction, BusSupervisor, Task};
use firmware::timing::budget_cycles;
use firmware::tmp117::{self, SensorHealth, Tmp117};
use firmware::txqueue::TxScheduler;
use firmware::wiring::CORE_CLOCK_HZ;
use firmware::{calib, can_timing, reset};

bind_interrupts!(struct Irqs {
    DMA1_CHANNEL1 => dma::InterruptHandler<DMA1_CH1>, ScanIrq;
    DMA1_CHANNEL2 => dma::InterruptHandler<DMA1_CH2>;
    DMA1_CHANNEL3 => dma::InterruptHandler<DMA1_CH3>;
    I2C2_EV => i2c::EventInterruptHandler<I2C2>;
    I2C2_ER => i2c::ErrorInterruptHandler<I2C2>;
    FDCAN1_IT0 => can::IT0InterruptHandler<FDCAN1>, TxPump;
    FDCAN1_IT1 => can::IT1InterruptHandler<FDCAN1>;
});

/// The DMA's circular buffer of two scans. Handed to the HAL once, which runs the DMA on
/// it and never reads it (its `read` is never called); the detector task reads each scan
/// from it with volatile loads while the DMA writes the other slot.
struct DmaBuffer(UnsafeCell<[u16; DMA_LEN]>);

// SAFETY: the DMA writes it and the detector task reads it, each in its own slot at a time
// (`ScanPicker::torn` catches a read the DMA overtook); no reference to it is used after
// the HAL takes it at boot.
unsafe impl Sync for DmaBuffer {}

static ADC_DMA: DmaBuffer = DmaBuffer(UnsafeCell::new([0; DMA_LEN]));

/// The DMA's progress, counted in scans by its interrupt: the detector's tick numbers.
static SCANS: ScanProgress = ScanProgress::new();
/// Raised by the DMA's interrupt when a scan completes; the detector task waits on it.
static SCAN_READY: Signal<RawMutex, ()> = Signal::new();

/// Counts the scans from the DMA's position at each of its interrupts (bound after the
/// HAL's handler, which acknowledges them), and wakes the detector.
struct ScanIrq;

impl interrupt::typelevel::Handler<interrupt::typelevel::DMA1_CHANNEL1> for ScanIrq {
    unsafe fn on_interrupt() {
        if SCANS.on_dma(regs::adc_dma_remaining(), DWT::cycle_count()) {
            SCAN_READY.signal(());
        }
    }
}

/// The detector's executor, run from an interrupt the board does not otherwise use
/// (UART4), at a priority below the DMA's and the FDCAN's interrupts and above every
/// thread-mode task.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();
/// Its priority.
const DETECTOR_PRIORITY: Priority = Priority::P1;

#[interrupt]
unsafe fn UART4() {
    // SAFETY: UART4's vector belongs to the executor alone (the board has no UART4).
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

/// The transmit path: the detector task queues each tick's frames and fills the FDCAN's
/// buffers, the FDCAN's interrupt refills them as they free up, the supervisor flushes it
/// after bus-off. Held for the few microseconds of a push or a pump.
static TX: Mutex<RawMutex, RefCell<TxScheduler>> = Mutex::new(RefCell::new(TxScheduler::new()));

/// Pumps the transmit path from the FDCAN's interrupt (bound after the HAL's handler):
/// a frame went out, or a cancellation finished.
struct TxPump;

impl interrupt::typelevel::Handler<interrupt::typelevel::FDCAN1_IT0> for TxPump {
    unsafe fn on_interrupt() {
        regs::clear_cancel_interrupt();
        TX.lock(|t| t.borrow_mut().pump(&mut regs::FdcanTx));
    }
}

/// A service-channel frame: its data and length.
type ServiceFrame = ([u8; 64], u8);

/// The spare detector a detector received over the bus is checked into.
static SPARE: ConstStaticCell<Detector> = ConstStaticCell::new(Detector::empty());
/// Where the service task and the detector task meet.
static MAILBOX: Mailbox<'static> = Mailbox::new();
/// The flight recorder: written by the detector task, read out by the service task.
static RECORDER: RecorderCell = RecorderCell::new();
/// The service channel's end (its reassembly buffer is 8 KiB): in a static, made at boot
/// (a `const` one would be 8 KiB of initialized data in flash).
static SERVICE_END: StaticCell<ServiceEnd> = StaticCell::new();
/// Frames on this node's request identifier, from the receive task to the service task.
/// Full, a frame is dropped: the transfer breaks and the tool sends it again.
static SERVICE_FRAMES: Channel<RawMutex, ServiceFrame, 4> = Channel::new();
/// The receiver the receive task uses: a detector loaded at run time may have another
/// phase count. Written by the detector task when it changes.
static RECEIVER: Mutex<RawMutex, Cell<Option<Receiver>>> = Mutex::new(Cell::new(None));

static EXECUTOR: StaticCell<Executor> = StaticCell::new();
/// The detector, empty until boot loads the embedded image into it, in place (in .bss).
static DETECTOR: ConstStaticCell<Detector> = ConstStaticCell::new(Detector::empty());
static SHARED: StaticCell<Shared> = StaticCell::new();
static SERVICE: StaticCell<Service<'static, ApproachTick>> = StaticCell::new();

/// IWDG period: four missed 50 ms rounds of the watchdog task.
const WATCHDOG_TIMEOUT_US: u32 = 200_000;
/// How often the watchdog task looks for the critical tasks' check-ins.
const WATCHDOG_ROUND: Duration = Duration::from_millis(50);
/// Temperature reading period: a dead sensor is noticed within 0.75 s (it converts once
/// a second, so most readings repeat the last value).
const TEMPERATURE_PERIOD: Duration = Duration::from_millis(250);
/// I2C transaction timeout: a 4-byte transaction takes under 0.5 ms at 100 kHz.
const I2C_TIMEOUT_MS: u32 = 5;
/// The temperature sensor is faulty after this many failed readings in a row.
const SENSOR_TRIP: u8 = 3;
/// CAN error-state polling period.
const CAN_SUPERVISOR_PERIOD: Duration = Duration::from_millis(2);
/// The CAN bit rate of the arbitration phase.
const CAN_BITRATE: u32 = 1_000_000;
/// The CAN FD data-phase bit rate (bit-rate switching).
const CAN_DATA_BITRATE: u32 = 5_000_000;
/// The FDCAN kernel clock: PLL Q, see [`clocks`].
const CAN_CLOCK_HZ: u32 = 85_000_000;
/// The bit timing: 85 quanta of one kernel clock, sample point at 87 % (CiA recommends
/// 87.5 %), computed at compile time (a clock that cannot make the rate fails the build).
const CAN_TIMING: can_timing::BitTiming = match can_timing::nominal(CAN_CLOCK_HZ, CAN_BITRATE, 875)
{
    Ok(t) => t,
    Err(_) => panic!("the FDCAN clock cannot make the CAN bit rate"),
};
/// The data phase: the nominal time quantum, 17 quanta per bit at 5 Mbit/s, sample point
/// at 76 %.
const CAN_DATA_TIMING: can_timing::BitTiming =
    match can_timing::data(CAN_CLOCK_HZ, CAN_DATA_BITRATE, CAN_TIMING.prescaler, 750) {
        Ok(t) => t,
        Err(_) => panic!("the FDCAN clock cannot make the CAN FD data rate"),
    };

/// Clocks: 24 MHz crystal (the fingertip board and the NUCLEO-G474RE alike) / 6 × 85 =
/// 340 MHz VCO; R / 2 = 170 MHz SYSCLK (boost mode); Q / 4 = 85 MHz for the FDCAN
/// (85 time quanta per bit at 1 Mbit/s, 17 at 5 Mbit/s); the ADC runs from SYSCLK,
/// divided to 42.5 MHz by the HAL. Without the crystal (`crystal` false: it did not
/// start), the internal 16 MHz oscillator / 4 × 85 gives the same frequencies, within its
/// ±1 % (outside the CAN FD data phase's tolerance: the status says so).
fn clocks(crystal: bool) -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    let (source, prediv) = if crystal {
        config.rcc.hse = Some(Hse {
            freq: Hertz(24_000_000),
            mode: HseMode::Oscillator,
        });
        (PllSource::HSE, PllPreDiv::DIV6)
    } else {
        config.rcc.hsi = true;
        (PllSource::HSI, PllPreDiv::DIV4)
    };
    config.rcc.pll = Some(Pll {
        source,
        prediv,
        mul: PllMul::MUL85,
        divp: None,
        divq: Some(PllQDiv::DIV4),
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = true;
    config.rcc.mux.fdcansel = mux::Fdcansel::PLL1_Q;
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    config
}

/// Spawns a task, or stops with its name: a task that cannot start (its one pool slot
/// taken) is a programming error found at the first boot.
macro_rules! spawn {
    ($spawner:expr, $task:ident($($arg:expr),* $(,)?)) => {
        match $task($($arg),*) {
            Ok(token) => $spawner.spawn(token),
            Err(_) => defmt::panic!("cannot spawn task {=str}", stringify!($task)),
        }
    };
}

/// Everything the tasks get, set up before the executor starts.
struct Board {
    service: &'static mut Service<'static, ApproachTick>,
    handles: Handles<'static>,
    rate_hz: u32,
    /// `None` in the fallback, which reads nothing: the receive task is not started.
    receiver: Option<Receiver>,
    adc: RingBufferedAdc<'static, ADC1>,
    timer: Timer<'static, TIM6>,
    front_end: FrontEnd,
    sensor: Tmp117<I2c<'static, Async, Master>, Delay>,
    can_rx: CanRx<'static>,
    can_properties: Properties,
    watchdog: IndependentWatchdog<'static, IWDG>,
    /// The service channel's handler: the loader, the flash.
    requests: Requests<'static, 'static, BoardFlash>,
    node: NodeId,
}

/// The crash record, in RAM a reset leaves alone (`.uninit`): written by the panic and
/// hard-fault handlers, read and cleared at boot ([`firmware::crash`]).
#[unsafe(link_section = ".uninit.CRASH")]
static mut CRASH: core::mem::MaybeUninit<CrashRecord> = core::mem::MaybeUninit::uninit();

/// Keeps `report` in the crash record and resets. Interrupts off: nothing else runs.
fn crash(report: &CrashReport) -> ! {
    cortex_m::interrupt::disable();
    // SAFETY: interrupts are off and this never returns: the record's one user now.
    unsafe { (*core::ptr::addr_of_mut!(CRASH)).write(CrashRecord::empty()) }.write(report);
    SCB::sys_reset()
}

/// The crash kept by the last run, if any, and the record cleared.
fn last_crash() -> Option<CrashReport> {
    // SAFETY: read once at boot, before any task or handler that writes it runs. After a
    // power-on the RAM holds whatever pattern it came up with: every pattern is a valid
    // array of words, and the magic and CRC-32 refuse all but a record.
    let record = unsafe { &mut *core::ptr::addr_of_mut!(CRASH).cast::<CrashRecord>() };
    let crash = record.read();
    record.clear();
    crash
}

/// A panic: its place and message kept for the next boot (the service channel's
/// LastCrash), logged, and a reset.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    use core::fmt::Write as _;
    let mut report = CrashReport::new(CrashKind::Panic, 0);
    if let Some(at) = info.location() {
        let file = at.file().rsplit('/').next().unwrap_or("");
        let _ = write!(report, "{file}:{}: ", at.line());
    }
    let _ = write!(report, "{}", info.message());
    error!("panic: {=str}", report.message.as_str());
    crash(&report)
}

/// A hard fault: where it happened kept for the next boot, and a reset.
#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    crash(&CrashReport::new(CrashKind::HardFault, frame.pc()))
}

/// The clock security system saw the crystal stop: the core fell back to the internal
/// oscillator and the PLL stopped, so no timing holds. Start over: the boot's probe finds
/// the crystal dead and runs from the internal oscillator (`FaultClockFallback`).
#[exception]
unsafe fn NonMaskableInt() {
    regs::clear_clock_failure();
    SCB::sys_reset();
}

/// The strap pins' levels, bit `i` strap `i` (PB4 + i), high when open: read with the
/// pull-ups on, which are switched off again (a tied strap would draw through them).
fn read_straps(pins: [Input<'_>; node_id::STRAPS]) -> u8 {
    // The pull-ups charge the pins' capacitance in well under 10 µs.
    cortex_m::asm::delay(CORE_CLOCK_HZ / 100_000);
    pins.iter()
        .enumerate()
        .fold(0, |v, (i, p)| v | (u8::from(p.is_high()) << i))
}

/// No node id: the board stays off the bus (any id it picked could be another finger's)
/// and says why, once a second, on its debug log. The watchdog is not running yet.
fn without_node_id(e: NodeIdError) -> ! {
    loop {
        error!(
            "{}: not joining the bus; strap the node id (see the wiring table)",
            e
        );
        cortex_m::asm::delay(CORE_CLOCK_HZ);
    }
}

#[entry]
fn main() -> ! {
    // `main` never returns and the executor runs inside its frame: keep that frame small
    // and do the heavy set-up (the detector's construction above all) in a function
    // whose frame is gone before the tasks run.
    let b = setup();
    let Handles {
        sampler,
        detector,
        temperature: sensor_handle,
        can_rx: can_rx_handle,
        bus,
        watchdog,
    } = b.handles;
    interrupt::UART4.set_priority(DETECTOR_PRIORITY);
    let high = EXECUTOR_HIGH.start(interrupt::UART4);
    spawn!(
        high,
        detector_task(
            b.service,
            Scans {
                adc: b.adc,
                timer: b.timer,
                front_end: b.front_end,
                handle: sampler,
            },
            detector,
            b.rate_hz,
        )
    );
    let executor = EXECUTOR.init(Executor::new());
    executor.run(move |spawner: Spawner| {
        spawn!(spawner, temperature(b.sensor, sensor_handle));
        if let Some(receiver) = b.receiver {
            spawn!(spawner, can_rx(b.can_rx, receiver, can_rx_handle, b.node));
        }
        spawn!(
            spawner,
            service_task(SERVICE_END.init_with(ServiceEnd::new), b.requests, b.node)
        );
        spawn!(spawner, can_supervisor(b.can_properties, bus));
        spawn!(spawner, watchdog_task(b.watchdog, watchdog));
    })
}

/// Clocks, the detector, the peripherals.
#[inline(never)]
fn setup() -> Board {
    // The reset reason, read before the HAL touches the RCC, and cleared so the next
    // boot reports its own; and why the last run stopped, when it could tell.
    let reset = reset::reset_reason(regs::take_reset_flags());
    let crashed = last_crash();
    if let Some(c) = &crashed {
        error!(
            "the last run stopped: {=str} at {=u32:#010x}: {=str}",
            c.kind.name(),
            c.pc,
            c.message.as_str()
        );
    }
    // A dead crystal must not hang the boot before the watchdog runs: probe it with a
    // timeout first, and fall back to the internal oscillator.
    let crystal = regs::hse_starts();
    let p = embassy_stm32::init(clocks(crystal));
    if crystal {
        regs::enable_clock_security();
    } else {
        warn!("the crystal did not start: running from the internal oscillator");
    }
    // What the board keeps in flash: its node id, its calibration, a saved detector. A
    // store that cannot be read leaves the straps, the nominal calibration and the
    // built-in detector.
    let mut nvm: BoardNvm = Nvm::new(BlockingAsync::new(Flash::new_blocking(p.FLASH)));
    let stored_node = block_on(nvm.node_id()).unwrap_or_else(|e| {
        error!("flash store: {}: node id from the straps", e);
        None
    });
    // The node id, at run time: one image serves every finger; the store's first.
    let straps = read_straps([
        Input::new(p.PB4, Pull::Up),
        Input::new(p.PB5, Pull::Up),
        Input::new(p.PB6, Pull::Up),
        Input::new(p.PB7, Pull::Up),
    ]);
    let (node, node_source) = match node_id::resolve(stored_node, straps) {
        Ok(found) => found,
        Err(e) => without_node_id(e),
    };
    info!(
        "fingertip node {=u8} (from its {=str}), reset: {=str}, config {=str} crc32 {=u32:#010x}, {=str}",
        node.get(),
        node_source.name(),
        reset.name(),
        boot::CONFIG_SOURCE,
        boot::CONFIG_CHECKSUM,
        boot::BUS_FORMAT.name()
    );
    let board = BoardInfo {
        node,
        node_source,
        format: boot::BUS_FORMAT,
        reset,
        clock_fallback: !crystal,
    };

    regs::freeze_watchdog_when_halted();

    // The cycle counter that times the detector's ticks.
    let Some(mut core) = cortex_m::Peripherals::take() else {
        defmt::panic!("core peripherals already taken");
    };
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();

    // The detector before anything else is built on the stack: loading the image is the
    // deepest stack of the firmware.
    let service = build_detector(board, &mut nvm);
    let calibration = match block_on(nvm.calibration(&calib::NOMINAL)) {
        Ok((c, refused)) => {
            if !refused.is_empty() {
                error!(
                    "flash store: the calibration of channels {=u32:#06b} is not one: nominal kept",
                    refused.bits()
                );
            }
            c
        }
        Err(e) => {
            error!("flash store: {}: nominal calibration", e);
            calib::NOMINAL
        }
    };
    let rate_hz = service.rate_hz();
    match service.fallback_reason() {
        None => info!("detector in service"),
        Some(reason) => error!(
            "{}: detector out of service, heartbeats only (FaultConfigFallback)",
            reason
        ),
    }
    let receiver = service.receiver();
    let handles = SHARED.init_with(Shared::new).split();

    // ADC1: the four analog channels, one scan per TIM6 update, circular DMA over two
    // scans (an interrupt per scan).
    let adc = Adc::new(p.ADC1, AdcConfig::default());
    let sequence = [
        (p.PA0.degrade_adc(), SampleTime::CYCLES47_5), // force_x
        (p.PA1.degrade_adc(), SampleTime::CYCLES47_5), // force_y
        (p.PB0.degrade_adc(), SampleTime::CYCLES47_5), // skin_accel
        (p.PB1.degrade_adc(), SampleTime::CYCLES47_5), // stress_rate
    ];
    // SAFETY: the only reference to the buffer ever made; see `DmaBuffer`.
    let dma_buffer: &'static mut [u16; DMA_LEN] = unsafe { &mut *ADC_DMA.0.get() };
    let ring = adc.into_ring_buffered(
        p.DMA1_CH1,
        dma_buffer,
        Irqs,
        sequence.into_iter(),
        embassy_stm32::triggers::TIM6_TRGO,
        embassy_stm32::adc::Exten::RISING_EDGE,
    );
    let timer = Timer::new(p.TIM6);
    // The period for the configuration's rate, computed and checked by build.rs.
    timer.set_period_clocks(u64::from(boot::TRIGGER_CLOCKS), RoundTo::Slower);
    // Load the prescaler now (it is buffered until an update), before TRGO is routed to
    // the ADC so this update triggers nothing.
    timer.generate_update_event();
    regs::trigger_on_update(&timer);
    info!(
        "sampling at {=u64} mHz ({=u32} timer clocks), budget {=u32} cycles per tick",
        boot::TRIGGER_RATE_MHZ,
        boot::TRIGGER_CLOCKS,
        budget_cycles(CORE_CLOCK_HZ, rate_hz)
    );

    // I2C2 for the TMP117.
    let i2c = I2c::new(
        p.I2C2,
        p.PA9,
        p.PA8,
        p.DMA1_CH2,
        p.DMA1_CH3,
        Irqs,
        i2c::Config::default(),
    );
    let sensor = Tmp117::new(i2c, Delay, tmp117::DEFAULT_ADDRESS, I2C_TIMEOUT_MS);

    // FDCAN1, CAN FD at 1 Mbit/s arbitration and 5 Mbit/s data (or classic CAN at
    // 1 Mbit/s). Only this node's receive identifiers are accepted, in hardware; bus-off
    // recovery is the supervisor's (with back-off), not the HAL's immediate one.
    let mut can = CanConfigurator::new(p.FDCAN1, p.PA11, p.PA12, Irqs);
    let field = |v: u8| NonZeroU8::new(v).unwrap_or(NonZeroU8::MIN);
    let prescaler = |v: u16| NonZeroU16::new(v).unwrap_or(NonZeroU16::MIN);
    let config = can
        .config()
        .set_nominal_bit_timing(can::config::NominalBitTiming {
            prescaler: prescaler(CAN_TIMING.prescaler),
            seg1: field(CAN_TIMING.seg1),
            seg2: field(CAN_TIMING.seg2),
            sync_jump_width: field(CAN_TIMING.sjw),
        })
        .set_automatic_bus_off_recovery(false)
        .set_global_filter(can::config::GlobalFilter::reject_all());
    can.set_config(match boot::BUS_FORMAT {
        BusFormat::Fd => config
            .set_data_bit_timing(can::config::DataBitTiming {
                transceiver_delay_compensation: true,
                prescaler: prescaler(CAN_DATA_TIMING.prescaler),
                seg1: field(CAN_DATA_TIMING.seg1),
                seg2: field(CAN_DATA_TIMING.seg2),
                sync_jump_width: field(CAN_DATA_TIMING.sjw),
            })
            .set_frame_transmit(can::config::FrameTransmissionConfig::AllowFdCanAndBRS),
        BusFormat::Classic => {
            config.set_frame_transmit(can::config::FrameTransmissionConfig::ClassicCanOnly)
        }
    });
    info!(
        "CAN FD {=u32}/{=u32} bit/s: {=u32}/{=u32} quanta per bit, sample points {=u32}/{=u32} per mille",
        CAN_BITRATE,
        CAN_DATA_BITRATE,
        CAN_TIMING.quanta(),
        CAN_DATA_TIMING.quanta(),
        CAN_TIMING.sample_point_permille(),
        CAN_DATA_TIMING.sample_point_permille()
    );
    if let Some(r) = &receiver {
        use can::filter::{Action, FilterType, StandardFilter, StandardFilterSlot};
        let [phase, context, part] = r.identifiers().map(|raw| {
            fingertip_can::StandardId::new(raw).unwrap_or(fingertip_can::StandardId::ZERO)
        });
        can.properties().set_standard_filter(
            StandardFilterSlot::_0,
            StandardFilter {
                filter: FilterType::DedicatedDual(phase, context),
                action: Action::StoreInFifo0,
            },
        );
        can.properties().set_standard_filter(
            StandardFilterSlot::_1,
            StandardFilter {
                filter: FilterType::DedicatedDual(part, fingertip_can::service_request_id(node)),
                action: Action::StoreInFifo0,
            },
        );
    }
    let can = can.into_normal_mode();
    // The HAL never enables transceiver delay compensation (writing the data bit timing
    // clears it); the 200 ns data bit at 5 Mbit/s is shorter than the transceiver's loop
    // delay, so the FDCAN must sample its own bits at a secondary point: set by register,
    // now that the controller is configured.
    if boot::BUS_FORMAT == BusFormat::Fd {
        let offset = CAN_DATA_TIMING.tdc_offset();
        if regs::enable_tdc(offset) {
            info!(
                "transceiver delay compensation on, offset {=u8} clocks",
                offset
            );
        } else {
            error!("transceiver delay compensation did not take: the data phase will err");
        }
    }
    let (can_tx_half, can_rx_half, properties) = can.split();
    // The transmit buffers are the transmit path's (`regs::FdcanTx`); the HAL's transmit
    // half stays unused but alive: dropping both halves switches the peripheral off.
    core::mem::forget(can_tx_half);
    regs::enable_cancel_interrupt();

    let watchdog = IndependentWatchdog::new(p.IWDG, WATCHDOG_TIMEOUT_US);

    Board {
        service,
        handles,
        rate_hz,
        receiver,
        adc: ring,
        timer,
        front_end: FrontEnd::new(calibration, rate_hz),
        sensor,
        can_rx: can_rx_half,
        can_properties: properties,
        watchdog,
        requests: Requests::new(
            Loader::new(SPARE.take(), rate_hz as f32),
            &MAILBOX,
            &RECORDER,
            nvm,
        )
        .with_last_crash(crashed),
        node,
    }
}

/// The board's flash, under embedded-storage's async traits.
type BoardFlash = BlockingAsync<Flash<'static, Blocking>>;
/// The board's flash: the detector slots and the store.
type BoardNvm = Nvm<BoardFlash>;

/// The detector task's service: the detector saved in flash, through the interpreter
/// (checked as one received over the bus), or the embedded image's through the generated
/// tick (the CRC of the image actually loaded is checked), or the fallback when the
/// image is rejected or is not the tick's; `FaultConfigFallback` when a saved detector
/// was chosen but cannot run ([`boot::start_saved`]). In a static, not moved into the
/// task: an async task's arguments are stored in its future twice (as arguments and as
/// locals), and the engine is 3 KiB.
#[inline(never)]
fn build_detector(
    board: BoardInfo,
    nvm: &mut BoardNvm,
) -> &'static mut Service<'static, ApproachTick> {
    let detector = DETECTOR.take();
    // The saved image is read onto the boot stack, gone before the tasks run.
    let mut image = [0u8; SLOT_IMAGE_MAX];
    let found = block_on(nvm.boot_image(&mut image)).unwrap_or_else(|e| {
        error!("flash store: {}: the built-in detector", e);
        BootImage::BuiltIn
    });
    let name;
    let saved = match &found {
        BootImage::BuiltIn => boot::Saved::None,
        BootImage::Slot(slot, header) => {
            info!(
                "detector `{=str}` saved in slot {}, crc32 {=u32:#010x}",
                header.name.as_str(),
                slot,
                header.crc
            );
            name = header.name.clone();
            boot::Saved::Image(&image[..header.len as usize], &name)
        }
        BootImage::Fallback => {
            error!("no saved detector is whole: the built-in one (FaultConfigFallback)");
            boot::Saved::Broken
        }
    };
    SERVICE.init_with(|| boot::start_saved(detector, saved, board))
}

/// The reading of the scans: the ADC and its trigger (kept alive for the DMA), the front
/// end, the sampler's handle.
struct Scans {
    adc: RingBufferedAdc<'static, ADC1>,
    timer: Timer<'static, TIM6>,
    front_end: FrontEnd,
    handle: SamplerHandle<'static>,
}

/// Scan `tick` from its slot of the DMA's ring.
fn read_scan(tick: Tick) -> [u16; SCAN_LEN] {
    let base = tick as usize % DMA_SCANS * SCAN_LEN;
    let ptr = ADC_DMA.0.get().cast::<u16>();
    // SAFETY: `base + k` < DMA_LEN; the DMA writes the other slot meanwhile (see
    // `DmaBuffer`), and a torn read is detected and dropped by the caller.
    core::array::from_fn(|k| unsafe { ptr.add(base + k).read_volatile() })
}

/// One tick per scan, as the DMA delivers it: the newest scan (older ones the DMA has
/// overtaken are counted lost), calibrated, then one service tick (the engine, or the
/// fallback's heartbeat) whose frames go into the transmit buffers at once; computation
/// and lateness timed with the DWT cycle counter.
#[embassy_executor::task]
async fn detector_task(
    service: &'static mut Service<'static, ApproachTick>,
    mut scans: Scans,
    mut shared: DetectorHandle<'static>,
    rate_hz: u32,
) {
    let mut runner = TickRunner::new(CORE_CLOCK_HZ, rate_hz);
    let mut picker = ScanPicker::new();
    let mut last_masks = (0u8, 0u8);
    let mut receiver = service.receiver();
    scans.adc.start();
    scans.timer.start();
    loop {
        SCAN_READY.wait().await;
        let Some(tick) = picker.pick(SCANS.completed()) else {
            continue;
        };
        let raw = read_scan(tick);
        let torn = picker.torn(tick, SCANS.completed());
        let h = &mut scans.handle;
        h.set_lost_samples(picker.lost());
        h.check_in();
        if torn {
            continue;
        }
        // What the service task posted: a staged detector, activation, the service
        // state; and what runs, published for it.
        MAILBOX.serve(service);
        scans.front_end.set_temperature(h.temperature());
        let mut sample = scans.front_end.process(tick, &raw);
        sample.converted_at = SCANS.completed_at(tick);
        h.set_rail_episodes(scans.front_end.rail_episodes());
        h.set_stuck_episodes(scans.front_end.stuck_episodes());
        let result = runner.step(service, &sample, &mut shared, DWT::cycle_count, |frames| {
            TX.lock(|t| {
                let mut t = t.borrow_mut();
                let pushed = t.push(frames);
                t.pump(&mut regs::FdcanTx);
                pushed
            })
        });

        // The flight recorder, once the frames are on their way.
        RECORDER.record(service);

        // A detector put in service may have another phase count: the receive task's
        // receiver follows.
        if service.receiver() != receiver {
            receiver = service.receiver();
            RECEIVER.lock(|r| r.set(receiver));
        }

        // Logs, after the timed part.
        let out = &result.output;
        for d in out.decisions.iter() {
            let name = service
                .detector()
                .and_then(|det| det.events().get(usize::from(d.event.0)))
                .map_or("?", |n| n.as_str());
            info!(
                "{=str} {=str} at tick {=u32} (onset {=u32}), confidence {=u16}/32768",
                name,
                d.level.name(),
                d.tick,
                d.onset,
                d.confidence.to_bits()
            );
        }
        let masks = (out.unjudgeable, out.degraded);
        if masks != last_masks {
            warn!(
                "events unjudgeable {=u8:#05b}, degraded {=u8:#05b} (faulty inputs)",
                masks.0, masks.1
            );
            last_masks = masks;
        }
    }
}

/// Reads the TMP117 four times a second; publishes the temperature and the fault.
#[embassy_executor::task]
async fn temperature(
    mut sensor: Tmp117<I2c<'static, Async, Master>, Delay>,
    mut shared: TemperatureHandle<'static>,
) {
    let mut health = SensorHealth::new(SENSOR_TRIP);
    let mut ticker = Ticker::every(TEMPERATURE_PERIOD);
    loop {
        let fault_changed = tmp117::poll_sensor(&mut sensor, &mut health).await;
        shared.publish(&health);
        if fault_changed {
            if health.is_faulty() {
                warn!("temperature sensor not answering: force drift compensation frozen");
            } else {
                info!("temperature sensor back");
            }
        }
        ticker.next().await;
    }
}

/// Hands every received frame to the protocol's receiver, stamped with the detector's tick;
/// the service channel's requests go to the service task.
#[embassy_executor::task]
async fn can_rx(
    mut rx: CanRx<'static>,
    receiver: Receiver,
    mut shared: CanRxHandle<'static>,
    node: NodeId,
) {
    let service = fingertip_can::service_request_id(node);
    loop {
        match rx.read_fd().await {
            Ok(envelope) => {
                let frame = &envelope.frame;
                if *frame.id() == fingertip_can::Id::Standard(service) {
                    let mut data = [0u8; 64];
                    let n = frame.data().len().min(64);
                    data[..n].copy_from_slice(&frame.data()[..n]);
                    let _ = SERVICE_FRAMES.try_send((data, n as u8));
                    continue;
                }
                let receiver = RECEIVER.lock(|r| r.get()).unwrap_or(receiver);
                // The decoding and the CRC outside the lock, which the detector shares:
                // under it, only the counter rule and the new values.
                let decoded = receiver.decode(*frame.id(), frame.data());
                let now = shared.now();
                let result = shared
                    .rx()
                    .with(|state| receiver.accept(state, now, decoded));
                shared.frame_received();
                if let Err(reason) = result {
                    defmt::debug!("frame rejected: {=str}", reason.name());
                }
            }
            Err(_) => shared.protocol_error(),
        }
    }
}

/// Watches the controller's error state; flushes the transmit path when the bus goes off
/// (what was queued is stale by the time it comes back) and lets the controller out of
/// bus-off after a back-off.
#[embassy_executor::task]
async fn can_supervisor(properties: Properties, mut shared: BusHandle<'static>) {
    let mut supervisor = BusSupervisor::new();
    let mut protocol_errors = 0u32;
    let mut ticker = Ticker::every(CAN_SUPERVISOR_PERIOD);
    loop {
        let status = regs::fdcan_status();
        let state = status.state;
        if status.protocol_error {
            protocol_errors = protocol_errors.saturating_add(1);
        }
        let (events, bus_offs) = (supervisor.error_events(), supervisor.bus_off());
        let action = supervisor.poll(Instant::now().as_millis(), state);
        if supervisor.bus_off() != bus_offs {
            TX.lock(|t| t.borrow_mut().flush(&mut regs::FdcanTx));
        }
        if action == BusAction::Recover {
            regs::fdcan_recover();
        }
        if supervisor.error_events() != events {
            shared.bus_error();
            warn!(
                "CAN {}: tx errors {=u8}, rx errors {=u8}",
                state,
                properties.tx_error_count(),
                properties.rx_error_count()
            );
        }
        shared.set_bus_off(supervisor.bus_off());
        shared.set_state_events(supervisor.error_events().saturating_add(protocol_errors));
        ticker.next().await;
    }
}

/// The service channel: reassembles requests, carries them out (checking and loading a
/// detector, writing the flash in the service state), answers on the response
/// identifier, at the status frames' priority.
#[embassy_executor::task]
async fn service_task(
    end: &'static mut ServiceEnd,
    mut requests: Requests<'static, 'static, BoardFlash>,
    node: NodeId,
) {
    let response = fingertip_can::service_response_id(node);
    loop {
        let now = Instant::now().as_micros();
        match select(
            SERVICE_FRAMES.receive(),
            embassy_time::Timer::after_millis(50),
        )
        .await
        {
            Either::First((data, len)) => {
                let data = data.get(..usize::from(len)).unwrap_or(&[]);
                let Some(answer) = end.on_frame(data, now, &mut requests).await else {
                    continue;
                };
                if let Some(frame) = CanFrame::new_fd(response, answer.data()) {
                    TX.lock(|t| {
                        let mut t = t.borrow_mut();
                        t.push(&[frame]);
                        t.pump(&mut regs::FdcanTx);
                    });
                }
            }
            Either::Second(()) => end.poll(now),
        }
    }
}

/// Refreshes the independent watchdog only while the critical tasks check in.
#[embassy_executor::task]
async fn watchdog_task(
    mut watchdog: IndependentWatchdog<'static, IWDG>,
    mut shared: WatchdogHandle<'static>,
) {
    watchdog.unleash();
    let mut ticker = Ticker::every(WATCHDOG_ROUND);
    loop {
        ticker.next().await;
        if shared.round(Task::CRITICAL) {
            watchdog.pet();
        } else {
            warn!("a critical task is silent: not refreshing the watchdog");
        }
    }
}
