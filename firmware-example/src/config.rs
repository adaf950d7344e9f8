//! Estimator settings of the firmware: the reference board profile
//! ([`microslam::profile`], which the host reference of `host-sim hil` uses too) and the
//! map embedded at build time.

pub use microslam::profile::*;

/// The map image embedded by `build.rs` (`MICROSLAM_MAP`), in `.rodata`: empty when the
/// firmware was built without a map. Checked at boot with
/// [`microslam::grid::MapImage::parse`].
pub static MAP_IMAGE: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/map.bin"));

include!(concat!(env!("OUT_DIR"), "/map_rows.rs"));
