//! Tests of the keyframe store: round trips, sizes, header checks, a full store, the
//! storage adapters. Power loss is in `tests/power_loss.rs`, property tests in
//! `tests/properties.rs`; `crate::testing::flash` is the NOR flash they run on.

use super::*;
use crate::geometry::Pose2;
use crate::pf::ScanPoints;
use crate::sensors::lidar::{Beam, LidarGeometry, LidarScan};
use core::cell::Cell;

mod power_loss;
mod properties;

use crate::testing::flash::MockFlash;

/// A lidar with a mount offset, 0.1–30 m, no return from 31 m.
pub(super) fn lidar() -> LidarGeometry {
    LidarGeometry {
        first_angle: -1.5,
        angle_increment: 0.0175,
        min_range: 0.1,
        max_range: 30.0,
        no_return_range: 31.0,
        mount: Pose2::new(0.2, -0.01, 0.03),
    }
}

/// Scan `k` of `len` ranges: whole millimetres between 0.1 and 29.1 m, which read back
/// bit for bit, and every seventh beam NaN.
pub(super) fn scan(k: u32, len: usize) -> Vec<f32> {
    (0..len)
        .map(|i| {
            if (i + k as usize) % 7 == 3 {
                f32::NAN
            } else {
                let mm = (500 + 37 * i + 101 * k as usize) % 29_000 + 100;
                mm as f32 / 1000.0
            }
        })
        .collect()
}

/// The pose of keyframe `k`.
pub(super) fn pose(k: u32) -> Pose2<f32> {
    Pose2::new(
        k as f32 * 0.5 + 0.25,
        -(k as f32) * 0.125,
        0.1 * k as f32 - 3.0,
    )
}

/// The motion into keyframe `k`.
pub(super) fn motion(k: u32) -> Pose2<f32> {
    Pose2::new(0.5, 0.0625 * k as f32, -0.01)
}

fn bits(p: &Pose2<f32>) -> [u32; 3] {
    [p.x.to_bits(), p.y.to_bits(), p.theta.to_bits()]
}

/// Appends keyframe `k` (scan of `scan_len`, motion and pose `k`).
pub(super) fn append_k<S: KeyframeStorage>(
    store: &mut KeyframeStore<S>,
    k: u32,
    scan_len: usize,
) -> Result<u32, StoreError> {
    let ranges = scan(k, scan_len);
    store.append(&Keyframe::new(motion(k), pose(k), &ranges))
}

/// Checks that keyframe `k` reads back as appended: poses bit for bit, every kept range
/// bit for bit (they are whole millimetres), NaN where it was NaN.
pub(super) fn assert_keyframe<S: KeyframeStorage>(
    store: &KeyframeStore<S>,
    k: u32,
    scan_len: usize,
) {
    let expected = scan(k, scan_len);
    let mut ranges = vec![0.0f32; store.beams()];
    let meta = store.read(k, &mut ranges).expect("keyframe reads");
    assert_eq!(meta.index, k);
    assert_eq!(bits(&meta.motion), bits(&motion(k)), "motion of {k}");
    assert_eq!(bits(&meta.pose), bits(&pose(k)), "pose of {k}");
    for (j, r) in ranges.iter().enumerate() {
        let e = expected[j * store.decimation()];
        assert!(
            r.to_bits() == e.to_bits() || (r.is_nan() && e.is_nan()),
            "keyframe {k} beam {j}: {r} != {e}"
        );
    }
}

/// The storage's bytes.
pub(super) fn image<S: KeyframeStorage>(storage: &S) -> Vec<u8> {
    let mut bytes = vec![0u8; storage.capacity()];
    storage.read(0, &mut bytes).unwrap();
    bytes
}

fn ram_from<const N: usize>(image: &[u8]) -> RamStorage<N> {
    let mut ram = RamStorage::<N>::new();
    ram.load_image(image).unwrap();
    ram
}

#[test]
fn ranges_round_trip_within_a_millimetre_and_missing_stays_missing() {
    // A minimum range between millimetres, ranges kept up to 80 m.
    let g = LidarGeometry {
        min_range: 0.1003,
        max_range: 80.0,
        no_return_range: 81.8,
        ..lidar()
    };
    // (range, Some(expected read-back) or None for missing), expected values by hand.
    let cases: Vec<(f32, Option<f32>)> = vec![
        (1.2344, Some(1.234)),
        (1.2346, Some(1.235)),
        (0.5006, Some(0.501)),
        (12.0, Some(12.0)),
        (0.1003, Some(0.101)), // 0.100 would read back below min_range: the next mm up
        (0.1004, Some(0.101)),
        (0.1002, None), // below min_range
        (0.1, None),
        (65.534, Some(65.534)),
        (65.5344, Some(65.534)),
        (65.5346, None), // usable, but beyond 65.534 m
        (79.9, None),
        (80.0, None), // at max_range
        (81.8, None), // the no-return code
        (f32::NAN, None),
        (f32::INFINITY, None),
        (f32::NEG_INFINITY, None),
        (-1.0, None),
        (-0.0, None),
        (f32::MAX, None),
    ];
    let ranges: Vec<f32> = cases.iter().map(|c| c.0).collect();
    let mut store = KeyframeStore::create(RamStorage::<1024>::new(), &g, 1, cases.len()).unwrap();
    store
        .append(&Keyframe::new(motion(0), pose(0), &ranges))
        .unwrap();
    let mut back = vec![0.0f32; cases.len()];
    store.read(0, &mut back).unwrap();
    for ((range, expected), r) in cases.iter().zip(back) {
        match expected {
            Some(e) => {
                assert!((r - e).abs() < 1e-6, "{range} read back as {r}, not {e}");
                assert!(
                    (r - range).abs() <= 1.0e-3 + 1e-6,
                    "{range} moved by > 1 mm"
                );
            }
            None => assert!(r.is_nan(), "{range} read back as {r}, not missing"),
        }
    }
    // Near max_range 30 m: rounding up to 30.000 would make the beam unusable.
    let mut near = KeyframeStore::create(RamStorage::<512>::new(), &lidar(), 1, 2).unwrap();
    near.append(&Keyframe::new(motion(0), pose(0), &[29.9996, 29.9994]))
        .unwrap();
    let mut back = [0.0f32; 2];
    near.read(0, &mut back).unwrap();
    assert_eq!(back, [29.999, 29.999]);
}

#[test]
fn poses_and_geometry_come_back_bit_for_bit() {
    let g = LidarGeometry {
        first_angle: -0.0,
        mount: Pose2::new(f32::MIN_POSITIVE / 4.0, -1.0e30, 3.0e-41),
        ..lidar()
    };
    let mut store = KeyframeStore::create(RamStorage::<1024>::new(), &g, 3, 5).unwrap();
    let odd = Pose2::new(-0.0, f32::MIN_POSITIVE / 2.0, -3.402_823_5e38);
    let ranges = [1.0f32; 13];
    store.append(&Keyframe::new(odd, odd, &ranges)).unwrap();
    let store = KeyframeStore::open(store.into_storage()).unwrap();
    let meta = store.meta(0).unwrap();
    assert_eq!(
        (bits(&meta.motion), bits(&meta.pose)),
        (bits(&odd), bits(&odd))
    );
    let back = store.lidar();
    assert_eq!(back.first_angle.to_bits(), (-0.0f32).to_bits());
    assert_eq!(bits(&back.mount), bits(&g.mount));
    assert_eq!(back, g);
    assert_eq!(
        (store.decimation(), store.beams(), store.scan_len()),
        (3, 5, 13)
    );
}

#[test]
fn open_finds_every_record_appended() {
    for k in 0..6u32 {
        let mut store = KeyframeStore::create(RamStorage::<2048>::new(), &lidar(), 2, 45).unwrap();
        for i in 0..k {
            assert_eq!(append_k(&mut store, i, 90), Ok(i));
        }
        let store = KeyframeStore::open(store.into_storage()).unwrap();
        assert_eq!(store.len(), k);
        assert_eq!(store.is_empty(), k == 0);
        assert_eq!(store.torn_records(), 0);
        assert_eq!(store.append_refused(), None);
        for i in 0..k {
            assert_keyframe(&store, i, 90);
        }
        assert_eq!(
            store.meta(k).err(),
            Some(StoreError::NoKeyframe),
            "past the end"
        );
    }
}

#[test]
fn open_names_what_is_wrong_with_the_header() {
    assert_eq!(
        KeyframeStore::open(RamStorage::<1024>::new()).err(),
        Some(StoreError::NoStore)
    );
    let mut store = KeyframeStore::create(RamStorage::<1024>::new(), &lidar(), 1, 20).unwrap();
    append_k(&mut store, 0, 20).unwrap();
    let good = image(store.storage());
    let with = |at: usize, value: u8| {
        let mut bytes = good.clone();
        bytes[at] = value;
        KeyframeStore::open(ram_from::<1024>(&bytes)).err()
    };
    assert_eq!(with(0, b'X'), Some(StoreError::BadMagic));
    assert_eq!(with(3, b'G'), Some(StoreError::BadMagic));
    assert_eq!(with(4, 2), Some(StoreError::UnsupportedVersion));
    assert_eq!(with(5, 1), Some(StoreError::UnsupportedVersion));
    assert_eq!(with(6, 64), Some(StoreError::BadHeader));
    // Any other byte of the header, the CRC included: the checksum.
    for (at, byte) in good.iter().enumerate().take(HEADER_BYTES).skip(8) {
        assert_eq!(
            with(at, byte ^ 0x04),
            Some(StoreError::HeaderChecksum),
            "byte {at}"
        );
    }
    assert!(KeyframeStore::open(ram_from::<1024>(&good)).is_ok());
    assert_eq!(
        KeyframeStore::open(RamStorage::<40>::new()).err(),
        Some(StoreError::TooSmall)
    );
}

#[test]
fn a_full_store_refuses_and_writes_nothing() {
    // Exactly the header and three 216-byte slots.
    let mut store = KeyframeStore::create(RamStorage::<704>::new(), &lidar(), 1, 90).unwrap();
    assert_eq!((store.capacity(), store.remaining()), (3, 3));
    for k in 0..3 {
        assert_eq!(append_k(&mut store, k, 90), Ok(k));
    }
    assert_eq!(store.remaining(), 0);
    let before = image(store.storage());
    assert_eq!(append_k(&mut store, 3, 90), Err(StoreError::Full));
    assert_eq!(image(store.storage()), before);
    assert_eq!(store.len(), 3);
    let store = KeyframeStore::open(store.into_storage()).unwrap();
    assert_eq!(store.len(), 3);
    for k in 0..3 {
        assert_keyframe(&store, k, 90);
    }
    // One byte short of three slots: two.
    let store = KeyframeStore::create(RamStorage::<703>::new(), &lidar(), 1, 90).unwrap();
    assert_eq!(store.capacity(), 2);
    assert_eq!(
        KeyframeStore::create(RamStorage::<271>::new(), &lidar(), 1, 90).err(),
        Some(StoreError::TooSmall)
    );
}

#[test]
fn bytes_per_record_and_header_are_as_documented() {
    assert_eq!(HEADER_BYTES, 56);
    assert_eq!((record_bytes(90), slot_bytes(90)), (216, 216));
    assert_eq!((record_bytes(73), slot_bytes(73)), (182, 184));
    assert_eq!((record_bytes(181), slot_bytes(181)), (398, 400));
    assert_eq!(store_bytes(90, 10), 56 + 2160);
    // 128 KB of flash: the module documentation's table.
    let in_128k = |beams| (128 * 1024 - 56) / slot_bytes(beams);
    assert_eq!((in_128k(73), in_128k(90), in_128k(181)), (712, 606, 327));

    // What a store really takes: the last programmed byte of two 90-beam records.
    let mut store = KeyframeStore::create(RamStorage::<1024>::new(), &lidar(), 2, 90).unwrap();
    assert_eq!(store.slot_bytes(), 216);
    for k in 0..2 {
        append_k(&mut store, k, 180).unwrap();
    }
    let bytes = image(store.storage());
    assert_eq!(&bytes[..4], b"MSKF");
    assert_eq!(&bytes[56..58], b"KF");
    assert_eq!(&bytes[56 + 216..56 + 218], b"KF");
    let used = bytes.iter().rposition(|&b| b != 0xFF).unwrap() + 1;
    // The last record's CRC ends the store; it may end in 0xFF bytes itself.
    assert!(used <= 56 + 2 * 216 && used > 56 + 2 * 216 - 4, "{used}");

    // 73 beams on flash written in 4-byte words: slots of 184 bytes, all erased padding.
    let flash = MockFlash::<4, 1, 256>::new(1024);
    let storage = NorFlashStorage::new(flash, 0, 1024).unwrap();
    let mut store = KeyframeStore::create(storage, &lidar(), 1, 73).unwrap();
    assert_eq!(store.slot_bytes(), 184);
    for k in 0..2 {
        append_k(&mut store, k, 73).unwrap();
    }
    let mem = store.into_storage().into_inner().mem;
    assert_eq!(&mem[56..58], b"KF");
    assert_eq!(&mem[240..242], b"KF");
    assert_eq!(&mem[56 + 182..56 + 184], &[0xFF, 0xFF]);
    assert!(mem[56 + 368..].iter().all(|&b| b == 0xFF));

    // The RAM of a store besides its storage, as the struct documentation says.
    assert_eq!(core::mem::size_of::<KeyframeStore<()>>(), 96);
}

#[test]
fn read_scan_gives_the_points_the_filter_saw() {
    let g = LidarGeometry::CARMEN_SICK_180;
    for (len, decimation) in [(181usize, 2usize), (180, 2), (181, 3), (90, 1)] {
        let beams = len.div_ceil(decimation);
        let mut store =
            KeyframeStore::create(RamStorage::<4096>::new(), &g, decimation, beams).unwrap();
        // Whole millimetres (as stored), a few unusable readings among them.
        let mut live = scan(4, len);
        live[0] = 81.9;
        live[len - 1] = 0.05;
        store
            .append(&Keyframe::new(motion(4), pose(4), &live))
            .unwrap();
        let mut back = vec![0.0f32; len];
        store.read_scan(0, &mut back).unwrap();
        let want: Vec<Beam> = LidarScan::new(&live, g).beams(decimation).collect();
        let got: Vec<Beam> = LidarScan::new(&back, g).beams(decimation).collect();
        assert!(!want.is_empty());
        assert_eq!(want, got, "{len} beams, decimation {decimation}");
        for (w, b) in want.iter().zip(&got) {
            assert_eq!(w.robot_point.0.to_bits(), b.robot_point.0.to_bits());
            assert_eq!(w.robot_point.1.to_bits(), b.robot_point.1.to_bits());
        }
        // The filter's own path: the same scan points.
        let (mut a, mut b) = (ScanPoints::<200>::new(), ScanPoints::<200>::new());
        a.load(&LidarScan::new(&live, g), decimation, 1.0);
        b.load(&LidarScan::new(&back, g), decimation, 1.0);
        assert_eq!(a.as_slice(), b.as_slice());
        // Entries between kept beams are NaN.
        if decimation > 1 {
            assert!(back[1].is_nan());
        }
    }
}

#[test]
fn bad_inputs_are_refused_and_change_nothing() {
    let g = lidar();
    let ram = || RamStorage::<1024>::new();
    let invalid = LidarGeometry {
        max_range: 0.0,
        ..g
    };
    for (geometry, decimation, beams) in [(invalid, 1, 10), (g, 0, 10), (g, 1, 0), (g, 70_000, 1)] {
        assert_eq!(
            KeyframeStore::create(ram(), &geometry, decimation, beams).err(),
            Some(StoreError::InvalidGeometry)
        );
    }
    let mut store = KeyframeStore::create(ram(), &g, 2, 10).unwrap();
    let before = image(store.storage());
    let ok = [1.0f32; 20];
    let nan = Pose2::new(0.0, f32::NAN, 0.0);
    let inf = Pose2::new(f32::INFINITY, 0.0, 0.0);
    let cases = [
        (
            Keyframe::new(motion(0), pose(0), &ok[..18]),
            StoreError::BeamCount,
        ),
        (
            Keyframe::new(motion(0), pose(0), &ok[..0]),
            StoreError::BeamCount,
        ),
        (Keyframe::new(nan, pose(0), &ok), StoreError::NonFinitePose),
        (
            Keyframe::new(motion(0), inf, &ok),
            StoreError::NonFinitePose,
        ),
    ];
    for (keyframe, error) in cases {
        assert_eq!(store.append(&keyframe), Err(error));
    }
    assert_eq!(image(store.storage()), before);
    assert!(store.is_empty());
    // 19 ranges at decimation 2 are 10 beams too: the last scan beam is kept.
    assert_eq!(
        store.append(&Keyframe::new(motion(0), pose(0), &ok[..19])),
        Ok(0)
    );
    let mut short = [0.0f32; 9];
    assert_eq!(store.read(0, &mut short), Err(StoreError::BufferTooShort));
    let mut short_scan = [0.0f32; 18];
    assert_eq!(
        store.read_scan(0, &mut short_scan),
        Err(StoreError::BufferTooShort)
    );
    let mut ranges = [0.0f32; 10];
    assert_eq!(store.read(1, &mut ranges), Err(StoreError::NoKeyframe));
}

/// RAM storage whose reads flip one byte, as if the flash changed after `open`.
struct FlipOnRead {
    ram: RamStorage<1024>,
    flip: Cell<Option<usize>>,
}

impl KeyframeStorage for FlipOnRead {
    fn capacity(&self) -> usize {
        self.ram.capacity()
    }

    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        self.ram.read(offset, bytes)?;
        if let Some(at) = self.flip.get()
            && let Some(b) = at.checked_sub(offset).and_then(|i| bytes.get_mut(i))
        {
            *b ^= 0x01;
        }
        Ok(())
    }

    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        self.ram.write(offset, bytes)
    }

    fn erase_all(&mut self) -> Result<(), StoreError> {
        self.ram.erase_all()
    }
}

#[test]
fn a_record_that_changed_after_open_reads_as_corrupt() {
    let storage = FlipOnRead {
        ram: RamStorage::new(),
        flip: Cell::new(None),
    };
    let mut store = KeyframeStore::create(storage, &lidar(), 1, 20).unwrap();
    for k in 0..3 {
        append_k(&mut store, k, 20).unwrap();
    }
    let record = record_bytes(20);
    let slot = slot_bytes(20);
    // Every byte of record 1, its CRC included.
    for at in 0..record {
        store.storage().flip.set(Some(56 + slot + at));
        let mut ranges = [0.0f32; 20];
        assert_eq!(store.read(1, &mut ranges), Err(StoreError::Corrupt), "{at}");
        assert!(ranges.iter().all(|r| r.is_nan()));
        let mut scan = [0.0f32; 20];
        assert_eq!(store.read_scan(1, &mut scan), Err(StoreError::Corrupt));
        assert!(scan.iter().all(|r| r.is_nan()));
        assert_keyframe(&store, 0, 20);
        assert_keyframe(&store, 2, 20);
    }
    store.storage().flip.set(None);
    assert_keyframe(&store, 1, 20);
}

#[test]
fn ram_storage_keeps_the_flash_rules() {
    let mut ram = RamStorage::<16>::new();
    let mut bytes = [0u8; 16];
    ram.read(0, &mut bytes).unwrap();
    assert_eq!(bytes, [0xFF; 16]);
    ram.write(2, &[1, 2, 3]).unwrap();
    assert_eq!(ram.write(4, &[9]), Err(StoreError::NotErased));
    assert_eq!(ram.write(15, &[1, 2]), Err(StoreError::OutOfBounds));
    assert_eq!(
        ram.read(usize::MAX, &mut bytes[..2]),
        Err(StoreError::OutOfBounds)
    );
    ram.read(0, &mut bytes[..6]).unwrap();
    assert_eq!(bytes[..6], [0xFF, 0xFF, 1, 2, 3, 0xFF]);
    ram.erase_all().unwrap();
    ram.write(4, &[9]).unwrap();
    assert_eq!(ram.load_image(&[0; 17]), Err(StoreError::OutOfBounds));
    ram.load_image(&[7, 8]).unwrap();
    ram.read(0, &mut bytes).unwrap();
    assert_eq!(bytes[..3], [7, 8, 0xFF]);
    // A `static` store: the storage needs no initial bytes.
    static STATIC: RamStorage<64> = RamStorage::new();
    assert_eq!(image(&STATIC), vec![0xFF; 64]);
}

#[test]
fn nor_flash_regions_must_fit_the_flash() {
    let flash = || MockFlash::<4, 1, 256>::new(1024);
    for (start, len) in [(128, 256), (0, 300)] {
        assert!(matches!(
            NorFlashStorage::new(flash(), start, len),
            Err(StoreError::Misaligned)
        ));
    }
    assert!(matches!(
        NorFlashStorage::new(flash(), 768, 512),
        Err(StoreError::OutOfBounds)
    ));
    assert!(matches!(
        NorFlashStorage::new(flash(), u32::MAX - 255, 512),
        Err(StoreError::OutOfBounds)
    ));
    assert!(matches!(
        NorFlashStorage::new(MockFlash::<3, 1, 3>::new(999), 0, 999),
        Err(StoreError::Misaligned)
    ));
    assert!(matches!(
        NorFlashStorage::new(MockFlash::<128, 1, 256>::new(1024), 0, 1024),
        Err(StoreError::Misaligned)
    ));
    assert!(matches!(
        NorFlashStorage::new(MockFlash::<4, 128, 256>::new(1024), 0, 1024),
        Err(StoreError::Misaligned)
    ));
    // A region in the middle: the bytes around it are never touched.
    let storage = NorFlashStorage::new(flash(), 256, 512).unwrap();
    let mut store = KeyframeStore::create(storage, &lidar(), 1, 40).unwrap();
    for k in 0..3 {
        append_k(&mut store, k, 40).unwrap();
    }
    assert_eq!(append_k(&mut store, 3, 40), Err(StoreError::Full));
    let mem = store.into_storage().into_inner().mem;
    assert!(mem[..256].iter().chain(&mem[768..]).all(|&b| b == 0xFF));
    assert_eq!(&mem[256..260], b"MSKF");
}

#[test]
fn wide_flash_words_widen_the_slots_and_dumps_still_open() {
    // 16- and 64-byte words (STM32H7: 32): slots and record 0 on word boundaries.
    fn check<const W: usize, const R: usize>(slot: usize, first: usize) {
        let flash = MockFlash::<W, R, 1024>::new(4096);
        let storage = NorFlashStorage::new(flash, 0, 4096).unwrap();
        let mut store = KeyframeStore::create(storage, &lidar(), 2, 73).unwrap();
        assert_eq!(store.slot_bytes(), slot);
        for k in 0..3 {
            append_k(&mut store, k, 146).unwrap();
        }
        let flash = store.into_storage().into_inner();
        assert_eq!((flash.double_writes, flash.misaligned), (0, 0));
        assert_eq!(&flash.mem[first..first + 2], b"KF");
        assert_eq!(&flash.mem[first + 2 * slot..first + 2 * slot + 2], b"KF");
        // The flash read out and opened in RAM, as the host does with a dump.
        let store = KeyframeStore::open(ram_from::<4096>(&flash.mem)).unwrap();
        assert_eq!(store.len(), 3);
        for k in 0..3 {
            assert_keyframe(&store, k, 146);
        }
    }
    check::<16, 8>(192, 64);
    check::<64, 16>(192, 64);
    check::<2, 2>(184, 56);
    // A store with 8-byte slots does not fit 16-byte words.
    let mut store = KeyframeStore::create(RamStorage::<4096>::new(), &lidar(), 2, 73).unwrap();
    append_k(&mut store, 0, 146).unwrap();
    let mut flash = MockFlash::<16, 1, 1024>::new(4096);
    flash.mem.copy_from_slice(&image(store.storage()));
    let storage = NorFlashStorage::new(flash, 0, 4096).unwrap();
    assert_eq!(
        KeyframeStore::open(storage).err(),
        Some(StoreError::Misaligned)
    );
}

#[test]
fn errors_have_distinct_messages() {
    use StoreError::*;
    let all = [
        Storage,
        OutOfBounds,
        Misaligned,
        NotErased,
        NoStore,
        BadMagic,
        UnsupportedVersion,
        HeaderChecksum,
        BadHeader,
        InvalidGeometry,
        TooSmall,
        Full,
        BeamCount,
        NonFinitePose,
        NoKeyframe,
        BufferTooShort,
        Corrupt,
        TooManyTorn,
        Damaged,
    ];
    let messages: std::collections::BTreeSet<String> = all.iter().map(|e| e.to_string()).collect();
    assert_eq!(messages.len(), all.len());
    let _: &dyn core::error::Error = &Full;
}
