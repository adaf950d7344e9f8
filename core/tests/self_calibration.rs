//! Self-calibration as filter states: the odometry scale factors
//! (`EkfSlam::estimate_odometry_scale`) and the range bias (`EkfSlam::estimate_range_bias`).
//! The factorised steps against dense computations, and convergence to the true values
//! from landmark sightings alone.

use microslam::EkfError;
use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::geometry::Pose2;
use microslam::motion::integrate_velocity;
use microslam::sensors::range_bearing::{RangeBearing, RangeBearingSensor};
use nalgebra::{DMatrix, Vector2};

type Slam = EkfSlam<f64, { state_dim(6) }, { factor_len(6) }>;

fn dense(slam: &Slam) -> DMatrix<f64> {
    let view = slam.active_covariance();
    let k = slam.active_dim();
    DMatrix::from_fn(k, k, |i, j| view.get(i, j).unwrap())
}

fn calibrated() -> Slam {
    let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
    slam.init(EkfConfig::DEFAULT_F64, Pose2::new(0.5, -0.2, 0.3))
        .unwrap();
    slam.estimate_odometry_scale(0.05, 0.08).unwrap();
    slam
}

#[test]
fn the_factors_take_slot_zero_and_start_at_one() {
    let mut slam = calibrated();
    assert_eq!(slam.odometry_scale(), Some((1.0, 1.0)));
    assert_eq!(slam.landmark_count(), 0);
    assert_eq!(slam.active_dim(), 5);
    let p = dense(&slam);
    assert!((p[(3, 3)] - 0.05 * 0.05).abs() < 1e-15);
    assert!((p[(4, 4)] - 0.08 * 0.08).abs() < 1e-15);
    let j = slam.add_landmark(&RangeBearing::new(2.0, 0.4)).unwrap();
    assert_eq!(j, 0);
    assert_eq!(slam.landmark_state(0), 5);
    let lm = slam.landmark(0).unwrap();
    assert_eq!(&slam.active_mean()[5..7], lm.as_slice());
    // Once only, before any landmark; bad priors refused.
    assert_eq!(
        slam.estimate_odometry_scale(0.05, 0.05),
        Err(EkfError::MapFull)
    );
    let mut fresh = Slam::new(EkfConfig::DEFAULT_F64);
    assert_eq!(
        fresh.estimate_odometry_scale(-0.1, 0.05),
        Err(EkfError::InvalidNoise)
    );
    assert_eq!(fresh.odometry_scale(), None);
    // The last slot is the landmarks' again: 6 slots, 5 landmarks beside the factors.
    for _ in 1..5 {
        slam.add_landmark(&RangeBearing::new(3.0, -0.4)).unwrap();
    }
    assert_eq!(
        slam.add_landmark(&RangeBearing::new(3.0, -0.4)),
        Err(EkfError::MapFull)
    );
}

#[test]
fn prediction_matches_the_dense_propagation_with_the_scale_jacobian() {
    let mut slam = calibrated();
    slam.add_landmark(&RangeBearing::new(2.0, 0.4)).unwrap();
    slam.add_landmark(&RangeBearing::new(1.5, -0.7)).unwrap();
    // Correlate everything: a few motions and sightings.
    for step in 0..5 {
        slam.predict_velocity(0.3, 0.2, 0.5).unwrap();
        let z = if step % 2 == 0 {
            RangeBearing::new(1.8, 0.3)
        } else {
            RangeBearing::new(1.4, -0.9)
        };
        slam.update(step % 2, &z).unwrap();
    }
    let before = dense(&slam);
    let pose = slam.pose();
    let (sv, sw) = slam.odometry_scale().unwrap();
    let (v, w, dt) = (0.25, -0.4, 0.2);
    let step = integrate_velocity(&pose, sv * v, sw * w, dt);
    let q = slam.config().velocity_noise.covariance(v, w, dt);
    let k = slam.active_dim();
    let mut a = DMatrix::<f64>::identity(k, k);
    let mut g = DMatrix::<f64>::zeros(k, 2);
    for r in 0..3 {
        for c in 0..3 {
            a[(r, c)] = step.wrt_pose[(r, c)];
        }
        a[(r, 3)] = step.wrt_input[(r, 0)] * v;
        a[(r, 4)] = step.wrt_input[(r, 1)] * w;
        g[(r, 0)] = step.wrt_input[(r, 0)];
        g[(r, 1)] = step.wrt_input[(r, 1)];
    }
    let qd = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![q[(0, 0)], q[(1, 1)]]));
    let expected = &a * &before * a.transpose() + &g * qd * g.transpose();
    slam.predict_velocity(v, w, dt).unwrap();
    let after = dense(&slam);
    assert!(
        (&after - &expected).abs().max() < 1e-12,
        "{after} vs {expected}"
    );
    assert!((slam.pose().x - step.pose.x).abs() < 1e-15);
    assert!((slam.pose().theta - step.pose.theta).abs() < 1e-15);
}

/// 3000 steps of 0.1 s of a robot circling four landmarks with odometry `(0.2 m/s, 0.15
/// rad/s)` while it truly moves at `scale` times that; every 5th step each landmark's
/// exact sighting goes through `camera` (which may distort or drop it), then to the
/// filter (a landmark's first sighting adds it).
fn circle_among_landmarks(
    slam: &mut Slam,
    scale: (f64, f64),
    camera: impl Fn(RangeBearing<f64>) -> Option<RangeBearing<f64>>,
) {
    let landmarks = [(2.0, 1.0), (-1.0, 2.5), (0.5, -2.0), (3.0, -1.0)];
    let sensor = RangeBearingSensor::at_robot_origin();
    let mut truth = Pose2::IDENTITY;
    let (v, w, dt) = (0.2, 0.15, 0.1);
    let mut seen = [None; 4];
    for i in 0..3000 {
        truth = integrate_velocity(&truth, scale.0 * v, scale.1 * w, dt).pose;
        slam.predict_velocity(v, w, dt).unwrap();
        if i % 5 != 0 {
            continue;
        }
        for (j, &(x, y)) in landmarks.iter().enumerate() {
            let Some(z) = camera(sensor.predict(&truth, &Vector2::new(x, y)).unwrap().z) else {
                continue;
            };
            match seen[j] {
                Some(index) => {
                    slam.update(index, &z).unwrap();
                }
                None => seen[j] = Some(slam.add_landmark(&z).unwrap()),
            }
        }
    }
}

/// A robot whose odometry reports 1/0.9 of its speed and 1/0.85 of its turn rate drives
/// circles among four landmarks; the filter, told nothing of the errors, finds them.
#[test]
fn the_factors_converge_to_the_true_scale_from_sightings() {
    let (true_sv, true_sw) = (0.9, 0.85);
    let mut config = EkfConfig::DEFAULT_F64;
    config.range_std = 0.02;
    config.bearing_std = 0.01;
    let mut slam = Slam::new(config);
    slam.init(config, Pose2::IDENTITY).unwrap();
    slam.estimate_odometry_scale(0.1, 0.1).unwrap();
    circle_among_landmarks(&mut slam, (true_sv, true_sw), Some);
    let (sv, sw) = slam.odometry_scale().unwrap();
    assert!((sv - true_sv).abs() < 0.01, "speed scale {sv}");
    assert!((sw - true_sw).abs() < 0.01, "turn scale {sw}");
}

fn with_bias() -> Slam {
    let mut slam = calibrated();
    slam.estimate_range_bias(0.1, 0.5).unwrap();
    slam
}

/// Dense `J P Jᵀ` with `J` the identity except rows `rows`, which are `jac`.
fn propagate(p: &DMatrix<f64>, k: usize, rows: &[(usize, Vec<(usize, f64)>)]) -> DMatrix<f64> {
    let mut j = DMatrix::<f64>::identity(k, p.nrows());
    for (r, entries) in rows {
        for c in 0..p.nrows() {
            j[(*r, c)] = 0.0;
        }
        for &(c, v) in entries {
            j[(*r, c)] = v;
        }
    }
    &j * p * j.transpose()
}

#[test]
fn the_bias_follows_the_scale_slot_and_is_refused_twice() {
    let mut slam = with_bias();
    assert_eq!(slam.range_bias(), Some((0.0, 0.0)));
    assert_eq!(slam.odometry_scale(), Some((1.0, 1.0)));
    assert_eq!(slam.active_dim(), 7);
    assert_eq!(slam.landmark_state(0), 7);
    let p = dense(&slam);
    assert!((p[(5, 5)] - 0.01).abs() < 1e-15 && (p[(6, 6)] - 0.25).abs() < 1e-15);
    assert_eq!(slam.estimate_range_bias(0.1, 0.1), Err(EkfError::MapFull));
    assert_eq!(
        slam.estimate_odometry_scale(0.1, 0.1),
        Err(EkfError::MapFull)
    );
    // Alone, in slot 0.
    let mut alone = Slam::new(EkfConfig::DEFAULT_F64);
    alone.estimate_range_bias(0.1, 0.5).unwrap();
    assert_eq!(alone.landmark_state(0), 5);
    assert_eq!(alone.odometry_scale(), None);
    assert_eq!(alone.range_bias_state(), Some(3));
    assert_eq!(slam.range_bias_state(), Some(5));
}

#[test]
fn the_bias_may_start_from_a_prior_mean() {
    let mut slam = calibrated();
    assert_eq!(
        slam.estimate_range_bias_from((f64::NAN, 0.0), 0.1, 0.5),
        Err(EkfError::NonFiniteInput)
    );
    assert_eq!(slam.range_bias(), None, "a refused prior changes nothing");
    slam.estimate_range_bias_from((0.17, -1.7), 0.1, 0.5)
        .unwrap();
    assert_eq!(slam.range_bias(), Some((0.17, -1.7)));
    let p = dense(&slam);
    assert!((p[(5, 5)] - 0.01).abs() < 1e-15 && (p[(6, 6)] - 0.25).abs() < 1e-15);
    // From the robot at (0.5, −0.2) heading 0.3 rad, a landmark sighted at bearing
    // 0.3 rad and range 3 m is placed at the corrected range 3 − 0.17 + 1.7 · 0.09 =
    // 2.983 m, in the direction 0.6 rad.
    let z = RangeBearing::new(3.0, 0.3);
    slam.add_landmark(&z).unwrap();
    let l = slam.landmark(0).unwrap();
    let r = 3.0 - 0.17 + 1.7 * 0.09;
    let (x, y) = (0.5 + r * 0.6f64.cos(), -0.2 + r * 0.6f64.sin());
    assert!((l.x - x).abs() < 1e-12 && (l.y - y).abs() < 1e-12, "{l:?}");
}

/// Adding a landmark, a sighting's innovation and an update with the range bias as
/// states, each against the dense linearised computation.
#[test]
fn landmark_innovation_and_update_match_dense_computations_with_the_bias() {
    let mut slam = with_bias();
    slam.predict_velocity(0.3, 0.2, 0.5).unwrap();
    // Give the bias a value and correlations first.
    slam.add_landmark(&RangeBearing::new(2.0, 0.4)).unwrap();
    slam.predict_velocity(0.3, -0.3, 1.0).unwrap();
    slam.update(0, &RangeBearing::new(1.8, 0.1)).unwrap();
    slam.predict_velocity(0.2, 0.3, 1.0).unwrap();
    slam.update(0, &RangeBearing::new(1.5, 0.5)).unwrap();
    let (b0, b2) = slam.range_bias().unwrap();
    assert!(b0 != 0.0 && b2 != 0.0);

    // New landmark: l = g(x_r, r − b₀ − b₂ β², β).
    let before = dense(&slam);
    let k = slam.active_dim();
    let z = RangeBearing::new(2.5, -0.45);
    let pose = slam.pose();
    let corrected = RangeBearing::new(z.range - b0 - b2 * z.bearing * z.bearing, z.bearing);
    let g = RangeBearingSensor::at_robot_origin().landmark_from(&pose, &corrected);
    let r = slam.config().measurement_covariance();
    // Augmented [x; z] with covariance diag(P, R).
    let mut aug = DMatrix::<f64>::zeros(k + 2, k + 2);
    aug.view_mut((0, 0), (k, k)).copy_from(&before);
    aug.view_mut((k, k), (2, 2)).copy_from(&r);
    let rows: Vec<(usize, Vec<(usize, f64)>)> = (0..2)
        .map(|a| {
            let dr = g.wrt_measurement[(a, 0)];
            let db = g.wrt_measurement[(a, 1)] - dr * 2.0 * b2 * z.bearing;
            let entries = vec![
                (0, g.wrt_robot[(a, 0)]),
                (1, g.wrt_robot[(a, 1)]),
                (2, g.wrt_robot[(a, 2)]),
                (5, -dr),
                (6, -dr * z.bearing * z.bearing),
                (k, dr),
                (k + 1, db),
            ];
            (k + a, entries)
        })
        .collect();
    let expected = propagate(&aug, k + 2, &rows);
    let j = slam.add_landmark(&z).unwrap();
    let after = dense(&slam);
    assert!(
        (&after - &expected).abs().max() < 1e-12,
        "{after} vs {expected}"
    );
    let lm = slam.landmark(j).unwrap();
    assert!((lm - g.landmark).abs().max() < 1e-15);

    // Innovation of a sighting of landmark 0: h = (|d| + b₀ + b₂ β², β).
    let p = dense(&slam);
    let k = slam.active_dim();
    let z = RangeBearing::new(1.7, 0.35);
    let inn = slam.innovation(0, &z).unwrap();
    let lm0 = slam.landmark(0).unwrap();
    let pred = RangeBearingSensor::at_robot_origin()
        .predict(&slam.pose(), &lm0)
        .unwrap();
    let beta = pred.z.bearing;
    let mut h = DMatrix::<f64>::zeros(2, k);
    for c in 0..3 {
        h[(0, c)] = pred.wrt_robot[(0, c)] + 2.0 * b2 * beta * pred.wrt_robot[(1, c)];
        h[(1, c)] = pred.wrt_robot[(1, c)];
    }
    let l0 = slam.landmark_state(0);
    for c in 0..2 {
        h[(0, l0 + c)] = pred.wrt_landmark[(0, c)] + 2.0 * b2 * beta * pred.wrt_landmark[(1, c)];
        h[(1, l0 + c)] = pred.wrt_landmark[(1, c)];
    }
    h[(0, 5)] = 1.0;
    h[(0, 6)] = beta * beta;
    let s = &h * &p * h.transpose() + DMatrix::from_fn(2, 2, |i, j| r[(i, j)]);
    for i in 0..2 {
        for j in 0..2 {
            assert!(
                (inn.s[(i, j)] - s[(i, j)]).abs() < 1e-12,
                "{} vs {s}",
                inn.s
            );
        }
    }
    assert!((inn.nu[0] - (z.range - pred.z.range - b0 - b2 * beta * beta)).abs() < 1e-12);

    // The update: P' = P − P Hᵀ S⁻¹ H P.
    let s_inv = s.clone().try_inverse().unwrap();
    let expected = &p - &p * h.transpose() * &s_inv * &h * &p;
    let nu = DMatrix::from_column_slice(2, 1, inn.nu.as_slice());
    let mean: Vec<f64> = slam.active_mean().to_vec();
    let expected_mean = DMatrix::from_column_slice(k, 1, &mean) + &p * h.transpose() * &s_inv * nu;
    slam.update(0, &z).unwrap();
    let after = dense(&slam);
    assert!(
        (&after - &expected).abs().max() < 1e-12,
        "{after} vs {expected}"
    );
    for (i, (a, e)) in slam
        .active_mean()
        .iter()
        .zip(expected_mean.iter())
        .enumerate()
    {
        assert!((a - e).abs() < 1e-12, "state {i}: {a} vs {e}");
    }
}

/// A camera whose ranges read `r + 0.15 − 1.6 β²` (as MRCLAM's do), on a robot with
/// exact odometry circling four landmarks: the filter finds the bias.
#[test]
fn the_range_bias_converges_from_sightings() {
    let (true_b0, true_b2) = (0.15, -1.6);
    let mut config = EkfConfig::DEFAULT_F64;
    config.range_std = 0.02;
    config.bearing_std = 0.01;
    // Exact odometry, and a filter that knows it is good.
    config.velocity_noise.linear_std = 0.001;
    config.velocity_noise.linear_std_per_mps = 0.01;
    config.velocity_noise.angular_std = 0.001;
    config.velocity_noise.angular_std_per_radps = 0.01;
    let mut slam = Slam::new(config);
    slam.init(config, Pose2::IDENTITY).unwrap();
    slam.estimate_range_bias(0.2, 2.0).unwrap();
    circle_among_landmarks(&mut slam, (1.0, 1.0), |mut z| {
        // A camera's field of view: ±0.6 rad.
        if z.bearing.abs() > 0.6 {
            return None;
        }
        z.range += true_b0 + true_b2 * z.bearing * z.bearing;
        (z.range >= 0.5).then_some(z)
    });
    let (b0, b2) = slam.range_bias().unwrap();
    assert!((b0 - true_b0).abs() < 0.01, "offset {b0}");
    assert!((b2 - true_b2).abs() < 0.05, "curvature {b2}");
}

/// A long velocity step with the scale factors as states: their share of the robot's
/// new covariance (`F_s P_ss F_sᵀ` and the cross terms) counts towards the variance caps
/// and the finiteness check. Found by the `ekf_steps` fuzzer in `f32` (a step of 10³⁶ s
/// that left an infinite pose variance); here in `f32` and `f64`, with steps from an hour
/// to beyond overflow.
#[test]
fn a_long_step_keeps_the_pose_covariance_within_the_caps() {
    use microslam::ekf::{MAX_HEADING_VARIANCE, MAX_POSITION_VARIANCE};
    fn check<T: microslam::scalar::Real + std::fmt::Debug>(config: EkfConfig<T>, dts: &[f64]) {
        for &dt in dts {
            let mut slam = EkfSlam::<T, { state_dim(2) }, { factor_len(2) }>::new(config);
            slam.estimate_odometry_scale(T::lit(0.05), T::lit(0.05))
                .unwrap();
            let before = slam.factor_storage().to_vec();
            match slam.predict_velocity(T::lit(12.0), T::lit(0.75), T::lit(dt)) {
                Err(e) => {
                    assert_eq!(e, EkfError::NumericalFailure, "dt {dt}");
                    assert_eq!(slam.factor_storage().to_vec(), before, "dt {dt}");
                }
                Ok(()) => {
                    let p = slam.pose_covariance();
                    let caps = [
                        MAX_POSITION_VARIANCE,
                        MAX_POSITION_VARIANCE,
                        MAX_HEADING_VARIANCE,
                    ];
                    for (a, cap) in caps.into_iter().enumerate() {
                        let v = p[(a, a)].to_f64();
                        assert!(
                            v.is_finite() && v <= cap * 1.001,
                            "dt {dt}: variance {a} = {v}"
                        );
                    }
                }
            }
        }
    }
    let dts = [3600.0, 1.0e6, 1.0e12, 1.0e20, 1.0e30, 1.0e36];
    check(EkfConfig::DEFAULT_F32, &dts);
    check(EkfConfig::DEFAULT_F64, &dts);
}
