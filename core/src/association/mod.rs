//! Data association: which landmark in the state a sighting belongs to.
//!
//! - [`KnownIds`]: the sighting carries an identity (traffic-sign class, marker id,
//!   barcode); a fixed-capacity table maps it to a landmark slot (seed 1's class-id
//!   dictionary).
//! - [`icnn()`]: individual compatibility nearest neighbour (seed 1, Fig. 11), one sighting
//!   at a time.
//! - [`Jcbb`]: joint compatibility branch and bound (Neira & Tardós 2001) over a batch of
//!   simultaneous sightings.
//! - [`LandmarkLabels`]: what perception called each landmark; a label that disagrees
//!   with the geometric association is overridden by it (seed 1 §III-C).
//!
//! Geometric association never changes the filter: it returns a [`Pairing`] per sighting
//! for the caller to apply with [`crate::ekf::EkfSlam::update`] or
//! [`crate::ekf::EkfSlam::add_landmark`].

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
