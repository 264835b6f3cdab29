//! The real front-end board: HSE 8 MHz → PLL 168 MHz, USART1 (PA9/PA10) to the lab PC, SPI1
//! shared by the ADS1262 and the AD7124-4, ADS1262 DRDY on PC4 (EXTI4), defmt over RTT,
//! panic-probe. Pin map in docs/drivers.md ("Front-end board wiring"); not verified on hardware.
//!
//! Acquisition is driven by the ADS1262's DRDY: one edge per settled conversion of the selected
//! input. The EXTI handler reads it, switches the mux to the other input (START1 restarts the
//! conversion, so the next edge is a settled conversion of that input), and after the tilt
//! conversion reads the AD7124's RTD result (polled over the shared bus, bounded) and hands the
//! complete [`RawSample`] to the worker. Driver errors become the pipeline's channel flags, so a
//! fault never turns into a silent number.

use core::cell::RefCell;

use critical_section::Mutex;
use defmt_rtt as _;
use embedded_hal::delay::DelayNs;
use embedded_hal_bus::spi::CriticalSectionDevice;
use panic_probe as _;
use stm32f4xx_hal::{
    gpio::{Edge, Input, Output, PushPull, PA4, PB0, PC4},
    pac,
    prelude::*,
    rcc::Config,
    serial::{self, Serial},
    spi::{Mode, Phase, Polarity, Spi},
};

use super::{Fatal, Parts};
use accomp::drivers::ad7124::{Ad7124, Ad7124Config};
use accomp::drivers::ads1262::{Ads1262, Ads1262Config, Channel};
use accomp::drivers::Error as DriverError;
use accomp::pipeline::{ChannelFlags, RawSample};
use accomp::protocol::Board;

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Frontend;

/// Core clock after the PLL; SysTick runs from it.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// Busy-wait delay from the core clock (SysTick belongs to the RTIC monotonic). Waits at least
/// the requested time; only used for the drivers' reset waits and the CS set-up of the bus.
#[derive(Debug, Clone, Copy, Default)]
pub struct CycleDelay;

impl DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (u64::from(ns) * u64::from(SYSTICK_HZ)).div_ceil(1_000_000_000);
        cortex_m::asm::delay(u32::try_from(cycles).unwrap_or(u32::MAX));
    }
}

/// The drivers' DRDY input when the firmware does not poll a pin: the ADS1262's DRDY is the
/// EXTI4 interrupt, and the AD7124's DOUT/RDY is the shared MISO line, so its driver polls
/// STATUS instead. Reads as "not ready": a polled wait on it times out (DRDY_TIMEOUT), it never
/// pretends data is there.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoDrdyPin;

impl embedded_hal::digital::ErrorType for NoDrdyPin {
    type Error = core::convert::Infallible;
}

impl embedded_hal::digital::InputPin for NoDrdyPin {
    fn is_high(&mut self) -> Result<bool, Self::Error> {
        Ok(true)
    }
    fn is_low(&mut self) -> Result<bool, Self::Error> {
        Ok(false)
    }
}

type Bus = Spi<pac::SPI1>;
type AdsDevice = CriticalSectionDevice<'static, Bus, PA4<Output<PushPull>>, CycleDelay>;
type RtdDevice = CriticalSectionDevice<'static, Bus, PB0<Output<PushPull>>, CycleDelay>;

/// The pipeline's channel flags for a driver error: which one tells the host why the value is
/// missing. Every error sets at least one flag.
fn flags_for<S, P>(e: &DriverError<S, P>) -> ChannelFlags {
    let bit = match e {
        // The bytes arrived but cannot be trusted.
        DriverError::Checksum { .. } | DriverError::CrcMismatch { .. } | DriverError::Spi(_) => {
            ChannelFlags::CHECKSUM
        }
        // The converter itself says the input is out of range or the conversion failed.
        DriverError::AdcError(_) => ChannelFlags::SATURATION,
        // No fresh, valid conversion: timeout, stale data, a reset that lost the configuration,
        // or a chip that does not answer as configured.
        DriverError::DrdyTimeout
        | DriverError::StaleData
        | DriverError::UnexpectedReset
        | DriverError::Pin(_)
        | DriverError::InvalidConfig
        | DriverError::DeviceId { .. }
        | DriverError::NotResponding { .. }
        | DriverError::ReadBack { .. } => ChannelFlags::DRDY_TIMEOUT,
    };
    ChannelFlags(bit)
}

/// DRDY pin plus the two converters on the shared SPI1.
pub struct Acquisition {
    drdy: PC4<Input>,
    ads: Ads1262<AdsDevice, NoDrdyPin, CycleDelay>,
    rtd: Ad7124<RtdDevice, NoDrdyPin, CycleDelay>,
    /// The accelerometer conversion waiting for the tilt conversion of the same sample.
    accel: Option<(i32, ChannelFlags)>,
}

impl Acquisition {
    /// Called from the DRDY interrupt: acknowledges it, reads the conversion DRDY announced and
    /// moves the sequence on; returns a sample when accelerometer, tilt and RTD are all read.
    pub fn on_drdy(&mut self) -> Option<RawSample> {
        self.drdy.clear_interrupt_pending_bit();
        let selected = self.ads.selected();
        let (code, flags) = match self.ads.read_conversion() {
            Ok(s) => {
                let alarm = s.status.is_some_and(|st| st.any_alarm());
                let flags = if alarm { ChannelFlags::SATURATION } else { 0 };
                (s.code.0, ChannelFlags(flags))
            }
            Err(e) => {
                if matches!(e, DriverError::UnexpectedReset) {
                    // The chip lost its configuration: configure it again (≈ 10 ms, rare).
                    if let Err(e) = self.ads.init() {
                        defmt::error!("ADS1262 re-init failed: {}", defmt::Debug2Format(&e));
                    }
                }
                (0, flags_for(&e))
            }
        };
        match selected {
            Some(Channel::Accelerometer) => {
                self.accel = Some((code, flags));
                self.switch_to(Channel::Tiltmeter);
                None
            }
            Some(Channel::Tiltmeter) => {
                // Without the accelerometer half (a failed switch lost it) the sample says so.
                let (accel, accel_flags) = self
                    .accel
                    .take()
                    .unwrap_or((0, ChannelFlags(ChannelFlags::DRDY_TIMEOUT)));
                let (rtd, rtd_flags) = match self.rtd.read_rtd_polled() {
                    Ok(c) => (c.0, ChannelFlags::default()),
                    Err(e) => (0, flags_for(&e)),
                };
                self.switch_to(Channel::Accelerometer);
                Some(RawSample {
                    accel,
                    rtd,
                    tilt: code,
                    accel_flags,
                    rtd_flags,
                    tilt_flags: flags,
                })
            }
            None => {
                // After a failed switch the driver does not know the mux: start a new sample.
                self.accel = None;
                self.switch_to(Channel::Accelerometer);
                None
            }
        }
    }

    fn switch_to(&mut self, channel: Channel) {
        if let Err(e) = self.ads.select_channel(channel) {
            // The driver forgets the selection; the next DRDY restarts the sequence.
            defmt::warn!("ADS1262 mux switch failed: {}", defmt::Debug2Format(&e));
        }
    }
}

/// HSE 8 MHz crystal, PLL to 168 MHz, USART1 115200 8N1, SPI1 mode 1 at 4 MHz (both ADCs
/// accept CPOL=0/CPHA=1), CS PA4 (ADS1262) and PB0 (AD7124), DRDY falling edge on PC4.
pub fn init(mut dp: pac::Peripherals) -> Parts {
    let mut rcc = dp
        .RCC
        .freeze(Config::hse(8.MHz()).sysclk(168.MHz()).pclk1(42.MHz()));
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);

    let serial = match Serial::new(
        dp.USART1,
        (gpioa.pa9, gpioa.pa10),
        serial::Config::default().baudrate(115_200.bps()),
        &mut rcc,
    ) {
        Ok(s) => s,
        Err(_) => fatal(Fatal::Uart),
    };
    let (tx, mut rx) = serial.split();
    rx.listen();

    let mode = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnSecondTransition,
    };
    let spi = dp.SPI1.spi(
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        mode,
        4.MHz(),
        &mut rcc,
    );
    // The bus lives for the whole program; both devices borrow it through a critical-section
    // mutex (what makes the devices Send for RTIC). Only the EXTI4 task uses them, so the
    // critical sections are short and never contended.
    let Some(bus) = cortex_m::singleton!(: Mutex<RefCell<Bus>> = Mutex::new(RefCell::new(spi)))
    else {
        fatal(Fatal::Spi)
    };
    let bus: &'static Mutex<RefCell<Bus>> = bus;
    let cs_ads = gpioa.pa4.into_push_pull_output();
    let cs_rtd = gpiob.pb0.into_push_pull_output();
    // Both CS pins are driven high here (GPIO writes are infallible): neither chip listens
    // until selected.
    let Ok(ads_dev) = CriticalSectionDevice::new(bus, cs_ads, CycleDelay);
    let Ok(rtd_dev) = CriticalSectionDevice::new(bus, cs_rtd, CycleDelay);

    let mut ads = Ads1262::new(
        ads_dev,
        NoDrdyPin,
        CycleDelay,
        Ads1262Config::board_default(),
    );
    let mut rtd = Ad7124::new(
        rtd_dev,
        NoDrdyPin,
        CycleDelay,
        Ad7124Config::board_default(),
    );
    // A converter that fails to start is reported and left alone: the ADS1262 then never raises
    // DRDY (no frames at all), the AD7124 makes every RTD reading fail (RTD_INVALID frames).
    match rtd.init() {
        Ok(info) => defmt::info!("AD7124 rev {}", info.silicon_revision),
        Err(e) => defmt::error!("AD7124 init failed: {}", defmt::Debug2Format(&e)),
    }
    match ads.init() {
        Ok(info) => defmt::info!("ADS1262 rev {}", info.revision),
        Err(e) => defmt::error!("ADS1262 init failed: {}", defmt::Debug2Format(&e)),
    }

    let mut drdy = gpioc.pc4.into_pull_up_input();
    drdy.make_interrupt_source(&mut syscfg);
    drdy.trigger_on_edge(&mut dp.EXTI, Edge::Falling);
    drdy.enable_interrupt(&mut dp.EXTI);

    Parts {
        rx,
        tx,
        acquisition: Acquisition {
            drdy,
            ads,
            rtd,
            accel: None,
        },
        flash: super::Flash::new(dp.FLASH),
    }
}

/// Logs the failure and resets: on the bench a reboot is the only way back.
pub fn fatal(reason: Fatal) -> ! {
    defmt::error!("fatal: {}", reason);
    cortex_m::peripheral::SCB::sys_reset()
}
