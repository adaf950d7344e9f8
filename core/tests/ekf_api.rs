//! Behaviour of the EKF's public API: memory layout, known answers of small cases, and
//! refusal of bad input without side effects.

use microslam::EkfError;
use microslam::ekf::{
    EKF_OVERHEAD_BYTES_F32, EkfConfig, EkfSlam, UpdateOutcome, factor_len, state_dim,
};
use microslam::gate::ChiSquareGate;
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use nalgebra::Matrix2;

fn documented_bytes_f32(landmarks: usize) -> usize {
    let n = state_dim(landmarks);
    (n + factor_len(landmarks)) * 4 + EKF_OVERHEAD_BYTES_F32
}

#[test]
fn size_matches_the_documented_formula() {
    assert_eq!(
        size_of::<EkfSlam<f32, { state_dim(16) }, { factor_len(16) }>>(),
        documented_bytes_f32(16)
    );
    assert_eq!(
        size_of::<EkfSlam<f32, { state_dim(32) }, { factor_len(32) }>>(),
        documented_bytes_f32(32)
    );
    assert_eq!(
        size_of::<EkfSlam<f32, { state_dim(64) }, { factor_len(64) }>>(),
        documented_bytes_f32(64)
    );
    // The figures printed in the crate documentation and docs/ekf-covariance.md.
    assert_eq!(factor_len(64), 131 * 132 / 2);
    assert_eq!(documented_bytes_f32(16), 2_940);
    assert_eq!(documented_bytes_f32(32), 9_660);
    assert_eq!(documented_bytes_f32(64), 35_388);
}

/// A `static` built by the `const fn` constructor: no stack copy of the covariance.
static STATIC_FILTER: EkfSlam<f32, { state_dim(64) }, { factor_len(64) }> =
    EkfSlam::new(EkfConfig::DEFAULT_F32);

#[test]
fn const_constructor_builds_a_static() {
    assert_eq!(STATIC_FILTER.landmark_count(), 0);
    assert_eq!(STATIC_FILTER.pose(), Pose2::IDENTITY);
    assert_eq!(
        <EkfSlam<f32, { state_dim(64) }, { factor_len(64) }>>::MAX_LANDMARKS,
        64
    );
}

type Slam = EkfSlam<f64, { state_dim(4) }, { factor_len(4) }>;

#[test]
fn adding_a_landmark_places_it_by_the_inverse_model() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.init(
        EkfConfig::DEFAULT_F64,
        Pose2::new(1.0, 2.0, core::f64::consts::FRAC_PI_2),
    )
    .unwrap();
    let i = slam.add_landmark(&RangeBearing::new(3.0, 0.0)).unwrap();
    let l = slam.landmark(i).unwrap();
    // Facing +y from (1, 2): 3 m ahead is (1, 5).
    assert!((l.x - 1.0).abs() < 1e-12 && (l.y - 5.0).abs() < 1e-12);
    // With a known robot, the landmark covariance is G_z R G_zᵀ: σ_r² along the ray (y),
    // (r σ_b)² across it (x).
    let p = slam.landmark_covariance(i).unwrap();
    let cfg = EkfConfig::DEFAULT_F64;
    assert!((p[(1, 1)] - cfg.range_std.powi(2)).abs() < 1e-12);
    assert!((p[(0, 0)] - (3.0 * cfg.bearing_std).powi(2)).abs() < 1e-12);
}

#[test]
fn an_update_pulls_towards_the_measurement_and_shrinks_uncertainty() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    let i = slam.add_landmark(&RangeBearing::new(4.0, 0.0)).unwrap();
    for _ in 0..10 {
        slam.predict_velocity(0.5, 0.0, 0.1).unwrap();
    }
    // Travelled 0.5 m: the landmark is now predicted at 3.5 m. Measure 3.4 m.
    let before = slam.pose_covariance()[(0, 0)];
    let x_before = slam.pose().x;
    let out = slam.update(i, &RangeBearing::new(3.4, 0.0)).unwrap();
    let UpdateOutcome::Accepted { nis } = out else {
        panic!("gated: {out:?}")
    };
    assert!(nis > 0.0);
    assert!(
        slam.pose().x > x_before,
        "a shorter range means the robot is further ahead"
    );
    assert!(slam.pose_covariance()[(0, 0)] < before);
    assert_eq!(slam.counters().updates, 1);
    assert_eq!(slam.counters().predictions, 10);
}

#[test]
fn gate_refuses_outliers_without_touching_the_state() {
    let cfg = EkfConfig {
        gate: ChiSquareGate::two_dof(0.99).unwrap(),
        ..EkfConfig::DEFAULT_F64
    };
    let mut slam = Slam::new(cfg);
    let i = slam.add_landmark(&RangeBearing::new(4.0, 0.0)).unwrap();
    slam.predict_velocity(0.5, 0.0, 0.1).unwrap();
    let mean = slam.active_mean().to_vec();
    let out = slam.update(i, &RangeBearing::new(9.0, 1.0)).unwrap();
    assert!(matches!(out, UpdateOutcome::Gated { nis } if nis > 9.21));
    assert_eq!(slam.active_mean(), &mean[..]);
    assert_eq!(slam.counters().gated, 1);
}

#[test]
fn bad_input_is_refused_and_changes_nothing() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    let i = slam.add_landmark(&RangeBearing::new(2.0, 0.5)).unwrap();
    slam.predict_velocity(0.3, 0.1, 0.1).unwrap();
    let mean = slam.active_mean().to_vec();
    let cov: Vec<f64> = slam.active_covariance().iter().collect();
    let z = RangeBearing::new(2.0, 0.5);
    let cases: [(Result<(), EkfError>, EkfError); 9] = [
        (
            slam.predict_velocity(f64::NAN, 0.0, 0.1),
            EkfError::NonFiniteInput,
        ),
        (
            slam.predict_velocity(0.1, 0.0, -0.1),
            EkfError::NegativeTimeStep,
        ),
        (
            slam.predict_increment(&Pose2::new(0.0, f64::INFINITY, 0.0)),
            EkfError::NonFiniteInput,
        ),
        (
            slam.update(i, &RangeBearing::new(-1.0, 0.0)).map(|_| ()),
            EkfError::InvalidRange,
        ),
        (
            slam.update(i, &RangeBearing::new(1.0, f64::NEG_INFINITY))
                .map(|_| ()),
            EkfError::NonFiniteInput,
        ),
        (slam.update(3, &z).map(|_| ()), EkfError::UnknownLandmark),
        (
            slam.update_with_covariance(i, &z, &Matrix2::new(-1.0, 0.0, 0.0, 1.0))
                .map(|_| ()),
            EkfError::InvalidNoise,
        ),
        (
            slam.add_landmark(&RangeBearing::new(0.0, 0.0)).map(|_| ()),
            EkfError::InvalidRange,
        ),
        (
            slam.add_landmark_with_covariance(&z, &Matrix2::new(1.0, 0.0, 0.0, f64::NAN))
                .map(|_| ()),
            EkfError::InvalidNoise,
        ),
    ];
    for (k, (got, want)) in cases.into_iter().enumerate() {
        assert_eq!(got, Err(want), "case {k}");
    }
    assert_eq!(slam.active_mean(), &mean[..]);
    assert_eq!(slam.active_covariance().iter().collect::<Vec<_>>(), cov);
    assert_eq!(slam.counters().rejected, 9);
    // A zero time step is a documented no-op.
    slam.predict_velocity(1.0, 1.0, 0.0).unwrap();
    assert_eq!(slam.active_mean(), &mean[..]);
}

#[test]
fn full_map_is_an_error_and_the_filter_goes_on() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    for k in 0..4 {
        assert_eq!(
            slam.add_landmark(&RangeBearing::new(2.0 + f64::from(k), 0.1)),
            Ok(k as usize)
        );
    }
    assert_eq!(
        slam.add_landmark(&RangeBearing::new(2.0, 0.1)),
        Err(EkfError::MapFull)
    );
    assert_eq!(slam.landmark_count(), 4);
    slam.predict_velocity(0.2, 0.0, 0.5).unwrap();
    assert!(matches!(
        slam.update(3, &RangeBearing::new(4.9, 0.1)),
        Ok(UpdateOutcome::Accepted { .. })
    ));
}

#[test]
fn init_clears_the_previous_run() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.add_landmark(&RangeBearing::new(2.0, 0.5)).unwrap();
    slam.predict_velocity(0.3, 0.1, 1.0).unwrap();
    slam.init(EkfConfig::DEFAULT_F64, Pose2::new(5.0, 0.0, 7.0))
        .unwrap();
    assert_eq!(slam.landmark_count(), 0);
    assert!(slam.factor_storage().iter().all(|v| *v == 0.0));
    assert!(
        (slam.pose().theta - (7.0 - core::f64::consts::TAU)).abs() < 1e-12,
        "heading wrapped"
    );
    let bad = EkfConfig {
        range_std: -0.1,
        ..EkfConfig::DEFAULT_F64
    };
    assert_eq!(slam.init(bad, Pose2::IDENTITY), Err(EkfError::InvalidNoise));
}

#[test]
fn robot_variances_are_capped_without_breaking_positive_definiteness() {
    use microslam::ekf::{MAX_HEADING_VARIANCE, MAX_POSITION_VARIANCE};
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.add_landmark(&RangeBearing::new(2.0, 0.5)).unwrap();
    // A turn of 10⁶ rad with 5 % noise per radian: σ_θ = 5·10⁴ rad without the cap.
    slam.predict_increment(&Pose2::new(3.0e4, 0.0, 1.0e6))
        .unwrap();
    let view = slam.active_covariance();
    let p = nalgebra::DMatrix::from_fn(view.dim(), view.dim(), |i, j| view.get(i, j).unwrap());
    assert!(
        p[(2, 2)] <= MAX_HEADING_VARIANCE * (1.0 + 1e-12),
        "{}",
        p[(2, 2)]
    );
    assert!(
        p[(0, 0)] <= MAX_POSITION_VARIANCE * (1.0 + 1e-12),
        "{}",
        p[(0, 0)]
    );
    assert!(
        (p[(2, 2)] - MAX_HEADING_VARIANCE).abs() < 1e-6,
        "the cap is reached, not undershot"
    );
    let trace = p.trace();
    let min_eig = p.symmetric_eigen().eigenvalues.min();
    assert!(min_eig >= -1e-12 * trace, "{min_eig}");
}

#[test]
fn pose_inflation_adds_to_the_robot_block_only() {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.predict_velocity(0.5, 0.2, 1.0).unwrap();
    slam.add_landmark(&RangeBearing::new(2.0, 0.5)).unwrap();
    slam.predict_velocity(0.5, 0.2, 1.0).unwrap();
    let before = slam.active_covariance();
    let k = before.dim();
    let old = nalgebra::DMatrix::from_fn(k, k, |i, j| before.get(i, j).unwrap());
    let added = nalgebra::Matrix3::new(0.5, 0.1, 0.0, 0.1, 0.2, 0.0, 0.0, 0.0, 0.3);
    slam.inflate_pose_covariance(&added).unwrap();
    let after = slam.active_covariance();
    for i in 0..k {
        for j in 0..k {
            let plus = if i < 3 && j < 3 { added[(i, j)] } else { 0.0 };
            let got = after.get(i, j).unwrap();
            assert!((got - old[(i, j)] - plus).abs() < 1e-12, "({i}, {j})");
        }
    }
    // Refused, with nothing changed: non-finite, indefinite.
    let snapshot: Vec<f64> = slam.active_covariance().iter().collect();
    let nan = nalgebra::Matrix3::from_diagonal_element(f64::NAN);
    assert_eq!(
        slam.inflate_pose_covariance(&nan),
        Err(EkfError::NonFiniteInput)
    );
    let indefinite = nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::new(1.0, -0.1, 1.0));
    assert_eq!(
        slam.inflate_pose_covariance(&indefinite),
        Err(EkfError::InvalidNoise)
    );
    assert_eq!(
        slam.active_covariance().iter().collect::<Vec<_>>(),
        snapshot
    );
}
