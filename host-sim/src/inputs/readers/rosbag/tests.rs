use super::*;

#[test]
fn cdr_round_trips_a_scan_and_refuses_short_or_foreign_data() {
    let scan = msg::LaserScan {
        header: msg::Header {
            stamp: msg::Time::from_seconds(976052857.337),
            frame_id: "laser".into(),
        },
        angle_min: -1.5,
        angle_increment: 0.01,
        range_max: 81.8,
        ranges: vec![1.0, 2.5, f32::INFINITY],
        ..Default::default()
    };
    let bytes = encode_cdr(&scan).unwrap();
    // Header (4) + stamp (8) + "laser\0" with its length (10) + 2 padding + 7 floats.
    assert_eq!(&bytes[..4], &CDR_LE_HEADER);
    assert_eq!(&bytes[16..22], b"laser\0");
    assert_eq!(decode_cdr::<msg::LaserScan>(&bytes).unwrap(), scan);
    assert!(decode_cdr::<msg::LaserScan>(&bytes[..bytes.len() - 3]).is_err());
    assert!(decode_cdr::<msg::LaserScan>(&bytes[..2]).is_err());
    let mut xcdr = bytes.clone();
    xcdr[1] = 7;
    let e = decode_cdr::<msg::LaserScan>(&xcdr).unwrap_err().to_string();
    assert!(e.contains("not plain CDR"), "{e}");
}

#[test]
fn time_and_yaw_convert_both_ways() {
    let t = msg::Time::from_seconds(12.999_999_999_9);
    assert_eq!((t.sec, t.nanosec), (13, 0));
    assert!((msg::Time::from_seconds(-1.25).seconds() + 1.25).abs() < 1e-12);
    for yaw in [-3.1, -1.0, 0.0, 0.5, 3.1] {
        assert!((msg::Quaternion::from_yaw(yaw).yaw() - yaw).abs() < 1e-12);
    }
}

#[test]
fn odometry_is_interpolated_in_file_order_around_the_scan() {
    let p = |x: f64| Pose2::new(x, 0.0, 0.0);
    // Stamps go backwards between messages 1 and 2.
    let odom = [(1.0, p(1.0)), (2.0, p(2.0)), (1.5, p(9.0)), (3.0, p(10.0))];
    assert_eq!(odometry_at(&odom, 2, 2.0), Some(p(2.0)), "exact stamp");
    assert_eq!(odometry_at(&odom, 1, 1.5), Some(p(1.5)), "between 0 and 1");
    let q = odometry_at(&odom, 3, 2.25).unwrap();
    assert!((q.x - 9.5).abs() < 1e-12, "between 2 and 3: {q:?}");
    assert_eq!(odometry_at(&odom, 4, 7.0), Some(p(10.0)), "after the last");
    assert_eq!(odometry_at(&[], 0, 1.0), None);
}

#[test]
fn the_mount_follows_the_static_transform_chain() {
    let t = |parent: &str, child: &str, x: f64, yaw: f64| msg::TransformStamped {
        header: msg::Header {
            frame_id: parent.into(),
            ..Default::default()
        },
        child_frame_id: child.into(),
        transform: msg::Transform {
            translation: msg::Vector3 { x, y: 0.0, z: 0.3 },
            rotation: msg::Quaternion::from_yaw(yaw),
        },
    };
    let tf = msg::TfMessage {
        transforms: vec![
            t("base_link", "mast", 0.2, core::f64::consts::FRAC_PI_2),
            t("/mast", "laser", 0.1, 0.0),
        ],
    };
    let table = static_transforms(&[tf]);
    let m = mount_from(&table, "base_link", "laser").unwrap();
    assert!(
        (m.x - 0.2).abs() < 1e-12 && (m.y - 0.1).abs() < 1e-12,
        "{m:?}"
    );
    assert!((m.theta - core::f64::consts::FRAC_PI_2).abs() < 1e-12);
    assert_eq!(mount_from(&table, "odom", "laser"), None);
}
