//! The robot's rows of the factor. Inside the factor the robot comes last: its own 3 × 3
//! block (`L_rr`, `D_r`), and its coupling rows over the states before it. A prediction
//! writes the own block and defers its effect on the coupling rows ([`super::deferred`]);
//! every other write of the factor goes through [`EkfSlam::factor_mut`], which applies the
//! deferred predictions first.

use super::EkfSlam;
use super::covariance::{ldl_product, pivot, row_start, strict_row};
use super::deferred::DeferredMotion;
use crate::scalar::Real;
use nalgebra::Matrix3;

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// The robot's own block of the factor: `L_rr` (unit lower) and `D_r`.
    #[allow(clippy::needless_range_loop)] // matrix indices read best as indices
    pub(super) fn robot_block(&self) -> ([[T; 3]; 3], [T; 3]) {
        let r0 = self.active_dim() - 3;
        let mut l = [[T::ZERO; 3]; 3];
        let mut d = [T::ZERO; 3];
        for a in 0..3 {
            let row = strict_row(&self.factor, r0 + a);
            for b in 0..a {
                l[a][b] = row.get(r0 + b).copied().unwrap_or(T::ZERO);
            }
            l[a][a] = T::ONE;
            d[a] = pivot(&self.factor, r0 + a);
        }
        (l, d)
    }

    /// Writes the robot's own block of the factor (the robot rows' entries in the robot
    /// columns and their pivots), which no deferred prediction concerns: the coupling rows
    /// stay as they are stored.
    pub(super) fn set_robot_block(&mut self, l: &[[T; 3]; 3], d: &[T; 3]) {
        let r0 = self.active_dim() - 3;
        for a in 0..3 {
            let start = row_start(r0 + a) + r0;
            if let Some(row) = self.factor.get_mut(start..=start + a) {
                for (b, slot) in row.iter_mut().enumerate() {
                    *slot = if b == a { d[a] } else { l[a][b] };
                }
            }
        }
    }

    /// `P_RR` and a bound on the largest |L_rc| of the robot rows over the columns left of
    /// the robot (non-finite when an entry may be): O(1) during a run of predictions,
    /// otherwise one pass over the robot's three rows.
    pub(super) fn robot_summary(&self) -> (Matrix3<T>, T) {
        let run = self.deferred.unwrap_or_else(|| self.start_deferral());
        (run.robot_covariance(), run.largest())
    }

    /// `L_rr D_r L_rrᵀ`: the robot's own block's part of `P_RR`.
    fn own_covariance(&self) -> Matrix3<T> {
        let (lrr, dr) = self.robot_block();
        ldl_product(&lrr, &dr)
    }

    /// A run of deferred predictions starting from the factor as stored (one pass over the
    /// robot's three rows). (A plain maximum in its loop saves a third of its host
    /// instructions but, unrolled, costs the firmware 4 KB of flash.)
    pub(super) fn start_deferral(&self) -> DeferredMotion<T> {
        let r0 = self.active_dim() - 3;
        let rows = [0, 1, 2].map(|a| {
            let row = strict_row(&self.factor, r0 + a);
            row.get(..r0).unwrap_or(&[])
        });
        let mut diag = 0;
        let pivots = (0..r0).map(move |c| {
            let d = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            d
        });
        DeferredMotion::start(rows, pivots, &self.own_covariance())
    }

    /// Applies the predictions made since the last update or new landmark to the stored
    /// factor now (O(n), once). The next update or new landmark does it anyway; call it
    /// before reading many entries of [`EkfSlam::active_covariance`] (a JCBB batch),
    /// whose reads otherwise apply the deferred predictions to every robot entry they
    /// compute. Nothing the filter shows changes.
    pub fn flush_predictions(&mut self) {
        self.settle();
    }

    /// The factor, to write: applies the deferred predictions first. (Inlined: the loops
    /// of an update and a new landmark call it per row or entry, and after the first call
    /// it is one test.)
    #[inline(always)]
    pub(super) fn factor_mut(&mut self) -> &mut [T; P] {
        self.settle();
        &mut self.factor
    }

    /// Applies the deferred predictions to the robot's coupling rows (O(n)), so that the
    /// stored factor is the true one.
    #[inline(always)]
    pub(super) fn settle(&mut self) {
        if self.deferred.is_some() {
            self.apply_deferred();
        }
    }

    /// [`EkfSlam::settle`] when predictions are deferred.
    #[inline(never)]
    fn apply_deferred(&mut self) {
        // The map only (not `take`: the whole run is ten times its size).
        let Some(map) = self.deferred.as_ref().map(|run| run.map()) else {
            return;
        };
        self.deferred = None;
        let r0 = self.active_dim() - 3;
        let s0 = row_start(r0);
        let Some(all) = self.factor.get_mut(s0..row_start(r0 + 3)) else {
            return;
        };
        let (ra, rest) = all.split_at_mut(r0 + 1);
        let (rb, rc) = rest.split_at_mut(r0 + 2);
        let rows = ra.iter_mut().zip(rb.iter_mut()).zip(rc.iter_mut()).take(r0);
        for (c, ((x, y), z)) in rows.enumerate() {
            [*x, *y, *z] = map.apply([*x, *y, *z]);
            if c < 2 {
                *x += map.near(0, c);
                *y += map.near(1, c);
                *z += map.near(2, c);
            }
        }
    }
}
