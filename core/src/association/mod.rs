//! Data association: which landmark in the state a sighting belongs to.
//!
//! - [`KnownIds`]: the sighting carries an identity (traffic-sign class, marker id,
//!   barcode); a fixed-capacity table maps it to a landmark slot (the class-id dictionary
//!   of El Masri El Chaarani et al. n.d., §II-A).
//! - [`icnn()`]: individual compatibility nearest neighbour (El Masri El Chaarani et al.
//!   n.d., Fig. 11), one sighting at a time.
//! - [`Jcbb`]: joint compatibility branch and bound (Neira & Tardós 2001) over a batch of
//!   simultaneous sightings.
//! - [`LandmarkLabels`]: what perception called each landmark; a label that disagrees
//!   with the geometric association is overridden by it (El Masri El Chaarani et al.
//!   n.d., §III-C).
//!
//! Geometric association never changes the filter: it returns a [`Pairing`] per sighting
//! for the caller to apply with [`crate::ekf::EkfSlam::update`] or
//! [`crate::ekf::EkfSlam::add_landmark`].
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The class-id dictionary (§II-A), ICNN (Fig.
//!   11), the label overridden by the association (§III-C).

mod compatibility;
mod icnn;
mod jcbb;
mod known_ids;
mod labels;

pub use compatibility::{AssociationConfig, Candidate, Candidates, Pairing};
pub use icnn::icnn;
pub use jcbb::{BatchTooLarge, Jcbb, JcbbOutcome};
pub use known_ids::{KnownIds, Observed, observe_known, observe_known_supervised};
pub use labels::{LabelCheck, LandmarkLabels};
