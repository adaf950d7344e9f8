//! The pose store: round trips, the turn to the other sector, refusals, and power cut at
//! every byte of a save (on flash written in words of 1, 4 and 8 bytes): the pose loaded
//! after the reset is the one before the save or the saved one, never another, and the
//! store goes on without programming a flash word twice.

use super::*;
use crate::testing::flash::{Cut, MockFlash};

/// Sectors of 256 bytes: 8 records each.
const SECTOR: u32 = 256;
type Flash<const W: usize> = MockFlash<W, 1, 256>;

fn pose(k: u32) -> Pose2<f32> {
    Pose2::new(k as f32 * 0.5, -(k as f32) * 0.25, 0.01 * k as f32)
}

fn open<const W: usize>(flash: Flash<W>) -> PoseStore<Flash<W>> {
    PoseStore::open(flash, 256, SECTOR).expect("the store opens")
}

/// A store that saved poses 0..n (checksum 7), reopened.
fn saved<const W: usize>(n: u32) -> Flash<W> {
    let mut store = open(Flash::<W>::new(1024));
    for k in 0..n {
        store.save(pose(k), 7).expect("saved");
    }
    store.into_inner()
}

#[test]
fn an_erased_store_has_no_pose_and_the_newest_save_wins() {
    let store = open(Flash::<4>::new(1024));
    assert_eq!(store.latest(), None);
    let flash = saved::<4>(3);
    let store = open(flash.reboot());
    assert_eq!(
        store.latest(),
        Some(SavedPose {
            pose: pose(2),
            map_checksum: 7,
            sequence: 2
        })
    );
    assert_eq!(store.latest_in(7), Some(pose(2)));
    // A pose saved in another map is not offered for this one.
    assert_eq!(store.latest_in(8), None);
    assert_eq!(store.torn_records(), 0);
    // Nothing outside the two sectors was touched.
    assert!(
        flash.mem[..256]
            .iter()
            .chain(&flash.mem[768..])
            .all(|&b| b == 0xFF)
    );
}

#[test]
fn saves_turn_to_the_other_sector_when_one_is_full_and_keep_the_newest() {
    // 8 records a sector: 30 saves fill sector 0, 1, 0 and half of 1 again.
    for n in [1, 8, 9, 16, 17, 30] {
        let flash = saved::<4>(n);
        assert_eq!(flash.double_writes, 0, "{n} saves");
        let mut store = open(flash.reboot());
        assert_eq!(store.latest().map(|s| s.sequence), Some(n - 1), "{n} saves");
        assert_eq!(store.latest_in(7), Some(pose(n - 1)));
        // Saving goes on after a reopen, in the right slot.
        store.save(pose(100), 9).expect("saved");
        let flash = store.into_inner();
        assert_eq!(flash.double_writes, 0);
        let store = open(flash.reboot());
        assert_eq!(store.latest_in(9), Some(pose(100)), "{n} saves");
        assert_eq!(store.latest().map(|s| s.sequence), Some(n));
    }
}

#[test]
fn bad_regions_and_poses_are_refused() {
    let flash = || Flash::<4>::new(1024);
    // Not on erase units; no record fits; past the flash's end.
    assert_eq!(
        PoseStore::open(flash(), 100, SECTOR).err(),
        Some(PoseStoreError::Misaligned)
    );
    assert_eq!(
        PoseStore::open(flash(), 0, 100).err(),
        Some(PoseStoreError::Misaligned)
    );
    assert_eq!(
        PoseStore::open(flash(), 768, SECTOR).err(),
        Some(PoseStoreError::OutOfBounds)
    );
    assert_eq!(
        PoseStore::open(flash(), 256, u32::MAX - 255).err(),
        Some(PoseStoreError::OutOfBounds)
    );
    // A write unit that does not divide a record.
    assert_eq!(
        PoseStore::open(MockFlash::<64, 1, 256>::new(1024), 0, SECTOR).err(),
        Some(PoseStoreError::Misaligned)
    );
    let mut store = open(flash());
    for bad in [f32::NAN, f32::INFINITY] {
        assert_eq!(
            store.save(Pose2::new(bad, 0.0, 0.0), 1),
            Err(PoseStoreError::NotFinite)
        );
        assert_eq!(
            store.save(Pose2::new(0.0, 0.0, bad), 1),
            Err(PoseStoreError::NotFinite)
        );
    }
    assert_eq!(store.latest(), None);
}

#[test]
fn a_corrupted_record_is_not_loaded_and_the_one_before_is() {
    let mut flash = saved::<4>(3);
    // The third record (slot 2 of sector 0 at 256): one bit of its x (1.0, 0x3F80_0000)
    // cleared.
    flash.mem[256 + 2 * RECORD_BYTES + 15] &= 0xFE;
    let store = open(flash.reboot());
    assert_eq!(store.latest_in(7), Some(pose(1)));
    assert_eq!(store.torn_records(), 1);
    // A record of another format version is not read either.
    let mut flash = saved::<4>(1);
    flash.mem[256 + 4] = 0;
    let store = open(flash.reboot());
    assert_eq!(store.latest(), None);
}

#[test]
fn the_sequence_number_orders_records_through_its_wrap() {
    assert!(newer(1, 0));
    assert!(newer(0, u32::MAX));
    assert!(!newer(u32::MAX, 0));
    assert!(!newer(5, 5));
}

/// Power cut at every byte of the save after `before` saves (which may erase the other
/// sector first), partly programmed or not, the flash off or only the write failing.
fn cut_every_byte<const W: usize>(before: u32) {
    let flash = saved::<W>(before);
    let erases_first = before > 0 && before.is_multiple_of(8);
    // The bytes programmed by the save: a record (the erase programs none).
    for after_bytes in 0..=RECORD_BYTES {
        for partial in [false, true] {
            for power_off in [true, false] {
                let mut flash = flash.reboot();
                flash.arm(Cut {
                    after_bytes,
                    partial,
                    power_off,
                });
                let mut store = open(flash);
                let result = store.save(pose(50), 7);
                let cut = store.into_inner();
                let completed = result.is_ok();
                let case = format!(
                    "W = {W}, {before} before, cut after {after_bytes} bytes (partial \
                     {partial}, off {power_off}, erase first {erases_first})"
                );
                let mut store = open(cut.reboot());
                // A completed save is loaded; a cut one leaves the pose before (or the
                // new one, when the cut byte happened to get all its bits).
                let got = store.latest_in(7);
                let before_pose = before.checked_sub(1).map(pose);
                assert!(
                    got == Some(pose(50)) || (!completed && got == before_pose),
                    "{case}: {got:?}"
                );
                if !completed && !partial {
                    assert_eq!(got, before_pose, "{case}");
                }
                // The store goes on: the next save is loaded, and no word was
                // programmed twice.
                store.save(pose(60), 7).expect(&case);
                let flash = store.into_inner();
                assert_eq!(flash.double_writes, 0, "{case}");
                assert_eq!(open(flash.reboot()).latest_in(7), Some(pose(60)), "{case}");
            }
        }
    }
}

#[test]
fn power_cut_at_any_byte_of_a_save_loads_the_pose_before_or_the_new_one() {
    for before in [0, 1, 5, 7, 8, 9, 16] {
        cut_every_byte::<1>(before);
        cut_every_byte::<4>(before);
        cut_every_byte::<8>(before);
    }
}

#[test]
fn poses_are_kept_after_a_saved_map_and_every_half_metre_or_half_radian_of_tracking() {
    use crate::wire::{Estimate, EstimatorKind, LocalizerReport, StepResult};
    let localization = |x: f32, theta: f32, state: TrackingState| ToHost::Localization {
        estimate: Estimate {
            seq: 1,
            stamp_us: 0,
            estimator: EstimatorKind::Localizer,
            result: StepResult::Applied,
            pose: [x, 0.0, theta],
            covariance: [0.0; 6],
            status: Default::default(),
            health: Default::default(),
        },
        localizer: LocalizerReport {
            state,
            ..LocalizerReport::default()
        },
    };
    let tracking = |x, theta| localization(x, theta, TrackingState::Tracking);
    // Mapping: nothing is kept before the map is saved (no map to be in).
    let mut keeping = PoseKeeping::new(None, None);
    assert_eq!(keeping.after(&tracking(3.0, 0.0)), None);
    let saved = ToHost::MapSaved {
        seq: 2,
        bytes: 100,
        checksum: 0xABCD,
        pose: [1.0, 2.0, 0.5],
    };
    assert_eq!(
        keeping.after(&saved),
        Some((Pose2::new(1.0, 2.0, 0.5), 0xABCD))
    );
    // Localizing from a pose loaded at boot: kept from 0.5 m or 0.5 rad on.
    let mut keeping = PoseKeeping::new(Some(7), Some(Pose2::new(0.0, 0.0, 0.0)));
    assert_eq!(keeping.after(&tracking(0.49, 0.0)), None);
    assert_eq!(keeping.after(&tracking(0.0, 0.49)), None);
    assert_eq!(
        keeping.after(&tracking(0.5, 0.0)),
        Some((Pose2::new(0.5, 0.0, 0.0), 7))
    );
    assert_eq!(keeping.after(&tracking(0.9, 0.0)), None);
    assert_eq!(
        keeping.after(&tracking(0.9, -0.5)),
        Some((Pose2::new(0.9, 0.0, -0.5), 7))
    );
    // Through ±π: a turn of 0.2 rad is not half a radian.
    let mut keeping = PoseKeeping::new(Some(7), Some(Pose2::new(0.0, 0.0, 3.1)));
    assert_eq!(keeping.after(&tracking(0.0, -3.08)), None);
    // Before a commanded restart: the newest tracked pose, once.
    let mut keeping = PoseKeeping::new(Some(7), Some(Pose2::new(0.0, 0.0, 0.0)));
    assert_eq!(keeping.before_restart(), None);
    assert_eq!(keeping.after(&tracking(0.3, 0.0)), None);
    assert_eq!(
        keeping.before_restart(),
        Some((Pose2::new(0.3, 0.0, 0.0), 7))
    );
    assert_eq!(keeping.before_restart(), None);
    // Lost or relocalizing: its pose is not where the robot is known to be.
    let mut keeping = PoseKeeping::new(Some(7), None);
    assert_eq!(
        keeping.after(&localization(5.0, 0.0, TrackingState::Lost)),
        None
    );
    assert!(keeping.after(&tracking(5.0, 0.0)).is_some());
}
