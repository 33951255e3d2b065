//! Driver for the TI TMP117 digital temperature sensor (±0.1 °C, 16-bit, I2C), generic
//! over `embedded-hal-async`.
//!
//! On the fingertip board the TMP117 sits next to the strain gauges; its reading drives
//! the force channels' zero-drift compensation ([`crate::calib`]). Register map
//! (TMP117 datasheet SNOSD82, section 8): `0x00` temperature result (two's complement,
//! 7.8125 m°C per LSB, `0x8000` = −256 °C until the first conversion completes), `0x01`
//! configuration, `0x0F` device id (bits 11..0 = `0x117`). Big-endian 16-bit registers,
//! read by writing the pointer then reading two bytes.
//!
//! Every bus transaction is bounded by a timeout (a [`DelayNs`] raced against the
//! transfer), so a sensor holding the bus, or a HAL waiting forever, cannot stall the
//! task that reads it. [`SensorHealth`] turns the outcomes into a fault flag.

use embassy_futures::select::{Either, select};
use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::i2c::I2c;

use detector_core::Signal;

/// The TMP117's address with its ADD0 pin tied to ground (0x49: V+, 0x4A: SDA, 0x4B: SCL).
pub const DEFAULT_ADDRESS: u8 = 0x48;

/// The device id the TMP117 reports in bits 11..0 of register `0x0F`.
pub const DEVICE_ID: u16 = 0x0117;

const REG_TEMPERATURE: u8 = 0x00;
const REG_CONFIGURATION: u8 = 0x01;
const REG_DEVICE_ID: u8 = 0x0F;

/// The raw result before the first conversion completes (−256 °C).
const NOT_READY: i16 = i16::MIN;

/// The conversion-mode field (MOD, bits 11..10) of the configuration register: `00` and
/// `10` convert continuously, `01` is shutdown, `11` one-shot.
const MOD_MASK: u16 = 0b11 << 10;
const MOD_SHUTDOWN: u16 = 0b01 << 10;
const MOD_ONE_SHOT: u16 = 0b11 << 10;

/// The configuration the TMP117 powers up with from the factory (reset value `0x0220`):
/// continuous conversion, 8 averages, a 1 s cycle. The driver only reads the sensor; a
/// fresh value every second is far faster than the board's thermal time constant.
pub const FACTORY_CONFIGURATION: u16 = 0x0220;

/// What went wrong talking to the sensor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Error<E> {
    /// The bus transaction failed (NACK, arbitration, bus error...); see [`Error::kind`].
    Bus(E),
    /// The transaction did not finish within the timeout.
    Timeout,
    /// Something answered at the address, but it is not a TMP117 (its id register).
    WrongDevice {
        /// The id it reported.
        id: u16,
    },
    /// No conversion has completed yet (the result register still reads −256 °C).
    NotReady,
    /// The sensor is not converting continuously (its EEPROM holds shutdown or one-shot
    /// mode): the configuration register read.
    NotConverting {
        /// The configuration register.
        configuration: u16,
    },
}

impl<E: embedded_hal::i2c::Error> Error<E> {
    /// The error's kind, in embedded-hal's vocabulary; [`Error::Timeout`] is
    /// [`ErrorKind::Other`], a wrong device or no result yet too.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Bus(e) => e.kind(),
            _ => ErrorKind::Other,
        }
    }
}

impl<E: core::fmt::Debug> core::fmt::Display for Error<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Error::Bus(e) => write!(f, "I2C error: {e:?}"),
            Error::Timeout => write!(f, "I2C transaction timed out"),
            Error::WrongDevice { id } => write!(f, "device id {id:#06x} is not a TMP117's"),
            Error::NotReady => write!(f, "no temperature conversion completed yet"),
            Error::NotConverting { configuration } => write!(
                f,
                "configuration {configuration:#06x} is not continuous conversion"
            ),
        }
    }
}

/// The raw result register to °C: 7.8125 m°C = 1/128 °C per LSB, so the 16.16 value is
/// exactly `raw << 9`.
pub const fn raw_to_celsius(raw: i16) -> Signal {
    Signal::from_bits((raw as i32) << 9)
}

/// A TMP117 on an I2C bus.
pub struct Tmp117<I, D> {
    i2c: I,
    delay: D,
    address: u8,
    timeout_ms: u32,
}

impl<I: I2c, D: DelayNs> Tmp117<I, D> {
    /// A driver for the sensor at `address` (7-bit), each transaction bounded by
    /// `timeout_ms` (a 4-byte transaction takes under 0.5 ms at 100 kHz).
    pub fn new(i2c: I, delay: D, address: u8, timeout_ms: u32) -> Self {
        Tmp117 {
            i2c,
            delay,
            address,
            timeout_ms,
        }
    }

    /// Checks the device id and that the sensor converts continuously (as it does from
    /// the factory, [`FACTORY_CONFIGURATION`]). Reads only: the driver never writes the
    /// sensor, so one bus operation (pointer write, then read) serves every access.
    pub async fn init(&mut self) -> Result<(), Error<I::Error>> {
        let id = self.read_register(REG_DEVICE_ID).await?;
        if id & 0x0FFF != DEVICE_ID {
            return Err(Error::WrongDevice { id });
        }
        let configuration = self.read_register(REG_CONFIGURATION).await?;
        let mode = configuration & MOD_MASK;
        if mode == MOD_SHUTDOWN || mode == MOD_ONE_SHOT {
            return Err(Error::NotConverting { configuration });
        }
        Ok(())
    }

    /// The latest temperature, °C.
    pub async fn read_celsius(&mut self) -> Result<Signal, Error<I::Error>> {
        let raw = self.read_register(REG_TEMPERATURE).await? as i16;
        if raw == NOT_READY {
            return Err(Error::NotReady);
        }
        Ok(raw_to_celsius(raw))
    }

    /// Gives the bus and the delay back.
    pub fn release(self) -> (I, D) {
        (self.i2c, self.delay)
    }

    async fn read_register(&mut self, register: u8) -> Result<u16, Error<I::Error>> {
        let mut buf = [0u8; 2];
        let Tmp117 {
            i2c,
            delay,
            address,
            timeout_ms,
        } = self;
        bounded(
            i2c.write_read(*address, &[register], &mut buf),
            delay.delay_ms(*timeout_ms),
        )
        .await?;
        Ok(u16::from_be_bytes(buf))
    }
}

/// Runs one bus operation, racing it against the timeout. A timed-out transfer is
/// dropped, which aborts it in the HAL.
async fn bounded<E>(
    op: impl core::future::Future<Output = Result<(), E>>,
    timeout: impl core::future::Future<Output = ()>,
) -> Result<(), Error<E>> {
    match select(op, timeout).await {
        Either::First(r) => r.map_err(Error::Bus),
        Either::Second(()) => Err(Error::Timeout),
    }
}

/// Counts of failed readings since boot, by cause (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorErrors {
    /// No acknowledge (the sensor is absent, unpowered or busy).
    pub nack: u32,
    /// Transactions that timed out.
    pub timeout: u32,
    /// Other bus errors (arbitration, bus error, overrun...).
    pub bus: u32,
    /// Wrong device id, not converting, or no result yet.
    pub invalid: u32,
}

impl SensorErrors {
    /// All failures together (saturating).
    pub fn total(&self) -> u32 {
        self.nack
            .saturating_add(self.timeout)
            .saturating_add(self.bus)
            .saturating_add(self.invalid)
    }
}

/// Turns reading outcomes into a fault flag: faulty after `trip` consecutive failures,
/// healthy again at the first good reading (which re-initializes nothing: the caller
/// re-runs [`Tmp117::init`] while [`SensorHealth::needs_init`] says so).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorHealth {
    trip: u8,
    failures: u8,
    initialized: bool,
    last: Option<Signal>,
    errors: SensorErrors,
    episodes: u32,
}

impl SensorHealth {
    /// Faulty after `trip` (≥ 1) consecutive failed readings.
    pub const fn new(trip: u8) -> SensorHealth {
        SensorHealth {
            trip: if trip == 0 { 1 } else { trip },
            failures: 0,
            initialized: false,
            last: None,
            errors: SensorErrors {
                nack: 0,
                timeout: 0,
                bus: 0,
                invalid: 0,
            },
            episodes: 0,
        }
    }

    /// Records the outcome of an init or a reading.
    pub fn record<E: embedded_hal::i2c::Error>(
        &mut self,
        outcome: Result<Option<Signal>, &Error<E>>,
    ) {
        match outcome {
            Ok(reading) => {
                self.initialized = true;
                if let Some(t) = reading {
                    self.failures = 0;
                    self.last = Some(t);
                }
            }
            Err(e) => {
                let n = match e {
                    Error::Timeout => &mut self.errors.timeout,
                    Error::WrongDevice { .. } | Error::NotReady | Error::NotConverting { .. } => {
                        &mut self.errors.invalid
                    }
                    Error::Bus(b) => match b.kind() {
                        ErrorKind::NoAcknowledge(_) => &mut self.errors.nack,
                        _ => &mut self.errors.bus,
                    },
                };
                *n = n.saturating_add(1);
                // A sensor that does not answer may have been reset: configure it again.
                if !matches!(e, Error::NotReady) {
                    self.initialized = false;
                }
                let was = self.is_faulty();
                self.failures = self.failures.saturating_add(1);
                if !was && self.is_faulty() {
                    self.episodes = self.episodes.saturating_add(1);
                }
            }
        }
    }

    /// Whether the sensor is faulty now.
    pub const fn is_faulty(&self) -> bool {
        self.failures >= self.trip
    }

    /// Whether the sensor must be (re)configured before reading.
    pub const fn needs_init(&self) -> bool {
        !self.initialized
    }

    /// The temperature to use: the last good reading while healthy, `None` when faulty
    /// (the calibration then holds its last compensation).
    pub fn temperature(&self) -> Option<Signal> {
        if self.is_faulty() { None } else { self.last }
    }

    /// Failed readings by cause.
    pub const fn errors(&self) -> &SensorErrors {
        &self.errors
    }

    /// Times the sensor became faulty since boot.
    pub const fn episodes(&self) -> u32 {
        self.episodes
    }
}

/// One round of the temperature task: (re)initializes the sensor while it needs it,
/// otherwise reads it, and records the outcome in `health` (the task then publishes
/// [`SensorHealth::temperature`], the fault and the error counts). Returns whether the
/// fault flag changed, for the log.
pub async fn poll_sensor<I: I2c, D: DelayNs>(
    sensor: &mut Tmp117<I, D>,
    health: &mut SensorHealth,
) -> bool {
    let was_faulty = health.is_faulty();
    if health.needs_init() {
        let r = sensor.init().await;
        health.record(r.as_ref().map(|()| None));
    } else {
        let r = sensor.read_celsius().await;
        health.record(r.as_ref().map(|t| Some(*t)));
    }
    health.is_faulty() != was_faulty
}

/// Whether an error is the sensor not acknowledging its address (absent or unpowered),
/// as opposed to a failure in the middle of a transfer.
pub fn is_address_nack<E: embedded_hal::i2c::Error>(e: &Error<E>) -> bool {
    matches!(e, Error::Bus(b) if b.kind() == ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address))
}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_futures::block_on;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::delay::NoopDelay;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction};

    const A: u8 = DEFAULT_ADDRESS;

    /// A delay that never ends: the bus operation always wins the race.
    struct Forever;
    impl DelayNs for Forever {
        async fn delay_ns(&mut self, _ns: u32) {
            core::future::pending::<()>().await
        }
    }

    /// A bus whose transactions never complete (SCL held low, a HAL waiting forever).
    struct Stuck;
    impl embedded_hal::i2c::ErrorType for Stuck {
        type Error = ErrorKind;
    }
    impl I2c for Stuck {
        async fn transaction(
            &mut self,
            _address: u8,
            _operations: &mut [embedded_hal::i2c::Operation<'_>],
        ) -> Result<(), ErrorKind> {
            core::future::pending().await
        }
    }

    fn id_read(id: u16) -> Transaction {
        Transaction::write_read(A, vec![0x0F], id.to_be_bytes().to_vec())
    }

    fn config_read(config: u16) -> Transaction {
        Transaction::write_read(A, vec![0x01], config.to_be_bytes().to_vec())
    }

    #[test]
    fn conversion_is_exact_over_the_whole_range() {
        assert_eq!(raw_to_celsius(0x0C80).to_f64(), 25.0);
        assert_eq!(raw_to_celsius(0x0001).to_f64(), 0.0078125);
        assert_eq!(raw_to_celsius(-1).to_f64(), -0.0078125);
        assert_eq!(raw_to_celsius(0x7FFF).to_f64(), 255.9921875);
        assert_eq!(raw_to_celsius(0xF380u16 as i16).to_f64(), -25.0);
        for raw in i16::MIN..=i16::MAX {
            assert_eq!(raw_to_celsius(raw).to_f64(), f64::from(raw) / 128.0);
        }
    }

    #[test]
    fn a_sensor_not_converting_is_refused() {
        for config in [0x0620u16, 0x0E20] {
            let expectations = [id_read(0x0117), config_read(config)];
            let mut i2c = Mock::new(&expectations);
            let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
            assert_eq!(
                block_on(t.init()),
                Err(Error::NotConverting {
                    configuration: config
                })
            );
            i2c.done();
        }
        // MOD = 10 reads as continuous too.
        let expectations = [id_read(0x0117), config_read(0x0A20)];
        let mut i2c = Mock::new(&expectations);
        let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
        assert_eq!(block_on(t.init()), Ok(()));
        i2c.done();
    }

    #[test]
    fn init_checks_the_id_and_the_mode_then_reads() {
        let expectations = [
            // Revision bits (15..12) are ignored.
            id_read(0x1117),
            config_read(FACTORY_CONFIGURATION),
            Transaction::write_read(A, vec![0x00], vec![0x0C, 0x80]),
        ];
        let mut i2c = Mock::new(&expectations);
        let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
        block_on(t.init()).unwrap();
        assert_eq!(block_on(t.read_celsius()).unwrap().to_f64(), 25.0);
        i2c.done();
    }

    #[test]
    fn a_wrong_device_is_refused_before_anything_else() {
        let expectations = [id_read(0x1116)];
        let mut i2c = Mock::new(&expectations);
        let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
        let e = block_on(t.init()).unwrap_err();
        assert_eq!(e, Error::WrongDevice { id: 0x1116 });
        assert!(format!("{e}").contains("0x1116"));
        i2c.done();
    }

    #[test]
    fn nacks_are_reported_with_their_kind() {
        let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);
        let expectations = [
            Transaction::write_read(A, vec![0x0F], vec![0, 0]).with_error(nack),
            Transaction::write_read(A, vec![0x00], vec![0, 0])
                .with_error(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data)),
        ];
        let mut i2c = Mock::new(&expectations);
        let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
        let e = block_on(t.init()).unwrap_err();
        assert_eq!(e.kind(), nack);
        assert!(is_address_nack(&e));
        let e = block_on(t.read_celsius()).unwrap_err();
        assert!(!is_address_nack(&e));
        assert_eq!(
            e,
            Error::Bus(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data))
        );
        i2c.done();
    }

    #[test]
    fn a_result_before_the_first_conversion_is_not_a_temperature() {
        let expectations = [Transaction::write_read(A, vec![0x00], vec![0x80, 0x00])];
        let mut i2c = Mock::new(&expectations);
        let mut t = Tmp117::new(&mut i2c, Forever, A, 5);
        assert_eq!(block_on(t.read_celsius()), Err(Error::NotReady));
        i2c.done();
    }

    #[test]
    fn a_stuck_bus_times_out() {
        let mut t = Tmp117::new(Stuck, NoopDelay::new(), A, 5);
        assert_eq!(block_on(t.read_celsius()), Err(Error::Timeout));
        assert_eq!(block_on(t.init()), Err(Error::Timeout));
        assert_eq!(Error::<ErrorKind>::Timeout.kind(), ErrorKind::Other);
    }

    #[test]
    fn health_trips_after_consecutive_failures_and_recovers_at_once() {
        let mut h = SensorHealth::new(3);
        assert!(h.needs_init());
        h.record::<ErrorKind>(Ok(None));
        assert!(!h.needs_init());
        h.record::<ErrorKind>(Ok(Some(Signal::from_f64(30.0))));
        assert_eq!(h.temperature(), Some(Signal::from_f64(30.0)));
        let nack = Error::Bus(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
        h.record(Err(&nack));
        assert!(
            h.needs_init(),
            "a sensor that stopped answering is configured again"
        );
        h.record::<ErrorKind>(Err(&Error::Timeout));
        assert!(!h.is_faulty());
        // Still the last good value until the fault trips.
        assert_eq!(h.temperature(), Some(Signal::from_f64(30.0)));
        h.record(Err(&Error::Bus(ErrorKind::Bus)));
        assert!(h.is_faulty());
        assert_eq!(h.temperature(), None);
        h.record::<ErrorKind>(Err(&Error::NotReady));
        assert_eq!(h.episodes(), 1);
        assert_eq!(
            *h.errors(),
            SensorErrors {
                nack: 1,
                timeout: 1,
                bus: 1,
                invalid: 1
            }
        );
        assert_eq!(h.errors().total(), 4);
        h.record::<ErrorKind>(Ok(Some(Signal::from_f64(31.0))));
        assert!(!h.is_faulty());
        assert_eq!(h.temperature(), Some(Signal::from_f64(31.0)));
    }

    #[test]
    fn a_sensor_that_stops_answering_is_flagged_counted_and_recovers() {
        use crate::shared::Shared;
        let nack = ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address);
        let temp = |raw: u16| Transaction::write_read(A, vec![0x00], raw.to_be_bytes().to_vec());
        let dead = || Transaction::write_read(A, vec![0x0F], vec![0, 0]).with_error(nack);
        let expectations = [
            id_read(0x0117),
            config_read(FACTORY_CONFIGURATION),
            temp(0x0C80), // 25 °C
            // Unplugged: the read fails, then every re-initialization.
            Transaction::write_read(A, vec![0x00], vec![0, 0]).with_error(nack),
            dead(),
            dead(),
            // Back.
            id_read(0x0117),
            config_read(FACTORY_CONFIGURATION),
            temp(0x0D00), // 26 °C
        ];
        let mut i2c = Mock::new(&expectations);
        let mut sensor = Tmp117::new(&mut i2c, Forever, A, 5);
        let mut health = SensorHealth::new(3);
        let mut shared = Shared::new();
        let mut h = shared.split();
        // The temperature task's round: poll, then publish.
        let mut poll = || {
            let changed = block_on(poll_sensor(&mut sensor, &mut health));
            h.temperature.publish(&health);
            changed
        };
        assert!(!poll()); // init
        assert!(!poll()); // 25 °C
        assert_eq!(h.sampler.temperature(), Some(Signal::from_f64(25.0)));
        assert!(!poll());
        assert!(!poll());
        assert!(poll(), "third failure in a row: faulty");
        assert!(h.detector.sensor_fault());
        assert_eq!(h.sampler.temperature(), None);
        assert_eq!(h.detector.counters().sensor_errors.get(), 3);
        assert!(!poll()); // init again: still faulty until a reading
        assert!(poll(), "a good reading clears the fault");
        assert!(!h.detector.sensor_fault());
        assert_eq!(h.sampler.temperature(), Some(Signal::from_f64(26.0)));
        i2c.done();
    }
}
