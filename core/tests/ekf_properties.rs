//! Property tests of the EKF over random sequences of steps, in f32 and f64: the active
//! covariance stays symmetric positive semi-definite, the heading stays wrapped, the
//! inactive part of the state is never touched, valid steps are accepted (a new landmark
//! only refused with `MapFull` when the table is full), and refused steps change nothing.

use microslam::ekf::{CovarianceUpdate, EkfConfig, EkfSlam, state_dim};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::{MIN_RANGE, RangeBearing};
use microslam::{EkfError, Real};
use nalgebra::DMatrix;
use proptest::prelude::*;

const L: usize = 6;
const N: usize = state_dim(L);

#[derive(Clone, Debug)]
enum Op {
    Velocity(f64, f64, f64),
    Increment(f64, f64, f64),
    /// Update landmark `i % n` with the predicted measurement plus an offset.
    Update(usize, f64, f64),
    Add(f64, f64),
    /// Input with a NaN or infinity somewhere: must be refused without effect.
    Bad(usize, f64),
}

fn op() -> impl Strategy<Value = Op> {
    let special = prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)];
    prop_oneof![
        3 => (-1.0..2.0f64, -2.0..2.0f64, 0.0..0.5f64).prop_map(|(v, w, dt)| Op::Velocity(v, w, dt)),
        2 => (-0.3..0.5f64, -0.2..0.2f64, -0.5..0.5f64).prop_map(|(x, y, t)| Op::Increment(x, y, t)),
        4 => (0..64usize, -0.3..0.3f64, -0.1..0.1f64).prop_map(|(i, dr, db)| Op::Update(i, dr, db)),
        2 => (0.3..8.0f64, -3.1..3.1f64).prop_map(|(r, b)| Op::Add(r, b)),
        1 => (0..6usize, special).prop_map(|(w, v)| Op::Bad(w, v)),
    ]
}

/// Applies one op; returns the filter's answer, `Ok(())` also when nothing was applied (an
/// update with no landmark yet, of a landmark on the sensor, or whose offset range falls
/// below `MIN_RANGE`).
fn apply<T: Real>(ekf: &mut EkfSlam<T, N>, op: &Op) -> Result<(), EkfError> {
    let t = T::lit;
    match *op {
        Op::Velocity(v, w, dt) => ekf.predict_velocity(t(v), t(w), t(dt)),
        Op::Increment(x, y, th) => ekf.predict_increment(&Pose2::new(t(x), t(y), t(th))),
        Op::Update(i, dr, db) => {
            let n = ekf.landmark_count();
            if n == 0 {
                return Ok(());
            }
            let idx = i % n;
            let l = ekf.landmark(idx).ok_or(EkfError::UnknownLandmark)?;
            // A landmark within `MIN_RANGE` of the sensor cannot be sighted: nothing to do.
            let Some(p) = ekf.config().sensor.predict(&ekf.pose(), &l) else {
                return Ok(());
            };
            let z = RangeBearing::new(p.z.range + t(dr), p.z.bearing + t(db));
            if z.range.to_f64() < MIN_RANGE {
                return Ok(());
            }
            // Accepted or gated: both are answers to valid input.
            ekf.update(idx, &z).map(|_| ())
        }
        Op::Add(r, b) => ekf.add_landmark(&RangeBearing::new(t(r), t(b))).map(|_| ()),
        Op::Bad(which, v) => {
            let v = t(v);
            let results = [
                ekf.predict_velocity(v, T::ZERO, t(0.1)).is_err(),
                ekf.predict_velocity(T::ZERO, T::ZERO, v).is_err(),
                ekf.predict_increment(&Pose2::new(T::ZERO, v, T::ZERO))
                    .is_err(),
                ekf.add_landmark(&RangeBearing::new(v, T::ZERO)).is_err(),
                ekf.add_landmark(&RangeBearing::new(T::ONE, v)).is_err(),
                ekf.update(0, &RangeBearing::new(T::ONE, v)).is_err(),
            ];
            if results[which] {
                Err(EkfError::NonFiniteInput)
            } else {
                Ok(())
            }
        }
    }
}

fn active_as_f64<T: Real>(ekf: &EkfSlam<T, N>) -> DMatrix<f64> {
    let p = ekf.active_covariance();
    DMatrix::from_fn(p.dim(), p.dim(), |i, j| p.get(i, j).unwrap().to_f64())
}

fn check_invariants<T: Real>(ekf: &EkfSlam<T, N>) -> Result<(), TestCaseError> {
    let k = ekf.active_dim();
    let p = active_as_f64(ekf);
    for i in 0..k {
        for j in 0..k {
            prop_assert!(p[(i, j)].is_finite());
            prop_assert_eq!(p[(i, j)], p[(j, i)], "asymmetric at ({}, {})", i, j);
        }
    }
    let trace = p.trace();
    let min_eig = p.clone().symmetric_eigen().eigenvalues.min();
    prop_assert!(
        min_eig >= -1e-6 * trace,
        "min eigenvalue {} with trace {}",
        min_eig,
        trace
    );
    let th = ekf.pose().theta.to_f64();
    prop_assert!(th > -core::f64::consts::PI - 1e-6 && th <= core::f64::consts::PI + 1e-6);
    prop_assert!(ekf.active_mean().iter().all(|v| v.finite()));
    // Nothing outside the upper triangle of the active block was ever written.
    let full = ekf.covariance_storage();
    for j in 0..N {
        for i in 0..N {
            if i >= k || j >= k || i > j {
                prop_assert!(
                    full[(i, j)] == T::ZERO,
                    "entry ({}, {}) outside the active upper triangle touched",
                    i,
                    j
                );
            }
        }
    }
    prop_assert!(ekf.full_mean().iter().skip(k).all(|v| *v == T::ZERO));
    Ok(())
}

fn run<T: Real>(config: EkfConfig<T>, ops: &[Op]) -> Result<(), TestCaseError> {
    let mut ekf = EkfSlam::<T, N>::new(config);
    for op in ops {
        let before_mean = ekf.active_mean().to_vec();
        let before_cov = active_as_f64(&ekf);
        let full = ekf.landmark_count() == L;
        let outcome = apply(&mut ekf, op);
        match op {
            Op::Bad(..) => {
                prop_assert!(outcome.is_err(), "{:?} was accepted", op);
                prop_assert_eq!(ekf.active_mean(), &before_mean[..]);
                prop_assert_eq!(active_as_f64(&ekf), before_cov);
            }
            Op::Add(..) if full => prop_assert_eq!(outcome, Err(EkfError::MapFull)),
            _ => prop_assert_eq!(outcome, Ok(()), "valid {:?} refused", op),
        }
        check_invariants(&ekf)?;
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn f64_joseph(ops in proptest::collection::vec(op(), 1..80)) {
        run(EkfConfig::DEFAULT_F64, &ops)?;
    }

    #[test]
    fn f64_symmetric(ops in proptest::collection::vec(op(), 1..80)) {
        run(EkfConfig { covariance_update: CovarianceUpdate::Symmetric, ..EkfConfig::DEFAULT_F64 }, &ops)?;
    }

    #[test]
    fn f32_joseph(ops in proptest::collection::vec(op(), 1..80)) {
        run(EkfConfig::DEFAULT_F32, &ops)?;
    }

    #[test]
    fn f32_symmetric(ops in proptest::collection::vec(op(), 1..80)) {
        run(EkfConfig { covariance_update: CovarianceUpdate::Symmetric, ..EkfConfig::DEFAULT_F32 }, &ops)?;
    }

    /// Both covariance forms give the same answer (up to rounding) with the optimal gain.
    #[test]
    fn joseph_equals_symmetric_form(ops in proptest::collection::vec(op(), 1..60)) {
        let mut a = EkfSlam::<f64, N>::new(EkfConfig::DEFAULT_F64);
        let mut b = EkfSlam::<f64, N>::new(EkfConfig { covariance_update: CovarianceUpdate::Symmetric, ..EkfConfig::DEFAULT_F64 });
        for op in &ops {
            let _ = apply(&mut a, op);
            let _ = apply(&mut b, op);
        }
        let (pa, pb) = (active_as_f64(&a), active_as_f64(&b));
        prop_assert!((pa.clone() - pb).abs().max() <= 1e-9 * (1.0 + pa.abs().max()));
    }
}

/// The fuzz finding `ekf_steps/psd-joseph-lost-robot-resightings`: an absurd step leaves
/// the robot at the variance caps with its x, y and heading almost perfectly correlated
/// (smallest eigenvalue 10⁻⁴ against 10⁴ m² variances, below `f32` resolution); a
/// landmark is added and seen again and again. The in-place Joseph update rounded the
/// near-null direction negative (−0.04) and the next updates, with gains near 20,
/// amplified it (−0.9 at trace 34). The sighting-variance floor and the loading of the
/// rows that cancel heavily keep `P` positive semi-definite.
#[test]
fn joseph_form_stays_psd_for_a_lost_robot_seeing_one_landmark_again() {
    let mut ekf = EkfSlam::<f32, N>::new(EkfConfig::DEFAULT_F32);
    ekf.predict_velocity(-5.393381e8, -1.7348298e9, 5.154045e10)
        .unwrap();
    ekf.predict_velocity(12.078369, 12.078431, 12.078431)
        .unwrap();
    // The fuzzer's bearings were 25.031862 and 12.078431 rad; bearings beyond one turn
    // are refused now, so the same directions are given within one turn (−6π, −2π).
    let landmark = ekf.add_landmark(&RangeBearing::new(
        12.078431,
        25.031862 - 6.0 * core::f32::consts::PI,
    ));
    let landmark = landmark.unwrap();
    let sighting = RangeBearing::new(12.078431, 12.078431 - 2.0 * core::f32::consts::PI);
    let mut worst = f64::INFINITY;
    for step in 0..6 {
        if step == 3 {
            ekf.predict_velocity(12.078369, 12.078431, 12.078422)
                .unwrap();
        }
        // Accepted, gated or refused: whatever happens, P must stay PSD.
        let _ = ekf.update(landmark, &sighting);
        let p = active_as_f64(&ekf);
        let min_eig = p.clone().symmetric_eigen().eigenvalues.min();
        worst = worst.min(min_eig);
        assert!(
            min_eig >= -1e-3 * p.trace(),
            "step {step}: min eigenvalue {min_eig}, trace {}",
            p.trace()
        );
    }
    assert!(worst > -1e-3, "worst eigenvalue {worst}");
}
