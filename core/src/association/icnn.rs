//! Individual compatibility nearest neighbour (El Masri El Chaarani et al. n.d., Fig. 11).
//!
//! Each sighting is compared with every landmark on its own: the nearest landmark by
//! Mahalanobis distance among those that pass the individual χ² gate is its pairing; with
//! none compatible it is a new landmark (or, between the gate and
//! [`AssociationConfig::new_landmark_threshold`], ambiguous and dropped). Sightings are
//! decided one at a time, so two sightings of one batch may pick the same landmark: that
//! is the weakness [`super::jcbb`] removes. With an
//! [`AssociationConfig::ambiguity_margin`], a sighting whose two nearest compatible
//! landmarks are about as near is dropped as ambiguous.
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The association, Fig. 11.

use super::compatibility::{AssociationConfig, Candidates, Pairing};
use crate::ekf::EkfSlam;
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;

/// ICNN for one sighting `z` against the landmarks of `slam`. O(n); no state change.
pub fn icnn<T: Real, const N: usize, const P: usize>(
    slam: &EkfSlam<T, N, P>,
    z: &RangeBearing<T>,
    config: &AssociationConfig<T>,
) -> Pairing {
    if !z.is_valid() {
        return Pairing::Invalid;
    }
    let candidates = Candidates::<T, 2>::of(slam, z, &config.individual_gate);
    match candidates.best() {
        Some(_) if candidates.is_ambiguous(config.ambiguity_margin) => Pairing::Ambiguous,
        Some(c) => Pairing::Landmark(c.landmark),
        None => candidates.unpaired_decision(config),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::{EkfConfig, factor_len, state_dim};

    fn cfg() -> AssociationConfig<f64> {
        AssociationConfig::default_gates()
    }

    #[test]
    fn nearest_compatible_new_and_ambiguous() {
        let mut slam =
            EkfSlam::<f64, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F64);
        // Landmarks at (2, 0) and (2, 1).
        slam.add_landmark(&RangeBearing::new(2.0, 0.0)).unwrap();
        slam.add_landmark(&RangeBearing::new(5f64.sqrt(), 0.5f64.atan()))
            .unwrap();
        // A sighting at (2, 0.05): landmark 0.
        let z = RangeBearing::new((4.0f64 + 0.0025).sqrt(), 0.025f64.atan());
        assert_eq!(icnn(&slam, &z, &cfg()), Pairing::Landmark(0));
        // Near (2, 0.95): landmark 1.
        let z = RangeBearing::new((4.0f64 + 0.9025).sqrt(), (0.95f64 / 2.0).atan());
        assert_eq!(icnn(&slam, &z, &cfg()), Pairing::Landmark(1));
        // Far behind the robot: new.
        assert_eq!(
            icnn(&slam, &RangeBearing::new(3.0, 3.0), &cfg()),
            Pairing::New
        );
        // Just outside the gate of landmark 0 but inside the new-landmark threshold.
        let mut c = cfg();
        let z = RangeBearing::new(2.35, 0.0);
        let d2 = slam.innovation(0, &z).unwrap().mahalanobis_squared;
        c.individual_gate.threshold = d2 * 0.9;
        c.new_landmark_threshold = d2 * 1.1;
        assert_eq!(icnn(&slam, &z, &c), Pairing::Ambiguous);
        c.new_landmark_threshold = d2 * 0.95;
        assert_eq!(icnn(&slam, &z, &c), Pairing::New);
        assert_eq!(
            icnn(&slam, &RangeBearing::new(f64::NAN, 0.0), &cfg()),
            Pairing::Invalid
        );
        // Half-way between the two landmarks: the nearest wins without a margin, and the
        // sighting is ambiguous with one.
        let z = RangeBearing::new((4.0f64 + 0.25).sqrt(), (0.5f64 / 2.0).atan());
        let mut c = cfg();
        c.individual_gate.threshold = 1e3;
        c.new_landmark_threshold = 1e3;
        assert!(matches!(icnn(&slam, &z, &c), Pairing::Landmark(_)));
        let d0 = slam.innovation(0, &z).unwrap().mahalanobis_squared;
        let d1 = slam.innovation(1, &z).unwrap().mahalanobis_squared;
        let gap = (d0 - d1).abs();
        assert!(gap > 1.0 && gap < 10.0, "{d0} {d1}");
        c.ambiguity_margin = gap * 0.9;
        assert!(matches!(icnn(&slam, &z, &c), Pairing::Landmark(_)));
        c.ambiguity_margin = gap * 1.1;
        assert_eq!(icnn(&slam, &z, &c), Pairing::Ambiguous);
    }
}
