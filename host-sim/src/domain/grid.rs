//! Settings of the grid particle filter on the host: the TOML overrides of
//! [`GridPfConfig`], the particle counts and beam capacity compiled in, and the lidar
//! geometry of CARMEN logs.

use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::pf::{GridPfConfig, MotionNoise};
use microslam::sensors::lidar::LidarGeometry;
use microslam::slam::GraphSlamConfig;
use std::path::Path;

/// Grid edge in cells on the host: 1024 × 1024 cells (51.2 m at 5 cm), 1 MB.
pub const GRID_CELLS: usize = 1024;
/// Bytes of the host grid's occupied-cell bitmap (128 KB): grid SLAM on the host keeps
/// one, like the firmware, so that the shift search reads only the occupied cells
/// (the scores are the same as without; Intel replay with `GridPfConfig::UNTUNED`
/// 4.3 → 3.5 CPU-s).
pub const GRID_BITMAP: usize = microslam::grid::occupancy_bytes(GRID_CELLS, GRID_CELLS);
/// Grid edge in cells of the larger host grid: 2048 × 2048 cells (102.4 m at 5 cm), 4 MB,
/// for a recording whose odometry does not fit [`GRID_CELLS`] ([`GridPlacement`]).
pub const GRID_CELLS_LARGE: usize = 2048;
/// Bytes of the larger grid's occupied-cell bitmap (512 KB).
pub const GRID_BITMAP_LARGE: usize =
    microslam::grid::occupancy_bytes(GRID_CELLS_LARGE, GRID_CELLS_LARGE);
/// Room kept between the odometry's extent and the grid's edge, metres: for the walls the
/// lidar sees beyond the path, and for the odometry's drift.
pub const GRID_MARGIN_M: f32 = 5.0;

/// Where the odometry goes: the box its positions span, in the frame of its first finite
/// pose (the frame a run that starts at the identity maps in), metres.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct OdometryExtent {
    /// Smallest x and y.
    pub min: [f32; 2],
    /// Largest x and y.
    pub max: [f32; 2],
}

impl OdometryExtent {
    /// The extent of `poses` (odometry poses in their own frame, in order; the ones that
    /// are not finite left out); `None` when none is finite.
    pub fn of(poses: impl IntoIterator<Item = Pose2<f32>>) -> Option<Self> {
        let mut poses = poses.into_iter().filter(Pose2::is_finite);
        let to_start = poses.next()?.inverse();
        let mut extent = Self {
            min: [0.0; 2],
            max: [0.0; 2],
        };
        for p in poses {
            let q = to_start.compose(&p);
            for (axis, v) in [q.x, q.y].into_iter().enumerate() {
                extent.min[axis] = extent.min[axis].min(v);
                extent.max[axis] = extent.max[axis].max(v);
            }
        }
        Some(extent)
    }

    /// Width and height, metres.
    pub fn size(&self) -> [f32; 2] {
        [self.max[0] - self.min[0], self.max[1] - self.min[1]]
    }
}

/// How far apart a run's scans are, from the odometry poses at the scans. The grid
/// filters are built for scans a few centimetres apart (the Intel raw part: 0.056 m
/// median): a prediction takes each step as an arc
/// ([`microslam::pf::prediction::arc_between`]), which leaves out a step's sideways
/// part, and a scan a metre from the last does not pin the pose to a cell; on the logs
/// with scans 0.7–1 m apart every grid SLAM run loses the map (`docs/results-grid.md`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ScanSpacing {
    /// Steps between consecutive scans whose odometry poses are both finite.
    pub steps: usize,
    /// Median distance between consecutive scans, metres.
    pub median_step_m: f32,
    /// Median heading change between consecutive scans, radians.
    pub median_turn_rad: f32,
    /// Median of the part of a step the arc leaves out, metres.
    pub median_arc_residual_m: f32,
    /// Largest part of a step the arc leaves out, metres.
    pub max_arc_residual_m: f32,
}

impl ScanSpacing {
    /// A median step longer than this, metres, makes the scans sparse
    /// ([`ScanSpacing::is_sparse`]): between the Intel raw part's 0.056 m, which grid SLAM
    /// maps, and the corrected logs' 0.67 m and 0.97 m, which it loses.
    pub const SPARSE_STEP_M: f32 = 0.25;

    /// The spacing of scans at the odometry poses `poses` (in scan order; a step with a
    /// pose that is not finite left out); `None` without a step.
    pub fn of(poses: impl IntoIterator<Item = Pose2<f32>>) -> Option<Self> {
        use microslam::pf::prediction::{arc_between, drive_arc};
        let poses: Vec<Pose2<f32>> = poses.into_iter().collect();
        let (mut step, mut turn, mut residual) = (Vec::new(), Vec::new(), Vec::new());
        for pair in poses.windows(2) {
            let [from, to] = pair else { continue };
            if !(from.is_finite() && to.is_finite()) {
                continue;
            }
            let (distance, heading_change) = arc_between(from, to);
            let on_arc = drive_arc(from, distance, heading_change, 0.0);
            step.push((to.x - from.x).hypot(to.y - from.y));
            turn.push(heading_change.abs());
            residual.push((to.x - on_arc.x).hypot(to.y - on_arc.y));
        }
        let median = |v: &mut Vec<f32>| {
            v.sort_by(f32::total_cmp);
            v.get(v.len() / 2).copied()
        };
        Some(Self {
            steps: step.len(),
            median_step_m: median(&mut step)?,
            median_turn_rad: median(&mut turn)?,
            median_arc_residual_m: median(&mut residual)?,
            max_arc_residual_m: residual.last().copied()?,
        })
    }

    /// `true` when the median step is longer than [`ScanSpacing::SPARSE_STEP_M`].
    pub fn is_sparse(&self) -> bool {
        self.median_step_m > Self::SPARSE_STEP_M
    }
}

/// Size and place of a SLAM run's square grid on the host.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GridPlacement {
    /// Cells along each edge ([`GRID_CELLS`] or [`GRID_CELLS_LARGE`]).
    pub cells: usize,
    /// World position of the grid's lower-left corner, metres.
    pub origin_m: [f32; 2],
    /// `true` when the grid is centred on the start (the world's origin).
    pub centred: bool,
    /// `false` when the odometry's extent with [`GRID_MARGIN_M`] on every side does not
    /// fit even the larger grid: end points beyond it are skipped (and counted).
    pub fits: bool,
}

impl GridPlacement {
    /// The smaller host grid ([`GRID_CELLS`], else [`GRID_CELLS_LARGE`]) that holds
    /// `extent` with [`GRID_MARGIN_M`] to spare on every side: centred on the start when
    /// it holds it so, else centred on the extent, rounded to whole cells (so that the
    /// cells lie where the centred grid's would). Without an extent, the smaller grid
    /// centred on the start.
    pub fn for_extent(extent: Option<&OdometryExtent>, resolution: f32) -> Self {
        let centred = |cells: usize| Self {
            cells,
            origin_m: [-(cells as f32) * resolution * 0.5; 2],
            centred: true,
            fits: true,
        };
        let Some(e) = extent else {
            return centred(GRID_CELLS);
        };
        let reach = |v: f32| v.abs() + GRID_MARGIN_M;
        let held_centred = |cells: usize| {
            let half = cells as f32 * resolution * 0.5;
            e.min.iter().chain(&e.max).all(|&v| reach(v) <= half)
        };
        let held = |cells: usize| {
            let side = cells as f32 * resolution;
            e.size().iter().all(|&s| s + 2.0 * GRID_MARGIN_M <= side)
        };
        for cells in [GRID_CELLS, GRID_CELLS_LARGE] {
            if held_centred(cells) {
                return centred(cells);
            }
            if held(cells) {
                return Self::on_extent(e, cells, resolution, true);
            }
        }
        Self::on_extent(e, GRID_CELLS_LARGE, resolution, false)
    }

    /// A grid of `cells` centred on `extent`'s middle, rounded to whole cells.
    fn on_extent(extent: &OdometryExtent, cells: usize, resolution: f32, fits: bool) -> Self {
        let half = cells as f32 * resolution * 0.5;
        let corner = |axis: usize| {
            let middle = 0.5 * (extent.min[axis] + extent.max[axis]);
            (middle / resolution).round() * resolution - half
        };
        Self {
            cells,
            origin_m: [corner(0), corner(1)],
            centred: false,
            fits,
        }
    }

    /// Edge length, metres.
    pub fn side_m(&self, resolution: f32) -> f32 {
        self.cells as f32 * resolution
    }
}

/// Most beams a scan may use (the Intel/ACES SICK has 180; more are decimated).
pub const MAX_BEAMS: usize = 361;

/// Particle counts compiled in (the count is a type parameter of the filter).
pub const SUPPORTED_PARTICLES: [usize; 8] = [8, 16, 32, 64, 100, 128, 200, 400];

/// Optional TOML overrides of the grid filter (`--config FILE`), every key optional:
/// `resolution`, `hit`, `miss`, `occupied_above`, `range_weight_exponent`,
/// `log_likelihood_per_unit`, `resample_neff_fraction`, `seed`, `shift_window_cells`,
/// `beam_decimation`, `shift_prior_std_cells`, and the [`MotionNoise`] fields.
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridToml {
    resolution: Option<f32>,
    hit: Option<i8>,
    miss: Option<i8>,
    occupied_above: Option<i8>,
    range_weight_exponent: Option<f32>,
    log_likelihood_per_unit: Option<f32>,
    resample_neff_fraction: Option<f32>,
    seed: Option<u64>,
    shift_window_cells: Option<u8>,
    beam_decimation: Option<usize>,
    shift_prior_std_cells: Option<f32>,
    distance_std: Option<f32>,
    distance_std_per_metre: Option<f32>,
    distance_std_per_radian: Option<f32>,
    heading_std: Option<f32>,
    heading_std_per_radian: Option<f32>,
    heading_std_per_metre: Option<f32>,
    sideways_std_per_metre: Option<f32>,
    /// `"untuned"` (or its deprecated old name `"seed"`) starts from
    /// [`GridPfConfig::UNTUNED`], `"microcontroller"` from
    /// [`GridPfConfig::MICROCONTROLLER`], otherwise [`GridPfConfig::DEFAULT`].
    base: Option<String>,
    /// `[loop_closure]`: grid SLAM's loop closure ([`LoopClosureToml`]).
    loop_closure: Option<LoopClosureToml>,
    /// Share of an input stream (scans, odometry poses) a run may skip or refuse before it
    /// says so on stderr and in `metrics.json` (`input_loss`); default
    /// [`LOSS_WARNING_FRACTION`].
    loss_warning_fraction: Option<f64>,
    /// The longest odometry step between two consecutive scans taken as motion, metres;
    /// a longer one is an odometry reset (default [`MAX_ODOMETRY_STEP_M`]).
    max_odometry_step_m: Option<f32>,
}

/// The longest odometry step between two consecutive scans a grid run takes as motion
/// (10 m): a longer one is taken as an odometry reset (the odometry node restarted, a
/// corrupt pose), counted, and the filter re-anchored on the new odometry frame without
/// moving. The shared logs' longest step is 1.54 m (ACES, whose scans are 0.5 m apart).
pub const MAX_ODOMETRY_STEP_M: f32 = 10.0;

/// The `max_odometry_step_m` of the settings file `config` (else [`MAX_ODOMETRY_STEP_M`]);
/// refused unless positive and finite, naming the file.
pub fn max_odometry_step_m(config: Option<&Path>) -> Result<f32> {
    let Some(path) = config else {
        return Ok(MAX_ODOMETRY_STEP_M);
    };
    let m = GridToml::read(path)?
        .max_odometry_step_m
        .unwrap_or(MAX_ODOMETRY_STEP_M);
    if !(m.is_finite() && m > 0.0) {
        bail!(
            "in {}: `max_odometry_step_m` = {m} must be a positive number of metres",
            path.display()
        );
    }
    Ok(m)
}

/// Share of an input stream a grid run may skip or refuse without a warning (10 %), unless
/// the settings file's `loss_warning_fraction` gives another.
pub const LOSS_WARNING_FRACTION: f64 = 0.1;

/// The `loss_warning_fraction` of the settings file `config` (else
/// [`LOSS_WARNING_FRACTION`]); refused outside 0 ..= 1, naming the file.
pub fn loss_warning_fraction(config: Option<&Path>) -> Result<f64> {
    let Some(path) = config else {
        return Ok(LOSS_WARNING_FRACTION);
    };
    let f = GridToml::read(path)?
        .loss_warning_fraction
        .unwrap_or(LOSS_WARNING_FRACTION);
    if !(0.0..=1.0).contains(&f) {
        bail!(
            "in {}: `loss_warning_fraction` = {f} must be within 0 ..= 1",
            path.display()
        );
    }
    Ok(f)
}

/// The `[loop_closure]` table of a grid settings file: `enabled` (default `true` when
/// the table is there) and any setting of [`GraphSlamConfig`] (the device's
/// building-scale grid SLAM) by the name its refusals use.
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopClosureToml {
    enabled: Option<bool>,
    keyframe_distance_m: Option<f32>,
    keyframe_turn_rad: Option<f32>,
    chain_position_std_m: Option<f32>,
    chain_position_std_per_m: Option<f32>,
    chain_heading_std_rad: Option<f32>,
    min_age_keyframes: Option<u16>,
    candidate_radius_m: Option<f32>,
    submap_radius_m: Option<f32>,
    window_half_width_cells: Option<u16>,
    window_half_angle_rad: Option<f32>,
    window_angle_step_rad: Option<f32>,
    min_hit_fraction: Option<f32>,
    distinct_cells: Option<u16>,
    max_runner_up: Option<f32>,
    work_budget: Option<u32>,
    old_keyframes_per_scan: Option<u16>,
    old_map_dilation_cells: Option<u8>,
    work_per_scan: Option<u32>,
    position_std_floor_m: Option<f32>,
    heading_std_floor_rad: Option<f32>,
    estimate_radius_m: Option<f32>,
    estimate_radius_rad: Option<f32>,
    heading_span_rad: Option<f32>,
    heading_span_per_radian: Option<f32>,
    heading_max_span_rad: Option<f32>,
    heading_step_rad: Option<f32>,
    heading_coarse_steps: Option<u8>,
    heading_min_gain: Option<f32>,
    solver_max_iterations: Option<u16>,
    solver_relative_tolerance: Option<f32>,
}

impl LoopClosureToml {
    /// The settings this table gives over [`GraphSlamConfig::MICROCONTROLLER`] (its `grid`
    /// part is the run's, set when the run starts), or `None` when it says
    /// `enabled = false`.
    pub fn apply(&self) -> Result<Option<GraphSlamConfig>> {
        if self.enabled == Some(false) {
            return Ok(None);
        }
        let mut c = GraphSlamConfig::MICROCONTROLLER;
        macro_rules! set {
            ($($key:ident => $($field:ident).+),* $(,)?) => {
                $(if let Some(v) = self.$key { c.$($field).+ = v; })*
            };
        }
        set!(
            keyframe_distance_m => keyframes.distance_m,
            keyframe_turn_rad => keyframes.turn_rad,
            chain_position_std_m => chain.position_std_m,
            chain_position_std_per_m => chain.position_std_per_m,
            chain_heading_std_rad => chain.heading_std_rad,
            min_age_keyframes => loop_closure.min_age_keyframes,
            candidate_radius_m => loop_closure.candidate_radius_m,
            submap_radius_m => loop_closure.submap_radius_m,
            window_half_width_cells => loop_closure.window.half_width_cells,
            window_half_angle_rad => loop_closure.window.half_angle,
            window_angle_step_rad => loop_closure.window.angle_step,
            min_hit_fraction => loop_closure.window.min_hit_fraction,
            distinct_cells => loop_closure.window.distinct_cells,
            max_runner_up => loop_closure.window.max_runner_up,
            work_budget => loop_closure.window.work_budget,
            old_keyframes_per_scan => loop_closure.old_keyframes_per_scan,
            old_map_dilation_cells => loop_closure.old_map_dilation_cells,
            work_per_scan => loop_closure.work_per_scan,
            position_std_floor_m => loop_closure.position_std_floor_m,
            heading_std_floor_rad => loop_closure.heading_std_floor_rad,
            estimate_radius_m => estimate_radius.position_m,
            estimate_radius_rad => estimate_radius.heading_rad,
            heading_span_rad => heading_search.span_rad,
            heading_span_per_radian => heading_search.span_per_radian,
            heading_max_span_rad => heading_search.max_span_rad,
            heading_step_rad => heading_search.step_rad,
            heading_coarse_steps => heading_search.coarse_steps,
            heading_min_gain => heading_search.min_gain,
            solver_max_iterations => loop_closure.solver.max_iterations,
            solver_relative_tolerance => loop_closure.solver.relative_tolerance,
        );
        if let Some(invalid) = c.invalid_setting() {
            bail!("[loop_closure]: {invalid}");
        }
        Ok(Some(c))
    }
}

impl GridToml {
    /// `true` when the file sets the shift window (`shift_window_cells`).
    pub fn sets_window(&self) -> bool {
        self.shift_window_cells.is_some()
    }

    /// The loop closure the file asks for: its `[loop_closure]` table over
    /// [`GraphSlamConfig::MICROCONTROLLER`], `None` without the table or with
    /// `enabled = false`.
    pub fn loop_closure(&self) -> Result<Option<GraphSlamConfig>> {
        self.loop_closure
            .as_ref()
            .map_or(Ok(None), LoopClosureToml::apply)
    }

    /// Reads a TOML file.
    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// The configuration these overrides give, laid over `GridPfConfig::DEFAULT` unless
    /// the file names a `base`.
    pub fn apply(&self) -> Result<GridPfConfig> {
        self.apply_over(GridPfConfig::DEFAULT)
    }

    /// The configuration these overrides give, laid over `fallback` unless the file
    /// names a `base`.
    pub fn apply_over(&self, fallback: GridPfConfig) -> Result<GridPfConfig> {
        let mut c = match self.base.as_deref() {
            None => fallback,
            Some("default") => GridPfConfig::DEFAULT,
            Some("untuned" | "seed") => GridPfConfig::UNTUNED,
            Some("microcontroller") => GridPfConfig::MICROCONTROLLER,
            Some(other) => {
                bail!("unknown base config `{other}` (default, untuned, microcontroller)")
            }
        };
        let n: &mut MotionNoise = &mut c.filter.motion_noise;
        macro_rules! set {
            ($($field:ident => $target:expr),* $(,)?) => {$(if let Some(v) = self.$field { $target = v; })*};
        }
        set!(distance_std => n.distance_std, distance_std_per_metre => n.distance_std_per_metre,
            distance_std_per_radian => n.distance_std_per_radian, heading_std => n.heading_std, heading_std_per_radian => n.heading_std_per_radian,
            heading_std_per_metre => n.heading_std_per_metre, sideways_std_per_metre => n.sideways_std_per_metre);
        set!(resolution => c.resolution, hit => c.log_odds.hit, miss => c.log_odds.miss,
            occupied_above => c.log_odds.occupied_above, range_weight_exponent => c.range_weight_exponent,
            log_likelihood_per_unit => c.filter.log_likelihood_per_unit,
            resample_neff_fraction => c.filter.resample_neff_fraction, seed => c.filter.seed,
            shift_window_cells => c.filter.shift_window_cells, beam_decimation => c.beam_decimation,
            shift_prior_std_cells => c.shift_prior_std_cells);
        if let Some(invalid) = c.invalid_setting() {
            bail!("grid filter settings: {invalid}");
        }
        if let Some((key, value, range)) = beyond_physical_range(&c) {
            bail!("grid filter settings: `{key}` = {value} is beyond any physical range ({range})");
        }
        Ok(c)
    }
}

/// Smallest and largest cell edge a grid setting may give, metres.
pub const RESOLUTION_RANGE_M: (f32, f32) = (0.001, 10.0);
/// Largest odometry noise figure a grid setting may give (m, rad, or m/m, rad/rad …):
/// the library takes any finite one, but a standard deviation of 100 m or 100 rad a step
/// is no model of a wheel, only a typo.
pub const MAX_MOTION_NOISE: f32 = 100.0;

/// The first value of `c` that is finite and of the right sign (the library checked
/// that) but beyond any physical range: `(key, value, the range)`.
fn beyond_physical_range(c: &GridPfConfig) -> Option<(&'static str, f32, String)> {
    let (lo, hi) = RESOLUTION_RANGE_M;
    if !(lo..=hi).contains(&c.resolution) {
        return Some(("resolution", c.resolution, format!("{lo} ..= {hi} m")));
    }
    let n = &c.filter.motion_noise;
    [
        ("distance_std", n.distance_std, "m"),
        ("distance_std_per_metre", n.distance_std_per_metre, "m/m"),
        (
            "distance_std_per_radian",
            n.distance_std_per_radian,
            "m/rad",
        ),
        ("heading_std", n.heading_std, "rad"),
        (
            "heading_std_per_radian",
            n.heading_std_per_radian,
            "rad/rad",
        ),
        ("heading_std_per_metre", n.heading_std_per_metre, "rad/m"),
        ("sideways_std_per_metre", n.sideways_std_per_metre, "m/m"),
    ]
    .into_iter()
    .find(|(_, v, _)| *v > MAX_MOTION_NOISE)
    .map(|(key, v, unit)| (key, v, format!("0 ..= {MAX_MOTION_NOISE} {unit}")))
}

/// The lidar geometry of a CARMEN log's front laser: `n` beams over 180° from −90°
/// (Intel, ACES: 180 × 1°), no return at ≥ 81.8 m.
pub fn carmen_lidar(beams: usize) -> LidarGeometry {
    LidarGeometry {
        angle_increment: core::f32::consts::PI / beams.max(1) as f32,
        ..LidarGeometry::CARMEN_SICK_180
    }
}

/// `beams` wanted → decimation of an `n`-beam scan: every `d`-th beam, so that
/// `⌈n / d⌉ ≤ beams`. Refused: no beam at all, or more beams than a scan has.
pub fn decimation_for(n: usize, beams: usize) -> anyhow::Result<usize> {
    if beams == 0 {
        anyhow::bail!("--beams 0: a scan needs at least one beam (1 ..= {n})");
    }
    if beams > n {
        anyhow::bail!("--beams {beams}: the log's scans have {n} beams (1 ..= {n})");
    }
    Ok(n.div_ceil(beams))
}

/// Options of the grid particle filter shared by `replay` and `localize`.
#[derive(Debug, Clone, Default)]
pub struct GridOptions {
    /// Particles (one of [`SUPPORTED_PARTICLES`]).
    pub particles: usize,
    /// Half-width k of the (2k+1)² shift window, cells (default: the preset's 4, 9 × 9,
    /// for SLAM; [`microslam::pf::LOCALIZER_SHIFT_WINDOW`] for a localizer).
    pub window: Option<u8>,
    /// What the filter does: SLAM, or localize on a map (its shift window).
    pub role: FilterRole,
    /// Beams used per scan (decimated from the log's; default all).
    pub beams: Option<usize>,
    /// Benchmark relations file (default: a `*.relations` file next to the log).
    pub relations: Option<std::path::PathBuf>,
    /// Named settings (default: [`Preset::for_particles`]).
    pub preset: Option<Preset>,
    /// Reference trajectory for ATE (TUM or a corrected CARMEN log).
    pub reference: Option<std::path::PathBuf>,
    /// Grid SLAM closes loops ([`GraphSlamConfig::MICROCONTROLLER`], or the settings
    /// file's `[loop_closure]` table, which also turns it on by itself).
    pub loop_closure: bool,
    /// Seconds added to the reference's stamps.
    pub reference_offset: f64,
}

/// What a grid filter is run for: its settings differ in the shift window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FilterRole {
    /// Grid SLAM: the preset's window.
    #[default]
    Slam,
    /// A localizer on a fixed map: [`GridPfConfig::for_localizer`]'s window unless the
    /// settings file or `--window` sets one.
    Localizer,
}

/// Named grid filter settings (`--preset`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// `GridPfConfig::DEFAULT`: tuned with 200 particles and every beam.
    Default,
    /// `GridPfConfig::MICROCONTROLLER`: the firmware's, tuned with 32 particles and 90
    /// beams.
    Microcontroller,
    /// `GridPfConfig::UNTUNED`: the settings of Du (n.d.) exactly, before any tuning
    /// (`seed`, its old name, is still accepted).
    #[value(alias = "seed")]
    Untuned,
}

impl Preset {
    /// The settings of the preset.
    pub fn config(self) -> GridPfConfig {
        match self {
            Self::Default => GridPfConfig::DEFAULT,
            Self::Microcontroller => GridPfConfig::MICROCONTROLLER,
            Self::Untuned => GridPfConfig::UNTUNED,
        }
    }

    /// The preset for `particles` when none is named: `microcontroller` below 100
    /// particles (`default` needs many particles to cover its heading noise and diverges
    /// on the Intel log with 32), `default` from 100 on.
    pub fn for_particles(particles: usize) -> Self {
        if particles < 100 {
            Self::Microcontroller
        } else {
            Self::Default
        }
    }

    /// The settings of `self` for `role` with the file `config` (if any) laid over them,
    /// and the `microcontroller` preset's beam count ([`MICROCONTROLLER_BEAMS`]) for a
    /// lidar of `lidar_beams` when neither the file nor `beams` sets one. A localizer gets
    /// the localizer's shift window ([`GridPfConfig::for_localizer`]) unless the file sets
    /// one.
    pub fn settings(
        self,
        config: Option<&Path>,
        beams: Option<usize>,
        lidar_beams: usize,
        role: FilterRole,
    ) -> Result<GridPfConfig> {
        let file = config.map(GridToml::read).transpose()?;
        let mut c = match (&file, config) {
            (Some(f), Some(path)) => f
                .apply_over(self.config())
                .with_context(|| format!("in {}", path.display()))?,
            _ => self.config(),
        };
        if role == FilterRole::Localizer && !file.as_ref().is_some_and(GridToml::sets_window) {
            c = c.for_localizer();
        }
        if let Some(beams) = beams {
            c.beam_decimation = decimation_for(lidar_beams, beams)?;
        } else if self == Self::Microcontroller && c.beam_decimation == 1 {
            // The firmware's settings were tuned with its beam count.
            c.beam_decimation =
                decimation_for(lidar_beams, MICROCONTROLLER_BEAMS.min(lidar_beams))?;
        }
        Ok(c)
    }
}

/// The loop closure of a grid run: the settings file's `[loop_closure]` table (which
/// turns it on unless it says `enabled = false`), else
/// [`GraphSlamConfig::MICROCONTROLLER`] when `requested` (`--loop-closure`), else none.
/// With one, grid SLAM is the device's building-scale SLAM ([`microslam::slam`]). A
/// localizer has a fixed map and no loops to close: asking for one is an error.
pub fn loop_closure_settings(
    config: Option<&Path>,
    requested: bool,
    role: FilterRole,
) -> Result<Option<GraphSlamConfig>> {
    let from_file = match config {
        Some(path) => GridToml::read(path)?
            .loop_closure()
            .with_context(|| format!("in {}", path.display()))?,
        None => None,
    };
    let chosen = from_file.or(requested.then_some(GraphSlamConfig::MICROCONTROLLER));
    if chosen.is_some() && role == FilterRole::Localizer {
        bail!("loop closure is for grid SLAM; a localizer's map is fixed");
    }
    Ok(chosen)
}

/// Beams the `microcontroller` preset uses when no beam count is given: the firmware's
/// (its settings were tuned with 90 of the Intel log's 180 beams).
pub const MICROCONTROLLER_BEAMS: usize = 90;

#[cfg(test)]
mod tests;

/// Options of global localization trials (`localize --global`, `sim --global`).
#[derive(Clone, Debug)]
pub struct GlobalOptions {
    /// Run the trials.
    pub enabled: bool,
    /// Number of trials.
    pub trials: usize,
    /// Seed of the random start scans.
    pub trial_seed: u64,
    /// Scans a trial may take to converge.
    pub max_scans: usize,
    /// Levels of the max-pooled map layers.
    pub levels: u8,
    /// Work budget of the search, per scan when it spans scans (`None`: the core's).
    pub work_budget: Option<u32>,
    /// Scans one search may span (`None`: the core's).
    pub search_scans: Option<u8>,
    /// Smallest hypothesis score, a fraction of the beams' total weight.
    pub min_score: Option<f32>,
    /// Beams farther than this are left out of the search, metres.
    pub search_range: Option<f32>,
    /// Beams the search uses at most.
    pub search_beams: Option<u16>,
    /// Particles spread over this many hypotheses.
    pub hypotheses: Option<u8>,
    /// Peaks of the wall-direction correlation the search visits (0: every heading).
    pub heading_peaks: Option<u8>,
    /// Half-width of the heading windows, degrees.
    pub heading_window_deg: Option<f32>,
    /// Minimum score of the first pass, a fraction of the beams' total weight.
    pub first_pass: Option<f32>,
    /// Score (fraction of the total weight) below which every heading is searched after
    /// the windows; 0: never.
    pub full_turn_below: Option<f32>,
    /// Run on the map's occupied-cell bitmap alone, as the firmware does.
    pub bitmap_only: bool,
}

impl Default for GlobalOptions {
    fn default() -> Self {
        Self {
            enabled: false,
            trials: 20,
            trial_seed: 1,
            max_scans: 10,
            levels: 6,
            work_budget: None,
            search_scans: None,
            min_score: None,
            search_range: None,
            search_beams: None,
            hypotheses: None,
            heading_peaks: None,
            heading_window_deg: None,
            first_pass: None,
            full_turn_below: None,
            bitmap_only: false,
        }
    }
}

#[cfg(test)]
mod physical_range_tests;
