//! Low-variance resampling: systematic and stratified (Du n.d., eq. 25 and its pseudocode).
//!
//! Both draw `P` positions `β_k = (k + u_k) / P` in `[0, 1)` and take the particle whose
//! cumulative weight first reaches `β_k`. *Stratified*: one uniform `u_k` per stratum (the
//! pseudocode of Du n.d.). *Systematic*: one `u` shared by all strata. Both are unbiased (the
//! expected number of copies of particle `i` is `P · w_i`) and keep the output indices in
//! increasing order.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. Stratified resampling when N_eff falls below 0.75 P, eq. 25.

use rand_core::RngCore;
use rand_distr::{Distribution, StandardUniform};

/// Which low-variance scheme to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Resampling {
    /// One uniform draw per stratum (as in Du n.d.). Discriminant 0: the scheme of zero
    /// bytes (a filter in `.bss` before its settings replace them).
    Stratified = 0,
    /// One uniform draw shared by all strata.
    Systematic,
}

/// Draws `weights.len()` ancestors from `weights` (normalised or not, non-negative) and
/// calls `emit(k, ancestor)` for `k = 0, 1, …` in order. Non-finite or negative weights
/// count as zero; if all are zero, every particle is its own ancestor.
pub fn resample<R: RngCore + ?Sized>(
    weights: &[f32],
    scheme: Resampling,
    rng: &mut R,
    mut emit: impl FnMut(usize, usize),
) {
    let n = weights.len();
    let clean = |w: f32| if w.is_finite() && w > 0.0 { w } else { 0.0 };
    let total: f32 = weights.iter().map(|w| clean(*w)).sum();
    if n == 0 {
        return;
    }
    if !(total > 0.0 && total.is_finite()) {
        for k in 0..n {
            emit(k, k);
        }
        return;
    }
    let shared: f32 = StandardUniform.sample(rng);
    let mut j = 0usize;
    let mut cumulative = weights.first().map_or(0.0, |w| clean(*w));
    for k in 0..n {
        let u = match scheme {
            Resampling::Systematic => shared,
            Resampling::Stratified => {
                if k == 0 {
                    shared
                } else {
                    StandardUniform.sample(rng)
                }
            }
        };
        let beta = (k as f32 + u) / n as f32 * total;
        while beta > cumulative && j + 1 < n {
            j += 1;
            cumulative += weights.get(j).map_or(0.0, |w| clean(*w));
        }
        emit(k, j);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_core::SeedableRng;
    use rand_xoshiro::Xoshiro128PlusPlus;

    fn counts(weights: &[f32], scheme: Resampling, rng: &mut Xoshiro128PlusPlus) -> Vec<u32> {
        let mut c = vec![0u32; weights.len()];
        resample(weights, scheme, rng, |_, j| c[j] += 1);
        c
    }

    #[test]
    fn unbiased_and_low_variance() {
        // Expected copies P·w_i; each scheme gives floor or ceil of it in every draw when
        // the strata are systematic, and the long-run mean matches for both.
        let w = [0.05f32, 0.3, 0.0, 0.15, 0.25, 0.01, 0.04, 0.2];
        let n = w.len() as f64;
        for scheme in [Resampling::Stratified, Resampling::Systematic] {
            let mut rng = Xoshiro128PlusPlus::seed_from_u64(42);
            let rounds = 20_000;
            let mut sum = vec![0f64; w.len()];
            for _ in 0..rounds {
                let c = counts(&w, scheme, &mut rng);
                assert_eq!(c.iter().sum::<u32>(), w.len() as u32);
                assert_eq!(c[2], 0, "a zero-weight particle is never drawn");
                if scheme == Resampling::Systematic {
                    for (ci, wi) in c.iter().zip(w) {
                        let e = n * f64::from(wi);
                        assert!((f64::from(*ci) - e).abs() < 1.0 + 1e-6);
                    }
                }
                for (s, ci) in sum.iter_mut().zip(&c) {
                    *s += f64::from(*ci);
                }
            }
            for (i, s) in sum.iter().enumerate() {
                let mean = s / f64::from(rounds);
                let expect = n * f64::from(w[i]);
                // Each count varies by at most ±1 around its expectation (std ≤ 0.5), so
                // the mean of 20 000 rounds is within 4.5 · 0.5/√20000 = 0.016.
                assert!(
                    (mean - expect).abs() < 0.016,
                    "{scheme:?} {i}: {mean} vs {expect}"
                );
            }
        }
    }

    #[test]
    fn degenerate_weights() {
        let mut rng = Xoshiro128PlusPlus::seed_from_u64(1);
        let c = counts(&[0.0, f32::NAN, -1.0], Resampling::Stratified, &mut rng);
        assert_eq!(c, vec![1, 1, 1]);
        let c = counts(&[0.0, 5.0, f32::INFINITY], Resampling::Systematic, &mut rng);
        assert_eq!(c, vec![0, 3, 0]);
        assert!(counts(&[], Resampling::Systematic, &mut rng).is_empty());
        // Ancestors come out in increasing order.
        let mut last = 0;
        resample(
            &[0.2, 0.1, 0.4, 0.3],
            Resampling::Stratified,
            &mut rng,
            |_, j| {
                assert!(j >= last);
                last = j;
            },
        );
    }
}
