//! # host-sim
//!
//! The host side of microslam: dataset readers that turn recorded logs into
//! [`microslam::event::Event`] streams, a deterministic simulator, the replay loop that
//! feeds the estimators, metrics against ground truth, and pictures.
//!
//! - [`cli`]: the command line (`replay`, `sim`).
//! - [`datasets`]: the one place that finds the shared datasets folder.
//! - [`readers`]: dataset files → time-ordered events + ground truth.
//! - [`replay`]: events → estimator → estimates; never parses anything.
//! - [`sim`]: the built-in simulator.
//! - [`metrics`]: ATE, landmark error, NEES/NIS, association purity → `metrics.json`.
//! - [`output`]: TUM trajectories and PNG pictures.
//! - [`config`]: estimator settings from TOML files.
//! - [`faults`]: fault injection into event streams (drops, duplicates, reordering,
//!   corrupted readings, clock jumps).
//! - [`camera`]: camera front ends on the simulator: rendered RGB-D frames, the floor
//!   texture map, sign detections through the EKF-SLAM.
//! - [`sweep`]: a grid of settings × recordings replayed in parallel, one table.
//! - [`grid_replay`]: the grid particle filter (SLAM, localization) on CARMEN lidar logs.
#![deny(missing_docs)]

pub mod camera;
pub mod cli;
pub mod config;
pub mod datasets;
pub mod faults;
pub mod grid_replay;
pub mod hil;
pub mod metrics;
pub mod output;
pub mod readers;
pub mod replay;
pub mod sim;
pub mod sweep;
