//! The command line as a user meets it.

use std::process::Command;

fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

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
    let out = host_sim()
        .args(["sim", "--seed", "3", "--quiet", "--config"])
        .arg(&cfg)
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
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
