//! What the filter reports: what an update did with a sighting ([`UpdateOutcome`]), how many
//! steps it applied, gated or refused ([`EkfCounters`]), and the innovation of a sighting
//! against a landmark ([`Innovation`]).

use crate::scalar::Real;
use nalgebra::{Matrix2, Matrix2x3, Vector2};

/// What [`EkfSlam::update`](super::EkfSlam::update) did with a sighting.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UpdateOutcome<T> {
    /// The sighting passed the gate and corrected the state; the normalised innovation
    /// squared (NIS, `νᵀ S⁻¹ ν`) is reported.
    Accepted {
        /// Normalised innovation squared.
        nis: T,
    },
    /// The sighting failed the gate and was not used; the state is unchanged.
    Gated {
        /// Normalised innovation squared.
        nis: T,
    },
}

impl<T: Copy> UpdateOutcome<T> {
    /// The normalised innovation squared, accepted or not.
    pub fn nis(&self) -> T {
        match *self {
            Self::Accepted { nis } | Self::Gated { nis } => nis,
        }
    }
}

/// Counters of what the filter did, for status reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EkfCounters {
    /// Prediction steps applied.
    pub predictions: u32,
    /// Sightings that corrected the state.
    pub updates: u32,
    /// Sightings refused by the innovation gate.
    pub gated: u32,
    /// Steps refused for bad input (any [`EkfError`](crate::error::EkfError)).
    pub rejected: u32,
}

/// Innovation of one sighting against one landmark: everything the association and the
/// update need.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation<T: Real> {
    /// `z − h(x)`, bearing wrapped.
    pub nu: Vector2<T>,
    /// Innovation covariance `H P Hᵀ + R`.
    pub s: Matrix2<T>,
    /// Its inverse.
    pub s_inv: Matrix2<T>,
    /// Squared Mahalanobis distance `νᵀ S⁻¹ ν`.
    pub mahalanobis_squared: T,
    /// ∂h/∂robot at the current estimate.
    pub jacobian_robot: Matrix2x3<T>,
    /// ∂h/∂landmark at the current estimate.
    pub jacobian_landmark: Matrix2<T>,
    /// ∂h/∂(b₀, b₂), the range bias' states (`[[1, β²], [0, 0]]`), when they are estimated
    /// ([`EkfSlam::estimate_range_bias`](super::EkfSlam::estimate_range_bias), at
    /// [`EkfSlam::range_bias_state`](super::EkfSlam::range_bias_state)); zero when not.
    pub jacobian_bias: Matrix2<T>,
}
