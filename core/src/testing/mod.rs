//! Helpers shared by the unit tests (compiled only for `cargo test`).

pub mod flash;
pub mod world;

use crate::error::InvalidSetting;
use crate::geometry::wrap_angle;
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// Central finite-difference Jacobian of `f` at `x`. Output rows listed in `angle_rows`
/// are differenced through [`wrap_angle`].
pub fn central_difference<const R: usize>(
    f: impl Fn(&DVector<f64>) -> SVector<f64, R>,
    x: &DVector<f64>,
    angle_rows: &[usize],
) -> DMatrix<f64> {
    let h = 1e-6;
    let mut jac = DMatrix::zeros(R, x.len());
    for j in 0..x.len() {
        let mut plus = x.clone();
        let mut minus = x.clone();
        plus[j] += h;
        minus[j] -= h;
        let fp = f(&plus);
        let fm = f(&minus);
        for i in 0..R {
            let d = if angle_rows.contains(&i) {
                wrap_angle(fp[i] - fm[i])
            } else {
                fp[i] - fm[i]
            };
            jac[(i, j)] = d / (2.0 * h);
        }
    }
    jac
}

/// Panics with a readable message when an analytic Jacobian differs from a numeric one.
pub fn assert_jacobian<const R: usize, const C: usize>(
    analytic: &SMatrix<f64, R, C>,
    numeric: &DMatrix<f64>,
    tol: f64,
) {
    assert_eq!((R, C), numeric.shape());
    for i in 0..R {
        for j in 0..C {
            let (a, n) = (analytic[(i, j)], numeric[(i, j)]);
            assert!(
                (a - n).abs() <= tol * (1.0 + n.abs()),
                "Jacobian entry ({i},{j}): analytic {a}, numeric {n}\n{analytic}\n{numeric}"
            );
        }
    }
}

/// One way to break a configuration: how, then the name and rule that must be reported.
pub type BrokenSetting<C> = (fn(&mut C), &'static str, &'static str);

/// Breaks `valid` each way of `cases` and checks that `judge` (`is_valid` and
/// `invalid_setting`) refuses it and names it with its rule.
pub fn each_broken_setting_is_named<C: Copy>(
    valid: C,
    cases: &[BrokenSetting<C>],
    judge: impl Fn(&C) -> (bool, Option<InvalidSetting>),
) {
    for &(break_it, name, rule) in cases {
        let mut c = valid;
        break_it(&mut c);
        let expected = Some(InvalidSetting { name, rule });
        assert_eq!(judge(&c), (false, expected), "{name}");
    }
}
