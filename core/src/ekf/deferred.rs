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

/// `a · b`. Not inlined on a microcontroller, like [`congruence`]: the firmware's flash
/// holds one copy of the 3 × 3 products every prediction runs (a host inlines them).
#[cfg_attr(target_os = "none", inline(never))]
pub(crate) fn product<T: Real>(a: &Matrix3<T>, b: &Matrix3<T>) -> Matrix3<T> {
    Matrix3::from_fn(|i, j| a[(i, 0)] * b[(0, j)] + a[(i, 1)] * b[(1, j)] + a[(i, 2)] * b[(2, j)])
}

/// `a · m · aᵀ` (not inlined on a microcontroller, see [`product`]).
#[cfg_attr(target_os = "none", inline(never))]
pub(crate) fn congruence<T: Real>(a: &Matrix3<T>, m: &Matrix3<T>) -> Matrix3<T> {
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

/// A run of predictions kept as a [`RowMap`], with what the robot's covariance needs of
/// the stored rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DeferredMotion<T: Real> {
    /// Stored rows → true rows.
    pub(crate) map: RowMap<T>,
    /// `M = L_rm D L_rmᵀ` of the stored rows.
    stored_coupled: Matrix3<T>,
    /// `C Bᵀ`-ready: the stored rows' columns 0 and 1 times their pivots `D₀`, `D₁` (last
    /// column zero).
    stored_near: Matrix3<T>,
    /// `diag(D₀, D₁, 0)` (zero when the state has no columns 0 and 1 left of the robot).
    near_pivots: Matrix3<T>,
    /// Largest |entry| of the stored rows (non-finite when an entry is).
    stored_largest: T,
    /// `L_rm D L_rmᵀ` of the true rows, computed once per prediction: the prediction
    /// after it and the pose covariance in between read it.
    coupled: Matrix3<T>,
}

impl<T: Real> DeferredMotion<T> {
    /// The start of a run: the stored rows are the true ones. `rows` are the robot's
    /// three rows over the columns left of the robot, `pivots` the `D` of those columns.
    pub(crate) fn start(rows: [&[T]; 3], pivots: impl Iterator<Item = T>) -> Self {
        let mut acc = [T::ZERO; 6];
        let mut largest = T::ZERO;
        let mut near = Matrix3::zeros();
        let mut near_pivots = Matrix3::zeros();
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
                near_pivots[(c, c)] = d;
            }
            largest = super::max_abs([largest, x, y, z].into_iter());
        }
        let stored_coupled = Matrix3::new(
            acc[0], acc[1], acc[2], acc[1], acc[3], acc[4], acc[2], acc[4], acc[5],
        );
        Self {
            map: RowMap {
                a: Matrix3::identity(),
                b: Matrix3::zeros(),
            },
            stored_coupled,
            stored_near: near,
            near_pivots,
            stored_largest: largest,
            coupled: stored_coupled,
        }
    }

    /// `L_rm D L_rmᵀ` of the true rows.
    pub(crate) fn coupled(&self) -> Matrix3<T> {
        self.coupled
    }

    /// [`DeferredMotion::coupled`] from the map and the stored rows' terms (O(1)):
    /// `A M Aᵀ + A C Bᵀ + B Cᵀ Aᵀ + B D₀₁ Bᵀ`.
    fn compute_coupled(&self) -> Matrix3<T> {
        let RowMap { a, b } = &self.map;
        let cross = product(a, &product(&self.stored_near, &b.transpose()));
        congruence(a, &self.stored_coupled)
            + cross
            + cross.transpose()
            + congruence(b, &self.near_pivots)
    }

    /// A bound on the largest |entry| of the true rows: `3 · max|A| · max|stored| +
    /// max|B|` (non-finite when an entry may be).
    pub(crate) fn largest(&self) -> T {
        let RowMap { a, b } = &self.map;
        T::lit(3.0) * super::max_abs(a.iter().copied()) * self.stored_largest
            + super::max_abs(b.iter().copied())
    }

    /// The run with one more prediction: true rows `f · rows + [added | 0]` (`added`: the
    /// odometry scale states' term in columns 0 and 1, last column zero).
    pub(crate) fn then(&self, f: &Matrix3<T>, added: Option<&Matrix3<T>>) -> Self {
        let mut next = *self;
        next.map.a = product(f, &self.map.a);
        next.map.b = product(f, &self.map.b);
        if let Some(t) = added {
            next.map.b += t;
        }
        next.coupled = next.compute_coupled();
        next
    }

    /// `true` when the run's map and the bound on the rows it gives are finite, with
    /// room for the rounding of applying it (the bound doubled stays finite).
    pub(crate) fn is_finite(&self) -> bool {
        (self.largest() * T::lit(2.0)).finite() && self.map.a.iter().all(|v| v.finite())
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
