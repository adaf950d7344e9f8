//! χ² gates on the Mahalanobis distance of innovations.
//!
//! An innovation `ν` with covariance `S` is accepted when `νᵀ S⁻¹ ν ≤ threshold`, where the
//! threshold is the χ² quantile of the gate's probability for the innovation's dimension.

use crate::scalar::Real;

/// Quantile of the χ² distribution: the `d²` with `P(χ²_dof ≤ d²) = probability`.
///
/// Exact for 2 degrees of freedom (`−2 ln(1 − p)`); otherwise Wilson–Hilferty's cube-root
/// normal approximation refined by Newton steps on the regularised incomplete gamma
/// function (relative error below 1e-9). Returns NaN for a probability outside (0, 1) or
/// zero degrees of freedom. Not meant for a hot loop: compute thresholds once.
pub fn chi_square_quantile(probability: f64, dof: u32) -> f64 {
    if !(probability > 0.0 && probability < 1.0) || dof == 0 {
        return f64::NAN;
    }
    if dof == 2 {
        return -2.0 * libm::log(1.0 - probability);
    }
    let k = f64::from(dof);
    let z = standard_normal_quantile(probability);
    let a = 2.0 / (9.0 * k);
    let c = 1.0 - a + z * libm::sqrt(a);
    let mut q = (k * c * c * c).max(1e-3);
    let half_k = k / 2.0;
    let ln_norm = half_k * core::f64::consts::LN_2 + libm::lgamma(half_k);
    for _ in 0..50 {
        let f = regularized_lower_gamma(half_k, q / 2.0) - probability;
        let ln_pdf = (half_k - 1.0) * libm::log(q) - q / 2.0 - ln_norm;
        let step = f / libm::exp(ln_pdf);
        let next = if q - step > 0.0 { q - step } else { q / 2.0 };
        let done = (next - q).abs() <= 1e-12 * q;
        q = next;
        if done {
            break;
        }
    }
    q
}

/// The regularised lower incomplete gamma function `P(a, x)` (series for `x < a + 1`,
/// Lentz's continued fraction otherwise).
fn regularized_lower_gamma(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    let ln_prefix = a * libm::log(x) - x - libm::lgamma(a);
    if x < a + 1.0 {
        let mut term = 1.0 / a;
        let mut sum = term;
        let mut n = a;
        for _ in 0..500 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        sum * libm::exp(ln_prefix)
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..500 {
            let an = -f64::from(i) * (f64::from(i) - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-16 {
                break;
            }
        }
        1.0 - libm::exp(ln_prefix) * h
    }
}

/// Quantile of the standard normal distribution (Acklam's rational approximation,
/// relative error below 1.2e-9).
pub fn standard_normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    if !(p > 0.0 && p < 1.0) {
        return f64::NAN;
    }
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail(libm::sqrt(-2.0 * libm::log(p)))
    } else if p > 1.0 - 0.02425 {
        -tail(libm::sqrt(-2.0 * libm::log(1.0 - p)))
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// A gate on the squared Mahalanobis distance of a 2-D innovation (range, bearing).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChiSquareGate<T> {
    /// Largest accepted squared Mahalanobis distance.
    pub threshold: T,
}

impl<T: Real> ChiSquareGate<T> {
    /// A gate from its threshold on `νᵀ S⁻¹ ν` (usable in `const` contexts).
    pub const fn from_threshold(threshold: T) -> Self {
        Self { threshold }
    }

    /// A gate that accepts a correct 2-D innovation with the given probability, e.g.
    /// `0.99` → threshold 9.21. `None` when the probability is not inside (0, 1).
    pub fn two_dof(probability: f64) -> Option<Self> {
        let t = chi_square_quantile(probability, 2);
        t.is_finite().then(|| Self::from_threshold(T::lit(t)))
    }

    /// A gate that accepts everything (no outlier rejection).
    pub fn open() -> Self {
        Self::from_threshold(T::max_value().unwrap_or(T::lit(f64::MAX)))
    }

    /// `true` when a squared Mahalanobis distance passes the gate.
    #[inline]
    pub fn accepts(&self, mahalanobis_squared: T) -> bool {
        mahalanobis_squared <= self.threshold
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_match_tables() {
        // Values from standard χ² tables.
        let cases = [
            (0.95, 2, 5.991_465),
            (0.99, 2, 9.210_340),
            (0.95, 3, 7.814_728),
            (0.975, 3, 9.348_404),
            (0.025, 3, 0.215_795_3),
            (0.95, 4, 9.487_729),
            (0.99, 10, 23.209_25),
            (0.975, 150, 185.800_4),
            (0.025, 150, 117.984_6),
        ];
        for (p, k, expected) in cases {
            let q = chi_square_quantile(p, k);
            assert!(
                (q - expected).abs() / expected < 1e-5,
                "p={p} dof={k}: {q} vs {expected}"
            );
        }
        assert!(chi_square_quantile(1.0, 2).is_nan());
        assert!(chi_square_quantile(0.5, 0).is_nan());
        assert!((standard_normal_quantile(0.975) - 1.959_964).abs() < 1e-6);
        assert!((standard_normal_quantile(0.001) + 3.090_232).abs() < 1e-6);
    }

    #[test]
    fn gate_accepts_inside_threshold() {
        let g = ChiSquareGate::<f32>::two_dof(0.99).unwrap();
        assert!(g.accepts(9.0) && !g.accepts(9.3));
        assert!(ChiSquareGate::<f32>::two_dof(1.5).is_none());
        assert!(ChiSquareGate::<f64>::open().accepts(1e300));
    }
}
