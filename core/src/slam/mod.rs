//! Grid SLAM at the scale of a building, in fixed memory: the particle filter of
//! [`crate::pf`] tracks the robot on a local map that moves with it, keyframes of its
//! scans are kept in an append-only store (flash on a microcontroller), and a pose graph
//! over the keyframes closes loops by matching a new keyframe against the old ones
//! nearby.
//!
//! - [`graph`]: the pose graph over the keyframes (chain and loop edges) and its solver,
//!   LAGO's two linear steps over the chain's increments by conjugate gradients.
//! - [`keyframes`]: the append-only keyframe store (records of fixed size with a CRC,
//!   on NOR flash or in RAM, that survive a reset mid-write).
//! - [`local_map`]: the map the filter tracks the robot on, a near log-odds window and a
//!   far occupancy bitmap that move with the robot.
//! - [`matcher`]: where near a guess a scan fits a map best (the loop closure's match).
//! - [`GraphSlam`]: all of it together, with its settings in [`config`].

pub mod config;
pub mod graph;
mod graph_slam;
pub mod keyframes;
pub mod local_map;
pub mod matcher;

pub use config::{ChainNoise, EstimateRadius, GraphSlamConfig, KeyframeSpacing, LoopClosureConfig};
pub use graph_slam::{
    ClosureOutcome, ClosureWork, GraphCounters, GraphSlam, GraphStep, MATCH_BYTES, MATCH_CELLS,
    MATCH_LEVELS, SlamError, WithKeyframes, workspace_bytes,
};
#[cfg(feature = "map-image")]
pub use graph_slam::{MAX_MAP_CELLS, MapImageSummary};
