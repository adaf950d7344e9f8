//! Stored keyframes read back as end points.

use super::SlamError;
use crate::pf::ScanPoints;
use crate::sensors::lidar::LidarScan;
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore};

/// Loads keyframe `index` from `store` into `points` (robot-frame end points of its
/// stored beams), reading the ranges into `ranges`.
pub(super) fn load_stored<S: KeyframeStorage, const B: usize>(
    points: &mut ScanPoints<B>,
    ranges: &mut [f32; B],
    index: usize,
    store: &KeyframeStore<S>,
) -> Result<(), SlamError> {
    let beams = store.beams().min(B);
    let read = ranges.get_mut(..beams).unwrap_or(&mut []);
    store.read(u32::try_from(index).unwrap_or(u32::MAX), read)?;
    // The stored beams are every `decimation`-th of the scan: the same directions as a
    // scan of them alone with the increment times the decimation.
    let geometry = store.beam_geometry();
    points.load(
        &LidarScan::new(ranges.get(..beams).unwrap_or(&[]), geometry),
        1,
        0.0,
    );
    Ok(())
}
