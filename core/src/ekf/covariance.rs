//! The covariance of [`EkfSlam`](super::EkfSlam), kept as a factorisation `P = L D Lᵀ`.
//!
//! `L` is unit lower triangular and `D` diagonal with `D ≥ 0`, so `P` is positive
//! semi-definite whatever rounding does to the entries of `L` and `D`: every step keeps
//! `D ≥ 0` by how it computes it (weighted sums of squares, or products and quotients of
//! non-negative numbers), never by a check after the fact.
//!
//! # Storage
//!
//! The factor is stored packed, row by row: row `i` of `L` (entries `0..i`) followed by
//! `Dᵢ` in place of the unit diagonal, at offset `i (i + 1) / 2`. A state of dimension `N`
//! takes `N (N + 1) / 2` scalars ([`factor_len`]).
//!
//! Inside the factor the state is ordered `[landmark 1, …, landmark n, robot]`: the
//! robot comes last and a new landmark is inserted just before it. With that order
//! - a prediction (which moves the robot only) changes only the robot's three rows;
//! - a new landmark adds two rows and moves the robot's three rows two slots down;
//! - nothing else ever moves.
//!
//! The public API keeps the robot-first order `[x, y, θ, x₁, y₁, …]`; [`CovarianceView`]
//! reads entries of `P` in that order, at O(n) each (`P_ij = Σ_c L_ic D_c L_jc`).

use super::deferred::RowMap;
use crate::scalar::Real;
use nalgebra::{Matrix3, SMatrix};

/// Packed length of the covariance factor for a maximum of `max_landmarks` landmarks:
/// `N (N + 1) / 2` with `N = 3 + 2 · max_landmarks` (the second const parameter of
/// [`EkfSlam`](super::EkfSlam)).
///
/// ```
/// use microslam::ekf::{factor_len, state_dim};
/// assert_eq!(state_dim(64), 131);
/// assert_eq!(factor_len(64), 131 * 132 / 2);
/// ```
pub const fn factor_len(max_landmarks: usize) -> usize {
    let n = super::state_dim(max_landmarks);
    n * (n + 1) / 2
}

/// Offset of row `i` in the packed factor.
#[inline(always)]
pub(crate) const fn row_start(i: usize) -> usize {
    i * (i + 1) / 2
}

/// Index inside the factor of public state index `s` (robot first) when the active
/// dimension is `k` (robot last inside the factor).
#[inline(always)]
pub(crate) const fn internal(s: usize, k: usize) -> usize {
    if s < 3 { k - 3 + s } else { s - 3 }
}

/// `Dᵢ`, zero outside `factor`.
#[inline(always)]
pub(crate) fn pivot<T: Real>(factor: &[T], i: usize) -> T {
    factor.get(row_start(i) + i).copied().unwrap_or(T::ZERO)
}

/// Row `i` of `L` without its unit diagonal (`L_i0 … L_i,i−1`), empty outside `factor`.
#[inline(always)]
pub(crate) fn strict_row<T: Real>(factor: &[T], i: usize) -> &[T] {
    factor.get(row_start(i)..row_start(i) + i).unwrap_or(&[])
}

/// Entry `(i, j)` of `P = L D Lᵀ` in the factor's own order: `Σ_{c ≤ min(i,j)} L_ic D_c L_jc`.
pub(crate) fn internal_entry<T: Real>(factor: &[T], i: usize, j: usize) -> T {
    let (hi, lo) = if i >= j { (i, j) } else { (j, i) };
    let (row_hi, row_lo) = (strict_row(factor, hi), strict_row(factor, lo));
    let mut acc = T::ZERO;
    for (c, (&a, &b)) in row_hi.iter().zip(row_lo).enumerate() {
        acc += a * pivot(factor, c) * b;
    }
    let l_hi_lo = if hi == lo {
        T::ONE
    } else {
        row_hi.get(lo).copied().unwrap_or(T::ZERO)
    };
    acc + l_hi_lo * pivot(factor, lo)
}

/// Modified weighted Gram–Schmidt (Thornton): the unit lower triangular `L` and the
/// diagonal `D ≥ 0` with `L diag(D) Lᵀ = W diag(w) Wᵀ`, for weights `w ≥ 0`.
///
/// Row `i` of `W` is made `w`-orthogonal to the rows before it; `Dᵢ` is the weighted
/// squared norm of what is left, a sum of non-negative terms. A zero `Dᵢ` leaves column
/// `i` of `L` zero (that direction carries no variance).
pub(crate) fn mwgs<T: Real, const R: usize, const C: usize>(
    mut w: [[T; C]; R],
    weights: &[T; C],
) -> ([[T; R]; R], [T; R]) {
    let mut l = [[T::ZERO; R]; R];
    let mut d = [T::ZERO; R];
    for i in 0..R {
        l[i][i] = T::ONE;
        let vi = w[i];
        let mut di = T::ZERO;
        for (&v, &q) in vi.iter().zip(weights) {
            // `(v q) v`, not `v² q`: a tiny `v` under a huge weight (a Jacobian entry of
            // 1e-25 times a turn-rate variance of 1e31) squares to zero in f32.
            di += v * q * v;
        }
        d[i] = di;
        if di > T::ZERO {
            for k in i + 1..R {
                let mut dot = T::ZERO;
                for ((&a, &q), &v) in w[k].iter().zip(weights).zip(&vi) {
                    dot += a * q * v;
                }
                let lki = dot / di;
                l[k][i] = lki;
                for (a, &v) in w[k].iter_mut().zip(&vi) {
                    *a -= lki * v;
                }
            }
        }
    }
    (l, d)
}

/// `L diag(d) Lᵀ` for a unit lower triangular 3 × 3 `L` (the inverse of [`ldl`]): the
/// terms of the full product that are not products with the zeros above `L`'s diagonal,
/// in the full product's order, so the same values. (Not inlined on a microcontroller:
/// one copy for the predictions that call it.)
#[cfg_attr(target_os = "none", inline(never))]
pub(crate) fn ldl_product<T: Real>(l: &[[T; 3]; 3], d: &[T; 3]) -> Matrix3<T> {
    Matrix3::from_fn(|i, j| {
        let mut sum = l[i][0] * d[0] * l[j][0];
        for k in 1..=i.min(j) {
            sum += l[i][k] * d[k] * l[j][k];
        }
        sum
    })
}

/// `A = L diag(D) Lᵀ` for a symmetric `R × R` matrix given by its lower triangle (the
/// mean of the two triangles is used), or `None` when `A` is not finite or not positive
/// semi-definite (a negative pivot, or a zero pivot whose column is not zero).
pub(crate) fn ldl<T: Real, const R: usize>(a: &SMatrix<T, R, R>) -> Option<([[T; R]; R], [T; R])> {
    let mut l = [[T::ZERO; R]; R];
    let mut d = [T::ZERO; R];
    if !a.iter().all(|v| v.finite()) {
        return None;
    }
    for j in 0..R {
        l[j][j] = T::ONE;
        let mut dj = a[(j, j)];
        for c in 0..j {
            dj -= l[j][c] * d[c] * l[j][c];
        }
        if dj < T::ZERO || !dj.finite() {
            return None;
        }
        d[j] = dj;
        for i in j + 1..R {
            let mut aij = (a[(i, j)] + a[(j, i)]) * T::lit(0.5);
            for c in 0..j {
                aij -= l[i][c] * d[c] * l[j][c];
            }
            if dj > T::ZERO {
                l[i][j] = aij / dj;
            } else if aij != T::ZERO {
                return None;
            }
        }
    }
    Some((l, d))
}

/// A read-only view of the active block of an EKF covariance, in the public order
/// (robot first). Entries are computed from the factor (O(n) each); nothing is copied.
///
/// ```
/// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
/// use microslam::sensors::range_bearing::RangeBearing;
///
/// let mut slam = EkfSlam::<f64, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F64);
/// slam.predict_velocity(1.0, 0.2, 0.5)?;
/// slam.add_landmark(&RangeBearing::new(2.0, 0.3))?;
/// let p = slam.active_covariance();
/// assert_eq!(p.dim(), 5);
/// assert_eq!(p.get(0, 3), p.get(3, 0));
/// assert_eq!(p.get(5, 0), None);
/// # Ok::<(), microslam::EkfError>(())
/// ```
#[derive(Clone, Copy, Debug)]
pub struct CovarianceView<'a, T: Real> {
    factor: &'a [T],
    dim: usize,
    /// The map from the stored robot coupling rows to the true ones, when predictions
    /// are deferred (see `EkfSlam::factor_storage`).
    robot: Option<RowMap<T>>,
}

impl<'a, T: Real> CovarianceView<'a, T> {
    pub(crate) fn new(factor: &'a [T], dim: usize, robot: Option<RowMap<T>>) -> Self {
        // The active factor must be stored whole; otherwise the view is empty.
        let dim = if row_start(dim) <= factor.len() {
            dim
        } else {
            0
        };
        Self { factor, dim, robot }
    }

    /// `L_ic` (`c < i`) in the factor's own order, deferred predictions applied.
    fn l(&self, i: usize, c: usize) -> T {
        let stored = |r: usize| {
            strict_row(self.factor, r)
                .get(c)
                .copied()
                .unwrap_or(T::ZERO)
        };
        let r0 = self.dim.saturating_sub(3);
        match &self.robot {
            Some(map) if i >= r0 && c < r0 => {
                map.entry(i - r0, c, [stored(r0), stored(r0 + 1), stored(r0 + 2)])
            }
            _ => stored(i),
        }
    }

    /// Entry `(i, j)` in the factor's own order.
    fn internal_entry(&self, i: usize, j: usize) -> T {
        let (hi, lo) = if i >= j { (i, j) } else { (j, i) };
        if self.robot.is_none() || hi + 3 < self.dim {
            // Neither row is a robot row, or nothing is deferred: the stored factor.
            return internal_entry(self.factor, hi, lo);
        }
        let mut acc = T::ZERO;
        for c in 0..lo {
            acc += self.l(hi, c) * pivot(self.factor, c) * self.l(lo, c);
        }
        let l_hi_lo = if hi == lo { T::ONE } else { self.l(hi, lo) };
        acc + l_hi_lo * pivot(self.factor, lo)
    }

    /// Dimension `k = 3 + 2n` of the active block.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Entry `(i, j)` (= entry `(j, i)`), `None` outside the active block.
    pub fn get(&self, i: usize, j: usize) -> Option<T> {
        let k = self.dim;
        (i < k && j < k).then(|| self.internal_entry(internal(i, k), internal(j, k)))
    }

    /// The `R × C` block whose top-left entry is `(i, j)`, `None` unless it lies inside
    /// the active block.
    pub fn block<const R: usize, const C: usize>(
        &self,
        i: usize,
        j: usize,
    ) -> Option<SMatrix<T, R, C>> {
        (i + R <= self.dim && j + C <= self.dim)
            .then(|| SMatrix::from_fn(|r, c| self.get(i + r, j + c).unwrap_or(T::ZERO)))
    }

    /// Row-major iteration over the whole active block, both triangles.
    pub fn iter(&self) -> impl Iterator<Item = T> + '_ {
        let k = self.dim;
        (0..k).flat_map(move |i| (0..k).map(move |j| self.get(i, j).unwrap_or(T::ZERO)))
    }

    /// `Dᵢ` and row `i` of `L` (entries `0..i`) in the factor's own order (landmarks,
    /// then the robot), `None` outside the active block: for diagnostics and tests.
    pub fn factor_row(&self, i: usize) -> Option<(T, impl Iterator<Item = T> + '_)> {
        (i < self.dim).then(|| (pivot(self.factor, i), (0..i).map(move |c| self.l(i, c))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    fn dense<const R: usize>(l: &[[f64; R]; R], d: &[f64; R]) -> DMatrix<f64> {
        let l = DMatrix::from_fn(R, R, |i, j| l[i][j]);
        &l * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(d)) * l.transpose()
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn mwgs_reproduces_the_weighted_gram_matrix() {
        let w = [
            [1.0, 0.5, -2.0, 0.3, 0.0],
            [0.2, -1.0, 0.7, 0.0, 1.5],
            [3.0, 0.1, 0.4, -0.6, 0.2],
        ];
        let q = [0.5, 2.0, 0.1, 1.0, 0.0];
        let (l, d) = mwgs(w, &q);
        let wm = DMatrix::from_fn(3, 5, |i, j| w[i][j]);
        let expected = &wm
            * DMatrix::from_diagonal(&nalgebra::DVector::from_column_slice(&q))
            * wm.transpose();
        assert!((dense(&l, &d) - expected).abs().max() < 1e-12);
        assert!(d.iter().all(|&v| v >= 0.0));
        for i in 0..3 {
            assert_eq!(l[i][i], 1.0);
            for j in i + 1..3 {
                assert_eq!(l[i][j], 0.0);
            }
        }
    }

    #[test]
    fn mwgs_of_a_rank_deficient_matrix_has_zero_pivots() {
        // Rows 0 and 2 are parallel: the third pivot is (up to rounding) zero, not negative.
        let w: [[f64; 2]; 3] = [[1.0, 2.0], [0.0, 1.0], [2.0, 4.0]];
        let (l, d) = mwgs(w, &[1.0, 1.0]);
        assert!(d[2].abs() < 1e-12 && d[2] >= 0.0, "{d:?}");
        let wm = DMatrix::from_fn(3, 2, |i, j| w[i][j]);
        assert!((dense(&l, &d) - &wm * wm.transpose()).abs().max() < 1e-12);
    }

    #[test]
    fn ldl_factors_psd_matrices_and_refuses_the_rest() {
        let a = Matrix3::new(4.0, 2.0, 0.0, 2.0, 5.0, 1.0, 0.0, 1.0, 3.0);
        let (l, d) = ldl(&a).unwrap();
        let got = dense(&l, &d);
        assert!((got - DMatrix::from_fn(3, 3, |i, j| a[(i, j)])).abs().max() < 1e-12);
        // Singular but PSD (a zero row and column) is accepted.
        assert!(
            ldl(&Matrix3::from_diagonal(&nalgebra::Vector3::new(
                1.0, 0.0, 2.0
            )))
            .is_some()
        );
        // Indefinite ones are refused: a negative pivot, a zero pivot with a nonzero column.
        assert!(ldl(&Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0)).is_none());
        assert!(ldl(&Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0)).is_none());
        assert!(
            ldl(&Matrix3::new(
                f64::NAN,
                0.0,
                0.0,
                0.0,
                1.0,
                0.0,
                0.0,
                0.0,
                1.0
            ))
            .is_none()
        );
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn entries_and_the_view_follow_the_factor() {
        // k = 5: one landmark (factor rows 0, 1), robot (rows 2, 3, 4).
        let l = [
            [1.0, 0.0, 0.0, 0.0, 0.0],
            [0.3, 1.0, 0.0, 0.0, 0.0],
            [-0.2, 0.5, 1.0, 0.0, 0.0],
            [0.1, 0.0, 0.4, 1.0, 0.0],
            [0.7, -0.3, 0.2, 0.6, 1.0],
        ];
        let d = [2.0, 1.0, 0.5, 3.0, 0.25];
        let mut packed = [0.0; 15 + 6];
        for i in 0..5 {
            for j in 0..i {
                packed[row_start(i) + j] = l[i][j];
            }
            packed[row_start(i) + i] = d[i];
        }
        let p = dense(&l, &d);
        let view = CovarianceView::new(&packed, 5, None);
        for i in 0..5 {
            for j in 0..5 {
                let got = view.get(i, j).unwrap();
                let want = p[(internal(i, 5), internal(j, 5))];
                assert!((got - want).abs() < 1e-12, "({i}, {j}): {got} vs {want}");
            }
        }
        assert_eq!(view.get(5, 0), None);
        assert!(view.block::<2, 2>(4, 4).is_none());
        assert_eq!(view.iter().count(), 25);
        let (d2, row2) = view.factor_row(2).unwrap();
        assert_eq!((d2, row2.collect::<Vec<_>>()), (0.5, vec![-0.2, 0.5]));
        // A dimension the storage cannot hold gives an empty view.
        assert_eq!(CovarianceView::new(&packed[..10], 5, None).dim(), 0);
    }
}
