//! Unit tests of the filter's internals: deferred predictions against predictions applied
//! one by one, the index map between the factor and the public state, and the names of
//! invalid settings.

use super::update::internal_to_public;
use super::*;
use crate::gate::ChiSquareGate;
use crate::sensors::range_bearing::RangeBearing;
use covariance::internal;
use nalgebra::Matrix3;

type Slam = EkfSlam<f64, { state_dim(6) }, { factor_len(6) }>;

/// A filter with both calibration slots and three landmarks, after some updates.
fn calibrated_with_landmarks() -> Slam {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.estimate_odometry_scale(0.05, 0.04).unwrap();
    slam.estimate_range_bias(0.1, 0.3).unwrap();
    for (i, z) in [(2.0, 0.4), (3.0, -0.7), (1.5, 1.2)]
        .into_iter()
        .enumerate()
    {
        slam.predict_velocity(0.4, 0.3, 0.5).unwrap();
        slam.add_landmark(&RangeBearing::new(z.0, z.1)).unwrap();
        slam.predict_velocity(0.3, -0.2, 0.5).unwrap();
        slam.update(i, &RangeBearing::new(z.0 - 0.1, z.1 + 0.05))
            .unwrap();
    }
    slam
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + a.abs().max(b.abs()))
}

/// Predictions deferred ([`deferred`]) and predictions applied one by one give the
/// same covariance, innovations and update: every reader of a deferred filter sees
/// the true factor.
#[test]
fn deferred_predictions_read_and_update_like_applied_ones() {
    let mut deferred = calibrated_with_landmarks();
    let mut applied = deferred.clone();
    for k in 0..40 {
        let (v, w) = (0.2 + 0.01 * f64::from(k), 0.3 - 0.02 * f64::from(k));
        deferred.predict_velocity(v, w, 0.1).unwrap();
        applied.predict_velocity(v, w, 0.1).unwrap();
        applied.flush_predictions();
    }
    deferred
        .inflate_pose_covariance(&Matrix3::from_diagonal_element(0.01))
        .unwrap();
    applied
        .inflate_pose_covariance(&Matrix3::from_diagonal_element(0.01))
        .unwrap();
    applied.flush_predictions();
    assert!(deferred.deferred.is_some() && applied.deferred.is_none());
    // The stored robot rows differ; what the filter shows does not.
    assert_ne!(deferred.factor_storage(), applied.factor_storage());
    let (pd, pa) = (deferred.active_covariance(), applied.active_covariance());
    // Two calibration slots, three landmarks.
    assert_eq!(pd.dim(), 13);
    for i in 0..13 {
        for j in 0..13 {
            let (a, b) = (pd.get(i, j).unwrap(), pa.get(i, j).unwrap());
            assert!(close(a, b), "({i}, {j}): {a} vs {b}");
        }
        let (da, ra) = pd.factor_row(i).unwrap();
        let (db, rb) = pa.factor_row(i).unwrap();
        assert_eq!(da, db);
        assert!(ra.zip(rb).all(|(a, b)| close(a, b)), "factor row {i}");
    }
    let (cd, ca) = (deferred.pose_covariance(), applied.pose_covariance());
    assert!(
        cd.iter().zip(ca.iter()).all(|(a, b)| close(*a, *b)),
        "{cd} vs {ca}"
    );
    // A sighting near the predicted one, so that the gate accepts it.
    let guess = RangeBearing::new(2.0, 0.0);
    let nu = applied.innovation(1, &guess).unwrap().nu;
    let z = RangeBearing::new(2.0 - nu[0] + 0.05, -nu[1] - 0.02);
    let (id, ia) = (
        deferred.innovation(1, &z).unwrap(),
        applied.innovation(1, &z).unwrap(),
    );
    assert!(close(id.mahalanobis_squared, ia.mahalanobis_squared));
    assert!(id.s.iter().zip(ia.s.iter()).all(|(a, b)| close(*a, *b)));
    // The update applies the deferred predictions, then both filters agree.
    let accepted = |o: UpdateOutcome<f64>| matches!(o, UpdateOutcome::Accepted { .. });
    assert!(accepted(deferred.update(1, &z).unwrap()));
    assert!(accepted(applied.update(1, &z).unwrap()));
    assert!(deferred.deferred.is_none());
    for (a, b) in deferred
        .factor_storage()
        .iter()
        .zip(applied.factor_storage())
    {
        assert!(close(*a, *b), "{a} vs {b}");
    }
    for (a, b) in deferred.active_mean().iter().zip(applied.active_mean()) {
        assert!(close(*a, *b), "{a} vs {b}");
    }
}

/// A new landmark after deferred predictions moves the true robot rows.
#[test]
fn a_new_landmark_applies_the_deferred_predictions() {
    let mut deferred = calibrated_with_landmarks();
    let mut applied = deferred.clone();
    for _ in 0..10 {
        deferred.predict_velocity(0.5, 0.2, 0.1).unwrap();
        applied.predict_velocity(0.5, 0.2, 0.1).unwrap();
        applied.flush_predictions();
    }
    let z = RangeBearing::new(2.5, -0.3);
    assert_eq!(deferred.add_landmark(&z), applied.add_landmark(&z));
    for (a, b) in deferred
        .factor_storage()
        .iter()
        .zip(applied.factor_storage())
    {
        assert!(close(*a, *b), "{a} vs {b}");
    }
}

#[test]
fn public_and_internal_indices_are_inverse() {
    for k in [3, 5, 9] {
        for s in 0..k {
            assert_eq!(internal_to_public(internal(s, k), k), s);
        }
    }
}

#[test]
fn an_invalid_setting_is_named_with_its_rule() {
    use crate::testing::{BrokenSetting, each_broken_setting_is_named};
    let valid = EkfConfig::<f64>::DEFAULT_F64;
    assert_eq!(valid.invalid_setting(), None);
    assert_eq!(EkfConfig::<f32>::MICROCONTROLLER.invalid_setting(), None);
    let cases: [BrokenSetting<EkfConfig<f64>>; 7] = [
        (
            |c| c.increment_noise.rotation_std_per_metre = -0.1,
            "rotation_std_per_metre",
            "finite and non-negative",
        ),
        (
            |c| c.velocity_noise.linear_std = f64::NAN,
            "linear_std",
            "finite and non-negative",
        ),
        (
            |c| c.velocity_noise.angular_std_per_mps = f64::INFINITY,
            "angular_std_per_mps",
            "finite and non-negative",
        ),
        (
            |c| c.range_std = -1.0,
            "range_std",
            "finite and non-negative",
        ),
        (
            |c| c.bearing_std = f64::NEG_INFINITY,
            "bearing_std",
            "finite and non-negative",
        ),
        (|c| c.sensor.mount.theta = f64::NAN, "mount", "finite"),
        (
            |c| c.gate = ChiSquareGate::from_threshold(0.0),
            "gate",
            "a positive threshold",
        ),
    ];
    each_broken_setting_is_named(valid, &cases, |c| (c.is_valid(), c.invalid_setting()));
    // The filter refuses each of them and keeps its own.
    for (break_it, name, _) in cases {
        let mut c = valid;
        break_it(&mut c);
        let mut slam = Slam::new(valid);
        assert_eq!(slam.set_config(c), Err(EkfError::InvalidNoise), "{name}");
        assert_eq!(slam.config(), &valid, "{name}");
        assert_eq!(
            slam.init(c, Pose2::new(1.0, 0.0, 0.0)),
            Err(EkfError::InvalidNoise)
        );
    }
}
