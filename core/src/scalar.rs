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
            crate::geometry::sin_cos_f32(self)
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
