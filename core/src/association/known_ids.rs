//! Known-identity association: a fixed-capacity table from external ids to state slots.

use crate::ekf::health::Supervisor;
use crate::ekf::{EkfSlam, UpdateOutcome};
use crate::error::{EkfError, MapFull};
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use heapless::Vec;

/// A table from an external landmark id (traffic-sign class, ArUco marker, barcode) to
/// the index of its landmark in the filter, with room for `L` ids.
///
/// `const fn new`, no allocation; lookups are a linear scan, which for the few dozen
/// landmarks a microcontroller holds is faster than hashing.
#[derive(Clone, Debug, Default)]
pub struct KnownIds<const L: usize> {
    entries: Vec<(u32, u16), L>,
}

impl<const L: usize> KnownIds<L> {
    /// An empty table.
    pub const fn new() -> Self {
        Self {
            entries: Vec::new(),
        }
    }

    /// The landmark index of `id`, if it has one.
    pub fn get(&self, id: u32) -> Option<usize> {
        self.entries
            .iter()
            .find(|(i, _)| *i == id)
            .map(|(_, s)| usize::from(*s))
    }

    /// The id bound to landmark `index`, if any.
    pub fn id_of(&self, index: usize) -> Option<u32> {
        self.entries
            .iter()
            .find(|(_, s)| usize::from(*s) == index)
            .map(|(i, _)| *i)
    }

    /// Binds `id` to landmark `index`. A full table hands the id back in
    /// `Err(MapFull(id))`; an id already present is rebound.
    pub fn insert(&mut self, id: u32, index: usize) -> Result<(), MapFull<u32>> {
        let slot = u16::try_from(index).map_err(|_| MapFull(id))?;
        if let Some(e) = self.entries.iter_mut().find(|(i, _)| *i == id) {
            e.1 = slot;
            return Ok(());
        }
        self.entries.push((id, slot)).map_err(|(id, _)| MapFull(id))
    }

    /// Number of ids in the table.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// `true` when no id has been seen.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Forgets every id.
    pub fn clear(&mut self) {
        self.entries.clear();
    }

    /// `(id, landmark index)` pairs in insertion order.
    pub fn iter(&self) -> impl Iterator<Item = (u32, usize)> + '_ {
        self.entries.iter().map(|(i, s)| (*i, usize::from(*s)))
    }
}

/// What happened to a sighting with a known id.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Observed<T> {
    /// The id was known: its landmark was updated (or the sighting gated).
    Updated {
        /// Landmark index.
        index: usize,
        /// Result of the update.
        outcome: UpdateOutcome<T>,
    },
    /// The id was new: a landmark was added at this index.
    Added {
        /// Landmark index.
        index: usize,
    },
}

/// The main loop of El Masri El Chaarani et al. (n.d., §II-A) for one sighting with a
/// known id: update the landmark bound to `id`, or add a new landmark and bind the id to
/// it.
///
/// When the filter or the table is full, the sighting is dropped with
/// [`EkfError::MapFull`]; the filter goes on with the landmarks it has.
pub fn observe_known<T: Real, const N: usize, const P: usize, const L: usize>(
    slam: &mut EkfSlam<T, N, P>,
    ids: &mut KnownIds<L>,
    id: u32,
    z: &RangeBearing<T>,
) -> Result<Observed<T>, EkfError> {
    if let Some(index) = ids.get(id) {
        let outcome = slam.update(index, z)?;
        return Ok(Observed::Updated { index, outcome });
    }
    add_known(slam, ids, id, z)
}

/// [`observe_known`] with the update run by `supervisor`: large innovations weighted
/// down, a lost filter recovered (see [`crate::ekf::health`]).
pub fn observe_known_supervised<T: Real, const N: usize, const P: usize, const L: usize>(
    slam: &mut EkfSlam<T, N, P>,
    ids: &mut KnownIds<L>,
    id: u32,
    z: &RangeBearing<T>,
    supervisor: &mut Supervisor<T>,
) -> Result<Observed<T>, EkfError> {
    if let Some(index) = ids.get(id) {
        let outcome = supervisor.update(slam, index, z)?;
        return Ok(Observed::Updated { index, outcome });
    }
    add_known(slam, ids, id, z)
}

/// Adds a landmark for the new `id` and binds the id to it.
fn add_known<T: Real, const N: usize, const P: usize, const L: usize>(
    slam: &mut EkfSlam<T, N, P>,
    ids: &mut KnownIds<L>,
    id: u32,
    z: &RangeBearing<T>,
) -> Result<Observed<T>, EkfError> {
    if ids.len() >= L {
        return Err(EkfError::MapFull);
    }
    let index = slam.add_landmark(z)?;
    // Cannot fail: the length was checked above.
    ids.insert(id, index).map_err(|_| EkfError::MapFull)?;
    Ok(Observed::Added { index })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::{EkfConfig, factor_len, state_dim};

    #[test]
    fn table_hands_back_ids_when_full() {
        let mut t = KnownIds::<2>::new();
        assert_eq!(t.insert(7, 0), Ok(()));
        assert_eq!(t.insert(9, 1), Ok(()));
        assert_eq!(t.insert(11, 2), Err(MapFull(11)));
        assert_eq!(t.insert(7, 1), Ok(()), "rebinding needs no room");
        assert_eq!(t.get(7), Some(1));
        assert_eq!(t.id_of(1), Some(7));
        assert_eq!(t.get(11), None);
    }

    #[test]
    fn full_filter_drops_new_ids_and_keeps_going() {
        let mut slam =
            EkfSlam::<f64, { state_dim(2) }, { factor_len(2) }>::new(EkfConfig::DEFAULT_F64);
        let mut ids = KnownIds::<4>::new();
        let z = RangeBearing::new(2.0, 0.3);
        assert_eq!(
            observe_known(&mut slam, &mut ids, 10, &z),
            Ok(Observed::Added { index: 0 })
        );
        let z2 = RangeBearing::new(3.0, -0.3);
        assert_eq!(
            observe_known(&mut slam, &mut ids, 20, &z2),
            Ok(Observed::Added { index: 1 })
        );
        let before = slam.active_mean().to_vec();
        assert_eq!(
            observe_known(&mut slam, &mut ids, 30, &RangeBearing::new(1.0, 0.0)),
            Err(EkfError::MapFull)
        );
        assert_eq!(slam.active_mean(), &before[..]);
        assert_eq!(ids.get(30), None);
        // Known ids are still updated.
        let r = observe_known(&mut slam, &mut ids, 10, &z).unwrap();
        assert!(matches!(
            r,
            Observed::Updated {
                index: 0,
                outcome: UpdateOutcome::Accepted { .. }
            }
        ));
    }
}
