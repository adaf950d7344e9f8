//! Property tests of the EKF over random sequences of steps, in f32 and f64: the factorised
//! covariance equals a dense Joseph-form reference in f64, the covariance read back stays
//! positive semi-definite (also for lost robots with huge variances), the heading stays
//! wrapped, the inactive part of the state is never touched, valid steps are accepted (a
//! new landmark refused only with `MapFull` when the table is full), and refused steps change
//! nothing.

use microslam::ekf::{EkfConfig, EkfSlam, UpdateOutcome, factor_len, state_dim};
use microslam::geometry::{Pose2, wrap_angle, wrap_near};
use microslam::motion::{MotionStep, compose_increment, integrate_velocity};
use microslam::sensors::range_bearing::{MIN_RANGE, RangeBearing};
use microslam::{EkfError, Real};
use nalgebra::{DMatrix, DVector, Matrix2, SMatrix};
use proptest::prelude::*;

const L: usize = 6;
const N: usize = state_dim(L);
const P: usize = factor_len(L);
type Slam<T> = EkfSlam<T, N, P>;

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

fn ordinary() -> impl Strategy<Value = Op> {
    let special = prop_oneof![Just(f64::NAN), Just(f64::INFINITY), Just(f64::NEG_INFINITY)];
    prop_oneof![
        3 => (-1.0..2.0f64, -2.0..2.0f64, 0.0..0.5f64).prop_map(|(v, w, dt)| Op::Velocity(v, w, dt)),
        2 => (-0.3..0.5f64, -0.2..0.2f64, -0.5..0.5f64).prop_map(|(x, y, t)| Op::Increment(x, y, t)),
        4 => (0..64usize, -0.3..0.3f64, -0.1..0.1f64).prop_map(|(i, dr, db)| Op::Update(i, dr, db)),
        2 => (0.3..8.0f64, -3.1..3.1f64).prop_map(|(r, b)| Op::Add(r, b)),
        1 => (0..6usize, special).prop_map(|(w, v)| Op::Bad(w, v)),
    ]
}

/// Ordinary steps mixed with a lost robot: speeds up to 10⁴ m/s and turn rates up to
/// 10³ rad/s held for up to 50 s (variances of 10¹⁰ m² and more), and sightings far
/// from what the filter predicts.
fn with_lost_robot() -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => ordinary(),
        1 => (-1.0e4..1.0e4f64, -1.0e3..1.0e3f64, 0.0..50.0f64).prop_map(|(v, w, dt)| Op::Velocity(v, w, dt)),
        2 => (0..64usize, -5.0..5.0f64, -3.0..3.0f64).prop_map(|(i, dr, db)| Op::Update(i, dr, db)),
    ]
}

/// What a step did to the filter.
enum Done {
    Nothing,
    Predicted(Box<(MotionStep<f64, 3>, SMatrix<f64, 3, 3>)>),
    Added(RangeBearing<f64>),
    Updated(usize, RangeBearing<f64>),
}

/// Applies one op; returns the filter's answer (`Ok(())` also when nothing was applied: an
/// update with no landmark yet, or of a landmark on the sensor) and what it did (in `f64`,
/// for the reference).
fn apply<T: Real>(ekf: &mut Slam<T>, op: &Op) -> (Result<(), EkfError>, Done) {
    let t = T::lit;
    let pose = ekf.pose();
    let pose64 = Pose2::new(pose.x.to_f64(), pose.y.to_f64(), pose.theta.to_f64());
    let cfg = ekf.config().cast::<f64>();
    match *op {
        Op::Velocity(v, w, dt) => {
            let (v, w, dt) = (t(v), t(w), t(dt));
            if let Err(e) = ekf.predict_velocity(v, w, dt) {
                return (Err(e), Done::Nothing);
            }
            if dt == T::ZERO {
                return (Ok(()), Done::Nothing);
            }
            let (v, w, dt) = (v.to_f64(), w.to_f64(), dt.to_f64());
            let step = integrate_velocity(&pose64, v, w, dt);
            let q = step.wrt_input
                * cfg.velocity_noise.covariance(v, w, dt)
                * step.wrt_input.transpose();
            let step = MotionStep {
                pose: step.pose,
                wrt_pose: step.wrt_pose,
                wrt_input: SMatrix::<f64, 3, 3>::zeros(),
            };
            (Ok(()), Done::Predicted(Box::new((step, q))))
        }
        Op::Increment(x, y, th) => {
            let inc = Pose2::new(t(x), t(y), t(th));
            if let Err(e) = ekf.predict_increment(&inc) {
                return (Err(e), Done::Nothing);
            }
            let inc = Pose2::new(inc.x.to_f64(), inc.y.to_f64(), inc.theta.to_f64());
            let step = compose_increment(&pose64, &inc);
            let q =
                step.wrt_input * cfg.increment_noise.covariance(&inc) * step.wrt_input.transpose();
            (Ok(()), Done::Predicted(Box::new((step, q))))
        }
        Op::Update(i, dr, db) => {
            let n = ekf.landmark_count();
            if n == 0 {
                return (Ok(()), Done::Nothing);
            }
            let idx = i % n;
            let Some(l) = ekf.landmark(idx) else {
                return (Err(EkfError::UnknownLandmark), Done::Nothing);
            };
            // A landmark within the minimum range of the sensor cannot be sighted.
            let Some(p) = ekf.config().sensor.predict(&ekf.pose(), &l) else {
                return (Ok(()), Done::Nothing);
            };
            let z = RangeBearing::new(p.z.range + t(dr), wrap_angle(p.z.bearing + t(db)));
            if z.range.to_f64() < MIN_RANGE {
                return (Ok(()), Done::Nothing);
            }
            match ekf.update(idx, &z) {
                Ok(UpdateOutcome::Accepted { .. }) => (
                    Ok(()),
                    Done::Updated(idx, RangeBearing::new(z.range.to_f64(), z.bearing.to_f64())),
                ),
                // Gated: an answer to valid input.
                Ok(_) => (Ok(()), Done::Nothing),
                Err(e) => (Err(e), Done::Nothing),
            }
        }
        Op::Add(r, b) => {
            let z = RangeBearing::new(t(r), t(b));
            match ekf.add_landmark(&z) {
                Ok(_) => (
                    Ok(()),
                    Done::Added(RangeBearing::new(z.range.to_f64(), z.bearing.to_f64())),
                ),
                Err(e) => (Err(e), Done::Nothing),
            }
        }
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
            let outcome = if results[which] {
                Err(EkfError::NonFiniteInput)
            } else {
                Ok(())
            };
            (outcome, Done::Nothing)
        }
    }
}

/// A dense EKF-SLAM in `f64` (robot first, full `P`, Joseph-form update): the textbook
/// equations, written independently of the factorised filter.
struct Dense {
    x: DVector<f64>,
    p: DMatrix<f64>,
    config: EkfConfig<f64>,
}

impl Dense {
    fn new(config: EkfConfig<f64>) -> Self {
        Self {
            x: DVector::zeros(3),
            p: DMatrix::zeros(3, 3),
            config,
        }
    }

    fn pose(&self) -> Pose2<f64> {
        Pose2::new(self.x[0], self.x[1], self.x[2])
    }

    /// `P ← F P Fᵀ + Q` with `F` the robot Jacobian embedded in the identity.
    fn predict(&mut self, step: &MotionStep<f64, 3>, q: &SMatrix<f64, 3, 3>) {
        let k = self.x.len();
        let mut f = DMatrix::identity(k, k);
        f.view_mut((0, 0), (3, 3)).copy_from(&step.wrt_pose);
        let mut qk = DMatrix::zeros(k, k);
        qk.view_mut((0, 0), (3, 3)).copy_from(q);
        self.p = &f * &self.p * f.transpose() + qk;
        self.x[0] = step.pose.x;
        self.x[1] = step.pose.y;
        self.x[2] = step.pose.theta;
    }

    fn add(&mut self, z: &RangeBearing<f64>) {
        let g = self.config.sensor.landmark_from(&self.pose(), z);
        let k = self.x.len();
        let mut j = DMatrix::zeros(k + 2, k);
        j.view_mut((0, 0), (k, k)).fill_with_identity();
        j.view_mut((k, 0), (2, 3)).copy_from(&g.wrt_robot);
        let mut r = DMatrix::zeros(k + 2, k + 2);
        let gz = g.wrt_measurement
            * self.config.measurement_covariance()
            * g.wrt_measurement.transpose();
        r.view_mut((k, k), (2, 2)).copy_from(&gz);
        self.p = &j * &self.p * j.transpose() + r;
        self.x = self.x.clone().insert_rows(k, 2, 0.0);
        self.x[k] = g.landmark[0];
        self.x[k + 1] = g.landmark[1];
    }

    fn update(&mut self, idx: usize, z: &RangeBearing<f64>) {
        let k = self.x.len();
        let li = 3 + 2 * idx;
        let l = nalgebra::Vector2::new(self.x[li], self.x[li + 1]);
        let pred = self.config.sensor.predict(&self.pose(), &l).unwrap();
        let mut h = DMatrix::zeros(2, k);
        h.view_mut((0, 0), (2, 3)).copy_from(&pred.wrt_robot);
        h.view_mut((0, li), (2, 2)).copy_from(&pred.wrt_landmark);
        let r: Matrix2<f64> = self.config.measurement_covariance();
        let r = DMatrix::from_fn(2, 2, |i, j| r[(i, j)]);
        let s = &h * &self.p * h.transpose() + &r;
        let gain = &self.p * h.transpose() * s.try_inverse().unwrap();
        let nu = DVector::from_vec(vec![
            z.range - pred.z.range,
            wrap_near(z.bearing - pred.z.bearing),
        ]);
        self.x += &gain * nu;
        self.x[2] = wrap_near(self.x[2]);
        let a = DMatrix::identity(k, k) - &gain * &h;
        self.p = &a * &self.p * a.transpose() + &gain * r * gain.transpose();
    }
}

fn active_as_f64<T: Real>(ekf: &Slam<T>) -> DMatrix<f64> {
    let p = ekf.active_covariance();
    DMatrix::from_fn(p.dim(), p.dim(), |i, j| p.get(i, j).unwrap().to_f64())
}

/// `L D Lᵀ` rebuilt in `f64` from the stored factor, in the factor's own order.
fn factor_product<T: Real>(ekf: &Slam<T>) -> DMatrix<f64> {
    let view = ekf.active_covariance();
    let k = view.dim();
    let mut l = DMatrix::identity(k, k);
    let mut d = DVector::zeros(k);
    for i in 0..k {
        let (di, row) = view.factor_row(i).unwrap();
        d[i] = di.to_f64();
        for (j, v) in row.enumerate() {
            l[(i, j)] = v.to_f64();
        }
    }
    &l * DMatrix::from_diagonal(&d) * l.transpose()
}

fn check_invariants<T: Real>(ekf: &Slam<T>) -> Result<(), TestCaseError> {
    let k = ekf.active_dim();
    let p = active_as_f64(ekf);
    for i in 0..k {
        prop_assert!(p[(i, i)] >= 0.0, "negative variance at {}", i);
        for j in 0..k {
            prop_assert!(p[(i, j)].is_finite());
            prop_assert_eq!(p[(i, j)], p[(j, i)], "asymmetric at ({}, {})", i, j);
        }
    }
    // Each entry read back is a sum of at most k products L_ic D_c L_jc with D ≥ 0,
    // computed in T: its error is at most γ_k Σ_c |L_ic| D_c |L_jc| ≤ γ_k √(P_ii P_jj)
    // (Cauchy–Schwarz), γ_k = k ε / (1 − k ε). The error matrix E then has
    // ‖E‖₂ ≤ ‖E‖_F ≤ γ_k trace P, so by Weyl's inequality the smallest eigenvalue of what
    // is read is at least −γ_k trace P; (k + 1) ε bounds γ_k for k ε < 1/(k + 1).
    let eps = T::default_epsilon().to_f64();
    let trace = p.trace();
    let min_eig = p.clone().symmetric_eigen().eigenvalues.min();
    prop_assert!(
        min_eig >= -((k + 1) as f64) * eps * trace,
        "min eigenvalue {} with trace {}",
        min_eig,
        trace
    );
    // The factor itself: D ≥ 0, and L D Lᵀ (in f64) positive semi-definite up to f64
    // rounding of the product and the eigen-solver.
    let view = ekf.active_covariance();
    for i in 0..k {
        prop_assert!(
            view.factor_row(i).unwrap().0 >= T::ZERO,
            "negative pivot at {}",
            i
        );
    }
    let exact = factor_product(ekf);
    let min_exact = exact.clone().symmetric_eigen().eigenvalues.min();
    prop_assert!(
        min_exact >= -((k + 1) as f64) * f64::EPSILON * exact.trace(),
        "L D Lᵀ: {}",
        min_exact
    );
    let th = ekf.pose().theta.to_f64();
    prop_assert!(th > -core::f64::consts::PI - 1e-6 && th <= core::f64::consts::PI + 1e-6);
    prop_assert!(ekf.active_mean().iter().all(|v| v.finite()));
    // Nothing outside the active part of the factor and the mean was ever written.
    let start = k * (k + 1) / 2;
    prop_assert!(ekf.factor_storage()[start..].iter().all(|v| *v == T::ZERO));
    prop_assert!(ekf.full_mean().iter().skip(k).all(|v| *v == T::ZERO));
    Ok(())
}

/// Runs `ops` and checks the invariants after each. Input with a NaN or infinity must be
/// refused without effect; with `valid_accepted`, every other step must be accepted (a new
/// landmark refused only with `MapFull` when the table is full). Drives with a lost robot
/// pass `false`: their absurd steps may be refused by the variance caps.
fn run<T: Real>(
    config: EkfConfig<T>,
    ops: &[Op],
    valid_accepted: bool,
) -> Result<(), TestCaseError> {
    let mut ekf = Slam::<T>::new(config);
    for op in ops {
        let before_mean = ekf.active_mean().to_vec();
        let before_cov = active_as_f64(&ekf);
        let full = ekf.landmark_count() == L;
        let (outcome, _) = apply(&mut ekf, op);
        match op {
            Op::Bad(..) => {
                prop_assert!(outcome.is_err(), "{:?} was accepted", op);
                prop_assert_eq!(ekf.active_mean(), &before_mean[..]);
                prop_assert_eq!(active_as_f64(&ekf), before_cov);
            }
            _ if !valid_accepted => {}
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
    fn f64_invariants(ops in proptest::collection::vec(ordinary(), 1..80)) {
        run(EkfConfig::DEFAULT_F64, &ops, true)?;
    }

    #[test]
    fn f32_invariants(ops in proptest::collection::vec(ordinary(), 1..80)) {
        run(EkfConfig::DEFAULT_F32, &ops, true)?;
    }

    #[test]
    fn f32_stays_psd_with_a_lost_robot(ops in proptest::collection::vec(with_lost_robot(), 1..80)) {
        run(EkfConfig::DEFAULT_F32, &ops, false)?;
    }

    #[test]
    fn f64_stays_psd_with_a_lost_robot(ops in proptest::collection::vec(with_lost_robot(), 1..80)) {
        run(EkfConfig::DEFAULT_F64, &ops, false)?;
    }

    /// The factorised filter equals a dense Joseph-form EKF in `f64` (mean and covariance,
    /// to 1e-9 of their magnitude) on every step it takes.
    #[test]
    fn factor_equals_the_dense_joseph_reference(ops in proptest::collection::vec(ordinary(), 1..60)) {
        let mut ekf = Slam::<f64>::new(EkfConfig::DEFAULT_F64);
        let mut dense = Dense::new(EkfConfig::DEFAULT_F64);
        for op in &ops {
            match apply(&mut ekf, op).1 {
                Done::Nothing => {}
                Done::Predicted(p) => dense.predict(&p.0, &p.1),
                Done::Added(z) => dense.add(&z),
                Done::Updated(idx, z) => dense.update(idx, &z),
            }
            let p = active_as_f64(&ekf);
            let scale = 1.0 + dense.p.abs().max();
            prop_assert_eq!(p.nrows(), dense.p.nrows());
            prop_assert!((&p - &dense.p).abs().max() <= 1e-9 * scale,
                "P differs by {} (scale {})", (&p - &dense.p).abs().max(), scale);
            for (i, (&a, &b)) in ekf.active_mean().iter().zip(dense.x.iter()).enumerate() {
                let diff = if i == 2 { wrap_angle(a - b) } else { a - b };
                prop_assert!(diff.abs() <= 1e-9 * (1.0 + b.abs()), "mean {} differs: {} vs {}", i, a, b);
            }
        }
    }
}

/// The fuzz finding `ekf_steps/psd-joseph-lost-robot-resightings` (of the dense Joseph
/// form): an absurd step leaves the robot with 10⁸ m² variances and its x, y and heading
/// almost perfectly correlated; a landmark is added and seen again and again. The factor
/// stays positive semi-definite.
#[test]
fn a_lost_robot_seeing_one_landmark_again_stays_psd() {
    let mut ekf = Slam::<f32>::new(EkfConfig::DEFAULT_F32);
    ekf.predict_velocity(-5.393381e8, -1.7348298e9, 5.154045e10)
        .unwrap();
    ekf.predict_velocity(12.078369, 12.078431, 12.078431)
        .unwrap();
    let landmark = ekf.add_landmark(&RangeBearing::new(
        12.078431,
        25.031862 - 6.0 * core::f32::consts::PI,
    ));
    let landmark = landmark.unwrap();
    let sighting = RangeBearing::new(12.078431, 12.078431 - 2.0 * core::f32::consts::PI);
    for step in 0..6 {
        if step == 3 {
            ekf.predict_velocity(12.078369, 12.078431, 12.078422)
                .unwrap();
        }
        // Accepted, gated or refused: whatever happens, P must stay PSD.
        let _ = ekf.update(landmark, &sighting);
        let p = active_as_f64(&ekf);
        let min_eig = p.clone().symmetric_eigen().eigenvalues.min();
        let bound = -6.0 * f64::from(f32::EPSILON) * p.trace();
        assert!(
            min_eig >= bound,
            "step {step}: min eigenvalue {min_eig}, trace {}",
            p.trace()
        );
    }
}
