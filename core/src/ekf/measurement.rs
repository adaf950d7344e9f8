//! A sighting against a landmark: the checks of a sighting and of its covariance, the
//! decorrelation of that covariance, the two measurement rows (range and bearing, with the
//! range bias when it is estimated), their projection through the factor, `f = Lᵀ hᵀ`, and
//! the innovation `ν`, `S = H P Hᵀ + R` (O(n), nothing written).

use super::EkfSlam;
use super::covariance::strict_row;
use super::deferred::pull_back;
use super::outcome::Innovation;
use crate::error::EkfError;
use crate::geometry::wrap_near;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use nalgebra::{Matrix2, Matrix2x3, Vector2};

/// One scalar measurement row: `(index inside the factor, coefficient)` for the five
/// states a sighting depends on, and the two of the range bias (zero when not estimated).
type SparseRow<T> = [(usize, T); 7];

impl<T: Real, const N: usize, const P: usize> EkfSlam<T, N, P> {
    /// The two measurement rows of a sighting of the landmark in slot `index` with Jacobians
    /// `hr` (robot) and `hl` (landmark), as sparse rows over the factor's order.
    fn sparse_rows(
        &self,
        index: usize,
        hr: &Matrix2x3<T>,
        hl: &Matrix2<T>,
        hb: [T; 2],
    ) -> [SparseRow<T>; 2] {
        let r0 = self.active_dim() - 3;
        let li = 2 * index;
        let bi = 2 * self.bias_slot().unwrap_or(0);
        [0, 1].map(|r| {
            let hb = if r == 0 { hb } else { [T::ZERO; 2] };
            [
                (bi, hb[0]),
                (bi + 1, hb[1]),
                (li, hl[(r, 0)]),
                (li + 1, hl[(r, 1)]),
                (r0, hr[(r, 0)]),
                (r0 + 1, hr[(r, 1)]),
                (r0 + 2, hr[(r, 2)]),
            ]
        })
    }

    /// `f = Lᵀ hᵀ` over the first `f.len()` states, for a sparse row `h`. With deferred
    /// predictions the robot's coefficients `h_r` act on the stored coupling rows as
    /// `Aᵀ h_r` and on columns 0 and 1 as `Bᵀ h_r` ([`super::deferred`]).
    fn project(&self, h: &SparseRow<T>, f: &mut [T]) {
        f.fill(T::ZERO);
        let r0 = self.active_dim() - 3;
        let deferred = self.deferred.as_ref().map(|run| run.map());
        let mut robot = [T::ZERO; 3];
        for &(s, hs) in h {
            if deferred.is_some()
                && let Some(v) = robot.get_mut(s.wrapping_sub(r0))
            {
                *v += hs;
                continue;
            }
            add_scaled(f, strict_row(&self.factor, s), hs);
            if let Some(fs) = f.get_mut(s) {
                *fs += hs;
            }
        }
        let Some(map) = deferred else {
            return;
        };
        let (on_stored, on_near) = pull_back(&map, robot);
        for (b, (&hr, &hs)) in robot.iter().zip(on_stored.iter()).enumerate() {
            let row = strict_row(&self.factor, r0 + b);
            let (coupling, own) = row.split_at(r0.min(row.len()));
            add_scaled(f, coupling, hs);
            add_scaled(f.get_mut(r0..).unwrap_or(&mut []), own, hr);
            if let Some(fs) = f.get_mut(r0 + b) {
                *fs += hr;
            }
        }
        if r0 >= 2 {
            add_scaled(f, &on_near, T::ONE);
        }
    }

    /// The innovation of sighting `z` (covariance `r`) against landmark `index`, without
    /// changing anything: `S = H P Hᵀ + R` with `H P Hᵀ = Fᵀ D F`, `F = Lᵀ Hᵀ` (O(n)).
    /// `f0`, `f1` (at least the active dimension long) receive the two columns of `F`.
    pub(super) fn innovation_into(
        &self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
        f0: &mut [T],
        f1: &mut [T],
    ) -> Result<Innovation<T>, EkfError> {
        if index >= self.landmark_count() {
            return Err(EkfError::UnknownLandmark);
        }
        let landmark = self
            .mean
            .fixed_rows::<2>(self.landmark_state(index))
            .into_owned();
        let mut pred = self
            .config
            .sensor
            .predict(&self.pose(), &landmark)
            .ok_or(EkfError::LandmarkOnSensor)?;
        // With the range bias: r + b₀ + b₂ β², its Jacobian by the chain rule.
        let mut hb = [T::ZERO; 2];
        if let Some((b0, b2)) = self.range_bias() {
            let beta = pred.z.bearing;
            pred.z.range += b0 + b2 * beta * beta;
            let k = T::lit(2.0) * b2 * beta;
            for c in 0..3 {
                let below = pred.wrt_robot[(1, c)];
                pred.wrt_robot[(0, c)] += k * below;
            }
            for c in 0..2 {
                let below = pred.wrt_landmark[(1, c)];
                pred.wrt_landmark[(0, c)] += k * below;
            }
            hb = [T::ONE, beta * beta];
        }
        let (hr, hl) = (pred.wrt_robot, pred.wrt_landmark);
        let [h0, h1] = self.sparse_rows(self.landmark_slot(index), &hr, &hl, hb);
        let k = self.active_dim();
        let (Some(f0), Some(f1)) = (f0.get_mut(..k), f1.get_mut(..k)) else {
            return Err(EkfError::NumericalFailure);
        };
        self.project(&h0, f0);
        self.project(&h1, f1);
        let (mut s00, mut s01, mut s11) = (T::ZERO, T::ZERO, T::ZERO);
        let mut diag = 0;
        for (c, (&a, &b)) in f0.iter().zip(f1.iter()).enumerate() {
            let d = self.factor.get(diag).copied().unwrap_or(T::ZERO);
            diag += c + 2;
            let (da, db) = (d * a, d * b);
            s00 += da * a;
            s01 += da * b;
            s11 += db * b;
        }
        let off = s01 + (r[(0, 1)] + r[(1, 0)]) * T::lit(0.5);
        let s = Matrix2::new(s00 + r[(0, 0)], off, off, s11 + r[(1, 1)]);
        let det = s[(0, 0)] * s[(1, 1)] - off * off;
        if !is_positive(det) || !is_positive(s[(0, 0)]) || !det.finite() {
            return Err(EkfError::SingularInnovation);
        }
        let s_inv = Matrix2::new(s[(1, 1)] / det, -off / det, -off / det, s[(0, 0)] / det);
        let nu = Vector2::new(
            z.range - pred.z.range,
            wrap_near(z.bearing - pred.z.bearing),
        );
        let d2 = (nu.transpose() * s_inv * nu)[(0, 0)];
        if !d2.finite() {
            return Err(EkfError::NumericalFailure);
        }
        Ok(Innovation {
            nu,
            s,
            s_inv,
            mahalanobis_squared: d2,
            jacobian_robot: hr,
            jacobian_landmark: hl,
            jacobian_bias: Matrix2::new(hb[0], hb[1], T::ZERO, T::ZERO),
        })
    }

    /// [`EkfSlam::innovation_into`] with its own scratch.
    fn innovation_with(
        &self,
        index: usize,
        z: &RangeBearing<T>,
        r: &Matrix2<T>,
    ) -> Result<Innovation<T>, EkfError> {
        let (mut f0, mut f1) = ([T::ZERO; N], [T::ZERO; N]);
        self.innovation_into(index, z, r, &mut f0, &mut f1)
    }

    /// Checks a sighting and its covariance; returns the covariance to use.
    pub(super) fn checked_measurement(
        &self,
        z: &RangeBearing<T>,
        r: Option<&Matrix2<T>>,
    ) -> Result<Matrix2<T>, EkfError> {
        if !(z.range.finite() && z.bearing.finite()) {
            return Err(EkfError::NonFiniteInput);
        }
        if z.bearing.abs() > T::lit(crate::sensors::range_bearing::MAX_BEARING) {
            return Err(EkfError::InvalidBearing);
        }
        if !z.is_valid() {
            return Err(EkfError::InvalidRange);
        }
        let r = r
            .copied()
            .unwrap_or_else(|| self.config.measurement_covariance());
        let det = r[(0, 0)] * r[(1, 1)] - r[(0, 1)] * r[(1, 0)];
        if !r.iter().all(|v| v.finite())
            || r[(0, 0)] < T::ZERO
            || r[(1, 1)] < T::ZERO
            || det < T::ZERO
        {
            return Err(EkfError::InvalidNoise);
        }
        Ok(r)
    }

    /// `R = L_R D_R L_Rᵀ` of a checked 2 × 2 measurement covariance: `(l₁₀, [d₀, d₁])`,
    /// `d ≥ 0` (the second pivot is `det R / r₀₀`, clamped at zero against rounding).
    pub(super) fn decorrelate(r: &Matrix2<T>) -> (T, [T; 2]) {
        let r00 = r[(0, 0)];
        let off = (r[(0, 1)] + r[(1, 0)]) * T::lit(0.5);
        if r00 > T::ZERO {
            let l = off / r00;
            let d1 = r[(1, 1)] - l * off;
            (l, [r00, if d1 > T::ZERO { d1 } else { T::ZERO }])
        } else {
            // r₀₀ = 0 and det ≥ 0 force the off-diagonal to zero.
            (T::ZERO, [T::ZERO, r[(1, 1)]])
        }
    }

    /// The innovation of sighting `z` against landmark `index` (for data association),
    /// with the configured measurement noise, without changing the state.
    pub fn innovation(&self, index: usize, z: &RangeBearing<T>) -> Result<Innovation<T>, EkfError> {
        let r = self.checked_measurement(z, None)?;
        self.innovation_with(index, z, &r)
    }
}

/// `f += a · row` over the shorter of the two (not inlined on a microcontroller: one copy
/// in the firmware's flash for every row a projection adds).
#[cfg_attr(target_os = "none", inline(never))]
fn add_scaled<T: Real>(f: &mut [T], row: &[T], a: T) {
    for (fc, &l) in f.iter_mut().zip(row) {
        *fc += a * l;
    }
}

/// `x > 0`, false for NaN.
fn is_positive<T: Real>(x: T) -> bool {
    x > T::ZERO
}
