//! STM32F411 on a Nucleo-F411RE: USART2 on PA2/PA3 (the ST-LINK's virtual COM port) at
//! 115 200 baud, user LED LD2 on PA5, 100 MHz from the internal oscillator; defmt over RTT.
//! With the feature `own-lidar`, an LD06 lidar on USART1 (PA10), read by its interrupt
//! ([`super::stm32f411_lidar`]).

use defmt_rtt as _;
use stm32f4xx_hal::gpio::{Output, PA5};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::Config;

use crate::nb_io::NbSerial;

/// Baud rate of the link to the host.
pub const BAUD: u32 = 115_200;

/// The serial port of this board.
pub type Serial = NbSerial<stm32f4xx_hal::serial::Serial<pac::USART2>>;
/// The heartbeat LED of this board.
pub type Led = PA5<Output>;

/// Clocks, USART2 and the LED. Call once.
pub fn init() -> (Serial, Led) {
    let Some(dp) = pac::Peripherals::take() else {
        defmt::error!("peripherals taken twice");
        halt(2)
    };
    // QEMU's netduinoplus2 does not model the RCC: its PLL never reports ready, so that
    // build stays on the 16 MHz HSI the chip starts on (the USART's divider follows).
    #[cfg(feature = "stm32-in-qemu")]
    let clocks = Config::hsi();
    #[cfg(not(feature = "stm32-in-qemu"))]
    let clocks = Config::hsi().sysclk(100.MHz());
    let mut rcc = dp.RCC.freeze(clocks);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let led = gpioa.pa5.into_push_pull_output();
    #[cfg(feature = "own-lidar")]
    {
        let Some(lidar) = super::stm32f411_lidar::start(dp.USART1, gpioa.pa10, &mut rcc) else {
            defmt::error!("USART1 (lidar) configuration refused");
            halt(2)
        };
        cortex_m::interrupt::free(|cs| LIDAR.borrow(cs).replace(Some(lidar)));
    }
    let serial = match dp
        .USART2
        .serial((gpioa.pa2, gpioa.pa3), BAUD.bps(), &mut rcc)
    {
        Ok(s) => s,
        Err(_) => {
            defmt::error!("USART2 configuration refused");
            halt(2)
        }
    };
    (NbSerial(serial), led)
}

/// The lidar's reader, made by [`init`], taken by [`lidar_uart`].
#[cfg(feature = "own-lidar")]
static LIDAR: cortex_m::interrupt::Mutex<core::cell::RefCell<Option<LidarUart>>> =
    cortex_m::interrupt::Mutex::new(core::cell::RefCell::new(None));

/// The UART a lidar is wired to.
#[cfg(feature = "own-lidar")]
pub use super::stm32f411_lidar::LidarUart;

/// The lidar on USART1 (PA10), started by [`init`]. Call once, after [`init`].
#[cfg(feature = "own-lidar")]
pub fn lidar_uart() -> LidarUart {
    match cortex_m::interrupt::free(|cs| LIDAR.borrow(cs).take()) {
        Some(lidar) => lidar,
        None => {
            defmt::error!("lidar_uart called before init, or twice");
            halt(2)
        }
    }
}

/// Stops here (a debugger sees the fault); `code` is logged.
pub fn halt(code: i32) -> ! {
    defmt::error!("halted with code {}", code);
    loop {
        cortex_m::asm::wfi();
    }
}
