//! Stored keyframes read back as end points.

use super::{GraphSlam, SlamError};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore};

impl<
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>
{
    /// Loads keyframe `index` from `store` into `self.stored` (robot-frame end points of
    /// its stored beams).
    pub(super) fn load_stored<S: KeyframeStorage>(
        &mut self,
        index: usize,
        store: &KeyframeStore<S>,
    ) -> Result<(), SlamError> {
        let beams = store.beams().min(B);
        let ranges = self.ranges.get_mut(..beams).unwrap_or(&mut []);
        store.read(u32::try_from(index).unwrap_or(u32::MAX), ranges)?;
        // The stored beams are every `decimation`-th of the scan: the same directions as a
        // scan of them alone with the increment times the decimation.
        let lidar = store.lidar();
        let geometry = LidarGeometry {
            angle_increment: lidar.angle_increment * store.decimation() as f32,
            ..lidar
        };
        self.stored.load(
            &LidarScan::new(self.ranges.get(..beams).unwrap_or(&[]), geometry),
            1,
            0.0,
        );
        Ok(())
    }
}
