//! Helpers of the cross-crate tests (the tests themselves are in `tests/tests/*.rs`).
//!
//! - [`firmware`]: runs the firmware of `firmware-example` under QEMU, streams wire frames
//!   to its UART and collects its replies; the same bytes through a host
//!   [`microslam::wire::Session`] give the reference it must equal.
//! - [`fuzzing`]: the checks of the fuzz targets in `fuzz/`, also replayed by `cargo test`
//!   over the kept regression inputs.

pub mod firmware;
pub mod fuzzing;
