//! The program a device runs behind its serial line (feature `wire`): received bytes in,
//! estimator steps, replies out.
//!
//! [`Session`] owns the frame decoder of [`crate::wire`] and borrows the estimators
//! (which live in `static`s on a microcontroller): the EKF-SLAM, and a grid estimator
//! ([`GridEstimator`]: the grid SLAM, or the building-scale SLAM of [`crate::slam`]) or
//! a localizer on a map in flash ([`LocalizerEstimator`]). The firmware runs it behind
//! its UART; a host runs the same code on the same bytes to get the reference the
//! firmware must match, bit for bit. A lidar wired to the device ([`LidarSource`]) can
//! feed the grid estimator in place of scans sent over the line. [`PoseStore`] keeps the robot's pose in flash
//! across resets.
//!
//! Layers: this module sits above [`crate::wire`] (bytes ↔ messages) and the estimators
//! ([`crate::ekf`], [`crate::pf`], [`crate::association`]); nothing below imports it.

pub mod lidar;
pub mod saved_pose;
pub mod session;

pub use crate::pf::GridEstimator;
pub use lidar::LidarSource;
pub use saved_pose::{PoseKeeping, PoseStore, PoseStoreError, SavedPose};
pub use session::{GridSetup, LocalizerEstimator, MAX_SCAN_BEAMS, Session};
