//! Layer 2: run drivers — events or scans in, the estimator's outputs out. They never
//! parse files and never write any.
//!
//! - [`ekf`]: a [`crate::domain::recording::Recording`]'s events → the landmark EKF-SLAM.
//! - [`grid_run`]: what a grid run takes and gives (scans with odometry, options, the
//!   estimates and the map).
//! - [`odometry`]: odometry samples → the velocity between them (held or interpolated,
//!   delayed by the odometry's latency), for [`ekf`].
//! - [`grid`]: lidar scans with odometry → grid SLAM or the grid localizer (the one grid
//!   drive loop of `replay`, `localize` and `sim`).
//! - [`scan_odometry`]: a scan's odometry pose → the step to predict (refused poses
//!   bridged, odometry resets re-anchored), for [`grid`] and [`graph_slam`].
//! - [`graph_slam`]: the device's building-scale grid SLAM (local map, keyframes, pose
//!   graph, loop closure) over lidar scans.
//! - [`detections`]: sign detections → range/bearing → EKF-SLAM with class hints.
//! - [`hil`]: the host's side of hardware in the loop: the wire frames of a recording,
//!   the QEMU and serial links, the bit-for-bit comparison of the replies;
//!   [`hil_localizer`] and [`hil_slam`]: the localizer's and the building-scale grid
//!   SLAM's lidar messages and host references.
//! - [`texture`]: RGB-D frames + poses → the coloured floor map.

pub mod detections;
pub mod ekf;
pub mod global;
pub mod graph_slam;
pub mod grid;
pub mod grid_run;
pub mod hil;
pub mod hil_lidar;
pub mod hil_localizer;
pub mod hil_slam;
pub mod odometry;
pub mod scan_odometry;
pub mod texture;
