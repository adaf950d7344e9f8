//! The command line as a user meets it.

mod common;

use common::{host_sim, succeeds};

#[test]
fn missing_datasets_folder_names_path_and_variable() {
    let out = host_sim()
        .args(["replay", "--dataset", "mrclam:dataset6", "--quiet"])
        .env("SLAM_DATASETS", "/nonexistent/datasets")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("/nonexistent/datasets") && err.contains("SLAM_DATASETS"),
        "{err}"
    );
}

#[test]
fn unknown_dataset_family_is_explained() {
    let out = host_sim()
        .args(["replay", "--dataset", "kitti:00"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("expected `mrclam:<dir>`"), "{err}");
}

#[test]
fn sim_writes_every_output() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("short.toml");
    std::fs::write(&cfg, "[scenario]\nduration_s = 20.0\n").unwrap();
    succeeds(
        host_sim()
            .args(["sim", "--seed", "3", "--quiet", "--config"])
            .arg(&cfg)
            .arg("--out")
            .arg(dir.path()),
    );
    for f in [
        "metrics.json",
        "trajectory.tum",
        "groundtruth.tum",
        "landmarks.csv",
        "map.png",
        "errors.png",
    ] {
        let p = dir.path().join(f);
        assert!(p.metadata().map(|m| m.len() > 100).unwrap_or(false), "{f}");
    }
    // The grid filters in the lidar world.
    for run in ["slam", "localize"] {
        for f in [
            "map.pgm",
            "map.yaml",
            "map.png",
            "trajectory.tum",
            "groundtruth.tum",
            "metrics.json",
        ] {
            let p = dir.path().join("grid").join(run).join(f);
            assert!(
                p.metadata().map(|m| m.len() > 50).unwrap_or(false),
                "grid/{run}/{f}"
            );
        }
        let m: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join("grid").join(run).join("metrics.json"))
                .unwrap(),
        )
        .unwrap();
        let ate = m["ate_rmse_m"].as_f64().unwrap();
        let odo = m["odometry_ate_rmse_m"].as_f64().unwrap();
        assert!(
            ate < odo / 4.0,
            "grid/{run}: ATE {ate} vs dead reckoning {odo}"
        );
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    for key in [
        "dataset",
        "steps",
        "sightings",
        "ate_rmse_m",
        "yaw_rmse_deg",
        "landmark_rmse_m",
        "landmarks_created",
        "association_purity",
        "nees_pose_mean",
        "nis_mean",
        "wall_time_s",
        "filter_time_s",
    ] {
        assert!(m.get(key).is_some(), "metrics.json lacks {key}");
    }
    for key in ["ate_rmse_m", "yaw_rmse_deg", "landmark_rmse_m"] {
        assert!(
            m[key]["first_pose"].is_number() && m[key]["se2"].is_number(),
            "{key}"
        );
    }
    assert_eq!(m["steps"], 400);
    let tum = std::fs::read_to_string(dir.path().join("trajectory.tum")).unwrap();
    assert_eq!(tum.lines().filter(|l| !l.starts_with('#')).count(), 400);
    assert_eq!(tum.lines().nth(1).unwrap().split(' ').count(), 8);
}

#[test]
fn hil_with_a_missing_or_wrong_elf_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let text = dir.path().join("qemu.elf");
    std::fs::write(&text, "not a firmware").unwrap();
    for (elf, expected) in [
        (dir.path().join("missing.elf"), "not found"),
        (text, "is not an ELF file"),
    ] {
        let out = host_sim()
            .args([
                "hil",
                "--dataset",
                "mrclam:dataset6",
                "--timeout-s",
                "5",
                "--qemu",
            ])
            .arg(&elf)
            .arg("--out")
            .arg(dir.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(err.contains(expected) && !err.contains("differ"), "{err}");
    }
}

/// `hil --scans 0` streams nothing: refused, naming the log, before a device is touched
/// (the serial port named does not exist).
#[test]
fn hil_of_no_scan_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = host_sim()
        .args([
            "hil",
            "--serial",
            "/nonexistent/tty",
            "--dataset",
            "carmen:intel/intel-raw-part.clf",
            "--scans",
            "0",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("--scans 0: no scan of") && err.contains("intel-raw-part.clf"),
        "{err}"
    );
}

/// What `hil --own-lidar` cannot do is refused before a device or a file is touched,
/// naming the option: a landmark log, a board, a restart, a fraction beyond 1, a line
/// fault without `--own-lidar`.
#[test]
fn hil_own_lidar_refuses_what_it_cannot_do() {
    let dir = tempfile::tempdir().unwrap();
    let map = dir.path().join("map.yaml");
    let run = |args: &[&str]| {
        let out = host_sim()
            .arg("hil")
            .args(args)
            .arg("--out")
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{args:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let intel = ["--dataset", "carmen:intel/intel-raw-part.clf", "--map"];
    let map = map.to_str().unwrap();
    let cases: [(Vec<&str>, &str); 5] = [
        (
            vec![
                "--serial",
                "/nonexistent/tty",
                "-d",
                "mrclam:dataset6",
                "--own-lidar",
            ],
            "--own-lidar streams a lidar log",
        ),
        (
            [
                &["--serial", "/nonexistent/tty"][..],
                &intel,
                &[map, "--own-lidar"],
            ]
            .concat(),
            "under QEMU (--qemu)",
        ),
        (
            [
                &["--qemu", "/nonexistent.elf"][..],
                &intel,
                &[map, "--own-lidar"],
            ]
            .concat()
            .into_iter()
            .chain(["--restart-after", "5"])
            .collect(),
            "without --restart-after",
        ),
        (
            [
                &["--qemu", "/nonexistent.elf"][..],
                &intel,
                &[map, "--own-lidar"],
            ]
            .concat()
            .into_iter()
            .chain(["--lidar-drop", "2"])
            .collect(),
            "--lidar-drop: a fraction",
        ),
        (
            [
                &["--serial", "/nonexistent/tty"][..],
                &intel,
                &[map, "--lidar-noise", "0.1"],
            ]
            .concat(),
            "--own-lidar",
        ),
    ];
    for (args, expected) in cases {
        let err = run(&args);
        assert!(err.contains(expected), "{args:?}: {err}");
    }
}

/// `--help` of `args`.
fn help(args: &[&str]) -> String {
    let out = host_sim().args(args).arg("--help").output().unwrap();
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn help_names_every_estimator_dataset_family_and_particle_count() {
    let top = help(&[]);
    assert!(
        top.contains("EKF-SLAM") && top.contains("grid SLAM"),
        "{top}"
    );

    let replay = help(&["replay"]);
    for family in ["mrclam:<dir>", "carmen:<log>", "thor:<dir>"] {
        assert!(
            replay.contains(family),
            "`--dataset` help without {family}: {replay}"
        );
    }
    // The counts the grid filters are compiled for, in both commands that take one.
    let counts = host_sim::domain::grid::SUPPORTED_PARTICLES;
    let (last, rest) = counts.split_last().unwrap();
    let list = format!(
        "{} or {last}",
        rest.iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    );
    assert!(
        replay.contains(&list),
        "replay --particles help without {list}: {replay}"
    );
    assert!(
        help(&["sim"]).contains(&list),
        "sim --grid-particles help without {list}"
    );

    let localize = help(&["localize"]);
    assert!(
        !localize.contains("GridToml") && localize.contains("base ="),
        "{localize}"
    );
}

#[test]
fn the_landmark_filter_on_a_lidar_log_is_refused_with_the_way_out() {
    // A bag is opened first (one with detections is a landmark recording): a lidar bag's
    // refusal is in tests/detections_bag.rs.
    for dataset in ["carmen:x.clf", "thor:thor"] {
        let out = host_sim()
            .args(["replay", "--dataset", dataset, "--filter", "ekf-slam"])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{dataset}");
        let family = dataset.split(':').next().unwrap();
        assert!(
            err.contains("range-bearing sightings")
                && err.contains(&format!("a {family} replay"))
                && err.contains("--filter grid-slam"),
            "{err}"
        );
    }
}

#[test]
fn a_setting_out_of_range_is_named_with_its_file_and_rule() {
    let dir = tempfile::tempdir().unwrap();
    let refused = |args: &[&str], text: &str| {
        let file = dir.path().join("bad.toml");
        std::fs::write(&file, text).unwrap();
        let out = host_sim()
            .args(args)
            .arg("--config")
            .arg(&file)
            .arg("--out")
            .arg(dir.path().join("out"))
            .output()
            .unwrap();
        assert!(!out.status.success(), "{text}");
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(err.contains(&file.display().to_string()), "{err}");
        err
    };
    // Grid settings.
    let grid = ["replay", "--dataset", "carmen:intel/intel-raw-part.clf"];
    let err = refused(&grid, "resample_neff_fraction = 2.0\n");
    assert!(
        err.contains("`resample_neff_fraction` must be within 0 ..= 1"),
        "{err}"
    );
    let err = refused(&grid, "hit = -3\n");
    assert!(err.contains("`hit` must be 0 or more"), "{err}");
    let err = refused(&grid, "[loop_closure]\nposition_std_floor_m = -1.0\n");
    assert!(
        err.contains("[loop_closure]: `position_std_floor_m` must be finite and positive"),
        "{err}"
    );
    // EKF settings.
    let ekf = ["replay", "--dataset", "mrclam:dataset6"];
    let err = refused(&ekf, "[sighting]\nrange_std = -1.0\n");
    assert!(err.contains("sighting.range_std = -1"), "{err}");
    let err = refused(&ekf, "[recovery]\nheading_std = nan\n");
    assert!(err.contains("recovery.heading_std = NaN"), "{err}");
    let err = refused(&ekf, "[recovery]\nhuber_sigma = 1e40\n");
    assert!(
        err.contains("recovery.huber_sigma: beyond the range of f32"),
        "{err}"
    );
    // A noise figure that large is beyond any physical range before f32's.
    let err = refused(&ekf, "[sighting]\nrange_std = 1e40\n");
    assert!(
        err.contains("sighting.range_std = 10000000000000000000000000000000000000000: beyond any physical range (0 ..= 100)"),
        "{err}"
    );
    // Options of the estimator the replay does not run.
    let out = host_sim()
        .args([&ekf[..], &["--particles", "32", "--reference", "ref.tum"]].concat())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("--particles, --reference applies to the grid filters (`--filter grid-slam`), which this replay of `mrclam:` does not run"),
        "{err}"
    );
    // A global search option: named with the option that sets it.
    let out = host_sim()
        .args([
            "sim",
            "--grid-particles",
            "16",
            "--global",
            "--min-score",
            "1.5",
        ])
        .arg("--out")
        .arg(dir.path().join("global"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("`min_score_fraction` must be within 0 ..= 1 (--min-score)"),
        "{err}"
    );
}

#[test]
fn particle_counts_that_are_not_compiled_in_are_refused_with_the_list() {
    let out = host_sim()
        .args(["replay", "--dataset", "carmen:x.clf", "--particles", "7"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("[8, 16, 32, 64, 100, 128, 200, 400]"), "{err}");
}

/// The PNG files under `dir`, at any depth.
fn pictures(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).expect("output folder").flatten() {
        let path = entry.path();
        if path.is_dir() {
            found.extend(pictures(&path));
        } else if path.extension().is_some_and(|e| e == "png") {
            found.push(path);
        }
    }
    found.sort();
    found
}

/// Runs `host-sim` with `args` into the folder `out`.
fn run_into(out: &std::path::Path, args: &[&str]) {
    succeeds(host_sim().args(args).arg("--quiet").arg("--out").arg(out));
}

#[test]
fn no_plots_leaves_out_every_picture_and_an_earlier_runs() {
    use host_sim::domain::datasets::dataset_path;
    let dir = tempfile::tempdir().unwrap();
    // The first 300 scans of the Intel log (its three header lines, then one scan a line).
    let intel = dataset_path("intel/intel-raw-part.clf").expect("the Intel log");
    let text = std::fs::read_to_string(intel).unwrap();
    let log = dir.path().join("intel300.clf");
    let head: String = text.lines().take(303).map(|l| format!("{l}\n")).collect();
    std::fs::write(&log, head).unwrap();
    let carmen = format!("carmen:{}", log.display());

    // Grid SLAM: the picture, then none (the earlier one removed), the data files kept.
    let slam = dir.path().join("slam");
    let grid_slam = ["replay", "--filter", "grid-slam", "--dataset", &carmen];
    run_into(&slam, &grid_slam);
    assert_eq!(pictures(&slam), [slam.join("map.png")]);
    run_into(&slam, &[&grid_slam[..], &["--no-plots"]].concat());
    assert_eq!(pictures(&slam), Vec::<std::path::PathBuf>::new());
    for f in ["map.pgm", "map.yaml", "trajectory.tum", "metrics.json"] {
        assert!(
            slam.join(f).is_file(),
            "grid SLAM without pictures lacks {f}"
        );
    }

    // The localizer on that map, the same way.
    let localized = dir.path().join("localize");
    let map = slam.join("map.yaml");
    let map = map.to_str().unwrap();
    let localize = ["localize", "--map", map, "--dataset", &carmen];
    run_into(&localized, &localize);
    assert_eq!(pictures(&localized), [localized.join("map.png")]);
    run_into(&localized, &[&localize[..], &["--no-plots"]].concat());
    assert_eq!(pictures(&localized), Vec::<std::path::PathBuf>::new());
    assert!(localized.join("trajectory.tum").is_file());

    // The landmark EKF (MRCLAM): map.png and errors.png, then neither.
    let ekf = dir.path().join("ekf");
    let mrclam = ["replay", "--dataset", "mrclam:dataset6"];
    run_into(&ekf, &mrclam);
    assert_eq!(
        pictures(&ekf),
        [ekf.join("errors.png"), ekf.join("map.png")]
    );
    run_into(&ekf, &[&mrclam[..], &["--no-plots"]].concat());
    assert_eq!(pictures(&ekf), Vec::<std::path::PathBuf>::new());
    assert!(ekf.join("trajectory.tum").is_file());

    // The simulator: no picture of the landmark run nor of either grid run.
    let sim = dir.path().join("sim");
    let cfg = dir.path().join("short.toml");
    std::fs::write(&cfg, "[scenario]\nduration_s = 20.0\n").unwrap();
    let cfg = cfg.to_str().unwrap();
    let sim_args = [
        "sim",
        "--seed",
        "3",
        "--grid-particles",
        "16",
        "--config",
        cfg,
    ];
    run_into(&sim, &[&sim_args[..], &["--no-plots"]].concat());
    assert_eq!(pictures(&sim), Vec::<std::path::PathBuf>::new());
    for f in [
        "grid/slam/map.pgm",
        "grid/localize/trajectory.tum",
        "metrics.json",
    ] {
        assert!(sim.join(f).is_file(), "sim without pictures lacks {f}");
    }
}
