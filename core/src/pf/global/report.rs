//! What a search did ([`SearchReport`]) and why a search was refused ([`GlobalError`]).

#[cfg(doc)]
use super::{GlobalSearchConfig, NODE_WORK};
use core::fmt;

/// What one search did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SearchReport {
    /// Beams used.
    pub beams: u16,
    /// Farthest beam used, metres.
    pub extent_m: f32,
    /// Heading step, radians.
    pub heading_step: f32,
    /// Candidate headings over the full turn.
    pub headings: u32,
    /// Heading windows searched (1: every heading).
    pub heading_windows: u8,
    /// Candidate headings inside the windows.
    pub headings_searched: u32,
    /// Node evaluations: bounds and leaf scores (each one pass over the beams, stopped
    /// at the beam that rules the node out).
    pub nodes: u32,
    /// Work done, the unit of [`GlobalSearchConfig::work_budget`]: the beams the node
    /// evaluations looked at, plus [`NODE_WORK`] per node evaluation.
    pub work: u32,
    /// Of those, leaf scores.
    pub leaves: u32,
    /// End-cell computations (one rotation of every beam each).
    pub rotations: u32,
    /// Node evaluations per level (index k: blocks of `2^k × 2^k` positions).
    pub nodes_per_level: [u32; crate::grid::layers::MAX_LEVELS as usize + 1],
    /// Total weight of the beams used (the score of a perfect match).
    pub total_weight: u32,
    /// Score a hypothesis needs (the lowest of the passes' minimum scores).
    pub min_score: u32,
    /// Passes run (see [`GlobalSearchConfig::first_pass_fraction`]).
    pub passes: u8,
    /// `true` when the headings outside the windows were searched too (the windows had
    /// found no hypothesis scoring [`GlobalSearchConfig::full_turn_below`] by then).
    pub full_turn: bool,
    /// `false` when the work budget stopped the search: the hypotheses are the best
    /// found, not proven best.
    pub complete: bool,
}

impl SearchReport {
    /// Estimated Cortex-M4F instructions of the search: 60 a unit of work
    /// ([`SearchReport::work`]), a little above what the budget-stopped relocalization
    /// scan under QEMU costs a unit with its fixed costs (`cost_relocalize`, every minimum
    /// score at 0 so that no node is pruned by score: 47.5 M for 830 000 units with 30
    /// beams, 49.3 M with 45); see `docs/global-localization.md`.
    pub fn estimated_instructions(&self) -> u64 {
        u64::from(self.work) * 60
    }
}

/// Why a search was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GlobalError {
    /// A setting is out of range or not finite.
    InvalidConfig,
    /// No beam of the scan is usable within the search's range.
    EmptyScan,
    /// The max-pooled layers were made for another map (size or threshold).
    LayersMismatch,
    /// The localizer has no max-pooled layers: it cannot search globally.
    NoLayers,
}

impl fmt::Display for GlobalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidConfig => "global search setting out of range",
            Self::EmptyScan => "scan has no usable beam for the global search",
            Self::LayersMismatch => "max-pool layers do not belong to this map",
            Self::NoLayers => "no max-pool layers: global localization is not available",
        })
    }
}

impl core::error::Error for GlobalError {}
