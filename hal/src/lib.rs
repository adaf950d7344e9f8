//! microslam's sensor models on a board's own buses, generic over the `embedded-hal` and
//! `embedded-io` traits that every HAL implements, `no_std` and in fixed memory:
//!
//! - [`lidar::Ld06Uart`]: an LDROBOT LD06 / LD19 lidar on a UART (`embedded_io::Read`):
//!   its bytes through [`microslam::sensors::ld06`]'s decoder and binner, a
//!   [`microslam::sensors::lidar::LidarScan`] a revolution.
//! - [`imu::YawGyro`]: an InvenSense MPU-6050 on an I2C bus (`embedded_hal::i2c::I2c`):
//!   checked to be one, configured, its yaw rate in rad/s with the bias measured at rest
//!   removed, for [`microslam::sensors::imu`].
//!
//! Wheel encoders need no bus: a timer in encoder mode is read as a number, which
//! [`microslam::sensors::encoder`] turns into ticks.
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![deny(missing_docs)]

pub mod imu;
pub mod lidar;
