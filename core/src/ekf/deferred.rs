//! Predictions that leave the robot's coupling rows of the factor for later.
//!
//! A prediction `P' = F P Fᵀ + G Q Gᵀ` changes the robot's rows of `L` in two ways: its
//! own 3 × 3 block is re-factored (O(1)), and its coupling to every other state,
//! `L_rm` (three rows as long as the state), becomes `F L_rm` (plus, with the odometry
//! scale states, `F_s L_s` in their two columns). Nothing but the robot's rows depends on
//! `L_rm` between two writes of the factor, so a run of predictions can keep the product
//! instead of applying each factor to `L_rm`:
//!
//! ```text
//! L_rm (true) = A · L_rm (stored) + [B | 0],      A ← F A,  B ← F B + F_s L_s  per prediction
//! ```
//!
//! with `A` 3 × 3 and `B` 3 × 2 (the scale states' columns 0 and 1). The robot's
//! covariance needs `L_rm D L_rmᵀ`, which is `A M Aᵀ + A C Bᵀ + B Cᵀ Aᵀ + B D₀₁ Bᵀ` for
//! `M = L_rm D L_rmᵀ` and `C` the stored rows' columns 0 and 1 times their pivots, both of
//! the stored rows and computed once (O(n)) when the run of predictions starts: every
//! prediction of the run, and the pose covariance after it, then costs O(1) instead of
//! O(n). The next write of the factor (an update, a new landmark) first applies `A` and
//! `B` to the stored rows (O(n), once); readers in between ([`super::CovarianceView`],
//! the innovation) apply them on the fly.

use crate::scalar::Real;
use nalgebra::Matrix3;

/// `Some([a, b])` when `m` is the shear `[[1, 0, a], [0, 1, b], [0, 0, 1]]`: the form of
/// every motion step's Jacobian with respect to the pose (a move along the heading), and
/// so of every product of them, the run's `A` included, unless a variance cap scaled a step.
#[inline]
fn shear<T: Real>(m: &Matrix3<T>) -> Option<[T; 2]> {
    let (one, zero) = (T::ONE, T::ZERO);
    let unit = m[(0, 0)] == one && m[(1, 1)] == one && m[(2, 2)] == one;
    let off = m[(1, 0)] == zero && m[(2, 0)] == zero && m[(0, 1)] == zero && m[(2, 1)] == zero;
    (unit && off).then(|| [m[(0, 2)], m[(1, 2)]])
}

/// `a · b` for the shear `a` with free entries `s` ([`shear`]): `b` with multiples of its
/// last row added to its first two, the terms of the full product that are not `1 · x`
/// or `0 · x`.
#[inline]
fn sheared_rows<T: Real>(s: [T; 2], b: &Matrix3<T>) -> Matrix3<T> {
    let mut p = *b;
    for j in 0..3 {
        for (r, sr) in s.iter().enumerate() {
            p[(r, j)] += *sr * b[(2, j)];
        }
    }
    p
}

/// `a · b`. Not inlined on a microcontroller, like [`congruence`]: the firmware's flash
/// holds one copy of the 3 × 3 products every prediction runs (a host inlines them).
///
/// A shear `a` (see [`shear`]) adds multiples of `b`'s last row to its first two: 6
/// products instead of 27, and the same values, since the terms left out are `1 · x`
/// and `0 · x`.
#[cfg_attr(target_os = "none", inline(never))]
pub(crate) fn product<T: Real>(a: &Matrix3<T>, b: &Matrix3<T>) -> Matrix3<T> {
    if let Some(s) = shear(a) {
        return sheared_rows(s, b);
    }
    Matrix3::from_fn(|i, j| a[(i, 0)] * b[(0, j)] + a[(i, 1)] * b[(1, j)] + a[(i, 2)] * b[(2, j)])
}

/// `a · m · aᵀ` (not inlined on a microcontroller, see [`product`]; a shear `a` costs 12
/// products instead of 54, with the same values).
#[cfg_attr(target_os = "none", inline(never))]
pub(crate) fn congruence<T: Real>(a: &Matrix3<T>, m: &Matrix3<T>) -> Matrix3<T> {
    if let Some(s) = shear(a) {
        // `a · m`, then `· aᵀ`: columns 0 and 1 gain multiples of column 2.
        let t = sheared_rows(s, m);
        let mut c = t;
        for i in 0..3 {
            for (r, sr) in s.iter().enumerate() {
                c[(i, r)] += *sr * t[(i, 2)];
            }
        }
        return c;
    }
    let t = product(a, m);
    Matrix3::from_fn(|i, j| t[(i, 0)] * a[(j, 0)] + t[(i, 1)] * a[(j, 1)] + t[(i, 2)] * a[(j, 2)])
}

/// The map from the stored robot coupling rows to the true ones: true entry `(r, c)` is
/// `Σ_b A_rb · stored_bc + B_rc` (`B` only in columns 0 and 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RowMap<T: Real> {
    /// `A`: the product of the deferred predictions' `F`.
    pub(crate) a: Matrix3<T>,
    /// `B`: what the deferred predictions added to columns 0 and 1 (the odometry scale
    /// states'; zero without them), as a 3 × 3 matrix whose last column is zero.
    pub(crate) b: Matrix3<T>,
}

impl<T: Real> RowMap<T> {
    /// `A · stored` of a column: the true entries of the robot's three rows in a column
    /// `c ≥ 2`, and in columns 0 and 1 before [`RowMap::near`] is added.
    #[inline]
    pub(crate) fn apply(&self, stored: [T; 3]) -> [T; 3] {
        let a = &self.a;
        [0, 1, 2].map(|r| a[(r, 0)] * stored[0] + a[(r, 1)] * stored[1] + a[(r, 2)] * stored[2])
    }

    /// `B`'s entry of robot row `r` in column `c` (zero from column 2 on).
    #[inline]
    pub(crate) fn near(&self, r: usize, c: usize) -> T {
        if c < 2 { self.b[(r, c)] } else { T::ZERO }
    }

    /// The true entry of robot row `r` in column `c`, from the stored entries of the
    /// three robot rows in that column.
    #[inline]
    pub(crate) fn entry(&self, r: usize, c: usize, stored: [T; 3]) -> T {
        let a = &self.a;
        a[(r, 0)] * stored[0] + a[(r, 1)] * stored[1] + a[(r, 2)] * stored[2] + self.near(r, c)
    }
}

/// What a run of predictions changes at each prediction: the map and the robot
/// covariance terms it gives. (Kept apart from the run's fixed terms so that a prediction
/// computes and copies only this.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RunState<T: Real> {
    /// Stored rows → true rows.
    pub(crate) map: RowMap<T>,
    /// The robot's covariance `P_RR` the run leaves: `L_rm D L_rmᵀ` of the true rows plus
    /// the robot's own block `L_rr D_r L_rrᵀ` as the last prediction stored it. The pose
    /// covariance read after each prediction is this copy, not a recomputation.
    robot: Matrix3<T>,
}

impl<T: Real> RunState<T> {
    /// The robot's covariance `P_RR` after the run (see the field).
    pub(crate) fn robot_covariance(&self) -> Matrix3<T> {
        self.robot
    }
}

/// A run of predictions kept as a [`RowMap`], with what the robot's covariance needs of
/// the stored rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DeferredMotion<T: Real> {
    /// The map and the covariance terms after the run's last prediction.
    pub(crate) state: RunState<T>,
    /// `M = L_rm D L_rmᵀ` of the stored rows.
    stored_coupled: Matrix3<T>,
    /// `C Bᵀ`-ready: the stored rows' columns 0 and 1 times their pivots `D₀`, `D₁` (last
    /// column zero).
    stored_near: Matrix3<T>,
    /// `D₀`, `D₁` (zero when the state has no columns 0 and 1 left of the robot).
    near_pivots: [T; 2],
    /// Largest |entry| of the stored rows (non-finite when an entry is).
    stored_largest: T,
}

impl<T: Real> DeferredMotion<T> {
    /// The start of a run: the stored rows are the true ones. `rows` are the robot's
    /// three rows over the columns left of the robot, `pivots` the `D` of those columns,
    /// `own` the robot's own block `L_rr D_r L_rrᵀ`.
    pub(crate) fn start(
        rows: [&[T]; 3],
        pivots: impl Iterator<Item = T>,
        own: &Matrix3<T>,
    ) -> Self {
        let mut acc = [T::ZERO; 6];
        let mut largest = T::ZERO;
        let mut near = Matrix3::zeros();
        let mut near_pivots = [T::ZERO; 2];
        for (c, (((&x, &y), &z), d)) in rows[0]
            .iter()
            .zip(rows[1])
            .zip(rows[2])
            .zip(pivots)
            .enumerate()
        {
            let (dx, dy, dz) = (d * x, d * y, d * z);
            acc[0] += dx * x;
            acc[1] += dx * y;
            acc[2] += dx * z;
            acc[3] += dy * y;
            acc[4] += dy * z;
            acc[5] += dz * z;
            if c < 2 {
                near[(0, c)] = dx;
                near[(1, c)] = dy;
                near[(2, c)] = dz;
                near_pivots[c] = d;
            }
            largest = super::max_abs([largest, x, y, z].into_iter());
        }
        let stored_coupled = Matrix3::new(
            acc[0], acc[1], acc[2], acc[1], acc[3], acc[4], acc[2], acc[4], acc[5],
        );
        Self {
            state: RunState {
                map: RowMap {
                    a: Matrix3::identity(),
                    b: Matrix3::zeros(),
                },
                robot: stored_coupled + own,
            },
            stored_coupled,
            stored_near: near,
            near_pivots,
            stored_largest: largest,
        }
    }

    /// The map from the stored rows to the true ones.
    pub(crate) fn map(&self) -> RowMap<T> {
        self.state.map
    }

    /// The robot's covariance `P_RR` after the run.
    pub(crate) fn robot_covariance(&self) -> Matrix3<T> {
        self.state.robot
    }

    /// `L_rm D L_rmᵀ` of the true rows under `map`, from the stored rows' terms (O(1)):
    /// `A M Aᵀ + A C Bᵀ + B Cᵀ Aᵀ + B D₀₁ Bᵀ`.
    fn coupled(&self, map: &RowMap<T>) -> Matrix3<T> {
        let RowMap { a, b } = map;
        // `C Bᵀ` and `B D₀₁ Bᵀ` over columns 0 and 1 only: `C`'s and `B`'s last columns
        // and `D₀₁`'s last pivot are zero, so the terms left out add nothing.
        let (near, [d0, d1]) = (&self.stored_near, self.near_pivots);
        let near_b = Matrix3::from_fn(|i, j| near[(i, 0)] * b[(j, 0)] + near[(i, 1)] * b[(j, 1)]);
        let cross = product(a, &near_b);
        let bdb = Matrix3::from_fn(|i, j| b[(i, 0)] * d0 * b[(j, 0)] + b[(i, 1)] * d1 * b[(j, 1)]);
        congruence(a, &self.stored_coupled) + cross + cross.transpose() + bdb
    }

    /// A bound on the largest |entry| of the true rows: `3 · max|A| · max|stored| +
    /// max|B|` (non-finite when an entry may be).
    pub(crate) fn largest(&self) -> T {
        self.largest_under(&self.state.map)
    }

    fn largest_under(&self, map: &RowMap<T>) -> T {
        let RowMap { a, b } = map;
        // A shear's entries are its two free ones, ones and zeros.
        let largest_a = match shear(a) {
            Some([s0, s1]) => super::max_abs([T::ONE, s0, s1].into_iter()),
            None => super::max_abs(a.iter().copied()),
        };
        // `B`'s last column is zero: a non-finite `F` that would make it NaN makes `A`
        // non-finite too, and `is_finite` tests `A` on its own.
        let largest_b = super::max_abs(b.iter().take(6).copied());
        T::lit(3.0) * largest_a * self.stored_largest + largest_b
    }

    /// The run's state after one more prediction: true rows `f · rows + [added | 0]`
    /// (`added`: the odometry scale states' term in columns 0 and 1, last column zero),
    /// and `own` the robot's own block `L_rr D_r L_rrᵀ` that the prediction stores.
    /// Nothing changes until [`DeferredMotion::advance`].
    pub(crate) fn then(
        &self,
        f: &Matrix3<T>,
        added: Option<&Matrix3<T>>,
        own: &Matrix3<T>,
    ) -> RunState<T> {
        let mut map = RowMap {
            a: product(f, &self.state.map.a),
            b: product(f, &self.state.map.b),
        };
        if let Some(t) = added {
            map.b += t;
        }
        let robot = self.coupled(&map) + own;
        RunState { map, robot }
    }

    /// `true` when `state`'s map and the bound on the rows it gives are finite, with room
    /// for the rounding of applying it (the bound doubled stays finite).
    pub(crate) fn is_finite(&self, state: &RunState<T>) -> bool {
        (self.largest_under(&state.map) * T::lit(2.0)).finite()
            && state.map.a.iter().all(|v| v.finite())
    }

    /// Makes `state` (from [`DeferredMotion::then`]) the run's.
    pub(crate) fn advance(&mut self, state: RunState<T>) {
        self.state = state;
    }
}

/// The coefficients `h` of the true robot rows (a measurement row's robot part) as
/// coefficients of the stored rows, `Aᵀ h`, and of columns 0 and 1, `Bᵀ h`.
pub(crate) fn pull_back<T: Real>(map: &RowMap<T>, h: [T; 3]) -> ([T; 3], [T; 2]) {
    let hv = nalgebra::Vector3::new(h[0], h[1], h[2]);
    let on_stored = map.a.transpose() * hv;
    let on_near = map.b.transpose() * hv;
    (
        [on_stored[0], on_stored[1], on_stored[2]],
        [on_near[0], on_near[1]],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every term of the 3 × 3 product, in the order the shear path claims to reproduce.
    fn full_product(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| {
            a[(i, 0)] * b[(0, j)] + a[(i, 1)] * b[(1, j)] + a[(i, 2)] * b[(2, j)]
        })
    }

    fn full_congruence(a: &Matrix3<f64>, m: &Matrix3<f64>) -> Matrix3<f64> {
        full_product(&full_product(a, m), &a.transpose())
    }

    fn shear_of(a: f64, b: f64) -> Matrix3<f64> {
        Matrix3::new(1.0, 0.0, a, 0.0, 1.0, b, 0.0, 0.0, 1.0)
    }

    fn dense() -> Matrix3<f64> {
        Matrix3::new(0.31, -0.027, 0.0113, 0.05, 1.7e-3, -0.4, 2.2, 0.9, 0.0071)
    }

    #[test]
    fn the_shear_paths_give_the_full_products_bit_for_bit() {
        let m = dense();
        let sym = m * m.transpose();
        for (a, b) in [(0.0, 0.0), (-0.0123, 0.0456), (3.7e-5, -1.9), (1e6, -2e-7)] {
            let s = shear_of(a, b);
            assert!(shear(&s).is_some());
            assert_eq!(product(&s, &m), full_product(&s, &m));
            assert_eq!(congruence(&s, &sym), full_congruence(&s, &sym));
            // A product of shears is a shear, the run's `A` included.
            assert!(shear(&product(&s, &shear_of(0.3, -0.2))).is_some());
        }
        // A scaled step is not a shear and takes the full product.
        let scaled = Matrix3::from_fn(|i, j| [0.5, 1.0, 1.0][i] * shear_of(0.1, 0.2)[(i, j)]);
        assert!(shear(&scaled).is_none());
        assert_eq!(product(&scaled, &m), full_product(&scaled, &m));
        assert_eq!(congruence(&scaled, &sym), full_congruence(&scaled, &sym));
        assert_eq!(congruence(&m, &sym), full_congruence(&m, &sym));
    }

    #[test]
    fn ldl_product_gives_the_full_congruence_bit_for_bit() {
        let l = [[1.0, 0.0, 0.0], [0.37, 1.0, 0.0], [-1.3, 0.021, 1.0]];
        let d = [0.04, 2.5e-3, 1.1e-5];
        let lm = Matrix3::from_fn(|i, j| l[i][j]);
        let expected = full_congruence(&lm, &Matrix3::from_diagonal(&d.into()));
        assert_eq!(crate::ekf::covariance::ldl_product(&l, &d), expected);
    }
}
