//! Data association: which landmark in the state a sighting belongs to.
//!
//! - [`KnownIds`]: the sighting carries an identity (traffic-sign class, marker id,
//!   barcode); a fixed-capacity table maps it to a landmark slot (seed 1's class-id
//!   dictionary).

mod known_ids;

pub use known_ids::{KnownIds, Observed, observe_known};
