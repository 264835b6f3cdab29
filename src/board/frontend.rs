//! The real front-end board: HSE 8 MHz → PLL 168 MHz, USART1 (PA9/PA10) to the lab PC, SPI1 to
//! the ADS1262 and the AD7124-4, ADS1262 DRDY on PC4 (EXTI4), defmt over RTT, panic-probe.
//!
//! The ADC drivers live on the `drivers` branch; until they are merged the acquisition is behind
//! [`AdcFrontEnd`], and [`Acquisition`] holds an implementation that reports a DRDY timeout on
//! every channel, so the firmware builds, runs, and never streams a made-up number.

use defmt_rtt as _;
use panic_probe as _;
use stm32f4xx_hal::{
    gpio::{Edge, Input, PC4},
    pac,
    prelude::*,
    rcc::Config,
    serial::{self, Serial},
    spi::{Mode, Phase, Polarity, Spi},
};

use super::{Fatal, Parts};
use accomp::pipeline::{ChannelFlags, RawSample};
use accomp::protocol::Board;

/// Board reported in READY and Info.
pub const BOARD: Board = Board::Frontend;

/// Core clock after the PLL; SysTick runs from it.
pub const SYSTICK_HZ: u32 = 168_000_000;

/// What the acquisition needs from the ADC drivers: one conversion set per DRDY.
pub trait AdcFrontEnd {
    /// Reads the accelerometer, RTD and tilt conversions that DRDY announced.
    fn read_sample(&mut self) -> RawSample;
}

/// Placeholder until the ADS1262/AD7124 drivers land: every channel reports a DRDY timeout,
/// which the pipeline turns into NaN + DRDY_TIMEOUT (no silent numbers).
pub struct NoDrivers {
    _spi: Spi<pac::SPI1>,
}

impl AdcFrontEnd for NoDrivers {
    fn read_sample(&mut self) -> RawSample {
        let timeout = ChannelFlags(ChannelFlags::DRDY_TIMEOUT);
        RawSample {
            accel: 0,
            rtd: 0,
            tilt: 0,
            accel_flags: timeout,
            rtd_flags: timeout,
            tilt_flags: timeout,
        }
    }
}

/// DRDY pin plus the ADC front-end.
pub struct Acquisition {
    drdy: PC4<Input>,
    adcs: NoDrivers,
}

impl Acquisition {
    /// Called from the DRDY interrupt: acknowledges it and reads the conversions.
    pub fn on_drdy(&mut self) -> Option<RawSample> {
        self.drdy.clear_interrupt_pending_bit();
        Some(self.adcs.read_sample())
    }
}

/// HSE 8 MHz crystal, PLL to 168 MHz, USART1 115200 8N1, SPI1 mode 1 at ≤ 4 MHz (both ADCs
/// accept CPOL=0/CPHA=1), DRDY falling edge on PC4.
pub fn init(mut dp: pac::Peripherals) -> Parts {
    let mut rcc = dp
        .RCC
        .freeze(Config::hse(8.MHz()).sysclk(168.MHz()).pclk1(42.MHz()));
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let gpioa = dp.GPIOA.split(&mut rcc);
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

    let mut drdy = gpioc.pc4.into_pull_up_input();
    drdy.make_interrupt_source(&mut syscfg);
    drdy.trigger_on_edge(&mut dp.EXTI, Edge::Falling);
    drdy.enable_interrupt(&mut dp.EXTI);

    Parts {
        rx,
        tx,
        acquisition: Acquisition {
            drdy,
            adcs: NoDrivers { _spi: spi },
        },
        flash: super::Flash::new(dp.FLASH),
    }
}

/// Logs the failure and resets: on the bench a reboot is the only way back.
pub fn fatal(reason: Fatal) -> ! {
    defmt::error!("fatal: {}", reason);
    cortex_m::peripheral::SCB::sys_reset()
}
