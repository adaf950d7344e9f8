//! Helpers of the cross-crate tests (the tests themselves are in `tests/tests/*.rs`).
//!
//! - [`firmware`]: runs the firmware of `firmware-example` under QEMU, streams wire frames
//!   to its UART and collects its replies; the same bytes through a host
//!   [`microslam::device::Session`] give the reference it must equal.
//! - [`fuzzing`]: the checks of the fuzz targets in `fuzz/`, also replayed by `cargo test`
//!   over the kept regression inputs.
//! - [`replay_known_f64`]: the EKF replay most tests measure.

pub mod firmware;
pub mod fuzzing;

use host_sim::domain::config::Settings;
use host_sim::domain::recording::Recording;
use host_sim::domain::{AssociationMode, Precision};
use host_sim::drivers::ekf::ReplayRun;

/// `recording` through the landmark EKF-SLAM with known ids in `f64`, no progress bar:
/// the replay most tests measure.
pub fn replay_known_f64(recording: &Recording, settings: &Settings) -> ReplayRun {
    host_sim::drivers::ekf::replay(
        recording,
        settings,
        AssociationMode::Known,
        Precision::F64,
        None,
    )
    .expect("the replay completes")
}
