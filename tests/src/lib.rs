//! Helpers of the cross-crate tests (the tests themselves are in `tests/tests/*.rs`).
//!
//! - [`firmware`]: runs the firmware of `firmware-example` under QEMU, streams wire frames
//!   to its UART and collects its replies; the same bytes through a host
//!   [`microslam::wire::Session`] give the reference it must equal.

pub mod firmware;
