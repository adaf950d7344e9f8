//! What a grid run takes and gives, shared by the one-map drive loop ([`super::grid`])
//! and the building-scale SLAM ([`super::graph_slam`]): one scan in, the estimates, the
//! map and the counts out.

use crate::domain::grid::ScanSpacing;
use microslam::geometry::Pose2;
use microslam::grid::GridGeometry;
use microslam::pf::GridPfConfig;
use microslam::sensors::lidar::LidarGeometry;

/// One scan as the driver consumes it.
#[derive(Clone, Copy, Debug)]
pub struct GridInput<'a> {
    /// Time stamp, seconds (reported with the estimate; never used for the motion).
    pub stamp: f64,
    /// Odometry pose at the scan (its increments drive the prediction).
    pub odometry: Pose2<f32>,
    /// Ranges, metres, in the order of the lidar geometry's beams.
    pub ranges: &'a [f32],
}

/// Settings of a grid run besides the map.
#[derive(Clone, Debug)]
pub struct GridRunOptions {
    /// Particles (one of [`crate::domain::grid::SUPPORTED_PARTICLES`]).
    pub particles: usize,
    /// Filter settings.
    pub config: GridPfConfig,
    /// Lidar geometry of the scans.
    pub lidar: LidarGeometry,
    /// Grid SLAM closes loops: the device's building-scale SLAM with these settings
    /// ([`super::graph_slam`]; their `grid` part is [`GridRunOptions::config`]); `None`
    /// for the one-map grid SLAM (and always for a localizer).
    pub loop_closure: Option<microslam::slam::GraphSlamConfig>,
    /// Grid SLAM's map: the world position of its lower-left corner, metres
    /// ([`crate::domain::grid::GridPlacement`]); `None`: centred on the start.
    pub grid_origin: Option<[f32; 2]>,
    /// The longest odometry step between consecutive scans taken as motion, metres
    /// ([`crate::domain::grid::MAX_ODOMETRY_STEP_M`] unless the settings say otherwise).
    pub max_odometry_step_m: f32,
}

/// Result of a run: the estimate at each processed scan, the map, and timing.
#[derive(Clone, Debug)]
pub struct GridRun {
    /// `(stamp, pose)` per processed scan, in input order.
    pub trajectory: Vec<(f64, Pose2<f32>)>,
    /// Final map cells (row-major) and geometry (SLAM) or the map used (localization).
    pub cells: Vec<i8>,
    /// Geometry of `cells`.
    pub geometry: GridGeometry,
    /// Seconds spent in the filter (prediction, scoring, map writes), the observer's time
    /// excluded.
    pub filter_time_s: f64,
    /// Seconds spent in the observer (e.g. writing an MCAP recording).
    pub observer_time_s: f64,
    /// Scans refused (no usable beam).
    pub skipped_scans: usize,
    /// Odometry poses refused (not finite): the prediction waits for the next good one.
    pub refused_odometry: usize,
    /// Odometry steps longer than [`GridRunOptions::max_odometry_step_m`]: taken as
    /// odometry resets (the filter re-anchored, not moved).
    pub odometry_resets: usize,
    /// Ranges that were NaN or ±∞ in the processed scans (skipped beam by beam).
    pub non_finite_beams: usize,
    /// End points off the grid: for grid SLAM those that fell off it and were not written,
    /// for a localizer those that lie outside its map seen from the estimate (either way
    /// the robot, or what it saw, left the map's area).
    pub off_grid_end_points: u64,
    /// Scans with at least one end point off the grid.
    pub scans_off_grid: usize,
    /// How far apart the scans are, from their odometry poses (`None` with fewer than two).
    pub scan_spacing: Option<ScanSpacing>,
    /// The map as it grew ([`super::grid::run_slam_observed`] with `snapshot_every` > 0; empty otherwise): the first entry holds
    /// the known cells of the starting map, each later one the cells changed since.
    pub snapshots: Vec<MapChanges>,
    /// A localizer's lost detection at the end of the run (`None` for SLAM).
    pub localizer: Option<LocalizerSummary>,
    /// What the loop closure did (`None` without one). With one, [`GridRun::trajectory`]
    /// is the graph's: every scan at its keyframe's final pose.
    pub loop_closure: Option<GraphSummary>,
    /// The map image the board writes at the end of a building-scale SLAM run
    /// (`microslam::slam::GraphSlam::write_map_image`; `None` for other runs).
    pub map_image: Option<Vec<u8>>,
}

/// What a localizer's lost detection saw over a run ([`microslam::pf::LocalizerStatus`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LocalizerSummary {
    /// Times it declared itself lost.
    pub lost_events: u32,
    /// Global relocalizations it made.
    pub relocalizations: u32,
    /// Its state after the last scan (`tracking`, `lost`, `relocalized`).
    pub final_state: &'static str,
    /// The last scan's hit fraction (best particle's correlation / the beams' weight).
    pub final_hit_fraction: f32,
    /// The running mean of the hit fraction while tracking.
    pub expected_hit_fraction: f32,
}

/// Cells of the map that changed since the previous snapshot.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MapChanges {
    /// Scans processed when the snapshot was taken (0: the starting map).
    pub scans: usize,
    /// `(cell index, new value)` of every changed cell.
    pub cells: Vec<(u32, i8)>,
}

/// The cells of `now` that differ from `before` (which is brought up to date).
pub(crate) fn changes(before: &mut [i8], now: &[i8], scans: usize) -> MapChanges {
    let mut cells = Vec::new();
    for (i, (b, n)) in before.iter_mut().zip(now).enumerate() {
        if b != n {
            *b = *n;
            cells.push((i as u32, *n));
        }
    }
    MapChanges { scans, cells }
}

impl GridRun {
    /// Refuses a run that used none of an input it needs, with `source` (the input, e.g.
    /// `carmen:<file>`) and the counts in the message: no scans at all, every scan skipped
    /// (no usable beam), or every odometry pose refused (not finite). Every grid command
    /// calls it before it scores and writes a run, so such a run never exits 0.
    pub fn check_used(&self, source: &str) -> anyhow::Result<()> {
        let scans = self.trajectory.len();
        if scans == 0 {
            anyhow::bail!("{source}: no scans to use (no front laser scan)");
        }
        if self.skipped_scans >= scans {
            anyhow::bail!(
                "{source}: none of the {scans} scans could be used ({} skipped: no usable beam)",
                self.skipped_scans
            );
        }
        if self.refused_odometry >= scans {
            anyhow::bail!(
                "{source}: none of the {scans} odometry poses could be used ({} refused: not finite)",
                self.refused_odometry
            );
        }
        Ok(())
    }

    pub(crate) fn empty(cells: Vec<i8>, geometry: GridGeometry, scans: usize) -> Self {
        Self {
            trajectory: Vec::with_capacity(scans),
            cells,
            geometry,
            filter_time_s: 0.0,
            observer_time_s: 0.0,
            skipped_scans: 0,
            refused_odometry: 0,
            odometry_resets: 0,
            non_finite_beams: 0,
            off_grid_end_points: 0,
            scans_off_grid: 0,
            scan_spacing: None,
            snapshots: Vec::new(),
            localizer: None,
            loop_closure: None,
            map_image: None,
        }
    }
}

/// What the graph did over a run (in `metrics.json`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct GraphSummary {
    /// Keyframes made.
    pub keyframes: u32,
    /// Keyframes refused because the graph or the store was full.
    pub keyframes_refused: u32,
    /// Loop closures tried.
    pub attempts: u32,
    /// Loop closures not tried because another was under way.
    pub closures_skipped: u32,
    /// Loop edges added.
    pub closures: u32,
}

impl From<microslam::slam::GraphCounters> for GraphSummary {
    fn from(c: microslam::slam::GraphCounters) -> Self {
        Self {
            keyframes: c.keyframes,
            keyframes_refused: c.keyframes_refused,
            attempts: c.attempts,
            closures_skipped: c.closures_skipped,
            closures: c.closures,
        }
    }
}
