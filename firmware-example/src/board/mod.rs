//! Board support: one module per board, chosen by feature, each offering the same items:
//! `Serial` (`embedded_io::Read + Write`), `Led` (`embedded_hal::digital::OutputPin`),
//! `init()` and `halt(code)`; with the feature `own-lidar`, `LidarUart` and `lidar_uart()`
//! (the UART a lidar is wired to).

#[cfg(feature = "qemu")]
pub mod qemu;
#[cfg(feature = "qemu")]
pub use qemu::{Led, Serial, halt, init};

#[cfg(feature = "stm32f411")]
pub mod stm32f411;
#[cfg(feature = "stm32f411")]
pub use stm32f411::{Led, Serial, halt, init};
#[cfg(all(feature = "stm32f411", feature = "own-lidar"))]
pub mod stm32f411_lidar;

#[cfg(all(feature = "qemu", feature = "own-lidar"))]
pub use qemu::{CmsdkUart as LidarUart, lidar_uart};
#[cfg(all(feature = "stm32f411", feature = "own-lidar"))]
pub use stm32f411::{LidarUart, lidar_uart};
