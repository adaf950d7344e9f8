//! Board support: one module per board, chosen by feature, each offering the same items:
//! `Serial` (`embedded_io::Read + Write`), `Led` (`embedded_hal::digital::OutputPin`),
//! `init()` and `halt(code)`.

#[cfg(feature = "qemu")]
pub mod qemu;
#[cfg(feature = "qemu")]
pub use qemu::{Led, Serial, halt, init};

#[cfg(feature = "stm32f411")]
pub mod stm32f411;
#[cfg(feature = "stm32f411")]
pub use stm32f411::{Led, Serial, halt, init};
