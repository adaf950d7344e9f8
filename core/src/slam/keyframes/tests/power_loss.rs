//! Power cut at every byte of an append and of a store's creation, on flash written in
//! words of 1, 4 and 8 bytes and read in units of 1 and 4: `open` afterwards finds
//! exactly the keyframes completed before the cut, never a torn one, and appending goes
//! on without programming any flash word twice.

use super::{append_k, assert_keyframe, image, lidar};
use crate::slam::keyframes::*;
use crate::testing::flash::{Cut, MockFlash};

/// 73 beams (scans of 146 at decimation 2): records of 182 bytes in 184-byte slots, so
/// the last flash word of a record is padded.
const BEAMS: usize = 73;
const SCAN: usize = 146;
const RECORD: usize = 182;
const SLOT: usize = 184;
const REGION: u32 = 2048;
/// Keyframes in the store before the one that is cut.
const BEFORE: u32 = 2;
/// Where the cut record's slot starts.
const CUT_SLOT: usize = 56 + BEFORE as usize * SLOT;

type Flash<const W: usize, const R: usize> = MockFlash<W, R, 256>;

fn storage<const W: usize, const R: usize>(flash: Flash<W, R>) -> NorFlashStorage<Flash<W, R>> {
    NorFlashStorage::new(flash, 0, REGION).unwrap()
}

fn open<const W: usize, const R: usize>(
    flash: Flash<W, R>,
) -> KeyframeStore<NorFlashStorage<Flash<W, R>>> {
    KeyframeStore::open(storage(flash)).unwrap()
}

/// The flash holding `BEFORE` keyframes, and the bytes it holds once one more is
/// appended without a cut.
fn before_and_after<const W: usize, const R: usize>() -> (Flash<W, R>, Vec<u8>) {
    let flash = Flash::<W, R>::new(REGION as usize);
    let mut store = KeyframeStore::create(storage(flash), &lidar(), 2, BEAMS).unwrap();
    for k in 0..BEFORE {
        append_k(&mut store, k, SCAN).unwrap();
    }
    let before = store.into_storage().into_inner();
    let mut store = open(before.reboot());
    append_k(&mut store, BEFORE, SCAN).unwrap();
    (before, store.into_storage().into_inner().mem)
}

/// `(whole, erased)`: the cut record's bytes are those of an uncut append; its slot
/// is still erased.
fn slot_state(mem: &[u8], golden: &[u8]) -> (bool, bool) {
    let whole = mem[CUT_SLOT..CUT_SLOT + RECORD] == golden[CUT_SLOT..CUT_SLOT + RECORD];
    let erased = mem[CUT_SLOT..CUT_SLOT + SLOT].iter().all(|&b| b == 0xFF);
    (whole, erased)
}

/// Power off at every byte of the third append, then a reset.
fn cut_and_reset_at_every_byte<const W: usize, const R: usize>(partial: bool) {
    let (before, golden) = before_and_after::<W, R>();
    for cut in 0..=SLOT {
        let mut flash = before.reboot();
        flash.arm(Cut {
            after_bytes: cut,
            partial,
            power_off: true,
        });
        let mut store = open(flash);
        let result = append_k(&mut store, BEFORE, SCAN);
        let flash = store.into_storage().into_inner();
        let cut_happened = !flash.armed();
        assert_eq!(result.is_ok(), !cut_happened, "W {W} R {R} cut {cut}");
        // Only the cut record's slot changed.
        assert_eq!(flash.mem[..CUT_SLOT], before.mem[..CUT_SLOT]);
        assert_eq!(flash.mem[CUT_SLOT + SLOT..], before.mem[CUT_SLOT + SLOT..]);
        let (whole, erased) = slot_state(&flash.mem, &golden);
        if cut + 4 < RECORD {
            assert!(!whole, "the test cut inside the record at {cut}");
        }

        // The reset: the same bytes, the same programmed words.
        let mut store = open(flash.reboot());
        let found = BEFORE + u32::from(whole);
        assert_eq!(
            store.len(),
            found,
            "W {W} R {R} cut {cut} partial {partial}"
        );
        assert_eq!(store.torn_records(), usize::from(!whole && !erased));
        assert_eq!(store.append_refused(), None);
        for k in 0..found {
            assert_keyframe(&store, k, SCAN);
        }
        // Mapping goes on: the next keyframe goes after the torn slot, if any.
        assert_eq!(append_k(&mut store, found, SCAN), Ok(found));
        let flash = store.into_storage().into_inner();
        assert_eq!((flash.double_writes, flash.misaligned), (0, 0), "cut {cut}");
        let store = open(flash.reboot());
        assert_eq!(store.len(), found + 1);
        for k in 0..=found {
            assert_keyframe(&store, k, SCAN);
        }
    }
}

/// A write that fails at every byte with the power on (a driver error): the store reads
/// the slot back and goes on in the same session.
fn transient_failure_at_every_byte<const W: usize, const R: usize>() {
    let (before, golden) = before_and_after::<W, R>();
    // The bytes an append programs: the record, and its padding on flash with words.
    let programmed = if W == 1 { RECORD } else { SLOT };
    for cut in 0..programmed {
        let mut flash = before.reboot();
        flash.arm(Cut {
            after_bytes: cut,
            partial: true,
            power_off: false,
        });
        let mut store = open(flash);
        let result = append_k(&mut store, BEFORE, SCAN);
        let mem = image(store.storage());
        let (whole, erased) = slot_state(&mem, &golden);
        // A record that reads back whole was appended, whatever the driver said.
        let expected = if whole {
            Ok(BEFORE)
        } else {
            Err(StoreError::Storage)
        };
        assert_eq!(result, expected, "W {W} R {R} cut {cut}");
        assert_eq!(store.torn_records(), usize::from(!whole && !erased));
        let next = store.len();
        assert_eq!(next, BEFORE + u32::from(whole));
        assert_eq!(append_k(&mut store, next, SCAN), Ok(next));
        assert_eq!(append_k(&mut store, next + 1, SCAN), Ok(next + 1));
        let flash = store.into_storage().into_inner();
        assert!(!flash.armed(), "the write failed at {cut}");
        assert_eq!((flash.double_writes, flash.misaligned), (0, 0), "cut {cut}");
        let store = open(flash.reboot());
        assert_eq!(store.len(), next + 2);
        for k in 0..next + 2 {
            assert_keyframe(&store, k, SCAN);
        }
    }
}

#[test]
fn power_cut_at_every_byte_of_an_append() {
    for partial in [false, true] {
        cut_and_reset_at_every_byte::<1, 1>(partial);
        cut_and_reset_at_every_byte::<4, 1>(partial);
        cut_and_reset_at_every_byte::<8, 1>(partial);
        cut_and_reset_at_every_byte::<1, 4>(partial);
        cut_and_reset_at_every_byte::<4, 4>(partial);
        cut_and_reset_at_every_byte::<8, 4>(partial);
    }
}

#[test]
fn write_failure_at_every_byte_of_an_append() {
    transient_failure_at_every_byte::<1, 1>();
    transient_failure_at_every_byte::<4, 1>();
    transient_failure_at_every_byte::<8, 4>();
}

#[test]
fn a_torn_header_is_never_a_store() {
    for partial in [false, true] {
        for cut in 0..=HEADER_BYTES {
            let mut flash = Flash::<4, 1>::new(1024);
            flash.arm(Cut {
                after_bytes: cut,
                partial,
                power_off: true,
            });
            let mut storage = NorFlashStorage::new(flash, 0, 1024).unwrap();
            // Through `&mut`, so that the storage is still ours when `create` fails.
            let created = KeyframeStore::create(&mut storage, &lidar(), 1, 20).map(|_| ());
            let flash = storage.into_inner().reboot();
            let opened = KeyframeStore::open(NorFlashStorage::new(flash, 0, 1024).unwrap());
            if cut == HEADER_BYTES {
                assert_eq!(created, Ok(()));
                assert_eq!(opened.map(|s| s.len()), Ok(0));
            } else {
                assert_eq!(created, Err(StoreError::Storage), "cut {cut}");
                let error = opened.err();
                assert!(
                    matches!(
                        error,
                        Some(
                            StoreError::NoStore
                                | StoreError::BadMagic
                                | StoreError::UnsupportedVersion
                                | StoreError::BadHeader
                                | StoreError::HeaderChecksum
                        )
                    ),
                    "cut {cut}: {error:?}"
                );
            }
        }
    }
}

#[test]
fn past_max_torn_records_appends_are_refused_and_reads_go_on() {
    let flash = Flash::<4, 1>::new(4096);
    let storage = NorFlashStorage::new(flash, 0, 4096).unwrap();
    let mut store = KeyframeStore::create(storage, &lidar(), 2, BEAMS).unwrap();
    for k in 0..BEFORE {
        append_k(&mut store, k, SCAN).unwrap();
    }
    let mut flash = store.into_storage().into_inner();
    for torn in 0..=MAX_TORN_RECORDS {
        let mut rebooted = flash.reboot();
        rebooted.arm(Cut {
            after_bytes: 5,
            partial: true,
            power_off: true,
        });
        let mut store =
            KeyframeStore::open(NorFlashStorage::new(rebooted, 0, 4096).unwrap()).unwrap();
        assert_eq!((store.len(), store.torn_records()), (BEFORE, torn));
        assert_eq!(append_k(&mut store, BEFORE, SCAN), Err(StoreError::Storage));
        flash = store.into_storage().into_inner();
    }
    let mut store =
        KeyframeStore::open(NorFlashStorage::new(flash.reboot(), 0, 4096).unwrap()).unwrap();
    assert_eq!(store.len(), BEFORE);
    assert_eq!(store.torn_records(), MAX_TORN_RECORDS);
    assert_eq!(store.append_refused(), Some(StoreError::TooManyTorn));
    assert_eq!(
        append_k(&mut store, BEFORE, SCAN),
        Err(StoreError::TooManyTorn)
    );
    for k in 0..BEFORE {
        assert_keyframe(&store, k, SCAN);
    }
    assert_eq!(store.into_storage().into_inner().double_writes, 0);
}

#[test]
fn a_whole_record_out_of_sequence_ends_the_store() {
    let mut store = KeyframeStore::create(RamStorage::<2048>::new(), &lidar(), 2, BEAMS).unwrap();
    for k in 0..3 {
        append_k(&mut store, k, SCAN).unwrap();
    }
    // Slot 2 gets a copy of record 1: whole, but index 1 where 2 is due.
    let mut bytes = image(store.storage());
    let (one, two) = (56 + SLOT, 56 + 2 * SLOT);
    bytes.copy_within(one..one + SLOT, two);
    let mut ram = RamStorage::<2048>::new();
    ram.load_image(&bytes).unwrap();
    let mut store = KeyframeStore::open(ram).unwrap();
    assert_eq!(store.len(), 2);
    assert_eq!(store.append_refused(), Some(StoreError::Damaged));
    assert_eq!(append_k(&mut store, 2, SCAN), Err(StoreError::Damaged));
    assert_keyframe(&store, 0, SCAN);
    assert_keyframe(&store, 1, SCAN);
}

#[test]
fn a_record_of_another_store_is_not_taken() {
    // Two stores that differ in the lidar's minimum range only.
    let other = crate::sensors::lidar::LidarGeometry {
        min_range: 0.05,
        ..lidar()
    };
    let mut ours = KeyframeStore::create(RamStorage::<1024>::new(), &lidar(), 2, BEAMS).unwrap();
    let mut theirs = KeyframeStore::create(RamStorage::<1024>::new(), &other, 2, BEAMS).unwrap();
    append_k(&mut ours, 0, SCAN).unwrap();
    append_k(&mut theirs, 0, SCAN).unwrap();
    let mut bytes = image(ours.storage());
    let record = 56..56 + SLOT;
    bytes[record.clone()].copy_from_slice(&image(theirs.storage())[record]);
    let mut ram = RamStorage::<1024>::new();
    ram.load_image(&bytes).unwrap();
    let store = KeyframeStore::open(ram).unwrap();
    assert_eq!((store.len(), store.torn_records()), (0, 1));
}
