//! What the perception front end called each landmark, and whether a new sighting's
//! label agrees with the landmark the geometry chose.
//!
//! As in El Masri El Chaarani et al. (n.d., §III-C): the front end's class or id is
//! checked against the data association; when they disagree the association wins and the
//! disagreement is counted.
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The misclassified sign corrected by the
//!   association, §III-C.

use crate::event::Identity;
use heapless::Vec;

/// How a sighting's label compares with the landmark the association chose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LabelCheck {
    /// Same label: perception and geometry agree.
    Agrees,
    /// Different labels: the geometry's choice is kept (the label is overridden).
    Overridden,
    /// The sighting or the landmark has no label to compare.
    Unlabelled,
}

/// The label of each of up to `L` landmarks, by landmark index.
#[derive(Clone, Debug, Default)]
pub struct LandmarkLabels<const L: usize> {
    labels: Vec<Identity, L>,
}

impl<const L: usize> LandmarkLabels<L> {
    /// No labels.
    pub const fn new() -> Self {
        Self { labels: Vec::new() }
    }

    /// Records the label of landmark `index` (the first sighting's label, normally).
    /// Indices beyond the capacity are ignored; gaps are filled with
    /// [`Identity::Unknown`].
    pub fn set(&mut self, index: usize, label: Identity) {
        while self.labels.len() <= index {
            if self.labels.push(Identity::Unknown).is_err() {
                return;
            }
        }
        if let Some(slot) = self.labels.get_mut(index) {
            *slot = label;
        }
    }

    /// The label of landmark `index`.
    pub fn get(&self, index: usize) -> Identity {
        self.labels.get(index).copied().unwrap_or(Identity::Unknown)
    }

    /// Compares a sighting's label with that of the landmark the association chose.
    pub fn check(&self, index: usize, sighting: Identity) -> LabelCheck {
        match (self.get(index), sighting) {
            (Identity::Unknown, _) | (_, Identity::Unknown) => LabelCheck::Unlabelled,
            (a, b) if a == b => LabelCheck::Agrees,
            _ => LabelCheck::Overridden,
        }
    }

    /// Forgets every label.
    pub fn clear(&mut self) {
        self.labels.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::association::{AssociationConfig, Pairing, icnn};
    use crate::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
    use crate::sensors::range_bearing::RangeBearing;

    #[test]
    fn geometry_overrides_a_wrong_class() {
        let mut slam =
            EkfSlam::<f64, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F64);
        let mut labels = LandmarkLabels::<4>::new();
        let stop = slam.add_landmark(&RangeBearing::new(2.0, 0.5)).unwrap();
        labels.set(stop, Identity::Class(1)); // "stop"
        let yield_sign = slam.add_landmark(&RangeBearing::new(3.0, -0.5)).unwrap();
        labels.set(yield_sign, Identity::Class(2)); // "yield"
        // The front end says "yield" for a sighting where the stop sign stands.
        let z = RangeBearing::new(2.02, 0.49);
        let pairing = icnn(&slam, &z, &AssociationConfig::default_gates());
        assert_eq!(pairing, Pairing::Landmark(stop));
        assert_eq!(
            labels.check(stop, Identity::Class(2)),
            LabelCheck::Overridden
        );
        assert_eq!(labels.check(stop, Identity::Class(1)), LabelCheck::Agrees);
        assert_eq!(
            labels.check(stop, Identity::Unknown),
            LabelCheck::Unlabelled
        );
        assert_eq!(labels.check(3, Identity::Class(1)), LabelCheck::Unlabelled);
        // Capacity is respected.
        labels.set(10, Identity::Class(9));
        assert_eq!(labels.get(10), Identity::Unknown);
    }
}
