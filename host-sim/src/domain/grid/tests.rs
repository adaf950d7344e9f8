use super::*;

fn extent(min: [f32; 2], max: [f32; 2]) -> OdometryExtent {
    OdometryExtent { min, max }
}

#[test]
fn the_extent_is_taken_in_the_frame_of_the_first_pose() {
    // An odometry frame turned by 90° and moved: the robot drives 2 m ahead, then 1 m
    // to its left.
    let poses = [
        Pose2::new(5.0, 3.0, std::f32::consts::FRAC_PI_2),
        Pose2::new(f32::NAN, 0.0, 0.0),
        Pose2::new(5.0, 5.0, std::f32::consts::FRAC_PI_2),
        Pose2::new(4.0, 5.0, std::f32::consts::PI),
    ];
    let e = OdometryExtent::of(poses).unwrap();
    for (got, want) in e.min.iter().chain(&e.max).zip([0.0, 0.0, 2.0, 1.0]) {
        assert!((got - want).abs() < 1e-5, "{e:?}");
    }
    assert_eq!(e.size().map(|v| (v * 1e4).round()), [2e4, 1e4]);
    assert_eq!(OdometryExtent::of([Pose2::new(f32::NAN, 0.0, 0.0)]), None);
}

#[test]
fn the_grid_is_the_smaller_one_that_holds_the_odometry_with_its_margin() {
    let r = 0.05;
    let place = |e: Option<OdometryExtent>| GridPlacement::for_extent(e.as_ref(), r);
    // No odometry, and a run around its start that the 51.2 m grid holds with 5 m to
    // spare (the Intel log's extent): the smaller grid centred on the start.
    for e in [None, Some(extent([-7.0, -14.5], [14.3, 3.4]))] {
        let p = place(e);
        assert_eq!(
            (p.cells, p.origin_m, p.centred, p.fits),
            (1024, [-25.6, -25.6], true, true)
        );
    }
    // 40 m along x from the start: centred it would not hold it, placed on it it does
    // (its middle at x = 20 m).
    let p = place(Some(extent([0.0, -5.0], [40.0, 5.0])));
    assert_eq!((p.cells, p.centred, p.fits), (1024, false, true));
    assert!(
        (p.origin_m[0] + 5.6).abs() < 1e-4 && p.origin_m[1] == -25.6,
        "{p:?}"
    );
    // Corners on whole cells: the middle 20.013 m is rounded to 20.0 m.
    let p = place(Some(extent([0.0, -5.0], [40.026, 5.0])));
    assert!((p.origin_m[0] + 5.6).abs() < 1e-4, "{p:?}");
    // 54 × 54 m (the ACES log in its start frame): the 102.4 m grid, centred.
    let p = place(Some(extent([-18.3, -44.3], [35.8, 9.7])));
    assert_eq!(
        (p.cells, p.origin_m, p.centred, p.fits),
        (2048, [-51.2, -51.2], true, true)
    );
    // 80 m from the start: the larger grid placed on it.
    let p = place(Some(extent([0.0, 0.0], [80.0, 10.0])));
    assert_eq!((p.cells, p.fits), (2048, true));
    assert!((p.origin_m[0] + 11.2).abs() < 1e-4, "{p:?}");
    // 95 m wide: even the larger grid leaves less than 5 m on each side.
    let p = place(Some(extent([0.0, 0.0], [95.0, 10.0])));
    assert_eq!((p.cells, p.fits), (2048, false));
}

#[test]
fn a_localizer_gets_the_narrow_window_unless_the_file_sets_one() {
    let window = |config: Option<&Path>, role| {
        Preset::Microcontroller
            .settings(config, None, 180, role)
            .unwrap()
            .filter
            .shift_window_cells
    };
    assert_eq!(window(None, FilterRole::Slam), 4);
    assert_eq!(window(None, FilterRole::Localizer), 1);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("w.toml");
    std::fs::write(&file, "shift_window_cells = 3\n").unwrap();
    assert_eq!(window(Some(&file), FilterRole::Slam), 3);
    assert_eq!(window(Some(&file), FilterRole::Localizer), 3);
    // A file that sets something else leaves the localizer's window.
    std::fs::write(&file, "seed = 7\n").unwrap();
    assert_eq!(window(Some(&file), FilterRole::Localizer), 1);
}

#[test]
fn the_untuned_preset_is_named_untuned_and_still_seed() {
    use clap::ValueEnum;
    for name in ["untuned", "seed"] {
        assert_eq!(Preset::from_str(name, false), Ok(Preset::Untuned), "{name}");
        let file: GridToml = toml::from_str(&format!("base = \"{name}\"\n")).unwrap();
        assert_eq!(file.apply().unwrap(), GridPfConfig::UNTUNED, "{name}");
    }
    let unknown: GridToml = toml::from_str("base = \"paper\"\n").unwrap();
    let e = unknown.apply().unwrap_err().to_string();
    assert!(e.contains("default, untuned, microcontroller"), "{e}");
}

#[test]
fn every_motion_noise_key_sets_its_field() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("noise.toml");
    std::fs::write(
        &file,
        "distance_std = 0.01\ndistance_std_per_metre = 0.02\n\
         distance_std_per_radian = 0.03\nheading_std = 0.04\n\
         heading_std_per_radian = 0.05\nheading_std_per_metre = 0.06\n\
         sideways_std_per_metre = 0.07\n",
    )
    .unwrap();
    let c = Preset::Default
        .settings(Some(&file), None, 180, FilterRole::Slam)
        .unwrap();
    assert_eq!(
        c.filter.motion_noise,
        MotionNoise {
            distance_std: 0.01,
            distance_std_per_metre: 0.02,
            distance_std_per_radian: 0.03,
            heading_std: 0.04,
            heading_std_per_radian: 0.05,
            heading_std_per_metre: 0.06,
            sideways_std_per_metre: 0.07,
        }
    );
}

#[test]
fn beams_outside_one_to_all_are_refused() {
    assert_eq!(decimation_for(180, 180).unwrap(), 1);
    assert_eq!(decimation_for(180, 90).unwrap(), 2);
    assert_eq!(
        decimation_for(180, 100).unwrap(),
        2,
        "⌈180 / 2⌉ = 90 ≤ 100 beams"
    );
    assert_eq!(decimation_for(180, 1).unwrap(), 180);
    let zero = decimation_for(180, 0).unwrap_err().to_string();
    assert!(
        zero.contains("--beams 0") && zero.contains("1 ..= 180"),
        "{zero}"
    );
    let many = decimation_for(180, 1000).unwrap_err().to_string();
    assert!(
        many.contains("--beams 1000") && many.contains("180 beams"),
        "{many}"
    );
}

#[test]
fn the_loop_closure_table_turns_it_on_and_sets_its_values() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lc.toml");
    let settings = |text: &str, requested, role| {
        std::fs::write(&file, text).unwrap();
        loop_closure_settings(Some(&file), requested, role)
    };
    let slam = FilterRole::Slam;
    // No table: only the flag turns it on, with the defaults.
    assert_eq!(settings("seed = 1\n", false, slam).unwrap(), None);
    assert_eq!(
        settings("seed = 1\n", true, slam).unwrap(),
        Some(GraphSlamConfig::MICROCONTROLLER)
    );
    assert_eq!(
        loop_closure_settings(None, true, slam).unwrap(),
        Some(GraphSlamConfig::MICROCONTROLLER)
    );
    // The table turns it on by itself and sets values over the defaults.
    let c = settings(
        "[loop_closure]\nwindow_half_width_cells = 10\n",
        false,
        slam,
    )
    .unwrap()
    .expect("on");
    assert_eq!(c.loop_closure.window.half_width_cells, 10);
    assert_eq!(c.keyframes, GraphSlamConfig::MICROCONTROLLER.keyframes);
    assert_eq!(
        settings("[loop_closure]\nenabled = false\n", false, slam).unwrap(),
        None
    );
    // Errors name what is wrong.
    let unknown = settings("[loop_closure]\nwindow = 0.5\n", false, slam).unwrap_err();
    assert!(
        format!("{unknown:#}").contains("unknown field `window`"),
        "{unknown:#}"
    );
    let range = settings("[loop_closure]\nmin_hit_fraction = 1.5\n", false, slam).unwrap_err();
    assert!(
        format!("{range:#}").contains("`min_hit_fraction` must be within 0 ..= 1"),
        "{range:#}"
    );
    let localizer = loop_closure_settings(None, true, FilterRole::Localizer).unwrap_err();
    assert!(localizer.to_string().contains("grid SLAM"), "{localizer}");
    assert!(settings("[loop_closure]\n", false, FilterRole::Localizer).is_err());
}

#[test]
fn scan_spacing_measures_the_steps_and_what_the_arc_leaves_out() {
    // Three steps: 1 m straight ahead, then a quarter circle of radius 1 m (on an
    // arc: nothing left out), then 0.1 m sideways (all of it left out).
    let poses = [
        Pose2::new(0.0, 0.0, 0.0),
        Pose2::new(1.0, 0.0, 0.0),
        Pose2::new(2.0, 1.0, core::f32::consts::FRAC_PI_2),
        Pose2::new(f32::NAN, 0.0, 0.0),
        Pose2::new(2.0, 1.0, 0.0),
        Pose2::new(2.0, 1.1, 0.0),
    ];
    let s = ScanSpacing::of(poses).expect("steps");
    assert_eq!(s.steps, 3);
    // Steps 1, √2 and 0.1 m; turns 0, π/2 and 0.
    assert!((s.median_step_m - 1.0).abs() < 1e-6, "{s:?}");
    assert_eq!(s.median_turn_rad, 0.0);
    assert!(s.median_arc_residual_m < 1e-6, "{s:?}");
    assert!((s.max_arc_residual_m - 0.1).abs() < 1e-6, "{s:?}");
    assert!(s.is_sparse());
    let dense = ScanSpacing::of((0..10).map(|i| Pose2::new(0.05 * i as f32, 0.0, 0.0)));
    assert!(!dense.expect("steps").is_sparse());
    assert_eq!(ScanSpacing::of([Pose2::new(0.0, 0.0, 0.0)]), None);
}
