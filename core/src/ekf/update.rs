//! The update with a sighting of a known landmark: gated on its innovation, then two scalar
//! (Bierman) updates, range then bearing, planned in O(n) and checked before anything is
//! written ([`EkfSlam::plan_update`]), then applied in one O(n²) pass over the factor, two
//! rows at a time ([`EkfSlam::apply_update`]).

use super::EkfSlam;
use super::bierman::{bierman_row, bierman_rows, bierman_step, sighting_floor};
use super::covariance::{pivot, row_start};
use super::outcome::UpdateOutcome;
use crate::error::EkfError;
use crate::geometry::wrap_near;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use nalgebra::{Matrix2, Vector2};

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// Corrects the state with a sighting `z` of landmark `index`, using the configured
    /// measurement noise. See [`EkfSlam::update_with_covariance`].
    pub fn update(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        self.update_inner(index, z, None)
    }

    /// Corrects the state with a sighting `z` of landmark `index` whose measurement
    /// covariance is `r` (range, bearing).
    ///
    /// Gating: when `νᵀ S⁻¹ ν` exceeds the configured gate the state is left unchanged and
    /// [`UpdateOutcome::Gated`] is returned. Errors (state unchanged): non-finite input,
    /// non-positive range, invalid covariance, unknown landmark, landmark on the sensor, a
    /// non-positive-definite innovation covariance.
    ///
    /// The correction is two scalar updates (range, then bearing; both rows linearised
    /// at the prior, a correlated `r` decorrelated first), which together equal the
    /// joint linear update.
    pub fn update_with_covariance(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        self.update_inner(index, z, Some(r))
    }

    fn update_inner(
        &mut self,
        index: usize,
        z: &RangeBearing<T>,
        r: Option<&Matrix2<T>>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        let r = match self.checked_measurement(z, r) {
            Ok(r) => r,
            Err(e) => return self.reject(e),
        };
        // f0, f1: the columns of Lᵀ Hᵀ; later f0 holds the new pivots.
        let (mut f0, mut f1) = ([T::ZERO; N], [T::ZERO; N]);
        let inn = match self.innovation_into(index, z, &r, &mut f0, &mut f1) {
            Ok(found) => found,
            Err(e) => return self.reject(e),
        };
        let nis = inn.mahalanobis_squared;
        if !self.config.gate.accepts(nis) {
            self.counters.gated = self.counters.gated.saturating_add(1);
            return Ok(UpdateOutcome::Gated { nis });
        }
        let mut terms = [[T::ZERO; 4]; N];
        let plan = match self.plan_update(&r, &inn.nu, &mut f0, &f1, &mut terms) {
            Ok(plan) => plan,
            Err(e) => return self.reject(e),
        };
        if self.apply_update(&plan, &f0, &terms).is_err() {
            return self.reject(EkfError::NumericalFailure);
        }
        self.counters.updates = self.counters.updates.saturating_add(1);
        Ok(UpdateOutcome::Accepted { nis })
    }

    /// Everything of an update but the O(n²) pass, in O(n), checked before anything is
    /// written: two scalar (Bierman) updates, range then bearing, both linearised at the
    /// prior, with `r` decorrelated first (`R = L_R D_R L_Rᵀ`, second row `h₁ − l h₀`).
    ///
    /// Scalar update `s` with `f = Lᵀ hᵀ`, `vⱼ = Dⱼ fⱼ` and `α` running from `r` over
    /// `j = k−1 … 0` (`α ← α + vⱼ fⱼ`) sets `Dⱼ' = Dⱼ α_before / α_after ≥ 0` and, row by
    /// row from the last entry to the first, `L_ij' = L_ij + bᵢ pⱼ`, `bᵢ ← bᵢ + L_ij vⱼ`,
    /// with `bᵢ = vᵢ` at the start and `pⱼ = −fⱼ / α_before`; `bᵢ` ends as `(P hᵀ)ᵢ`, so
    /// the gain is `b / α_total`. The second update's `f` after the first is
    /// `f₂ⱼ = f̃₁ⱼ + p₁ⱼ Σ_{t>j} v₁ₜ f̃₁ₜ` (no pass over `L` needed), so both run in one
    /// pass. On return `f0` holds the final pivots and `terms[j] = [p₁ⱼ, v₁ⱼ, p₂ⱼ, v₂ⱼ]`.
    fn plan_update(
        &self,
        r: &Matrix2<T>,
        nu: &Vector2<T>,
        f0: &mut [T; N],
        f1: &[T; N],
        terms: &mut [[T; 4]; N],
    ) -> Result<UpdatePlan<T>, EkfError> {
        let k = self.active_dim();
        let (l, d) = Self::decorrelate(r);
        let (Some(f0), Some(f1), Some(terms)) = (f0.get_mut(..k), f1.get(..k), terms.get_mut(..k))
        else {
            return Err(EkfError::NumericalFailure);
        };
        // First scalar: v₁ = D f₀.
        let mut hph = T::ZERO;
        let mut diag = 0;
        for (c, (t, &fc)) in terms.iter_mut().zip(f0.iter()).enumerate() {
            let dc = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            t[1] = dc * fc;
            hph += t[1] * fc;
        }
        let r0 = sighting_floor(d[0], hph);
        let total0 = hph + r0;
        // Descending: D', p₁, and f₂ = f̃₁ + p₁ β with β the suffix sum of v₁ f̃₁.
        let mut alpha = r0;
        let mut beta = T::ZERO;
        let mut hph = T::ZERO;
        for c in (0..k).rev() {
            let (Some(t), Some(fc), Some(&g)) = (terms.get_mut(c), f0.get_mut(c), f1.get(c)) else {
                return Err(EkfError::NumericalFailure);
            };
            let g = g - l * *fc;
            let next = alpha + t[1] * *fc;
            let dc = pivot(&self.factor, c);
            let (new_d, p) = bierman_step(dc, *fc, alpha, next);
            t[0] = p;
            let f2 = g + p * beta;
            beta += t[1] * g;
            t[3] = new_d * f2;
            hph += t[3] * f2;
            // f0 now carries f₂ until the second chain below.
            *fc = f2;
            // The first update's pivot, kept in t[2] until the second chain.
            t[2] = new_d;
            alpha = next;
        }
        let r1 = sighting_floor(d[1], hph);
        let total1 = hph + r1;
        let mut alpha = r1;
        let mut poison = T::ZERO;
        for c in (0..k).rev() {
            let (Some(t), Some(fc)) = (terms.get_mut(c), f0.get_mut(c)) else {
                return Err(EkfError::NumericalFailure);
            };
            let next = alpha + t[3] * *fc;
            let (new_d, p) = bierman_step(t[2], *fc, alpha, next);
            t[2] = p;
            *fc = new_d;
            poison += (t[0] + t[1] + t[2] + t[3] + new_d) * T::ZERO;
            alpha = next;
        }
        // ν̃₁ = ν₁ − l ν₀, minus what the first correction explains: h̃₁ K₀ ν₀.
        let scale0 = if total0 > T::ZERO {
            nu[0] / total0
        } else {
            T::ZERO
        };
        let nu1 = nu[1] - l * nu[0] - beta * scale0;
        let scale1 = if total1 > T::ZERO {
            nu1 / total1
        } else {
            T::ZERO
        };
        poison += (total0 + total1 + scale0 + scale1) * T::ZERO;
        if poison != T::ZERO {
            return Err(EkfError::NumericalFailure);
        }
        Ok(UpdatePlan { scale0, scale1 })
    }

    /// The O(n²) pass of an update planned by [`EkfSlam::plan_update`]: each row of `L`
    /// once, both scalar updates per entry, and `x ← x + K₀ ν₀ + K₁ ν̃₁` (heading wrapped).
    /// `Err` when the result is not finite (the state is then no longer what it was).
    fn apply_update(
        &mut self,
        plan: &UpdatePlan<T>,
        pivots: &[T; N],
        terms: &[[T; 4]; N],
    ) -> Result<(), ()> {
        let k = self.active_dim();
        let mut poison = T::ZERO;
        // Rows two at a time: rows i and i + 1 share the terms of columns 0..i, loaded once.
        let mut i = 0;
        while i < k {
            let pair = i + 1 < k;
            let len = if pair { 2 * i + 3 } else { i + 1 };
            let start = row_start(i);
            let (Some(rows), Some(head), Some(&[_, va, _, vb])) = (
                self.factor_mut().get_mut(start..start + len),
                terms.get(..i),
                terms.get(i),
            ) else {
                return Err(());
            };
            let (row_a, rest) = rows.split_at_mut(i + 1);
            let Some((diag_a, row_a)) = row_a.split_last_mut() else {
                return Err(());
            };
            *diag_a = pivots.get(i).copied().unwrap_or(T::ZERO);
            let (ba, bb) = if let Some((diag_b, row_b)) = rest.split_last_mut() {
                *diag_b = pivots.get(i + 1).copied().unwrap_or(T::ZERO);
                let Some((last_b, row_b)) = row_b.split_last_mut() else {
                    return Err(());
                };
                let (Some(&[_, wa, _, wb]), Some(own)) = (terms.get(i + 1), terms.get(i..=i))
                else {
                    return Err(());
                };
                // Row i + 1's entry in column i first (its last), then both rows together.
                let b = bierman_row(core::slice::from_mut(last_b), own, wa, wb);
                bierman_rows(row_a, row_b, head, (va, vb), b)
            } else {
                (bierman_row(row_a, head, va, vb), (T::ZERO, T::ZERO))
            };
            for (r, (b0, b1)) in [(i, ba), (i + 1, bb)]
                .into_iter()
                .take(if pair { 2 } else { 1 })
            {
                let dx = b0 * plan.scale0 + b1 * plan.scale1;
                if let Some(x) = self.mean.as_mut_slice().get_mut(internal_to_public(r, k)) {
                    *x += dx;
                }
                poison += dx * T::ZERO;
            }
            i += 2;
        }
        self.mean[2] = wrap_near(self.mean[2]);
        if poison != T::ZERO { Err(()) } else { Ok(()) }
    }
}

/// The O(n) results of [`EkfSlam::plan_update`]: the mean moves by
/// `b₀ · scale0 + b₁ · scale1` per state (`K ν` of the two scalar updates).
struct UpdatePlan<T> {
    scale0: T,
    scale1: T,
}

/// Public state index (robot first) of index `i` inside the factor (robot last), for an
/// active dimension `k`.
#[inline(always)]
pub(super) fn internal_to_public(i: usize, k: usize) -> usize {
    if i + 3 >= k { i + 3 - k } else { i + 3 }
}
