//! Numerical soak: long random runs of the f32 EKF through a field of landmarks, with
//! realistic magnitudes, two seeds. Every 500 steps the covariance must be finite,
//! exactly symmetric and positive semi-definite (smallest eigenvalue ≥ −1e-6 · trace),
//! and valid input is never refused; over the short run the position error must also stay
//! inside the filter's own uncertainty.
//!
//! `cargo test -p microslam --test soak` runs 20 000 steps per seed; the full soak of
//! 10⁶ steps per seed is `cargo test --release -p microslam --test soak -- --ignored`.

use microslam::association::{KnownIds, observe_known};
use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::geometry::{Pose2, wrap_angle};
use microslam::motion::integrate_velocity;
use microslam::sensors::range_bearing::RangeBearing;
use nalgebra::{DMatrix, Vector2};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

const L: usize = 16;
type Slam = EkfSlam<f32, { state_dim(L) }, { factor_len(L) }>;

#[derive(Debug, Default)]
struct SoakReport {
    steps: usize,
    updates: u32,
    refused: u32,
    worst_relative_eigenvalue: f64,
    max_position_error: f64,
    max_position_nees: f64,
}

fn check(ekf: &Slam, report: &mut SoakReport) {
    let p = ekf.active_covariance();
    let k = p.dim();
    let dense = DMatrix::from_fn(k, k, |i, j| {
        let v = p.get(i, j).unwrap();
        assert!(v.is_finite(), "non-finite P at ({i}, {j})");
        f64::from(v)
    });
    // Nothing beyond the active part of the factor is ever written.
    let storage = ekf.factor_storage();
    assert!(storage[k * (k + 1) / 2..].iter().all(|v| *v == 0.0));
    let trace = dense.trace();
    let rel = dense.symmetric_eigen().eigenvalues.min() / trace;
    report.worst_relative_eigenvalue = report.worst_relative_eigenvalue.min(rel);
    assert!(
        rel >= -1e-6,
        "smallest eigenvalue {rel} · trace after {} steps",
        report.steps
    );
    assert!(ekf.active_mean().iter().all(|v| v.is_finite()));
}

fn soak(steps: usize, seed: u64) -> SoakReport {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut ekf = Box::new(Slam::new(EkfConfig::DEFAULT_F32));
    let mut ids = KnownIds::<L>::new();
    // 16 landmarks on a 20 m grid of 4 × 4, the robot wanders among them.
    let world: Vec<Vector2<f64>> = (0..L)
        .map(|i| Vector2::new(5.0 * (i % 4) as f64 - 7.5, 5.0 * (i / 4) as f64 - 7.5))
        .collect();
    let mut truth = Pose2::<f64>::IDENTITY;
    let (nr, nb) = (
        Normal::new(0.0, 0.1).unwrap(),
        Normal::new(0.0, 0.035).unwrap(),
    );
    let mut report = SoakReport::default();
    for step in 0..steps {
        report.steps = step;
        let dt = rng.random_range(0.01..0.2);
        // Steer back towards the origin when far out.
        let home = wrap_angle(truth.y.atan2(truth.x) + core::f64::consts::PI - truth.theta);
        let omega = if truth.x.hypot(truth.y) > 9.0 {
            home.signum() * 0.8
        } else {
            rng.random_range(-1.0..1.0)
        };
        let v = rng.random_range(0.0..1.0);
        truth = integrate_velocity(&truth, v, omega, dt).pose;
        let (vm, wm) = (
            v + rng.random_range(-0.02..0.02),
            omega + rng.random_range(-0.02..0.02),
        );
        if ekf
            .predict_velocity(vm as f32, wm as f32, dt as f32)
            .is_err()
        {
            report.refused += 1;
        }
        if step % 5 == 0 {
            for (id, l) in world.iter().enumerate() {
                let d = truth.inverse_transform_point(l);
                let (r, b) = (d.norm(), d.y.atan2(d.x));
                if !(0.5..=6.0).contains(&r) || b.abs() > 1.2 {
                    continue;
                }
                let z = RangeBearing::new(
                    (r + nr.sample(&mut rng)) as f32,
                    wrap_angle(b + nb.sample(&mut rng)) as f32,
                );
                match observe_known(&mut ekf, &mut ids, id as u32, &z) {
                    Ok(_) => {}
                    Err(e) => {
                        eprintln!("step {step}: sighting of {id} refused: {e}");
                        report.refused += 1
                    }
                }
            }
        }
        if step % 500 == 0 {
            check(&ekf, &mut report);
            let est = ekf.pose();
            let err = (f64::from(est.x) - truth.x).hypot(f64::from(est.y) - truth.y);
            report.max_position_error = report.max_position_error.max(err);
            let p = ekf.pose_covariance().cast::<f64>();
            let e = nalgebra::Vector2::new(f64::from(est.x) - truth.x, f64::from(est.y) - truth.y);
            if let Some(inv) = p.fixed_view::<2, 2>(0, 0).into_owned().try_inverse() {
                report.max_position_nees = report
                    .max_position_nees
                    .max((e.transpose() * inv * e)[(0, 0)]);
            }
        }
    }
    check(&ekf, &mut report);
    report.updates = ekf.counters().updates;
    report
}

/// `nees_bound`: the largest position NEES allowed at any checkpoint, or `None` to only
/// report it (over 10⁶ steps EKF-SLAM's known overconfidence in heading shows: measured
/// maximum 33.7 at one of 2 000 checkpoints, against 8.1 over the first 20 000 steps).
fn run(steps: usize, nees_bound: Option<f64>) {
    for seed in [2, 1] {
        let r = soak(steps, seed);
        println!("seed {seed}: {r:?}");
        assert_eq!(r.refused, 0, "valid input refused");
        assert!(
            r.updates > (steps / 10) as u32,
            "too few updates: {}",
            r.updates
        );
        if let Some(bound) = nees_bound {
            assert!(
                r.max_position_nees < bound,
                "position NEES {}",
                r.max_position_nees
            );
        }
    }
}

#[test]
fn soak_short() {
    // The error stays inside the filter's own uncertainty: below the 2-DOF χ² quantile of
    // 1 − 1e-5 at each of the 40 checkpoints (measured maxima 8.1 and 3.0).
    run(20_000, Some(23.0));
}

#[test]
#[ignore = "10⁶ steps per form: run with --release -- --ignored"]
fn soak_million_steps() {
    run(1_000_000, None);
}
