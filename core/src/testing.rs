//! Helpers shared by the unit tests (compiled only for `cargo test`).

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
