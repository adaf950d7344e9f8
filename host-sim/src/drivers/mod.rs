//! Layer 2: run drivers — events or scans in, the estimator's outputs out. They never
//! parse files and never write any.
//!
//! - [`ekf`]: a [`crate::domain::recording::Recording`]'s events → the landmark EKF-SLAM.
//! - [`grid`]: lidar scans with odometry → grid SLAM or the grid localizer (the one grid
//!   drive loop of `replay`, `localize` and `sim`).
//! - [`detections`]: sign detections → range/bearing → EKF-SLAM with class hints.
//! - [`hil`]: the host's side of hardware in the loop: the wire frames of a recording,
//!   the QEMU and serial links, the bit-for-bit comparison of the replies.
//! - [`texture`]: RGB-D frames + poses → the coloured floor map.

pub mod detections;
pub mod ekf;
pub mod grid;
pub mod hil;
pub mod texture;
