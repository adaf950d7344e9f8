//! The robot's pose kept in flash by a firmware ([`KeptPose`]): the library's
//! [`PoseStore`] written by the library's rule ([`PoseKeeping`]) after every reply, and
//! the hook a firmware's `serve` calls after each reply ([`after_reply`]).

use embedded_storage::nor_flash::NorFlash;
use microslam::device::{PoseKeeping, PoseStore};
use microslam::wire::ToHost;

/// A pose store and when to write it.
pub struct KeptPose<F> {
    store: PoseStore<F>,
    keeping: PoseKeeping,
}

impl<F: NorFlash> KeptPose<F> {
    /// Keeping poses in `store` for the map with CRC-32 `map_checksum` (`None` while
    /// mapping); the newest pose the store holds for that map counts as written.
    pub fn new(store: PoseStore<F>, map_checksum: Option<u32>) -> Self {
        let last = map_checksum.and_then(|crc| store.latest_in(crc));
        Self {
            store,
            keeping: PoseKeeping::new(map_checksum, last),
        }
    }

    /// Writes what [`PoseKeeping`] says after `reply`, and before a reset the firmware was
    /// told to make (`restarting`). A failed write is logged: the pose before it stays
    /// the saved one.
    pub fn after_reply(&mut self, reply: &ToHost, restarting: bool) {
        let writes = [
            self.keeping.after(reply),
            restarting.then(|| self.keeping.before_restart()).flatten(),
        ];
        for (pose, map) in writes.into_iter().flatten() {
            if let Err(e) = self.store.save(pose, map) {
                defmt::warn!("pose not kept: {}", e);
            }
        }
    }
}

/// What a firmware's `serve` calls after each reply: `kept`'s
/// [`KeptPose::after_reply`], or nothing when the firmware keeps no pose.
pub fn after_reply<F: NorFlash>(mut kept: Option<KeptPose<F>>) -> impl FnMut(&ToHost, bool) {
    move |reply: &ToHost, restarting: bool| {
        if let Some(kept) = kept.as_mut() {
            kept.after_reply(reply, restarting);
        }
    }
}

/// The pose store in the board's flash (two sectors of [`crate::board::POSE_SECTOR_BYTES`]:
/// QEMU's stand-in, or sectors 1 and 2 of the STM32F411 in the building-slam build);
/// `None`, logged, when the sectors are taken or the store refuses them: the firmware
/// then keeps no pose.
#[cfg(any(feature = "qemu", feature = "building-slam"))]
pub fn store() -> Option<PoseStore<crate::board::PoseFlash>> {
    use crate::board::{POSE_SECTOR_BYTES, pose_flash};
    let store = pose_flash().and_then(|flash| PoseStore::open(flash, 0, POSE_SECTOR_BYTES).ok());
    if store.is_none() {
        defmt::error!("pose store refused: poses are not kept");
    }
    store
}
