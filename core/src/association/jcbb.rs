//! Joint compatibility branch and bound (Neira & Tardós, IEEE T-RA 17(6), 2001).
//!
//! A batch of simultaneous sightings is paired with landmarks *jointly*: a hypothesis
//! `H = {(sighting i → landmark j_i)}` is accepted only when the joint innovation of all
//! its pairings, with the joint covariance `C_H = H_H P H_Hᵀ + R_H` (which carries the
//! correlations between the pairings through the robot pose and the landmarks), passes
//! the χ²(2k) gate. Among jointly compatible hypotheses the one with the most pairings
//! wins, ties broken by the smaller joint NIS. A common error in the robot heading shifts
//! every sighting the same way: individually each sighting may look nearest to the wrong
//! landmark, jointly only the right pairing fits (the unit tests build such a case).
//!
//! The search is a depth-first branch and bound over the sightings, each tried with its
//! individually compatible landmarks ([`Candidates`], the `K` nearest) and with "no
//! pairing". The joint NIS is computed incrementally with a block Cholesky factor of
//! `C_H` (2 × 2 blocks, extended by one block row per pairing: O(k²) per node, nothing
//! allocated). Memory is fixed by the type: `B` sightings per batch, `K` candidates each.

use super::compatibility::{AssociationConfig, Candidates, Pairing};
use crate::ekf::{CovarianceView, EkfSlam};
use crate::gate::chi_square_quantile;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use core::fmt;
use nalgebra::{Matrix2, Vector2};

/// A batch holds more sightings than the association was built for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BatchTooLarge {
    /// Sightings in the batch.
    pub sightings: usize,
    /// Largest batch the association takes.
    pub capacity: usize,
}

impl fmt::Display for BatchTooLarge {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "batch of {} sightings exceeds the capacity of {}",
            self.sightings, self.capacity
        )
    }
}

impl core::error::Error for BatchTooLarge {}

/// What a JCBB search found.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct JcbbOutcome<T> {
    /// Sightings paired with existing landmarks.
    pub pairings: usize,
    /// Joint NIS of the chosen hypothesis (0 with no pairing).
    pub joint_nis: T,
    /// Hypotheses visited.
    pub nodes: u32,
    /// `true` when the search hit [`AssociationConfig::max_search_nodes`] and the best
    /// hypothesis found until then was used.
    pub truncated: bool,
}

/// JCBB for batches of up to `B` sightings, each with up to `K` candidate landmarks.
///
/// Holds the configuration and the joint gate thresholds χ²(2k), k = 1…B (computed once
/// in [`Jcbb::new`]). Stack use of [`Jcbb::associate`] is about
/// `(B·K·22 + 4·B² + 4·B) · size_of::<T>()` bytes.
#[derive(Clone, Debug, PartialEq)]
pub struct Jcbb<T: Real, const B: usize, const K: usize> {
    config: AssociationConfig<T>,
    joint_thresholds: [T; B],
}

impl<T: Real, const B: usize, const K: usize> Jcbb<T, B, K> {
    /// A JCBB association with the given settings.
    pub fn new(config: AssociationConfig<T>) -> Self {
        let mut joint_thresholds = [T::ZERO; B];
        for (k, t) in joint_thresholds.iter_mut().enumerate() {
            let dof = 2 * (k as u32 + 1);
            *t = T::lit(chi_square_quantile(config.joint_probability, dof));
        }
        Self {
            config,
            joint_thresholds,
        }
    }

    /// The settings in use.
    pub fn config(&self) -> &AssociationConfig<T> {
        &self.config
    }

    /// Pairs the batch `sightings` with the landmarks of `slam`, writing one [`Pairing`]
    /// per sighting into `pairings[..sightings.len()]`. The filter is not changed: apply
    /// the pairings with [`EkfSlam::update`] / [`EkfSlam::add_landmark`].
    ///
    /// Unpaired sightings are [`Pairing::New`] when far from every landmark, otherwise
    /// [`Pairing::Ambiguous`]; invalid ones [`Pairing::Invalid`]. A batch larger than `B`
    /// (or than `pairings`) is refused with nothing written.
    pub fn associate<const N: usize, const P: usize>(
        &self,
        slam: &EkfSlam<T, N, P>,
        sightings: &[RangeBearing<T>],
        pairings: &mut [Pairing],
    ) -> Result<JcbbOutcome<T>, BatchTooLarge> {
        let m = sightings.len();
        if m > B || m > pairings.len() {
            return Err(BatchTooLarge {
                sightings: m,
                capacity: B.min(pairings.len()),
            });
        }
        let mut candidates: [Candidates<T, K>; B] = core::array::from_fn(|_| Candidates::default());
        for (c, z) in candidates.iter_mut().zip(sightings) {
            *c = Candidates::of(slam, z, &self.config.individual_gate);
        }
        let candidates = candidates.get(..m).unwrap_or(&[]);
        let mut search = Search::<T, B, K> {
            covariance: slam.active_covariance(),
            first_landmark: slam.landmark_state(0),
            bias_state: slam.range_bias_state(),
            candidates,
            thresholds: &self.joint_thresholds,
            pairs: [(0, 0); B],
            depth: 0,
            nis: T::ZERO,
            factor: [[Matrix2::zeros(); B]; B],
            whitened: [Vector2::zeros(); B],
            best: [None; B],
            best_pairings: 0,
            best_nis: T::max_value().unwrap_or(T::lit(f64::MAX)),
            runner_up: None,
            nodes: 0,
            max_nodes: self.config.max_search_nodes,
            truncated: false,
        };
        search.explore(0);
        // Sightings on which the runner-up differs, when it is nearly as good.
        let contested = |i: usize| {
            search.runner_up.is_some_and(|(other, nis)| {
                nis - search.best_nis < self.config.ambiguity_margin
                    && other.get(i) != search.best.get(i)
            })
        };
        for (i, (out, z)) in pairings.iter_mut().zip(sightings).enumerate() {
            let cands = candidates.get(i);
            *out = match (search.best.get(i).copied().flatten(), cands) {
                _ if !z.is_valid() => Pairing::Invalid,
                (Some(_), Some(_)) if contested(i) => Pairing::Ambiguous,
                (Some(c), Some(cands)) => cands
                    .nearest
                    .get(c)
                    .map_or(Pairing::Ambiguous, |c| Pairing::Landmark(c.landmark)),
                (None, Some(cands)) => match cands.unpaired_decision(&self.config) {
                    Pairing::Ambiguous
                        if self.config.distinct_in_batch
                            && near_ones_taken(slam, z, &search.best, candidates, &self.config) =>
                    {
                        Pairing::New
                    }
                    other => other,
                },
                (_, None) => Pairing::Invalid,
            };
        }
        Ok(JcbbOutcome {
            pairings: search.best_pairings,
            joint_nis: if search.best_pairings == 0 {
                T::ZERO
            } else {
                search.best_nis
            },
            nodes: search.nodes,
            truncated: search.truncated,
        })
    }
}

/// `true` when every landmark within the new-landmark quantile of `z` is paired, by the
/// chosen hypothesis `best`, with another sighting of the batch.
fn near_ones_taken<T: Real, const N: usize, const P: usize, const B: usize, const K: usize>(
    slam: &EkfSlam<T, N, P>,
    z: &RangeBearing<T>,
    best: &[Option<usize>; B],
    candidates: &[Candidates<T, K>],
    config: &AssociationConfig<T>,
) -> bool {
    let taken = |landmark: usize| {
        best.iter().zip(candidates).any(|(b, c)| {
            b.and_then(|b| c.nearest.get(b))
                .is_some_and(|p| p.landmark == landmark)
        })
    };
    (0..slam.landmark_count()).all(|l| match slam.innovation(l, z) {
        Ok(i) => i.mahalanobis_squared > config.new_landmark_threshold || taken(l),
        Err(_) => true,
    })
}

/// State of one branch-and-bound search.
struct Search<'a, T: Real, const B: usize, const K: usize> {
    covariance: CovarianceView<'a, T>,
    /// Public state index of landmark 0's x ([`EkfSlam::landmark_state`]).
    first_landmark: usize,
    /// Public state index of the range bias, when it is estimated
    /// ([`EkfSlam::range_bias_state`]).
    bias_state: Option<usize>,
    candidates: &'a [Candidates<T, K>],
    thresholds: &'a [T; B],
    /// The current hypothesis: (sighting, candidate index) for each of `depth` pairings.
    pairs: [(usize, usize); B],
    depth: usize,
    /// Joint NIS of the current hypothesis.
    nis: T,
    /// Block lower-triangular Cholesky factor of `C_H`: `factor[a][b]`, b ≤ a.
    factor: [[Matrix2<T>; B]; B],
    /// `L⁻¹ ν_H`, block by block.
    whitened: [Vector2<T>; B],
    /// Best hypothesis: candidate index per sighting.
    best: [Option<usize>; B],
    best_pairings: usize,
    best_nis: T,
    /// Second-best hypothesis with as many pairings as the best, and its joint NIS.
    runner_up: Option<([Option<usize>; B], T)>,
    nodes: u32,
    max_nodes: u32,
    truncated: bool,
}

impl<T: Real, const B: usize, const K: usize> Search<'_, T, B, K> {
    fn explore(&mut self, sighting: usize) {
        if self.nodes >= self.max_nodes {
            self.truncated = true;
            return;
        }
        self.nodes += 1;
        let m = self.candidates.len();
        if sighting >= m {
            let mut current = [None; B];
            for &(i, c) in self.pairs.get(..self.depth).unwrap_or(&[]) {
                if let Some(b) = current.get_mut(i) {
                    *b = Some(c);
                }
            }
            if self.depth > self.best_pairings {
                self.runner_up = None;
                self.best = current;
                self.best_pairings = self.depth;
                self.best_nis = self.nis;
            } else if self.depth == self.best_pairings {
                if self.nis < self.best_nis {
                    if self.depth > 0 {
                        self.runner_up = Some((self.best, self.best_nis));
                    }
                    self.best = current;
                    self.best_nis = self.nis;
                } else if self.depth > 0 && self.runner_up.is_none_or(|(_, n)| self.nis < n) {
                    self.runner_up = Some((current, self.nis));
                }
            }
            return;
        }
        let count = self.candidates.get(sighting).map_or(0, |c| c.nearest.len());
        for c in 0..count {
            if self.landmark_used(sighting, c) {
                continue;
            }
            if let Some(nis) = self.extend(sighting, c) {
                let saved = self.nis;
                if let Some(p) = self.pairs.get_mut(self.depth) {
                    *p = (sighting, c);
                }
                self.depth += 1;
                self.nis = nis;
                self.explore(sighting + 1);
                self.depth -= 1;
                self.nis = saved;
            }
        }
        // Leave this sighting unpaired, when that can still tie or beat the best.
        if self.depth + (m - sighting - 1) >= self.best_pairings {
            self.explore(sighting + 1);
        }
    }

    fn candidate(&self, sighting: usize, c: usize) -> Option<&super::compatibility::Candidate<T>> {
        self.candidates.get(sighting)?.nearest.get(c)
    }

    fn landmark_used(&self, sighting: usize, c: usize) -> bool {
        let Some(new) = self.candidate(sighting, c) else {
            return true;
        };
        self.pairs
            .get(..self.depth)
            .unwrap_or(&[])
            .iter()
            .any(|&(i, ci)| {
                self.candidate(i, ci)
                    .is_some_and(|p| p.landmark == new.landmark)
            })
    }

    /// Extends the factor by the pairing (sighting → candidate `c`) at row `depth`;
    /// returns the joint NIS of the extended hypothesis when it passes the joint gate.
    fn extend(&mut self, sighting: usize, c: usize) -> Option<T> {
        let k = self.depth;
        let new = *self.candidate(sighting, c)?;
        let threshold = *self.thresholds.get(k)?;
        let (hr_k, hl_k) = (
            new.innovation.jacobian_robot,
            new.innovation.jacobian_landmark,
        );
        let jk = self.first_landmark + 2 * new.landmark;
        let p = self.covariance;
        let p_rr = p.block::<3, 3>(0, 0)?;
        let p_r_jk = p.block::<3, 2>(0, jk)?;
        // Row k of the factor: L[k][a] for a < k.
        for a in 0..k {
            let (ia, ca) = *self.pairs.get(a)?;
            let old = *self.candidate(ia, ca)?;
            let (hr_a, hl_a) = (
                old.innovation.jacobian_robot,
                old.innovation.jacobian_landmark,
            );
            let ja = self.first_landmark + 2 * old.landmark;
            let p_ja_r = p.block::<2, 3>(ja, 0)?;
            let p_ja_jk = p.block::<2, 2>(ja, jk)?;
            // C[a][k] = H_a P H_kᵀ, H nonzero on the robot and the landmark columns and,
            // when the range bias is estimated, on the bias' columns.
            let mut c_ak = hr_a * p_rr * hr_k.transpose()
                + hr_a * p_r_jk * hl_k.transpose()
                + hl_a * p_ja_r * hr_k.transpose()
                + hl_a * p_ja_jk * hl_k.transpose();
            if let Some(bs) = self.bias_state {
                let (hb_a, hb_k) = (old.innovation.jacobian_bias, new.innovation.jacobian_bias);
                let p_rb = p.block::<3, 2>(0, bs)?;
                let p_ja_b = p.block::<2, 2>(ja, bs)?;
                let p_b_jk = p.block::<2, 2>(bs, jk)?;
                let p_bb = p.block::<2, 2>(bs, bs)?;
                c_ak += hr_a * p_rb * hb_k.transpose()
                    + hb_a * p_rb.transpose() * hr_k.transpose()
                    + hl_a * p_ja_b * hb_k.transpose()
                    + hb_a * p_b_jk * hl_k.transpose()
                    + hb_a * p_bb * hb_k.transpose();
            }
            let row_k = self.factor.get(k)?;
            let row_a = self.factor.get(a)?;
            let mut acc = c_ak.transpose();
            for b in 0..a {
                acc -= row_k.get(b)? * row_a.get(b)?.transpose();
            }
            let l_aa_inv = lower_inverse(row_a.get(a)?)?;
            let l_ka = acc * l_aa_inv.transpose();
            *self.factor.get_mut(k)?.get_mut(a)? = l_ka;
        }
        // Diagonal block: chol(S − Σ L[k][b] L[k][b]ᵀ), and the whitened innovation.
        let row_k = self.factor.get(k)?;
        let mut schur = new.innovation.s;
        let mut nu = new.innovation.nu;
        for b in 0..k {
            let l_kb = row_k.get(b)?;
            schur -= l_kb * l_kb.transpose();
            nu -= l_kb * self.whitened.get(b)?;
        }
        let l_kk = cholesky2(&schur)?;
        let w = lower_inverse(&l_kk)? * nu;
        let nis = self.nis + w.norm_squared();
        if !nis.finite() || nis > threshold {
            return None;
        }
        *self.factor.get_mut(k)?.get_mut(k)? = l_kk;
        *self.whitened.get_mut(k)? = w;
        Some(nis)
    }
}

/// Lower Cholesky factor of a symmetric 2 × 2 matrix; `None` when not positive definite.
fn cholesky2<T: Real>(s: &Matrix2<T>) -> Option<Matrix2<T>> {
    let s00 = s[(0, 0)];
    if s00 <= T::ZERO || !s00.finite() {
        return None;
    }
    let l00 = s00.sqrt();
    let l10 = (s[(1, 0)] + s[(0, 1)]) * T::lit(0.5) / l00;
    let d = s[(1, 1)] - l10 * l10;
    if d <= T::ZERO || !d.finite() {
        return None;
    }
    Some(Matrix2::new(l00, T::ZERO, l10, d.sqrt()))
}

/// Inverse of a lower-triangular 2 × 2 matrix with a positive diagonal.
fn lower_inverse<T: Real>(l: &Matrix2<T>) -> Option<Matrix2<T>> {
    let (a, b, c) = (l[(0, 0)], l[(1, 0)], l[(1, 1)]);
    if !(a > T::ZERO && c > T::ZERO) {
        return None;
    }
    Some(Matrix2::new(T::ONE / a, T::ZERO, -b / (a * c), T::ONE / c))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::association::compatibility::Candidates;
    use crate::association::icnn::icnn;
    use crate::ekf::{EkfConfig, factor_len, state_dim};
    use crate::geometry::Pose2;
    use crate::motion::IncrementNoise;

    type Slam = EkfSlam<f64, { state_dim(8) }, { factor_len(8) }>;

    fn sighting(robot: Pose2<f64>, x: f64, y: f64) -> RangeBearing<f64> {
        let (dx, dy) = (x - robot.x, y - robot.y);
        RangeBearing::new(
            (dx * dx + dy * dy).sqrt(),
            crate::geometry::wrap_angle(dy.atan2(dx) - robot.theta),
        )
    }

    /// An empty filter whose sightings are precise (2 cm, 0.01 rad), and its settings.
    fn precise() -> (Slam, EkfConfig<f64>) {
        let mut config = EkfConfig::DEFAULT_F64;
        config.range_std = 0.02;
        config.bearing_std = 0.01;
        (Slam::new(config), config)
    }

    /// Two landmarks 0.4 m apart at 3 m, a well-known map and a robot whose heading is
    /// uncertain (σ 0.1 rad) and actually 0.13 rad off: every sighting is shifted the
    /// same way, so the sighting of A lands on B.
    fn planted() -> (Slam, [RangeBearing<f64>; 2]) {
        let (mut slam, config) = precise();
        let origin = Pose2::new(0.0, 0.0, 0.0);
        slam.add_landmark(&sighting(origin, 3.0, 0.2)).unwrap(); // A = 0
        slam.add_landmark(&sighting(origin, 3.0, -0.2)).unwrap(); // B = 1
        // Heading uncertainty without motion: a zero increment with 0.1 rad noise.
        let mut noisy = config;
        noisy.increment_noise = IncrementNoise {
            translation_std: 0.0,
            translation_std_per_metre: 0.0,
            rotation_std: 0.1,
            rotation_std_per_radian: 0.0,
            rotation_std_per_metre: 0.0,
        };
        slam.set_config(noisy).unwrap();
        slam.predict_increment(&Pose2::new(0.0, 0.0, 0.0)).unwrap();
        slam.set_config(config).unwrap();
        let truth = Pose2::new(0.0, 0.0, 0.13);
        (
            slam,
            [sighting(truth, 3.0, 0.2), sighting(truth, 3.0, -0.2)],
        )
    }

    #[test]
    fn jcbb_beats_icnn_on_a_common_heading_error() {
        let (slam, z) = planted();
        let cfg = AssociationConfig::default_gates();
        // ICNN: the sighting of A is nearest to B, and so is the sighting of B.
        assert_eq!(icnn(&slam, &z[0], &cfg), Pairing::Landmark(1));
        assert_eq!(icnn(&slam, &z[1], &cfg), Pairing::Landmark(1));
        // JCBB pairs both correctly.
        let jcbb = Jcbb::<f64, 4, 4>::new(cfg);
        let mut out = [Pairing::Invalid; 4];
        let r = jcbb.associate(&slam, &z, &mut out).unwrap();
        assert_eq!(&out[..2], &[Pairing::Landmark(0), Pairing::Landmark(1)]);
        assert_eq!(r.pairings, 2);
        assert!(!r.truncated);
        // The joint NIS is close to that of one common 0.13 rad shift (~1.7), far below
        // the sum of the individual distances it would have without the correlation.
        let d0 = slam.innovation(0, &z[0]).unwrap().mahalanobis_squared;
        let d1 = slam.innovation(1, &z[1]).unwrap().mahalanobis_squared;
        assert!(
            r.joint_nis < 0.7 * (d0 + d1),
            "{} vs {}",
            r.joint_nis,
            d0 + d1
        );
    }

    /// The joint NIS JCBB reports for pairing sighting `i` with landmark `i` (i = 0, 1)
    /// against `νᵀ C⁻¹ ν` with a dense `C = H P Hᵀ + R` over the whole active state.
    fn assert_joint_nis_is_dense(slam: &Slam, z: &[RangeBearing<f64>; 2]) {
        let jcbb = Jcbb::<f64, 4, 4>::new(AssociationConfig::default_gates());
        let mut out = [Pairing::Invalid; 2];
        let r = jcbb.associate(slam, z, &mut out).unwrap();
        assert_eq!(out, [Pairing::Landmark(0), Pairing::Landmark(1)]);
        let k = slam.active_dim();
        let cov = slam.active_covariance();
        let p = nalgebra::DMatrix::from_fn(k, k, |i, j| cov.get(i, j).unwrap());
        let mut h = nalgebra::DMatrix::<f64>::zeros(4, k);
        let mut nu = nalgebra::DVector::<f64>::zeros(4);
        for (s, lm) in [(0usize, 0usize), (1, 1)] {
            let inn = slam.innovation(lm, &z[s]).unwrap();
            let lj = slam.landmark_state(lm);
            for r in 0..2 {
                for c in 0..3 {
                    h[(2 * s + r, c)] = inn.jacobian_robot[(r, c)];
                }
                for c in 0..2 {
                    h[(2 * s + r, lj + c)] = inn.jacobian_landmark[(r, c)];
                    if let Some(bj) = slam.range_bias_state() {
                        h[(2 * s + r, bj + c)] = inn.jacobian_bias[(r, c)];
                    }
                }
                nu[2 * s + r] = inn.nu[r];
            }
        }
        let mut c = &h * &p * h.transpose();
        let rm = slam.config().measurement_covariance();
        for s in 0..2 {
            for i in 0..2 {
                for j in 0..2 {
                    c[(2 * s + i, 2 * s + j)] += rm[(i, j)];
                }
            }
        }
        let dense = (nu.transpose() * c.try_inverse().unwrap() * &nu)[(0, 0)];
        assert!(
            (r.joint_nis - dense).abs() < 1e-9 * dense.max(1.0),
            "{} vs {dense}",
            r.joint_nis
        );
    }

    #[test]
    fn joint_nis_matches_a_dense_computation() {
        let (slam, z) = planted();
        assert_joint_nis_is_dense(&slam, &z);
    }

    #[test]
    fn joint_nis_matches_a_dense_computation_with_the_calibration_states() {
        // The planted map, with the odometry scale and the range bias estimated: the two
        // sightings are also correlated through the bias' states.
        let (mut slam, config) = precise();
        slam.estimate_odometry_scale(0.05, 0.05).unwrap();
        slam.estimate_range_bias(0.2, 2.0).unwrap();
        let origin = Pose2::new(0.0, 0.0, 0.0);
        slam.add_landmark(&sighting(origin, 3.0, 0.2)).unwrap();
        slam.add_landmark(&sighting(origin, 3.0, -0.2)).unwrap();
        let mut noisy = config;
        noisy.increment_noise.rotation_std = 0.05;
        slam.set_config(noisy).unwrap();
        slam.predict_increment(&Pose2::new(0.0, 0.0, 0.0)).unwrap();
        slam.set_config(config).unwrap();
        assert_eq!(slam.range_bias_state(), Some(5));
        let truth = Pose2::new(0.02, -0.01, 0.03);
        let z = [sighting(truth, 3.0, 0.2), sighting(truth, 3.0, -0.2)];
        assert_joint_nis_is_dense(&slam, &z);
    }

    #[test]
    fn unpaired_sightings_become_new_or_ambiguous() {
        let (slam, z) = planted();
        let cfg = AssociationConfig::default_gates();
        let jcbb = Jcbb::<f64, 4, 4>::new(cfg);
        let far = RangeBearing::new(4.0, 2.5);
        let batch = [z[0], far, RangeBearing::new(-1.0, 0.0), z[1]];
        let mut out = [Pairing::Invalid; 4];
        jcbb.associate(&slam, &batch, &mut out).unwrap();
        assert_eq!(
            out,
            [
                Pairing::Landmark(0),
                Pairing::New,
                Pairing::Invalid,
                Pairing::Landmark(1)
            ]
        );
        // Too many sightings: refused, nothing written.
        let mut small = [Pairing::Ambiguous; 4];
        let five = [z[0]; 5];
        assert_eq!(
            jcbb.associate(&slam, &five, &mut small),
            Err(BatchTooLarge {
                sightings: 5,
                capacity: 4
            })
        );
        assert_eq!(small, [Pairing::Ambiguous; 4]);
        // An empty filter: everything is new.
        let empty = Slam::new(EkfConfig::DEFAULT_F64);
        let r = jcbb.associate(&empty, &z, &mut out).unwrap();
        assert_eq!(&out[..2], &[Pairing::New, Pairing::New]);
        assert_eq!(r.pairings, 0);
    }

    /// One frame sees a landmark of the map and, 0.1 m beside it, one the map lacks: at
    /// 3 m, with 1 cm / 0.01 rad sightings, both sightings are individually compatible
    /// with the landmark.
    #[test]
    fn a_second_sighting_near_a_taken_landmark_is_new_when_distinct_in_batch() {
        let (mut slam, _) = precise();
        let origin = Pose2::new(0.0, 0.0, 0.0);
        slam.add_landmark(&sighting(origin, 3.0, 0.0)).unwrap(); // A = 0
        slam.add_landmark(&sighting(origin, 0.0, 3.0)).unwrap(); // far away
        let (a, beside) = (sighting(origin, 3.0, 0.0), sighting(origin, 3.0, 0.1));
        let mut cfg = AssociationConfig::default_gates();
        let near = Candidates::<f64, 4>::of(&slam, &beside, &cfg.individual_gate);
        assert_eq!(near.nearest.len(), 1);
        assert_eq!(near.nearest.first().map(|c| c.landmark), Some(0));
        let pair = |slam: &Slam, cfg: AssociationConfig<f64>, batch: &[RangeBearing<f64>]| {
            let mut out = [Pairing::Invalid; 2];
            Jcbb::<f64, 4, 4>::new(cfg)
                .associate(slam, batch, &mut out)
                .unwrap();
            out
        };
        assert_eq!(
            pair(&slam, cfg, &[a, beside]),
            [Pairing::Landmark(0), Pairing::Ambiguous]
        );
        cfg.distinct_in_batch = true;
        assert_eq!(
            pair(&slam, cfg, &[a, beside]),
            [Pairing::Landmark(0), Pairing::New]
        );
        // Alone in its batch, the sighting pairs with A, which nothing else takes.
        assert_eq!(pair(&slam, cfg, &[beside])[0], Pairing::Landmark(0));
        // A landmark outside the individual gate of `beside` but inside its new-landmark
        // quantile, which no sighting of the batch takes: ambiguous again.
        slam.add_landmark(&sighting(origin, 3.0, 0.247)).unwrap();
        let c = Candidates::<f64, 4>::of(&slam, &beside, &cfg.individual_gate);
        assert_eq!(c.nearest.len(), 1);
        assert_eq!(
            pair(&slam, cfg, &[a, beside]),
            [Pairing::Landmark(0), Pairing::Ambiguous]
        );
    }

    #[test]
    fn near_tie_between_hypotheses_is_ambiguous() {
        // One sighting half-way between A and B: two one-pairing hypotheses, nearly tied.
        let (slam, _) = planted();
        let z = [sighting(Pose2::new(0.0, 0.0, 0.0), 3.0, 0.0)];
        let mut cfg = AssociationConfig::default_gates();
        let mut out = [Pairing::Invalid; 1];
        Jcbb::<f64, 4, 4>::new(cfg)
            .associate(&slam, &z, &mut out)
            .unwrap();
        assert!(matches!(out[0], Pairing::Landmark(_)));
        cfg.ambiguity_margin = 1.0;
        Jcbb::<f64, 4, 4>::new(cfg)
            .associate(&slam, &z, &mut out)
            .unwrap();
        assert_eq!(out[0], Pairing::Ambiguous);
        // The planted batch stays unambiguous: the swapped pairing is not jointly
        // compatible.
        let (slam, z) = planted();
        let mut out = [Pairing::Invalid; 2];
        Jcbb::<f64, 4, 4>::new(cfg)
            .associate(&slam, &z, &mut out)
            .unwrap();
        assert_eq!(out, [Pairing::Landmark(0), Pairing::Landmark(1)]);
    }

    #[test]
    fn search_bound_is_respected() {
        let (slam, z) = planted();
        let mut cfg = AssociationConfig::default_gates();
        cfg.max_search_nodes = 2;
        let jcbb = Jcbb::<f64, 4, 4>::new(cfg);
        let mut out = [Pairing::Invalid; 2];
        let r = jcbb.associate(&slam, &z, &mut out).unwrap();
        assert!(r.truncated);
        assert_eq!(r.nodes, 2);
    }

    #[test]
    fn works_in_f32() {
        let (slam64, z64) = planted();
        let mut config = EkfConfig::DEFAULT_F32;
        config.range_std = 0.02;
        config.bearing_std = 0.01;
        let mut slam = EkfSlam::<f32, { state_dim(8) }, { factor_len(8) }>::new(config);
        // Same state as the f64 filter, built the same way.
        let origin = Pose2::new(0.0f32, 0.0, 0.0);
        let to32 = |z: &RangeBearing<f64>| RangeBearing::new(z.range as f32, z.bearing as f32);
        let _ = origin;
        slam.add_landmark(&to32(&sighting(Pose2::new(0.0, 0.0, 0.0), 3.0, 0.2)))
            .unwrap();
        slam.add_landmark(&to32(&sighting(Pose2::new(0.0, 0.0, 0.0), 3.0, -0.2)))
            .unwrap();
        let mut noisy = config;
        noisy.increment_noise.rotation_std = 0.1;
        noisy.increment_noise.translation_std_per_metre = 0.0;
        noisy.increment_noise.rotation_std_per_radian = 0.0;
        noisy.increment_noise.rotation_std_per_metre = 0.0;
        slam.set_config(noisy).unwrap();
        slam.predict_increment(&Pose2::new(0.0, 0.0, 0.0)).unwrap();
        let jcbb = Jcbb::<f32, 4, 4>::new(AssociationConfig::default_gates());
        let mut out = [Pairing::Invalid; 2];
        let z = [to32(&z64[0]), to32(&z64[1])];
        let r = jcbb.associate(&slam, &z, &mut out).unwrap();
        assert_eq!(out, [Pairing::Landmark(0), Pairing::Landmark(1)]);
        let r64 = Jcbb::<f64, 4, 4>::new(AssociationConfig::default_gates())
            .associate(&slam64, &z64, &mut [Pairing::Invalid; 2])
            .unwrap();
        assert!((f64::from(r.joint_nis) - r64.joint_nis).abs() < 1e-3);
    }
}
