//! # host-sim
//!
//! The host side of microslam: dataset readers that turn recorded logs into
//! [`microslam::event::Event`] streams, a deterministic simulator, the run drivers that
//! feed the estimators, metrics against ground truth, and pictures.
//!
//! The modules are layers; each imports only the layers below it (checked by
//! `tests/layers.rs`), and the folder a file is in names its layer:
//!
//! | layer | folder | what |
//! | --- | --- | --- |
//! | 6 | [`cli`] | the command line (clap only): arguments → the commands' options |
//! | 5 | [`commands`] | one module per subcommand: wiring, progress bars, printing |
//! | 4 | [`output`] | TUM trajectories, `metrics.json`, ROS maps, PNG pictures |
//! | 3 | [`metrics`] | ATE, landmark error, NEES/NIS, association purity, relation error |
//! | 2 | [`drivers`] | the EKF run driver, the grid run driver, the camera chains |
//! | 1 | [`inputs`] | dataset readers, the simulator's worlds, fault injection, the camera world |
//! | 0 | [`domain`] | settings and plain domain types (association mode, precision, true poses) |
#![deny(missing_docs)]

pub mod cli;
pub mod commands;
pub mod domain;
pub mod drivers;
pub mod inputs;
pub mod metrics;
pub mod output;
