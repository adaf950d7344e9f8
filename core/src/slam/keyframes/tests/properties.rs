//! Property tests: random geometry and ranges (NaN, ±∞, negative, huge, at the limits)
//! round-trip what a record can hold and nothing else; random bytes and bit flips never
//! panic and never pass as a keyframe.

use super::{image, lidar};
use crate::geometry::Pose2;
use crate::sensors::lidar::{BeamStatus, LidarGeometry};
use crate::slam::keyframes::*;
use proptest::prelude::*;

fn geometry() -> impl Strategy<Value = LidarGeometry> {
    (
        (-4.0f32..4.0, -0.1f32..0.1, 0.0f32..2.0, 0.5f32..90.0),
        (
            prop_oneof![Just(f32::INFINITY), 0.0f32..10.0],
            -1.0f32..1.0,
            -1.0f32..1.0,
            -3.2f32..3.2,
        ),
    )
        .prop_map(
            |((first, step, min, span), (beyond, mx, my, mt))| LidarGeometry {
                first_angle: first,
                angle_increment: step,
                min_range: min,
                max_range: min + span,
                no_return_range: min + span + beyond,
                mount: Pose2::new(mx, my, mt),
            },
        )
}

/// A reading: `(kind, fraction, anything)`, turned into a range for a geometry by
/// [`reading`].
type Reading = (u8, f32, f32);

fn readings(len: usize) -> impl Strategy<Value = Vec<Reading>> {
    proptest::collection::vec((0u8..8, 0.0f32..1.0, any::<f32>()), len)
}

/// Ranges of every sort: just inside and outside the limits, around 65.535 m, NaN, ±∞,
/// negative, any `f32` at all.
fn reading(g: &LidarGeometry, (kind, u, any): Reading) -> f32 {
    match kind {
        0 => g.min_range + u * 2.0e-3,
        1 => g.max_range - u * 2.0e-3,
        2 => g.min_range - u * 2.0e-3,
        3 => 65.53 + u * 0.01,
        4 => [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.0][(u * 4.0) as usize % 4],
        5 => -u * 100.0,
        6 => any,
        _ => g.min_range + u * (g.max_range - g.min_range),
    }
}

fn pose() -> impl Strategy<Value = Pose2<f32>> {
    (-1.0e3f32..1.0e3, -1.0e3f32..1.0e3, -7.0f32..7.0).prop_map(|(x, y, t)| Pose2::new(x, y, t))
}

fn same(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Random geometry, decimation and ranges: a usable range below 65.5 m reads back
    /// within 1 mm and usable; an unusable one, or one beyond 65.535 m, reads back NaN;
    /// poses come back bit for bit, before and after `open`.
    #[test]
    fn random_scans_round_trip_what_is_representable(
        g in geometry(),
        decimation in 1usize..5,
        scans in proptest::collection::vec((readings(300), pose(), pose()), 1..4),
        len in 1usize..300,
    ) {
        let beams = len.div_ceil(decimation);
        let mut store = KeyframeStore::create(RamStorage::<4096>::new(), &g, decimation, beams).unwrap();
        let scans: Vec<(Vec<f32>, Pose2<f32>, Pose2<f32>)> = scans
            .into_iter()
            .map(|(r, m, p)| (r[..len].iter().map(|&x| reading(&g, x)).collect(), m, p))
            .collect();
        for (k, (ranges, motion, pose)) in scans.iter().enumerate() {
            prop_assert_eq!(store.append(&Keyframe::new(*motion, *pose, ranges)), Ok(k as u32));
        }
        let reopened = KeyframeStore::open(store.into_storage()).unwrap();
        prop_assert_eq!(reopened.len() as usize, scans.len());
        let mut back = vec![0.0f32; beams];
        let mut spread = vec![0.0f32; len];
        for (k, (ranges, motion, pose)) in scans.iter().enumerate() {
            let meta = reopened.read(k as u32, &mut back).unwrap();
            prop_assert_eq!(meta.index, k as u32);
            prop_assert!(same(meta.motion.x, motion.x) && same(meta.motion.y, motion.y));
            prop_assert!(same(meta.motion.theta, motion.theta));
            prop_assert!(same(meta.pose.x, pose.x) && same(meta.pose.y, pose.y));
            prop_assert!(same(meta.pose.theta, pose.theta));
            reopened.read_scan(k as u32, &mut spread).unwrap();
            for (j, r) in back.iter().enumerate() {
                let original = ranges[j * decimation];
                prop_assert!(same(spread[j * decimation], *r));
                if g.classify(original) != BeamStatus::Valid || original > 65.5351 {
                    prop_assert!(r.is_nan(), "{} read back as {}", original, r);
                } else if original < 65.5 {
                    prop_assert!((r - original).abs() <= 1.0e-3 + 1.0e-5, "{} read back as {}", original, r);
                    prop_assert_eq!(g.classify(*r), BeamStatus::Valid);
                } else {
                    prop_assert!(r.is_nan() || (r - original).abs() <= 1.0e-3 + 1.0e-5);
                }
            }
            for (i, s) in spread.iter().enumerate() {
                if i % decimation != 0 {
                    prop_assert!(s.is_nan());
                }
            }
        }
    }

    /// Any bytes after a valid header: `open` does not panic, and what it counts reads.
    #[test]
    fn random_bytes_never_panic(
        rest in proptest::collection::vec(any::<u8>(), 0..1500),
        beams in 1usize..40,
    ) {
        let store = KeyframeStore::create(RamStorage::<1600>::new(), &lidar(), 1, beams).unwrap();
        let mut bytes = image(store.storage());
        bytes.truncate(HEADER_BYTES);
        bytes.extend_from_slice(&rest);
        let mut ram = RamStorage::<1600>::new();
        ram.load_image(&bytes).unwrap();
        if let Ok(store) = KeyframeStore::open(ram) {
            let mut ranges = vec![0.0f32; beams];
            for k in 0..store.len() {
                prop_assert!(store.read(k, &mut ranges).is_ok());
            }
        }
        // And any bytes at all, header included.
        let mut ram = RamStorage::<1600>::new();
        ram.load_image(&rest).unwrap();
        let _ = KeyframeStore::open(ram);
    }

    /// Up to three bit flips in the records: every keyframe `open` still finds is the one
    /// appended, and it finds those before the first damaged record.
    #[test]
    fn bit_flips_never_pass_as_a_keyframe(
        flips in proptest::collection::vec((0usize..4 * 184, 0u32..8), 1..4),
    ) {
        // 73 beams: 182-byte records in 184-byte slots.
        let mut store = KeyframeStore::create(RamStorage::<1024>::new(), &lidar(), 2, 73).unwrap();
        for k in 0..4 {
            super::append_k(&mut store, k, 146).unwrap();
        }
        let mut bytes = image(store.storage());
        for &(at, bit) in &flips {
            bytes[HEADER_BYTES + at] ^= 1 << bit;
        }
        // Slots whose record bytes (not padding) changed; by hand from the layout.
        let damaged: Vec<usize> = (0..4)
            .filter(|s| flips.iter().any(|&(at, _)| at / 184 == *s && at % 184 < 182))
            .filter(|s| {
                let slot = HEADER_BYTES + s * 184;
                bytes[slot..slot + 182] != image(store.storage())[slot..slot + 182]
            })
            .collect();
        let mut ram = RamStorage::<1024>::new();
        ram.load_image(&bytes).unwrap();
        let reopened = KeyframeStore::open(ram).unwrap();
        let first = damaged.first().copied().unwrap_or(4);
        prop_assert_eq!(reopened.len() as usize, first);
        let intact_after = (first..4).any(|s| !damaged.contains(&s));
        let refused = if intact_after { Some(StoreError::Damaged) } else { None };
        prop_assert_eq!(reopened.append_refused(), refused);
        for k in 0..reopened.len() {
            super::assert_keyframe(&reopened, k, 146);
        }
    }
}
