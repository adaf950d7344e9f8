//! Board support: one module per board, chosen by feature, each offering the same items:
//! `Serial` (`embedded_io::Read + Write`), `Led` (`embedded_hal::digital::OutputPin`),
//! `init()` and `halt(code)`; with the feature `own-lidar`, `LidarUart` and `lidar_uart()`
//! (the UART a lidar is wired to). What survives a reset: `PoseFlash`, `pose_flash()` and
//! `POSE_SECTOR_BYTES` (the saved pose's two sectors); with `building-slam`, `SlamFlash`,
//! `keyframe_flash()`, `map_flash()`, `KEYFRAME_BYTES` and `MAP_BYTES` (the SLAM's
//! keyframes and map image). The STM32F411 has them in the building-slam build only: the
//! localizer's map leaves no sector free.

#[cfg(feature = "qemu")]
pub mod qemu;
#[cfg(all(feature = "qemu", feature = "building-slam"))]
pub use qemu::{KEYFRAME_BYTES, MAP_BYTES, SlamFlash, keyframe_flash, map_flash};
#[cfg(feature = "qemu")]
pub use qemu::{Led, POSE_SECTOR_BYTES, PoseFlash, Serial, halt, init, pose_flash};

#[cfg(feature = "stm32f411")]
pub mod stm32f411;
#[cfg(feature = "stm32f411")]
pub use stm32f411::{Led, Serial, halt, init};
#[cfg(all(feature = "stm32f411", feature = "building-slam"))]
pub mod stm32f411_flash;
#[cfg(all(feature = "stm32f411", feature = "building-slam"))]
pub use stm32f411_flash::{
    KEYFRAME_BYTES, MAP_BYTES, POSE_SECTOR_BYTES, PoseFlash, SlamFlash, keyframe_flash, map_flash,
    pose_flash,
};
#[cfg(all(feature = "stm32f411", feature = "own-lidar"))]
pub mod stm32f411_lidar;

#[cfg(all(feature = "qemu", feature = "own-lidar"))]
pub use qemu::{CmsdkUart as LidarUart, lidar_uart};
#[cfg(all(feature = "stm32f411", feature = "own-lidar"))]
pub use stm32f411::{LidarUart, lidar_uart};
