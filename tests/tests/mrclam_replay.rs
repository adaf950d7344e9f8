//! MRCLAM dataset 6, robots 1–5, replayed through the landmark EKF-SLAM with the one
//! built-in settings file (`host-sim/configs/mrclam.toml`, chosen on robots 1–3 of
//! datasets 3, 4 and 6 and stress variants of them, checked on the others; every other
//! run and variant is held by `mrclam_every_run.rs`). Bounds are the figures measured with these settings plus at most 5 % (see
//! `docs/results-ekf.md`; re-measure with
//! `host-sim replay -d mrclam:dataset6/robot<k> [-a jcbb] [--precision f32]`).

use host_sim::domain::config::Settings;
use host_sim::domain::recording::Recording;
use host_sim::domain::{AssociationMode, Precision};
use host_sim::inputs::readers::{self, DatasetSpec};
use host_sim::metrics::{Metrics, evaluate};
use std::sync::OnceLock;

fn recording(robot: u8) -> &'static Recording {
    static RECS: [OnceLock<Recording>; 5] = [const { OnceLock::new() }; 5];
    RECS[usize::from(robot - 1)].get_or_init(|| {
        readers::read(&DatasetSpec::Mrclam("dataset6".into()), robot).expect("MRCLAM dataset 6")
    })
}

fn run(robot: u8, mode: AssociationMode, precision: Precision) -> Metrics {
    let settings = Settings::load_for("mrclam", None, Some(mode)).unwrap();
    let rec = recording(robot);
    let run = host_sim::drivers::ekf::replay(rec, &settings, mode, precision, None).unwrap();
    evaluate(rec, &run)
}

fn se2(v: &host_sim::metrics::Aligned) -> f64 {
    v.se2.expect("se2 figure")
}

/// Measured with known ids, f64: (robot, ATE(se2) m, landmarks(se2) m, pose NEES mean,
/// share of steps inside the 95 % NEES band, dead reckoning ATE(se2) m).
const KNOWN: [(u8, f64, f64, f64, f64, f64); 5] = [
    (1, 0.1888, 0.2163, 0.359, 1.000, 2.0983),
    (2, 0.1771, 0.1209, 3.181, 1.000, 2.0757),
    (3, 0.1680, 0.1127, 0.408, 1.000, 3.0537),
    (4, 0.2464, 0.2417, 0.486, 1.000, 1.2656),
    (5, 0.2222, 0.1931, 2.305, 1.000, 1.1411),
];

/// The range bias of each robot's sightings fitted by least squares against the Vicon
/// ground truth: range error (measured − true range) = `b₀ + b₂ β² + c r`, `β` the
/// measured bearing and `r` the true range, errors beyond 1 m left out; computed outside
/// the code under test (`scripts/mrclam-vicon-errors`, first table): (robot, b₀ m,
/// b₂ m/rad²). The filter never sees it.
const RANGE_BIAS_FROM_GROUND_TRUTH: [(u8, f64, f64); 5] = [
    (1, 0.126, -1.540),
    (2, 0.188, -1.932),
    (3, 0.211, -1.789),
    (4, 0.233, -1.509),
    (5, 0.172, -1.756),
];

/// 5 % above a measured figure.
fn bound(measured: f64) -> f64 {
    measured * 1.05
}

fn check_known(robot: u8) {
    let &(_, ate, landmarks, nees, in_band, dr) =
        KNOWN.iter().find(|k| k.0 == robot).expect("robot");
    let m = run(robot, AssociationMode::Known, Precision::F64);
    assert_eq!(m.dataset, format!("mrclam/dataset6/robot{robot}"));
    assert!(se2(&m.ate_rmse_m) < bound(ate), "{m:?}");
    assert!(se2(&m.landmark_rmse_m) < bound(landmarks), "{m:?}");
    let n = m.nees_pose_mean.unwrap();
    assert!(n < bound(nees), "NEES {n}");
    let share = m.nees_pose_within_95.unwrap();
    assert!(share > in_band / 1.05, "in band {share}");
    assert_eq!(m.landmarks_created, 15);
    assert_eq!(m.association_purity, Some(1.0));
    // The floor: odometry alone, independent of the settings' noise figures.
    let d = se2(&m.dead_reckoning_ate_rmse_m);
    assert!((d - dr).abs() < 0.001, "dead reckoning {d}");
    // At least 4× better than dead reckoning on every robot (measured 5.1× to 18.2×).
    assert!(se2(&m.ate_rmse_m) * 4.0 < d, "{m:?}");
    // Every robot ≤ 0.30 m, NEES mean ≤ 10.
    assert!(se2(&m.ate_rmse_m) <= 0.30 && n <= 10.0, "{m:?}");
    // The self-calibration finds the range bias the ground truth shows (measured within
    // 0.084 m and 0.16 m/rad²: the wide noise figures of the settings, 0.7 m and
    // 0.15 rad, leave the bias less well determined than earlier settings with 0.4 m and
    // 0.1 rad, which came within 0.057 m and 0.091 m/rad²), a speed scale below 1 (the
    // odometry reads fast; measured 0.94–0.98) and a turn-rate scale near the
    // ground truth's fit of 0.87–0.93 (measured 0.915–0.957, robot 4 1.056).
    let &(_, b0, b2) = RANGE_BIAS_FROM_GROUND_TRUTH
        .iter()
        .find(|k| k.0 == robot)
        .expect("robot");
    let [e0, e2] = m.calibration.range_bias.expect("range bias estimated");
    assert!(
        (e0 - b0).abs() < 0.09 && (e2 - b2).abs() < 0.17,
        "{e0} {e2}"
    );
    let [sv, sw] = m
        .calibration
        .odometry_scale
        .expect("odometry scale estimated");
    assert!(
        (0.9..0.99).contains(&sv) && (0.9..1.06).contains(&sw),
        "{sv} {sw}"
    );
    // Quiet: the lost flag up for at most 1 % of the estimates (measured 0–1.0 %).
    assert!(m.lost_share < 0.0105 && !m.lost_reported, "{m:?}");
    // f32, as on the microcontroller, within 1 mm of f64.
    let m32 = run(robot, AssociationMode::Known, Precision::F32);
    assert!(
        (se2(&m32.ate_rmse_m) - se2(&m.ate_rmse_m)).abs() < 0.001,
        "f32 {m32:?}"
    );
    assert!((se2(&m32.landmark_rmse_m) - se2(&m.landmark_rmse_m)).abs() < 0.001);
}

#[test]
fn known_ids_robot1() {
    check_known(1);
    // Ground truth ends ~130 s before the odometry: only the covered part is scored.
    let m = run(1, AssociationMode::Known, Precision::F64);
    assert!(m.evaluated_poses < m.steps - 8000, "{m:?}");
}

#[test]
fn known_ids_robot2() {
    check_known(2);
}

#[test]
fn known_ids_robot3() {
    // The shipped settings of the robot-1-only tuning locked this robot out (3.14 m, worse
    // than dead reckoning).
    check_known(3);
}

#[test]
fn known_ids_robot4() {
    check_known(4);
}

#[test]
fn known_ids_robot5() {
    check_known(5);
}

/// The settings before self-calibration (noise figures that cover the range bias and
/// the scale errors instead of estimating them, odometry held and not delayed), under
/// which robot 3's filter grows overconfident: what the supervision is for.
fn uncalibrated() -> Settings {
    let mut settings = Settings::load_for("mrclam", None, Some(AssociationMode::Known)).unwrap();
    let (o, s) = (&mut settings.odometry, &mut settings.sighting);
    o.linear_std = 0.01;
    o.linear_std_per_mps = 0.15;
    o.angular_std = 0.005;
    o.angular_std_per_radps = 0.05;
    o.speed_scale_std = 0.0;
    o.turn_scale_std = 0.0;
    o.latency_s = 0.0;
    o.interpolate = false;
    s.range_std = 0.3;
    s.bearing_std = 0.03;
    s.range_bias_offset_std = 0.0;
    s.range_bias_curvature_std = 0.0;
    settings
}

#[test]
fn self_calibrated_settings_hold_robot3_without_supervision() {
    // With the self-calibration the filter stays consistent (NEES 0.4) on robot 3 even
    // with `[recovery]` off: measured 0.168 m, 4 sightings gated.
    let mut settings = Settings::load_for("mrclam", None, Some(AssociationMode::Known)).unwrap();
    settings.recovery = host_sim::domain::config::RecoverySettings::default();
    let rec = recording(3);
    let run = microslam_replay_tests::replay_known_f64(rec, &settings);
    let m = evaluate(rec, &run);
    assert!(se2(&m.ate_rmse_m) < bound(0.1680), "{m:?}");
    assert!(m.counts.gated < 10, "{:?}", m.counts);
}

#[test]
fn without_supervision_robot3_locks_out() {
    // The uncalibrated settings with `[recovery]` off: the χ² gate refuses the true
    // sightings of an overconfident filter and it never comes back (measured 2.49 m ATE,
    // 3106 sightings refused).
    let mut settings = uncalibrated();
    settings.recovery = host_sim::domain::config::RecoverySettings::default();
    let rec = recording(3);
    let run = microslam_replay_tests::replay_known_f64(rec, &settings);
    let m = evaluate(rec, &run);
    assert!(se2(&m.ate_rmse_m) > 2.0, "{m:?}");
    assert!(m.counts.gated > 1000, "{:?}", m.counts);
    // The lost flag alone (the file's lost_memory and lost_rate, no recovery) sees it:
    // up for 74.5 % of the estimates, agreeing with the error being above 1 m on 74.9 %
    // of them; the run reports itself lost, as its ATE says it is.
    settings.recovery.lost_memory = 20;
    settings.recovery.lost_rate = 0.1;
    let run = microslam_replay_tests::replay_known_f64(rec, &settings);
    let m = evaluate(rec, &run);
    assert!(m.lost_share > 0.745 / 1.05 && m.lost_reported, "{m:?}");
    assert_eq!(m.lost_report_agrees, Some(true));
    assert!(m.lost_flag_agreement.unwrap() > 0.749 / 1.05, "{m:?}");
}

#[test]
fn recovery_alone_reacquires_robot3() {
    // The uncalibrated settings, Huber weighting off, recovery on: after 10 refusals in a
    // row the pose covariance is inflated and the filter re-acquires its map (measured:
    // one recovery, 0.204 m).
    let mut settings = uncalibrated();
    settings.recovery.huber_sigma = 0.0;
    let rec = recording(3);
    let run = microslam_replay_tests::replay_known_f64(rec, &settings);
    let m = evaluate(rec, &run);
    assert_eq!(m.counts.recoveries, 1, "{:?}", m.counts);
    assert!(se2(&m.ate_rmse_m) < bound(0.2045), "{m:?}");
}

/// Measured with hidden ids (JCBB), f64: (robot, ATE(se2) m, landmarks(se2) m, purity,
/// landmarks created).
const JCBB: [(u8, f64, f64, f64, usize); 5] = [
    (1, 0.3091, 0.5369, 0.761, 15),
    (2, 0.2784, 0.2115, 0.900, 15),
    (3, 0.4713, 0.8605, 0.875, 19),
    (4, 0.5407, 0.2456, 0.788, 19),
    (5, 0.2708, 0.3148, 0.919, 15),
];

#[test]
fn jcbb_hidden_ids_every_robot() {
    for &(robot, ate, landmarks, purity, created) in &JCBB {
        let m = run(robot, AssociationMode::Jcbb, Precision::F64);
        assert!(se2(&m.ate_rmse_m) < bound(ate), "robot {robot}: {m:?}");
        assert!(
            se2(&m.landmark_rmse_m) < bound(landmarks),
            "robot {robot}: {m:?}"
        );
        let p = m.association_purity.unwrap();
        assert!(p > purity / 1.05, "robot {robot}: purity {p}");
        // Not the bar of purity ≥ 0.8 on every robot any more (measured 0.761 to 0.919):
        // the hidden-id settings are chosen across recordings and stress variants now,
        // not on dataset 6 alone (docs/results-ekf.md).
        assert!(p >= 0.75, "robot {robot}: purity {p}");
        assert_eq!(m.landmarks_created, created, "robot {robot}");
        let m32 = run(robot, AssociationMode::Jcbb, Precision::F32);
        assert!(
            (se2(&m32.ate_rmse_m) - se2(&m.ate_rmse_m)).abs() < 0.001,
            "robot {robot} f32: {m32:?}"
        );
    }
}

/// MRCLAM dataset 1 (robot 1 only, no robot ground truth: the maps are aligned on each
/// other) with the settings file (which checks on it, never tunes on it).
fn run_dataset1(mode: AssociationMode) -> Metrics {
    let settings = Settings::load_for("mrclam", None, Some(mode)).unwrap();
    let rec = readers::read(&DatasetSpec::Mrclam("dataset1".into()), 1).expect("MRCLAM dataset 1");
    let run = host_sim::drivers::ekf::replay(&rec, &settings, mode, Precision::F64, None).unwrap();
    evaluate(&rec, &run)
}

/// Dataset 1's tables disagree about two landmarks: with known ids, the estimates of
/// subjects 11 and 17 (barcodes 18 and 61) each lie about 6 m from their tabled positions
/// (which are 6.08 m apart; with the two exchanged the maps align to 0.094 m,
/// docs/results-ekf.md), while the other thirteen are within 0.16 m of theirs (measured
/// 0.034–0.157 m). The map error is that of the
/// tables, not of the filter; `landmark_errors_m` shows it landmark by landmark.
#[test]
fn dataset1_known_ids_two_landmarks_sit_at_each_others_tabled_positions() {
    let m = run_dataset1(AssociationMode::Known);
    assert_eq!(m.landmark_alignment.as_deref(), Some("landmarks"));
    assert_eq!(m.landmark_errors_m.len(), 15);
    for e in &m.landmark_errors_m {
        if e.id == 11 || e.id == 17 {
            assert!((5.8..6.2).contains(&e.error_m), "{e:?}");
        } else {
            assert!(e.error_m < bound(0.157), "{e:?}");
        }
    }
    // The RMSE is the root of the mean of the squared errors listed (measured 2.1979 m).
    let mean_sq = m
        .landmark_errors_m
        .iter()
        .map(|e| e.error_m.powi(2))
        .sum::<f64>()
        / 15.0;
    assert!((se2(&m.landmark_rmse_m) - mean_sq.sqrt()).abs() < 1e-12);
    assert!(se2(&m.landmark_rmse_m) < bound(2.1979), "{m:?}");
}

/// Hidden ids on dataset 1, a check run of the settings' method: measured 40 landmarks
/// for 15, map error 0.626 m, purity 0.778 (with the earlier settings, chosen on dataset
/// 6 alone: 42 landmarks, 0.723 m, 0.806). Hidden ids do not hold here yet
/// (docs/results-ekf.md).
#[test]
fn dataset1_jcbb() {
    let m = run_dataset1(AssociationMode::Jcbb);
    assert_eq!(m.landmark_alignment.as_deref(), Some("landmarks"));
    assert!(se2(&m.landmark_rmse_m) < bound(0.626), "{m:?}");
    assert!(m.association_purity.unwrap() > 0.778 / 1.05, "{m:?}");
    assert_eq!(m.landmarks_created, 40);
}
