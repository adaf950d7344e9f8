//! Layer 0, the bottom: settings and plain domain types that every other layer shares.
//! Nothing here imports another layer of host-sim.
//!
//! - [`config`]: the landmark EKF's settings from TOML files (and the simulator's
//!   `[scenario]`).
//! - [`grid`]: the grid particle filter's settings (TOML overrides, particle counts,
//!   lidar geometry of CARMEN logs).
//! - [`recording`]: a dataset in memory (events, true poses, true landmarks) and the
//!   interpolation of true poses.
//! - [`datasets`]: where the shared datasets folder is.
//! - [`leave_outs`]: the measurement switches of `scripts/mrclam-leave-outs` (feature
//!   `leave-outs`; constant `false` otherwise).

pub mod config;
pub mod datasets;
pub mod grid;
pub mod leave_outs;
pub mod recording;

/// How sightings are associated with landmarks.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum AssociationMode {
    /// The sighting's id (barcode) names the landmark.
    Known,
    /// Ids hidden; individual compatibility nearest neighbour (El Masri El Chaarani et
    /// al. n.d., Fig. 11).
    Icnn,
    /// Ids hidden; joint compatibility branch and bound over each batch of sightings.
    Jcbb,
}

/// Scalar the filter runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum Precision {
    /// Single precision, as on the microcontroller.
    F32,
    /// Double precision.
    #[default]
    F64,
}

/// Which estimator a replay drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum FilterKind {
    /// Landmark EKF-SLAM (landmark datasets).
    #[default]
    EkfSlam,
    /// Grid particle-filter SLAM (lidar datasets).
    GridSlam,
}
