//! The scalar types the estimators run on.
//!
//! Every estimator is generic over [`Real`]: `f32` on a microcontroller with an FPU,
//! `f64` allowed on the host. The trait adds to nalgebra's [`RealField`] the few things a
//! `no_std`, allocation-free filter needs: constants usable in `const fn` (so that large
//! filters can be built directly in a `static`) and lossless conversion of literals.

use nalgebra::RealField;

/// A real scalar usable by the estimators: `f32` or `f64`.
pub trait Real: RealField + Copy + Default {
    /// Zero, usable in `const` contexts.
    const ZERO: Self;
    /// One, usable in `const` contexts.
    const ONE: Self;

    /// Converts an `f64` literal or setting to this type (rounding for `f32`).
    fn lit(value: f64) -> Self;

    /// Converts to `f64` (exact for both implementations).
    fn to_f64(self) -> f64;

    /// `true` when the value is neither NaN nor infinite.
    fn finite(self) -> bool;

    /// `(sin x, cos x)` in this type's own arithmetic, for the estimators' per-step
    /// trigonometry. `f32`: [`crate::geometry::sin_cos_f32`] for |x| ≤ 100 (error
    /// ≤ 2·10⁻⁷; `libm`'s `sinf`/`cosf` compute in `f64`, which a Cortex-M4F runs in
    /// software, ≈ 900 instructions a call against ≈ 30), `libm` beyond. `f64`: `libm`.
    fn sin_cos_native(self) -> (Self, Self);
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;

    #[inline]
    fn lit(value: f64) -> Self {
        value as f32
    }

    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }

    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }

    // Not inlined on a microcontroller: one copy of the polynomials in the firmware's
    // flash for the four call sites of the velocity motion model and the sighting model.
    #[cfg_attr(target_os = "none", inline(never))]
    #[cfg_attr(not(target_os = "none"), inline)]
    fn sin_cos_native(self) -> (Self, Self) {
        if self.abs() <= 100.0 {
            sin_cos_f32(self)
        } else {
            nalgebra::ComplexField::sin_cos(self)
        }
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;

    #[inline]
    fn lit(value: f64) -> Self {
        value
    }

    #[inline]
    fn to_f64(self) -> f64 {
        self
    }

    #[inline]
    fn finite(self) -> bool {
        self.is_finite()
    }

    #[inline]
    fn sin_cos_native(self) -> (Self, Self) {
        nalgebra::ComplexField::sin_cos(self)
    }
}

/// `true` when every value is finite.
#[inline]
pub fn all_finite<T: Real>(values: &[T]) -> bool {
    values.iter().all(|v| v.finite())
}

/// `(sin x, cos x)` in `f32` arithmetic only, for headings of a few turns at most: the
/// particle filter's per-particle trigonometry on a single-precision FPU.
///
/// `libm::sincosf` evaluates its polynomials in `f64`, which a Cortex-M4F runs in
/// software (≈ 900 instructions a call); this reduces `x` by the nearest multiple of
/// π/2 (Cody–Waite, π/2 split in three `f32` parts, exact products for |x| < 2¹²) and
/// evaluates Cephes' `sinf`/`cosf` minimax polynomials on |r| ≤ π/4 (≈ 30 instructions).
/// Error ≤ 2·10⁻⁷ for |x| ≤ 100 (against `f64`); NaN for a non-finite `x`. Same results
/// on every target (IEEE `f32` arithmetic, no fused operations).
///
/// ```
/// use microslam::scalar::sin_cos_f32;
/// let (s, c) = sin_cos_f32(0.5);
/// assert!((s - 0.5f64.sin() as f32).abs() < 2e-7 && (c - 0.5f64.cos() as f32).abs() < 2e-7);
/// ```
#[inline]
pub fn sin_cos_f32(x: f32) -> (f32, f32) {
    // π/2 = P1 + P2 + P3, P1 and P2 with few significant bits (Cephes' DP1..DP3 × 2).
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    // The nearest quadrant: floor(x·2/π + ½), saturating, 0 for NaN.
    let y = x * core::f32::consts::FRAC_2_PI + 0.5;
    let t = y as i32;
    let q = if (t as f32) > y {
        t.saturating_sub(1)
    } else {
        t
    };
    let qf = q as f32;
    let r = ((x - qf * P1) - qf * P2) - qf * P3;
    let z = r * r;
    let sin = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * r + r;
    let cos = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    match q & 3 {
        0 => (sin, cos),
        1 => (cos, -sin),
        2 => (-sin, -cos),
        _ => (-cos, sin),
    }
}
