use super::*;
use crate::sensors::wheel_odometry::DiffDriveGeometry;
use proptest::prelude::*;

#[test]
fn a_sixteen_bit_counter_wraps_both_ways() {
    let mut c = EncoderCounter::new(16, 1_000).expect("valid");
    assert_eq!(c.read(65_530), Ok(0), "the first read is the reference");
    assert_eq!(c.read(4), Ok(10), "forward through 65 535 → 0");
    assert_eq!(c.read(65_533), Ok(-7), "backward through 0 → 65 535");
    assert_eq!(c.read(65_533), Ok(0));
    c.reset();
    assert_eq!(c.read(100), Ok(0));
    assert_eq!(c.read(300), Ok(200));
}

#[test]
fn thirty_two_and_twelve_bit_counters() {
    let mut c = EncoderCounter::new(32, 1_000_000).expect("valid");
    c.read(u32::MAX - 5).expect("reference");
    assert_eq!(c.read(4), Ok(10));
    let mut c = EncoderCounter::new(12, 100).expect("valid");
    c.read(4_090).expect("reference");
    assert_eq!(c.read(3), Ok(9));
    assert_eq!(
        c.read(4_096),
        Err(EncoderError::RawOutOfRange { raw: 4_096 }),
        "a 12-bit counter never reads 4 096"
    );
}

#[test]
fn a_jump_beyond_the_setting_is_refused_and_becomes_the_reference() {
    let mut c = EncoderCounter::new(16, 1_000).expect("valid");
    c.read(0).expect("reference");
    assert_eq!(
        c.read(5_000),
        Err(EncoderError::TooManyTicks { ticks: 5_000 })
    );
    assert_eq!(
        c.read(5_010),
        Ok(10),
        "counting goes on from the refused read"
    );
    assert_eq!(c.read(0), Err(EncoderError::TooManyTicks { ticks: -5_010 }));
}

#[test]
fn settings_that_could_alias_are_refused() {
    assert!(EncoderCounter::new(0, 1).is_none());
    assert!(EncoderCounter::new(33, 1).is_none());
    assert!(
        EncoderCounter::new(16, 32_768).is_none(),
        "half the range is ambiguous"
    );
    assert!(EncoderCounter::new(16, 32_767).is_some());
    assert!(EncoderCounter::new(32, u32::MAX).is_none());
}

#[test]
fn both_wheels_become_the_odometry_models_ticks() {
    let c = EncoderCounter::new(16, 5_000).expect("valid");
    let mut wheels = DiffDriveEncoders::new(c.inverted(), c);
    wheels.read(1_000, 1_000).expect("reference");
    // Turning on the spot to the left: the left wheel backwards, the right forwards; the
    // left counter counts the other way.
    let t = wheels.read(1_200, 1_200).expect("ticks");
    assert_eq!(
        (t.front_left, t.rear_left, t.front_right, t.rear_right),
        (-200, -200, 200, 200)
    );
    let g = DiffDriveGeometry::<f64> {
        metres_per_tick: 0.001,
        track_width: 0.4,
    };
    let m = g.motion(&t).expect("motion");
    assert!(m.distance.abs() < 1e-12);
    assert!(
        (m.heading_change - 1.0).abs() < 1e-12,
        "{}",
        m.heading_change
    );
    // One side refused: the other still takes its read.
    assert!(wheels.read(1_200, 60_000).is_err());
    assert_eq!(
        wheels
            .read(1_210, 60_010)
            .map(|t| (t.front_left, t.front_right)),
        Ok((-10, 10))
    );
}

proptest! {
    /// Any walk of steps within the setting: the reads add up to the walk, whatever the
    /// counter's width and where it starts.
    #[test]
    fn reads_add_up_to_the_walk(
        bits in 8u8..=32,
        start in any::<u32>(),
        steps in proptest::collection::vec(-100i64..=100, 0..200),
    ) {
        let mask = if bits == 32 { u32::MAX } else { (1u32 << bits) - 1 };
        let mut c = EncoderCounter::new(bits, 100).expect("valid");
        let mut position = i64::from(start & mask);
        prop_assert_eq!(c.read((position as u32) & mask), Ok(0));
        let mut sum = 0i64;
        for s in &steps {
            position += s;
            let raw = (position.rem_euclid(1i64 << bits)) as u32;
            sum += i64::from(c.read(raw).expect("within the setting"));
        }
        prop_assert_eq!(sum, steps.iter().sum::<i64>());
    }
}
