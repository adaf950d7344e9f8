//! QEMU `mps2-an386` (Cortex-M4F): CMSDK APB UART0 (the host link) and UART1 (a lidar's
//! packet stream, QEMU's second `-serial`), an FPGA I/O LED; semihosting for exit codes
//! and for defmt output.

use core::convert::Infallible;

use crate::flash::SramFlash;

use defmt_semihosting as _;

/// UART0 of the mps2 boards.
const UART0_BASE: usize = 0x4000_4000;
/// UART1 of the mps2 boards.
const UART1_BASE: usize = 0x4000_5000;
/// FPGA I/O block: register 0 drives the two user LEDs.
const FPGAIO_LED: usize = 0x4002_8000;

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;
const STATE_TX_FULL: u32 = 1 << 0;
const STATE_RX_FULL: u32 = 1 << 1;
const CTRL_TX_RX_ENABLE: u32 = 0b11;
const CTRL_RX_INTERRUPT: u32 = 1 << 3;
const INT_RX: u32 = 1 << 1;

/// UART0's receive interrupt on mps2-an386 (QEMU `hw/arm/mps2.c`: UART0 RX is IRQ 0).
#[derive(Clone, Copy)]
struct Uart0Rx;

// SAFETY: 0 is a valid external interrupt number of this device.
unsafe impl cortex_m::interrupt::InterruptNumber for Uart0Rx {
    fn number(self) -> u16 {
        0
    }
}

/// The serial port of this board.
pub type Serial = CmsdkUart;
/// The heartbeat LED of this board.
pub type Led = FpgaLed;

/// A CMSDK APB UART (ARM's example UART, modelled by QEMU): one byte of buffer each way.
pub struct CmsdkUart {
    base: usize,
    sleep: bool,
}

impl CmsdkUart {
    /// Enables transmitter and receiver of the UART at `base`.
    ///
    /// # Safety
    /// `base` must be the address of a CMSDK UART, and only one `CmsdkUart` may drive it.
    pub unsafe fn new(base: usize) -> Self {
        let uart = Self { base, sleep: false };
        uart.write_reg(BAUDDIV, 16);
        uart.write_reg(CTRL, CTRL_TX_RX_ENABLE);
        uart
    }

    /// Sleeps (WFI) while the receiver is empty instead of spinning, woken by the RX
    /// interrupt. The interrupt is enabled in the NVIC but masked by PRIMASK, so no
    /// handler runs: a pending interrupt still ends WFI. Under QEMU a sleeping CPU leaves
    /// the host core to the thread that delivers the bytes, which makes the link faster.
    pub fn sleep_while_idle(&mut self) {
        cortex_m::interrupt::disable();
        self.write_reg(CTRL, CTRL_TX_RX_ENABLE | CTRL_RX_INTERRUPT);
        // SAFETY: PRIMASK is set above and never cleared: unmasking cannot start a
        // handler, it only lets the pending state wake WFI.
        unsafe { cortex_m::peripheral::NVIC::unmask(Uart0Rx) };
        self.sleep = true;
    }

    /// Undoes [`CmsdkUart::sleep_while_idle`] for a program that needs exceptions (the
    /// cost probes: SysTick's counts the counter's wraps): the RX interrupt is masked in
    /// the NVIC and disabled in the UART, then PRIMASK is cleared. Reads spin again.
    pub fn spin_while_idle(&mut self) {
        cortex_m::peripheral::NVIC::mask(Uart0Rx);
        self.write_reg(CTRL, CTRL_TX_RX_ENABLE);
        self.sleep = false;
        // SAFETY: no interrupt is unmasked in the NVIC (the UART's was masked above), so
        // clearing PRIMASK lets only the core's exceptions (SysTick) run their handlers.
        unsafe { cortex_m::interrupt::enable() };
    }

    fn wait_for_rx(&self) {
        while !self.rx_ready() {
            if self.sleep {
                cortex_m::asm::wfi();
                self.write_reg(INTCLEAR, INT_RX);
                cortex_m::peripheral::NVIC::unpend(Uart0Rx);
            }
        }
    }

    fn read_reg(&self, offset: usize) -> u32 {
        // SAFETY: `new`'s contract: `base` is a UART's register block, owned by `self`.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    fn write_reg(&self, offset: usize, value: u32) {
        // SAFETY: as in `read_reg`.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, value) }
    }

    fn rx_ready(&self) -> bool {
        self.read_reg(STATE) & STATE_RX_FULL != 0
    }

    fn tx_ready(&self) -> bool {
        self.read_reg(STATE) & STATE_TX_FULL == 0
    }
}

impl embedded_io::ErrorType for CmsdkUart {
    type Error = Infallible;
}

impl embedded_io::Read for CmsdkUart {
    /// Waits for the first byte, then takes what else is ready.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        if buf.is_empty() {
            return Ok(0);
        }
        self.wait_for_rx();
        let mut n = 0;
        for slot in buf.iter_mut() {
            if !self.rx_ready() {
                break;
            }
            *slot = self.read_reg(DATA) as u8;
            n += 1;
        }
        Ok(n)
    }
}

impl embedded_io::ReadReady for CmsdkUart {
    fn read_ready(&mut self) -> Result<bool, Infallible> {
        Ok(self.rx_ready())
    }
}

impl embedded_io::Write for CmsdkUart {
    /// Waits until the transmitter takes one byte.
    fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let Some(&b) = buf.first() else {
            return Ok(0);
        };
        while !self.tx_ready() {}
        self.write_reg(DATA, u32::from(b));
        Ok(1)
    }

    fn flush(&mut self) -> Result<(), Infallible> {
        while !self.tx_ready() {}
        Ok(())
    }
}

/// Writes text (for the `cost` binary's report).
impl core::fmt::Write for CmsdkUart {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        embedded_io::Write::write_all(self, s.as_bytes()).map_err(|_| core::fmt::Error)
    }
}

/// One of the two user LEDs of the FPGA I/O block.
pub struct FpgaLed {
    mask: u32,
}

impl embedded_hal::digital::ErrorType for FpgaLed {
    type Error = Infallible;
}

impl embedded_hal::digital::OutputPin for FpgaLed {
    fn set_low(&mut self) -> Result<(), Infallible> {
        self.update(false);
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        self.update(true);
        Ok(())
    }
}

impl FpgaLed {
    fn update(&mut self, on: bool) {
        let reg = FPGAIO_LED as *mut u32;
        // SAFETY: the FPGA I/O LED register; only `FpgaLed`s (one per bit) write it, from
        // the main thread (no interrupt touches it).
        unsafe {
            let v = core::ptr::read_volatile(reg);
            let v = if on { v | self.mask } else { v & !self.mask };
            core::ptr::write_volatile(reg, v);
        }
    }
}

/// The UART a lidar is wired to: UART1 (QEMU's second `-serial`). Its reads spin while
/// it is empty (its interrupt is not the one that ends the link's WFI). Call once.
pub fn lidar_uart() -> CmsdkUart {
    // SAFETY: UART1's address on mps2-an386; `lidar_uart` is called once, and nothing
    // else drives UART1.
    unsafe { CmsdkUart::new(UART1_BASE) }
}

/// Takes the board: UART0 and LED 0. Call once.
pub fn init() -> (Serial, Led) {
    // SAFETY: UART0's address on mps2-an386, and `init` is called once.
    let mut uart = unsafe { CmsdkUart::new(UART0_BASE) };
    uart.sleep_while_idle();
    (uart, FpgaLed { mask: 1 })
}

/// Ends the program: QEMU exits with `code` (semihosting).
pub fn halt(code: i32) -> ! {
    semihosting::process::exit(code)
}

/// The flash a pose store takes under QEMU: the SRAM stand-in ([`SramFlash`], which keeps
/// NOR flash's rules and survives a system reset).
pub type PoseFlash = SramFlash;
/// Bytes of each of the pose store's two sectors.
pub const POSE_SECTOR_BYTES: u32 = crate::config::POSE_SECTOR_BYTES;

/// The pose store's two sectors in the stand-in, handed out once; `None` after.
pub fn pose_flash() -> Option<PoseFlash> {
    SramFlash::take_poses(2 * POSE_SECTOR_BYTES)
}

/// The flash the building-scale SLAM keeps its keyframes and its map image in: the
/// stand-in.
#[cfg(feature = "building-slam")]
pub type SlamFlash = SramFlash;
/// Bytes of the keyframes' region (the profile's: the STM32F411's sector 7).
#[cfg(feature = "building-slam")]
pub const KEYFRAME_BYTES: u32 = crate::config::SLAM_KEYFRAME_BYTES;
/// Bytes of the map image's region (the profile's: the STM32F411's sector 6).
#[cfg(feature = "building-slam")]
pub const MAP_BYTES: u32 = crate::config::SLAM_MAP_BYTES;

/// The keyframes' region of the stand-in, handed out once; `None` after.
#[cfg(feature = "building-slam")]
pub fn keyframe_flash() -> Option<SlamFlash> {
    SramFlash::take(KEYFRAME_BYTES)
}

/// The map image's region of the stand-in, handed out once; `None` after.
#[cfg(feature = "building-slam")]
pub fn map_flash() -> Option<SlamFlash> {
    SramFlash::take_map(MAP_BYTES)
}
