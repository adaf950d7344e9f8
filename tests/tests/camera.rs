//! Camera front ends against the simulator's truth (issue 6): conversions checked on
//! rendered RGB-D frames (bearing sign, depth vs range, pitched camera), the floor
//! texture map's colour error, and the misclassified-sign scenario through the EKF-SLAM.
//!
//! Expected values come from the room's geometry (trigonometry written out here), never
//! from the conversion under test. Accuracy bounds are measured figures plus at most 5 %
//! (see each test); re-measure with `cargo test -p microslam-replay-tests --test camera --
//! --nocapture`.
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The bearing formula (eq. 26) and the class-id
//!   dictionary (§II-A).

use host_sim::drivers::detections::{ClassUse, DetectorSettings};
use host_sim::drivers::texture::TextureSettings;
use host_sim::inputs::camera::world::{Room, Sign, SimCamera, Surface, floor_colour, render};
use microslam::geometry::{Pose2, wrap_angle};
use microslam::sensors::camera::{DetectionNoise, kinect_v1};

/// The default camera with its principal point on a pixel centre, so that the optical
/// axis is the ray of pixel (80, 60).
fn centred_camera() -> SimCamera {
    let mut cam = SimCamera::default();
    cam.camera.intrinsics.cx = 80.0;
    cam.camera.intrinsics.cy = 60.0;
    cam
}

#[test]
fn pitched_camera_optical_axis_meets_the_floor_where_trigonometry_says() {
    let cam = centred_camera();
    let mount = kinect_v1::thor_mount::<f64>();
    let room = Room::default();
    let pose = Pose2::new(1.0, -0.5, 0.7);
    let frame = render(&cam, &room, &pose, None);
    let i = frame.index(80, 60);
    assert_eq!(frame.surface[i], Surface::Floor);
    // The axis leaves the camera at height z, tilted `pitch` down: it meets the floor
    // z / sin(pitch) along the axis, z / tan(pitch) ahead in the mount's yaw direction.
    let depth = f64::from(frame.depth[i]);
    assert!(
        (depth - mount.z / mount.pitch.sin()).abs() < 1e-5,
        "{depth}"
    );
    let ahead = mount.z / mount.pitch.tan();
    let (rx, ry) = (
        mount.x + ahead * mount.yaw.cos(),
        mount.y + ahead * mount.yaw.sin(),
    );
    let (s, c) = pose.theta.sin_cos();
    let (wx, wy) = (pose.x + c * rx - s * ry, pose.y + s * rx + c * ry);
    let p = cam.camera.pixel_to_world(&pose, 80.0, 60.0, depth).unwrap();
    assert!((p[0] - wx).abs() < 1e-5 && (p[1] - wy).abs() < 1e-5 && p[2].abs() < 1e-5);
    // The image's upper rows see the walls (above the horizon), the lower ones the floor.
    assert_eq!(frame.surface[frame.index(80, 119)], Surface::Floor);
    assert_eq!(frame.surface[frame.index(80, 0)], Surface::Wall);
}

#[test]
fn every_rendered_pixel_back_projects_onto_its_surface() {
    let cam = SimCamera::default();
    let room = Room::default();
    let h = room.half_size;
    for pose in [
        Pose2::new(0.0, 0.0, 0.0),
        Pose2::new(3.0, 2.0, 2.5),
        Pose2::new(-5.5, 4.0, -1.2),
    ] {
        let frame = render(&cam, &room, &pose, None);
        let (mut floor, mut wall, mut same_colour) = (0, 0, 0);
        for row in 0..frame.height {
            for col in 0..frame.width {
                let i = frame.index(col, row);
                let depth = f64::from(frame.depth[i]);
                let surface = frame.surface[i];
                if surface == Surface::Nothing {
                    assert_eq!(depth, 0.0);
                    continue;
                }
                let p = cam
                    .camera
                    .pixel_to_world(&pose, col as f64, row as f64, depth)
                    .unwrap();
                // Depth is along the optical axis: the distance to the point is longer
                // by the ray's slant, √(1 + x'² + y'²) with x' = (u − cx)/fx, y' likewise.
                let k = cam.camera.intrinsics;
                let slant = (1.0
                    + ((col as f64 - k.cx) / k.fx).powi(2)
                    + ((row as f64 - k.cy) / k.fy).powi(2))
                .sqrt();
                let t = cam.camera.mount.translation();
                let (s, c) = pose.theta.sin_cos();
                let origin = [
                    pose.x + c * t[0] - s * t[1],
                    pose.y + s * t[0] + c * t[1],
                    t[2],
                ];
                let dist = ((p[0] - origin[0]).powi(2)
                    + (p[1] - origin[1]).powi(2)
                    + (p[2] - origin[2]).powi(2))
                .sqrt();
                assert!((dist - depth * slant).abs() < 1e-4 * (1.0 + dist));
                let tol = 2e-5 * (1.0 + depth);
                match surface {
                    Surface::Floor => {
                        floor += 1;
                        assert!(p[2].abs() < tol, "floor point at height {}", p[2]);
                        same_colour += usize::from(floor_colour(p[0], p[1]) == frame.rgb[i]);
                    }
                    Surface::Wall => {
                        wall += 1;
                        let on_wall = (p[0].abs() - h).abs() < tol || (p[1].abs() - h).abs() < tol;
                        assert!(on_wall && p[2] > -tol && p[2] < room.wall_height + tol);
                    }
                    _ => unreachable!(),
                }
            }
        }
        assert!(floor > 5000 && wall > 1000, "{floor} {wall}");
        // f32 depths move a point by micrometres: only pixels on a tile edge may differ.
        assert!(
            same_colour as f64 >= 0.999 * floor as f64,
            "{same_colour}/{floor}"
        );
    }
}

/// Bounding box centre and the depth at its pixel, as a detector would report them.
fn detect(frame: &host_sim::inputs::camera::world::RgbdFrame, id: u32) -> Option<(f64, f64, f64)> {
    let (mut c0, mut c1, mut r0, mut r1) = (u32::MAX, 0, u32::MAX, 0);
    for row in 0..frame.height {
        for col in 0..frame.width {
            if frame.surface[frame.index(col, row)] == Surface::Sign(id) {
                (c0, c1, r0, r1) = (c0.min(col), c1.max(col), r0.min(row), r1.max(row));
            }
        }
    }
    (c0 <= c1).then(|| {
        let (u, v) = (f64::from(c0 + c1) / 2.0, f64::from(r0 + r1) / 2.0);
        let i = frame.index(u.round() as u32, v.round() as u32);
        (u, v, f64::from(frame.depth[i]))
    })
}

#[test]
fn signs_in_rendered_frames_give_true_range_and_ccw_bearing() {
    let pose = Pose2::new(-1.0, 0.5, 0.3);
    let place = |id, bearing: f64, dist: f64, z| {
        let a = pose.theta + bearing;
        Sign {
            id,
            position: [pose.x + dist * a.cos(), pose.y + dist * a.sin(), z],
            half_size: 0.12,
        }
    };
    // Left, right, straight ahead, and a low one well below the (pitched) optical axis.
    let room = Room {
        signs: vec![
            place(1, 0.45, 3.0, 0.3),
            place(2, -0.4, 2.5, 0.4),
            place(3, 0.0, 4.0, 0.35),
            place(4, 0.15, 1.5, 0.12),
        ],
        ..Room::default()
    };
    for cam in [SimCamera::default(), centred_camera()] {
        let frame = render(&cam, &room, &pose, None);
        let mount = cam.camera.mount;
        for sign in &room.signs {
            let (u, v, depth) = detect(&frame, sign.id).expect("sign in view");
            let got = cam
                .camera
                .sighting(u, v, depth, &DetectionNoise::NONE)
                .unwrap();
            // Truth: from the camera's planar position to the sign, relative to the
            // camera's planar heading (robot heading + mount yaw), CCW positive.
            let (s, c) = pose.theta.sin_cos();
            let (cx, cy) = (
                pose.x + c * mount.x - s * mount.y,
                pose.y + s * mount.x + c * mount.y,
            );
            let (dx, dy) = (sign.position[0] - cx, sign.position[1] - cy);
            let range = dx.hypot(dy);
            let bearing = wrap_angle(dy.atan2(dx) - pose.theta - mount.yaw);
            // Box centres are quantised to half pixels (0.005 rad at f = 100 px).
            assert!(
                wrap_angle(got.z.bearing - bearing).abs() < 0.008,
                "sign {}: bearing {} vs {bearing}",
                sign.id,
                got.z.bearing
            );
            assert!(
                (got.z.range - range).abs() < 0.03,
                "sign {}: range {} vs {range}",
                sign.id,
                got.z.range
            );
            assert!((got.height - sign.position[2]).abs() < 0.03);
            // Left of the camera's heading is left in the image (u < cx) and a positive
            // bearing: atan((u − u0)/f) of El Masri El Chaarani et al. (n.d., eq. 26) has
            // the opposite sign.
            let published_theta =
                ((u - cam.camera.intrinsics.cx) / cam.camera.intrinsics.fx).atan();
            if bearing.abs() > 0.05 {
                assert_eq!(got.z.bearing > 0.0, bearing > 0.0);
                assert!(published_theta * bearing < 0.0, "published formula sign");
            }
            // Depth is not range: off-axis and below a pitched axis, the range exceeds the
            // depth by far more than the error allowed above.
            if bearing.abs() > 0.3 {
                assert!(range - depth > 0.1, "range {range} depth {depth}");
            }
        }
    }
}

/// Small settings for tests: one frame every 2 s, every second pixel.
fn test_texture_settings() -> TextureSettings {
    TextureSettings {
        frame_rate_hz: 0.5,
        pixel_stride: 2,
        ..TextureSettings::default()
    }
}

#[test]
fn texture_map_matches_the_true_floor() {
    let (report, map, _) =
        host_sim::commands::texture::run_texture(1, &test_texture_settings()).unwrap();
    eprintln!("{report:#?}");
    let t = report.true_poses;
    let e = report.ekf_poses;
    // Measured (seed 1, 0.5 Hz, stride 2): true poses 1.837 mean |ΔRGB| (0-255 scale),
    // coverage 0.547 of the room; EKF poses (ATE 0.0370 m) 5.859.
    assert!(t.mean_abs_rgb_error.unwrap() < 1.92, "{t:?}");
    assert!(t.coverage > 0.53, "{t:?}");
    assert!(e.mean_abs_rgb_error.unwrap() < 6.1, "{e:?}");
    assert!(e.mean_abs_rgb_error > t.mean_abs_rgb_error);
    assert!(report.ekf_ate_rmse_m.unwrap() < 0.0385);
    // The metric can fail: a map shifted by 0.1 m is far worse.
    let mut shifted = host_sim::drivers::texture::TextureMap::new(7.0, map.resolution_m);
    for i in 0..map.size * map.size {
        if let Some(c) = map.colour(i) {
            let (x, y) = map.centre(i);
            shifted.add(x + 0.1, y, c);
        }
    }
    let s = shifted.error(&Room::default());
    assert!(s.mean_abs_rgb_error.unwrap() > 3.0 * t.mean_abs_rgb_error.unwrap());
}

#[test]
fn seed_height_band_paints_walls_into_the_floor_map() {
    let narrow = test_texture_settings();
    let seed_band = TextureSettings {
        band: (-0.5, 0.25),
        ..narrow
    };
    let (a, _, _) = host_sim::commands::texture::run_texture(1, &narrow).unwrap();
    let (b, _, _) = host_sim::commands::texture::run_texture(1, &seed_band).unwrap();
    eprintln!("{:?}\n{:?}", a.true_poses, b.true_poses);
    assert!(b.true_pose_points.in_band > a.true_pose_points.in_band);
    assert!(b.true_poses.mean_abs_rgb_error > a.true_poses.mean_abs_rgb_error);
}

#[test]
fn association_corrects_wrong_class_ids() {
    let (report, _, _) = host_sim::commands::detections::run_detections(
        1,
        &DetectorSettings::default(),
        host_sim::commands::detections::SignField::default(),
    )
    .unwrap();
    let mode = |m| report.modes.iter().find(|r| r.class_use == m).unwrap();
    for m in &report.modes {
        eprintln!(
            "{:?}: ATE {:?} {:?} landmarks {}",
            m.class_use, m.ekf.ate_rmse_m.se2, m.classes, m.ekf.landmarks_created
        );
    }
    let hints = mode(ClassUse::GeometryWithHints);
    let c = hints.classes;
    // The detector's wrong-class share is 15 %.
    let share = c.wrong_class as f64 / c.detections as f64;
    assert!((0.13..0.17).contains(&share), "{share}");
    // Measured (seed 1): 673 of 684 wrong classes corrected (98.4 %), ATE 0.0370 m,
    // 24 landmarks for 24 signs, no wrong-class detection paired with another sign.
    assert!(c.corrected_share.unwrap() >= 0.97, "{c:?}");
    assert_eq!(c.misassociated, 0);
    assert_eq!(c.right_class_misassociated, 0);
    assert!(hints.ekf.ate_rmse_m.se2.unwrap() < 0.0385);
    assert_eq!(hints.ekf.landmarks_created, 24);
    // The dictionary of El Masri El Chaarani et al. (n.d.; the class names the landmark)
    // breaks on the same detections
    // (measured: 3.5 % corrected, ATE 1.69 m): the contrast, not a figure to hold.
    let dict = mode(ClassUse::Dictionary);
    assert!(dict.classes.corrected_share.unwrap() < 0.1);
    assert!(dict.ekf.ate_rmse_m.se2.unwrap() > 0.5);
}
