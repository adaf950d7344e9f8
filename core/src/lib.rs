//! # microslam
//!
//! SLAM estimators that run on a robot's microcontroller — `no_std`, no allocation, all
//! memory sized at compile time — and, unchanged, on a laptop replaying recorded datasets.
//!
//! - [`sensors::camera`]: pinhole / RGB-D camera geometry: a detection's pixel and depth
//!   to a range-bearing sighting with its covariance, pixels back to the robot and world.
//! - [`ekf::EkfSlam`]: landmark EKF-SLAM with range-bearing sightings of signs or markers
//!   and a compile-time maximum number of landmarks; data association in
//!   [`association`]: known ids, ICNN and JCBB (joint compatibility over a batch of
//!   sightings), all with fixed capacity.
//! - [`pf::GridSlam`] / [`pf::GridLocalizer`]: the grid particle filter — lidar scans
//!   scored by map correlation with a local shift search against a saturating `i8`
//!   log-odds [`grid::OccupancyGrid`] (SLAM) or a fixed, borrowed map (localization, e.g.
//!   from flash); wheel odometry, IMU yaw-rate filtering and stream alignment in
//!   [`sensors`].
//! - [`slam::GraphSlam`]: grid SLAM at the scale of a building in fixed memory: the
//!   particle filter on a local map that follows the robot, keyframes kept in flash, a
//!   pose graph that closes loops.
//! - [`event::Event`]: one time-stamped sensor sample; readers produce them, and
//!   [`feed::EventFeed`] turns a stream of them into estimator steps.
//! - `wire` (feature `wire`): the messages between a host and the device on a serial line,
//!   with a streaming, allocation-free frame decoder; `device` (same feature): the
//!   program that answers them on the device, `device::Session`.
//!
//! Every estimator is generic over the scalar ([`Real`]: `f32` on a Cortex-M4F, `f64` on
//! the host), returns errors as small `Copy` values and never panics on bad input: a step
//! that returns an error leaves the state as it was.
//!
//! ```
//! use microslam::association::{observe_known, KnownIds};
//! use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
//! use microslam::sensors::range_bearing::RangeBearing;
//!
//! // Up to 32 landmarks: 18 KB in f32, usually a `static` on the target.
//! let mut slam = EkfSlam::<f32, { state_dim(32) }, { factor_len(32) }>::new(EkfConfig::DEFAULT_F32);
//! let mut ids = KnownIds::<32>::new();
//!
//! slam.predict_velocity(0.2, 0.05, 0.1)?; // v [m/s], ω [rad/s], dt [s]
//! observe_known(&mut slam, &mut ids, 42, &RangeBearing::new(3.0, 0.25))?; // marker 42
//! let pose = slam.pose();
//! assert!(pose.x > 0.0);
//! # Ok::<(), microslam::EkfError>(())
//! ```
//!
//! Runnable examples are in `core/examples/` (`cargo run -p microslam --example NAME`):
//! `ekf_events` (EKF-SLAM with known ids from an event stream), `grid_slam`, `localizer`
//! (on a map in flash) and `statics` (every estimator in a `static`).
//!
//! ## Features
//! - `std`: build against the standard library (host tools). Off by default.
//! - `defmt`: `defmt::Format` for public types and log lines through defmt.
//! - `serde`: `Serialize`/`Deserialize` for the settings (grid filters, building-scale
//!   SLAM), for host tools that read and write them.
//! - `wire`: `microslam::wire`, the serial-line messages (serde + postcard, COBS, CRC-16).
//! - `map-image`: `grid::map_image`, a map as a versioned, CRC-32-checked image for flash.
//! - `libm-force`: use libm for float math even with `std`, so host and target agree
//!   bit for bit.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(unsafe_code)]
#![deny(missing_docs)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod association;
mod checksum;
#[cfg(feature = "wire")]
pub mod device;
pub mod ekf;
pub mod error;
pub mod event;
pub mod feed;
pub mod gate;
pub mod geometry;
pub mod grid;
mod log;
pub mod motion;
pub mod pf;
pub mod profile;
pub mod scalar;
pub mod sensors;
pub mod slam;
#[cfg(feature = "wire")]
pub mod wire;

#[cfg(test)]
mod testing;

/// The README's code examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
pub struct ReadmeDoctests;

pub use error::{EkfError, MapFull};
pub use geometry::Pose2;
pub use scalar::Real;
