//! Individual compatibility of a sighting with the landmarks in the filter, and the
//! shared settings of the geometric associations ([`super::icnn()`], [`super::jcbb`]).

use crate::ekf::{EkfSlam, Innovation};
use crate::gate::{ChiSquareGate, chi_square_quantile};
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use heapless::Vec;

/// Settings of geometric data association.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AssociationConfig<T> {
    /// Individual compatibility: a sighting may pair with a landmark when the squared
    /// Mahalanobis distance of its innovation passes this gate (2 degrees of freedom).
    pub individual_gate: ChiSquareGate<T>,
    /// A sighting that pairs with nothing becomes a new landmark only when it is farther
    /// than this from *every* landmark (squared Mahalanobis distance); in between it is
    /// ambiguous and dropped. Set it equal to the individual gate to always add.
    pub new_landmark_threshold: T,
    /// Probability of the joint compatibility gate of JCBB: a hypothesis with `k`
    /// pairings is accepted when its joint NIS is below the χ²(2k) quantile of this.
    pub joint_probability: f64,
    /// Bound on the hypotheses JCBB visits for one batch; past it, the best hypothesis
    /// found so far is used (and the outcome says the search was cut).
    pub max_search_nodes: u32,
    /// Ambiguity rejection: when the runner-up pairing (ICNN: the second-nearest
    /// compatible landmark; JCBB: the second-best hypothesis with as many pairings) is
    /// within this much squared Mahalanobis distance of the best, the sightings on which
    /// they differ are [`Pairing::Ambiguous`] and dropped rather than risk a wrong update.
    /// `0` disables it.
    pub ambiguity_margin: T,
    /// The sightings of one JCBB batch are of distinct landmarks (one camera frame sees
    /// each landmark at most once): an unpaired sighting whose every landmark within
    /// [`new_landmark_threshold`](Self::new_landmark_threshold) is paired with *another*
    /// sighting of the batch is then [`Pairing::New`] instead of ambiguous — the frame
    /// saw two things where the map holds one. Off, such a sighting is dropped and a
    /// landmark standing close to another is never added. ICNN ignores it.
    pub distinct_in_batch: bool,
}

impl<T: Real> AssociationConfig<T> {
    /// 99 % individual and joint gates, new landmarks beyond the 99.99 % quantile,
    /// at most 10 000 JCBB nodes, no ambiguity margin, sightings of a batch not assumed
    /// distinct.
    pub fn default_gates() -> Self {
        Self {
            individual_gate: ChiSquareGate::from_threshold(T::lit(chi_square_quantile(0.99, 2))),
            new_landmark_threshold: T::lit(chi_square_quantile(0.9999, 2)),
            joint_probability: 0.99,
            max_search_nodes: 10_000,
            ambiguity_margin: T::ZERO,
            distinct_in_batch: false,
        }
    }

    /// `true` when the gates are positive and ordered and the probability inside (0, 1).
    pub fn is_valid(&self) -> bool {
        self.individual_gate.threshold > T::ZERO
            && self.new_landmark_threshold >= self.individual_gate.threshold
            && self.joint_probability > 0.0
            && self.joint_probability < 1.0
            && self.ambiguity_margin >= T::ZERO
    }
}

/// A landmark a sighting is individually compatible with, and its innovation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate<T: Real> {
    /// Landmark index in the filter.
    pub landmark: usize,
    /// Innovation of the sighting against that landmark.
    pub innovation: Innovation<T>,
}

/// The individually compatible landmarks of one sighting, nearest first, at most `K`.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidates<T: Real, const K: usize> {
    /// Compatible landmarks sorted by squared Mahalanobis distance (the `K` nearest).
    pub nearest: Vec<Candidate<T>, K>,
    /// Smallest squared Mahalanobis distance to any landmark, compatible or not
    /// (`None` when the filter has no landmark the sighting can be compared with).
    pub min_distance_squared: Option<T>,
}

impl<T: Real, const K: usize> Default for Candidates<T, K> {
    fn default() -> Self {
        Self {
            nearest: Vec::new(),
            min_distance_squared: None,
        }
    }
}

impl<T: Real, const K: usize> Candidates<T, K> {
    /// Compares sighting `z` with every landmark of `slam` (O(n) 2 × 2 innovations).
    ///
    /// Landmarks the sighting cannot be compared with (on the sensor, singular
    /// innovation) are skipped. An invalid sighting (NaN, non-positive range) has no
    /// candidates.
    pub fn of<const N: usize, const P: usize>(
        slam: &EkfSlam<T, N, P>,
        z: &RangeBearing<T>,
        gate: &ChiSquareGate<T>,
    ) -> Self {
        let mut out = Self::default();
        if !z.is_valid() {
            return out;
        }
        for landmark in 0..slam.landmark_count() {
            let Ok(innovation) = slam.innovation(landmark, z) else {
                continue;
            };
            let d2 = innovation.mahalanobis_squared;
            out.min_distance_squared = Some(match out.min_distance_squared {
                Some(m) if m <= d2 => m,
                _ => d2,
            });
            if !gate.accepts(d2) {
                continue;
            }
            let candidate = Candidate {
                landmark,
                innovation,
            };
            // Insertion into the sorted list; the farthest falls off when full.
            let pos = out
                .nearest
                .iter()
                .position(|c| c.innovation.mahalanobis_squared > d2)
                .unwrap_or(out.nearest.len());
            if pos >= K {
                continue;
            }
            if out.nearest.is_full() {
                out.nearest.pop();
            }
            // Cannot fail: there is room and `pos` ≤ len.
            let _ = out.nearest.insert(pos, candidate);
        }
        out
    }

    /// The nearest compatible landmark, if any.
    pub fn best(&self) -> Option<&Candidate<T>> {
        self.nearest.first()
    }

    /// `true` when the second-nearest compatible landmark is within `margin` (squared
    /// Mahalanobis distance) of the nearest.
    pub fn is_ambiguous(&self, margin: T) -> bool {
        match (self.nearest.first(), self.nearest.get(1)) {
            (Some(a), Some(b)) => {
                b.innovation.mahalanobis_squared - a.innovation.mahalanobis_squared < margin
            }
            _ => false,
        }
    }

    /// What to do with the sighting when it pairs with no landmark: a new landmark when
    /// it is far from all of them, otherwise ambiguous.
    pub fn unpaired_decision(&self, config: &AssociationConfig<T>) -> Pairing {
        match self.min_distance_squared {
            Some(d2) if d2 <= config.new_landmark_threshold => Pairing::Ambiguous,
            _ => Pairing::New,
        }
    }
}

/// What the association decided for one sighting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pairing {
    /// The sighting is of this landmark (index in the filter).
    Landmark(usize),
    /// The sighting is of a landmark not yet in the filter: add it.
    New,
    /// Neither clearly a known landmark nor clearly a new one: drop it.
    Ambiguous,
    /// The sighting itself is invalid (NaN, non-positive range): drop it.
    Invalid,
}
