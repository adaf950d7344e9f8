//! The covariance of [`EkfSlam`](super::EkfSlam), kept as its upper triangle.
//!
//! The storage is a column-major `N × N` array. Entry `(i, j)` with `i ≤ j` lives in
//! column `j`, row `i`, so the upper part of each column (rows `0..=j`) is one contiguous
//! run of memory. The strict lower triangle is never written: it stays zero. Compared with
//! keeping both halves this halves the work of the O(n²) update and removes its strided
//! mirror writes; the matrix is symmetric by construction.
//!
//! Everything that reads the covariance goes through [`CovarianceView`] (or the crate's
//! internal equivalents), which fold `(i, j)` onto the upper triangle.

use crate::scalar::Real;
use nalgebra::SMatrix;

/// Entry `(i, j)` of the symmetric matrix stored as the upper triangle of `p`; zero
/// outside `N × N`.
#[inline]
pub(crate) fn entry<T: Real, const N: usize>(p: &SMatrix<T, N, N>, i: usize, j: usize) -> T {
    let (row, col) = if i <= j { (i, j) } else { (j, i) };
    p.as_slice().get(col * N + row).copied().unwrap_or(T::ZERO)
}

/// The `R × C` block at `(i, j)` of the symmetric matrix stored as the upper triangle of
/// `p` (zero outside `N × N`).
pub(crate) fn block<T: Real, const N: usize, const R: usize, const C: usize>(
    p: &SMatrix<T, N, N>,
    i: usize,
    j: usize,
) -> SMatrix<T, R, C> {
    SMatrix::from_fn(|r, c| entry(p, i + r, j + c))
}

/// Writes the entries of the symmetric `R × R` block `value` at `(i, i)` that lie on or
/// above the diagonal; the rest of `value` is ignored.
pub(crate) fn set_diagonal_block<T: Real, const N: usize, const R: usize>(
    p: &mut SMatrix<T, N, N>,
    i: usize,
    value: &SMatrix<T, R, R>,
) {
    let data = p.as_mut_slice();
    for c in 0..R {
        for r in 0..=c {
            if let Some(slot) = data.get_mut((i + c) * N + i + r) {
                *slot = value[(r, c)];
            }
        }
    }
}

/// Adds `scale · dᵢ` to variance `i` of `p` for each `dᵢ` of `d`: a diagonal loading,
/// positive semi-definite when `scale` and the `dᵢ` are non-negative.
pub(crate) fn load_diagonal<T: Real, const N: usize>(p: &mut SMatrix<T, N, N>, d: &[T], scale: T) {
    for (v, d) in p.as_mut_slice().iter_mut().step_by(N + 1).zip(d) {
        *v += scale * *d;
    }
}

/// Per-row terms of one EKF update, for row (and column) `i` of the active block.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct UpdateRow<T> {
    /// Row `i` of `M = P Hᵀ`.
    pub m: [T; 2],
    /// Row `i` of the gain `K = M S⁻¹`.
    pub k: [T; 2],
    /// Row `i` of `K S` (optimal-gain form) or of the Joseph form's `D`.
    pub a: [T; 2],
}

/// New value of entry `(i, j)` in the optimal-gain form `P − (K S) Kᵀ`.
///
/// Two chained multiply-subtracts (`VMLS` on a Cortex-M4F, the same rounding as a
/// separate multiply and subtract on every target).
#[inline(always)]
pub(crate) fn symmetric_entry<T: Real>(p: T, row: &UpdateRow<T>, col: &UpdateRow<T>) -> T {
    (p - row.a[0] * col.k[0]) - row.a[1] * col.k[1]
}

/// New value of entry `(i, j)` in the Joseph form `P + D Kᵀ − K Mᵀ`.
#[inline(always)]
pub(crate) fn joseph_entry<T: Real>(p: T, row: &UpdateRow<T>, col: &UpdateRow<T>) -> T {
    (((p + row.a[0] * col.k[0]) + row.a[1] * col.k[1]) - row.k[0] * col.m[0]) - row.k[1] * col.m[1]
}

/// Sets entry `(i, j)`, `i ≤ j < k`, of the upper triangle of the active `k × k` block
/// to `f(p_ij, rows[i], rows[j])`, with `k = rows.len()`.
///
/// The hot loop of the EKF update. Columns go four at a time, so each row's terms are
/// loaded once for four entries (the last `k mod 4` columns one at a time). The entries
/// are computed by the same `f` in any order, so the result does not depend on the
/// blocking. Not inlined: as a function of its own its arguments keep their no-alias
/// guarantees, so the row and column terms are loaded once rather than after every
/// store to `p`.
#[inline(never)]
pub(crate) fn update_upper<T: Real, const N: usize, R: Copy>(
    p: &mut SMatrix<T, N, N>,
    rows: &[R],
    f: impl Fn(T, &R, &R) -> T,
) {
    let k = rows.len().min(N);
    let data = p.as_mut_slice();
    let mut j = 0;
    while j + 4 <= k {
        let (Some(block), Some([c0, c1, c2, c3]), Some(head)) = (
            data.get_mut(j * N..(j + 4) * N),
            rows.get(j..j + 4),
            rows.get(..=j),
        ) else {
            return;
        };
        // Copies, so that the column terms stay in registers.
        let (c0, c1, c2, c3) = (*c0, *c1, *c2, *c3);
        let (p0, rest) = block.split_at_mut(N);
        let (p1, rest) = rest.split_at_mut(N);
        let (p2, p3) = rest.split_at_mut(N);
        // Rows 0..=j are above the diagonal in all four columns.
        let columns = p0
            .iter_mut()
            .zip(p1.iter_mut())
            .zip(p2.iter_mut().zip(p3.iter_mut()));
        for (((x0, x1), (x2, x3)), &r) in columns.zip(head) {
            *x0 = f(*x0, &r, &c0);
            *x1 = f(*x1, &r, &c1);
            *x2 = f(*x2, &r, &c2);
            *x3 = f(*x3, &r, &c3);
        }
        // The corner: rows j+1..=j+c of column j+c.
        for (c, (column, col)) in [(p1, c1), (p2, c2), (p3, c3)].into_iter().enumerate() {
            let corner = j + 1..j + 2 + c;
            if let (Some(xs), Some(rs)) = (column.get_mut(corner.clone()), rows.get(corner)) {
                for (x, r) in xs.iter_mut().zip(rs) {
                    *x = f(*x, r, &col);
                }
            }
        }
        j += 4;
    }
    while j < k {
        let (Some(column), Some(&col)) = (data.get_mut(j * N..=j * N + j), rows.get(j)) else {
            return;
        };
        for (x, r) in column.iter_mut().zip(rows) {
            *x = f(*x, r, &col);
        }
        j += 1;
    }
}

/// A read-only view of the active block of an EKF covariance (symmetric; see the
/// [module docs](self)).
///
/// ```
/// use microslam::ekf::{state_dim, EkfConfig, EkfSlam};
/// use microslam::sensors::range_bearing::RangeBearing;
///
/// let mut slam = EkfSlam::<f64, { state_dim(4) }>::new(EkfConfig::DEFAULT_F64);
/// slam.predict_velocity(1.0, 0.2, 0.5)?;
/// slam.add_landmark(&RangeBearing::new(2.0, 0.3))?;
/// let p = slam.active_covariance();
/// assert_eq!(p.dim(), 5);
/// assert_eq!(p.get(0, 3), p.get(3, 0));
/// assert_eq!(p.get(5, 0), None);
/// # Ok::<(), microslam::EkfError>(())
/// ```
#[derive(Clone, Copy, Debug)]
pub struct CovarianceView<'a, T: Real, const N: usize> {
    storage: &'a SMatrix<T, N, N>,
    dim: usize,
}

impl<'a, T: Real, const N: usize> CovarianceView<'a, T, N> {
    pub(crate) fn new(storage: &'a SMatrix<T, N, N>, dim: usize) -> Self {
        Self {
            storage,
            dim: dim.min(N),
        }
    }

    /// Dimension `k = 3 + 2n` of the active block.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Entry `(i, j)` (= entry `(j, i)`), `None` outside the active block.
    pub fn get(&self, i: usize, j: usize) -> Option<T> {
        (i < self.dim && j < self.dim).then(|| entry(self.storage, i, j))
    }

    /// The `R × C` block whose top-left entry is `(i, j)`, `None` unless it lies inside
    /// the active block.
    pub fn block<const R: usize, const C: usize>(
        &self,
        i: usize,
        j: usize,
    ) -> Option<SMatrix<T, R, C>> {
        (i + R <= self.dim && j + C <= self.dim).then(|| block(self.storage, i, j))
    }

    /// Rows `0..=j` of column `j`: the stored (upper) part of the column, contiguous.
    pub fn upper_column(&self, j: usize) -> Option<&'a [T]> {
        if j >= self.dim {
            return None;
        }
        self.storage.as_slice().get(j * N..=j * N + j)
    }

    /// Row-major iteration over the whole active block, both triangles.
    pub fn iter(&self) -> impl Iterator<Item = T> + '_ {
        let k = self.dim;
        (0..k).flat_map(move |i| (0..k).map(move |j| entry(self.storage, i, j)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric 5 × 5 test matrix in upper storage within an 7 × 7 array.
    fn stored(values: impl Fn(usize, usize) -> f64) -> SMatrix<f64, 7, 7> {
        SMatrix::from_fn(|i, j| if i <= j { values(i, j) } else { 0.0 })
    }

    fn row(i: usize) -> UpdateRow<f64> {
        let x = i as f64;
        UpdateRow {
            m: [0.3 - 0.1 * x, 0.05 * x * x - 0.2],
            k: [1.0 / (1.0 + x), -0.4 + 0.15 * x],
            a: [0.2 * x - 0.5, 0.7 - 0.03 * x * x],
        }
    }

    fn upper(k: usize, p: &SMatrix<f64, 7, 7>) -> Vec<f64> {
        (0..k)
            .flat_map(|j| (0..=j).map(move |i| entry(p, i, j)))
            .collect()
    }

    #[test]
    fn blocked_update_matches_the_plain_loop_for_every_size() {
        type Form = fn(f64, &UpdateRow<f64>, &UpdateRow<f64>) -> f64;
        let forms: [Form; 2] = [symmetric_entry, joseph_entry];
        for f in forms {
            for k in 0..=7 {
                let mut p = stored(|i, j| 1.0 + (i * 7 + j) as f64 / 9.0);
                let rows: Vec<_> = (0..k).map(row).collect();
                let mut expected = Vec::new();
                for j in 0..k {
                    for i in 0..=j {
                        expected.push(f(entry(&p, i, j), &rows[i], &rows[j]));
                    }
                }
                let untouched = p;
                update_upper(&mut p, &rows, f);
                assert_eq!(upper(k, &p), expected, "k = {k}");
                for j in 0..7 {
                    for i in 0..7 {
                        if i > j || j >= k {
                            assert_eq!(p[(i, j)], untouched[(i, j)], "({i}, {j}) written");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn update_forms_are_the_textbook_expressions() {
        let (r, c) = (row(2), row(5));
        let sym = 1.5 - (r.a[0] * c.k[0] + r.a[1] * c.k[1]);
        let jos = 1.5 + (r.a[0] * c.k[0] + r.a[1] * c.k[1]) - (r.k[0] * c.m[0] + r.k[1] * c.m[1]);
        assert!((symmetric_entry(1.5, &r, &c) - sym).abs() < 1e-12);
        assert!((joseph_entry(1.5, &r, &c) - jos).abs() < 1e-12);
    }

    #[test]
    fn the_view_is_symmetric_and_bounded() {
        let p = stored(|i, j| (i + 2 * j) as f64);
        let v = CovarianceView::new(&p, 4);
        assert_eq!(v.dim(), 4);
        assert_eq!(v.get(3, 1), Some(7.0));
        assert_eq!(v.get(1, 3), Some(7.0));
        assert_eq!(v.get(4, 0), None);
        assert_eq!(v.upper_column(2), Some(&[4.0, 5.0, 6.0][..]));
        assert_eq!(v.upper_column(4), None);
        assert!(v.block::<2, 2>(3, 3).is_none());
        assert_eq!(v.iter().count(), 16);
    }
}
