//! The covariance of [`EkfSlam`](super::EkfSlam), kept as its upper triangle.
//!
//! The storage is a column-major `N × N` array. Entry `(i, j)` with `i ≤ j` lives in
//! column `j`, row `i`, so the upper part of each column (rows `0..=j`) is one contiguous
//! run of memory. The strict lower triangle is never written: it stays zero. Compared with
//! keeping both halves this halves the work of the O(n²) update and removes its strided
//! mirror writes; the matrix is symmetric by construction.
//!
//! Everything that reads the covariance goes through [`entry`], [`block`] or
//! [`CovarianceView`], which fold `(i, j)` onto the upper triangle.

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

/// The first `rows` rows of columns `j` and `j + 1` of the storage, for writing.
fn column_pair_mut<T: Real, const N: usize>(
    data: &mut [T],
    j: usize,
    rows: usize,
) -> Option<(&mut [T], &mut [T])> {
    let pair = data.get_mut(j * N..(j + 2) * N)?;
    let (first, second) = pair.split_at_mut(N);
    Some((first.get_mut(..rows)?, second.get_mut(..rows)?))
}

/// `P ← P − A Gᵀ` on the upper triangle of the active `k × k` block, for a symmetric
/// `A Gᵀ` of rank 2 (`A = K S`, `G = K` in the optimal-gain form): entry `(i, j)`,
/// `i ≤ j < k`, becomes `p_ij − (a0_i · g0_j + a1_i · g1_j)`.
///
/// The hot loop of the EKF update. Two columns share each row's loads of `a0_i`, `a1_i`;
/// every entry is computed by the same expression in any case, so the result does not
/// depend on the blocking.
pub(crate) fn subtract_rank2<T: Real, const N: usize>(
    p: &mut SMatrix<T, N, N>,
    k: usize,
    a: (&[T], &[T]),
    g: (&[T], &[T]),
) {
    let data = p.as_mut_slice();
    let (a0, a1) = a;
    let (g0, g1) = g;
    let update = |p: &mut T, x0: T, x1: T, y0: T, y1: T| *p -= x0 * y0 + x1 * y1;
    let mut j = 0;
    while j + 1 < k {
        let (Some(&gj0), Some(&gj1), Some(&gk0), Some(&gk1)) =
            (g0.get(j), g1.get(j), g0.get(j + 1), g1.get(j + 1))
        else {
            return;
        };
        // Rows 0..=j of columns j and j + 1, then the last row (j + 1) of column j + 1.
        let Some((left, right)) = column_pair_mut::<T, N>(data, j, j + 2) else {
            return;
        };
        let (left, _) = left.split_at_mut(j + 1);
        let (right, corner) = right.split_at_mut(j + 1);
        let rows = left.iter_mut().zip(right.iter_mut()).zip(a0.iter().zip(a1));
        for ((pl, pr), (&x0, &x1)) in rows {
            update(pl, x0, x1, gj0, gj1);
            update(pr, x0, x1, gk0, gk1);
        }
        if let (Some(pc), Some(&x0), Some(&x1)) = (corner.first_mut(), a0.get(j + 1), a1.get(j + 1))
        {
            update(pc, x0, x1, gk0, gk1);
        }
        j += 2;
    }
    if j < k {
        let (Some(&gj0), Some(&gj1)) = (g0.get(j), g1.get(j)) else {
            return;
        };
        if let Some(col) = data.get_mut(j * N..=j * N + j) {
            for ((pl, &x0), &x1) in col.iter_mut().zip(a0).zip(a1) {
                update(pl, x0, x1, gj0, gj1);
            }
        }
    }
}

/// The Joseph form's `P ← P + D Kᵀ − K Mᵀ` on the upper triangle of the active `k × k`
/// block (see `EkfSlam::joseph_terms`): entry `(i, j)`, `i ≤ j < k`, becomes
/// `p_ij + ((d0_i k0_j + d1_i k1_j) − (k0_i m0_j + k1_i m1_j))`.
pub(crate) fn joseph_pass<T: Real, const N: usize>(
    p: &mut SMatrix<T, N, N>,
    k: usize,
    gain: (&[T], &[T]),
    m: (&[T], &[T]),
    d: (&[T], &[T]),
) {
    let data = p.as_mut_slice();
    let (g0, g1) = gain;
    let (m0, m1) = m;
    let (d0, d1) = d;
    let update = |p: &mut T, row: (T, T, T, T), col: (T, T, T, T)| {
        let (di0, di1, ki0, ki1) = row;
        let (kj0, kj1, mj0, mj1) = col;
        *p += (di0 * kj0 + di1 * kj1) - (ki0 * mj0 + ki1 * mj1);
    };
    let column = |j: usize| Some((*g0.get(j)?, *g1.get(j)?, *m0.get(j)?, *m1.get(j)?));
    let row = |i: usize| Some((*d0.get(i)?, *d1.get(i)?, *g0.get(i)?, *g1.get(i)?));
    let mut j = 0;
    while j + 1 < k {
        let (Some(cl), Some(cr)) = (column(j), column(j + 1)) else {
            return;
        };
        let Some((left, right)) = column_pair_mut::<T, N>(data, j, j + 2) else {
            return;
        };
        let (left, _) = left.split_at_mut(j + 1);
        let (right, corner) = right.split_at_mut(j + 1);
        let rows = d0.iter().zip(d1).zip(g0.iter().zip(g1));
        for ((pl, pr), ((&di0, &di1), (&ki0, &ki1))) in
            left.iter_mut().zip(right.iter_mut()).zip(rows)
        {
            update(pl, (di0, di1, ki0, ki1), cl);
            update(pr, (di0, di1, ki0, ki1), cr);
        }
        if let (Some(pc), Some(r)) = (corner.first_mut(), row(j + 1)) {
            update(pc, r, cr);
        }
        j += 2;
    }
    if j < k {
        let Some(c) = column(j) else {
            return;
        };
        if let Some(col) = data.get_mut(j * N..=j * N + j) {
            for (i, pl) in col.iter_mut().enumerate() {
                if let Some(r) = row(i) {
                    update(pl, r, c);
                }
            }
        }
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

    fn dense_rank2(k: usize, p: &SMatrix<f64, 7, 7>, a: [&[f64]; 2], g: [&[f64]; 2]) -> Vec<f64> {
        let mut out = Vec::new();
        for j in 0..k {
            for i in 0..=j {
                out.push(entry(p, i, j) - (a[0][i] * g[0][j] + a[1][i] * g[1][j]));
            }
        }
        out
    }

    fn upper(k: usize, p: &SMatrix<f64, 7, 7>) -> Vec<f64> {
        (0..k)
            .flat_map(|j| (0..=j).map(move |i| entry(p, i, j)))
            .collect()
    }

    #[test]
    fn entries_fold_onto_the_upper_triangle() {
        let p = stored(|i, j| (10 * i + j) as f64);
        assert_eq!(entry(&p, 1, 3), 13.0);
        assert_eq!(entry(&p, 3, 1), 13.0);
        assert_eq!(entry(&p, 9, 0), 0.0);
        let b: SMatrix<f64, 2, 3> = block(&p, 2, 1);
        assert_eq!(
            b,
            SMatrix::<f64, 2, 3>::new(12.0, 22.0, 23.0, 13.0, 23.0, 33.0)
        );
    }

    #[test]
    fn rank2_update_matches_the_plain_loop_for_every_size() {
        let a0 = [0.3, -1.2, 2.5, 0.7, -0.4, 1.1, 0.9];
        let a1 = [1.5, 0.2, -0.8, 0.1, 2.2, -0.6, 0.4];
        let g0 = [0.11, 0.52, -0.3, 0.9, 0.05, -0.7, 0.2];
        let g1 = [-0.4, 0.33, 0.6, -0.2, 0.8, 0.1, -0.9];
        for k in 0..=7 {
            let mut p = stored(|i, j| 1.0 + (i * 7 + j) as f64 / 9.0);
            let expected = dense_rank2(k, &p, [&a0, &a1], [&g0, &g1]);
            let untouched = p;
            subtract_rank2(&mut p, k, (&a0, &a1), (&g0, &g1));
            assert_eq!(upper(k, &p), expected, "k = {k}");
            for j in 0..7 {
                for i in 0..7 {
                    if i > j || j >= k {
                        assert_eq!(p[(i, j)], untouched[(i, j)], "({i}, {j}) written, k = {k}");
                    }
                }
            }
        }
    }

    #[test]
    fn joseph_pass_matches_the_plain_loop_for_every_size() {
        let g0 = [0.3, -1.2, 2.5, 0.7, -0.4, 1.1, 0.9];
        let g1 = [1.5, 0.2, -0.8, 0.1, 2.2, -0.6, 0.4];
        let m0 = [0.11, 0.52, -0.3, 0.9, 0.05, -0.7, 0.2];
        let m1 = [-0.4, 0.33, 0.6, -0.2, 0.8, 0.1, -0.9];
        let d0 = [0.2, 0.1, -0.5, 0.3, 0.6, 0.25, -0.15];
        let d1 = [0.7, -0.35, 0.45, -0.1, 0.05, 0.9, 0.3];
        for k in 0..=7 {
            let mut p = stored(|i, j| 2.0 - (i + 3 * j) as f64 / 11.0);
            let mut expected = Vec::new();
            for j in 0..k {
                for i in 0..=j {
                    expected.push(
                        entry(&p, i, j)
                            + ((d0[i] * g0[j] + d1[i] * g1[j]) - (g0[i] * m0[j] + g1[i] * m1[j])),
                    );
                }
            }
            joseph_pass(&mut p, k, (&g0, &g1), (&m0, &m1), (&d0, &d1));
            assert_eq!(upper(k, &p), expected, "k = {k}");
            assert!((0..7).all(|j| (j + 1..7).all(|i| p[(i, j)] == 0.0)));
        }
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
