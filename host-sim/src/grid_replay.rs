//! Grid particle filter on lidar logs: `host-sim replay --filter grid-slam` and
//! `host-sim localize`. Reads a CARMEN log ([`crate::readers::carmen`]), drives
//! [`microslam::pf::GridSlam`] / [`microslam::pf::GridLocalizer`] with the odometry pose
//! increments between consecutive scans in **file order** (never with stamp differences:
//! the Intel log's stamps go backwards), and writes `map.pgm` + `map.yaml` (ROS
//! `map_server`), `map.png` (map and trajectory), `trajectory.tum` and `metrics.json`
//! (Kümmerle relation error when a relations file is given or found next to the log).

use crate::faults::FaultReport;
use crate::metrics::relations::{self, RelationError};
use crate::readers::carmen::{self, CarmenLog, LaserMessage};
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, GridView, OccupancyGrid};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam, MotionNoise};
use microslam::sensors::lidar::{LidarGeometry, LidarScan};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Grid edge in cells on the host: 1024 × 1024 cells (51.2 m at 5 cm), 1 MB.
pub const GRID_CELLS: usize = 1024;
/// Most beams a scan may use (the Intel/ACES SICK has 180; more are decimated).
pub const MAX_BEAMS: usize = 361;

type HostGrid = OccupancyGrid<GRID_CELLS, GRID_CELLS>;

/// Settings of a grid run besides [`GridPfConfig`].
#[derive(Clone, Debug)]
pub struct GridRunOptions {
    /// Particles (one of [`SUPPORTED_PARTICLES`]).
    pub particles: usize,
    /// Filter settings.
    pub config: GridPfConfig,
    /// Lidar geometry of the log.
    pub lidar: LidarGeometry,
}

/// Particle counts compiled in (the count is a type parameter of the filter).
pub const SUPPORTED_PARTICLES: [usize; 8] = [8, 16, 32, 64, 100, 128, 200, 400];

/// Result of a run: the estimate at each processed scan, the map, and timing.
#[derive(Clone, Debug)]
pub struct GridRun {
    /// `(stamp, pose)` per processed scan, in file order.
    pub trajectory: Vec<(f64, Pose2<f32>)>,
    /// Final map cells (row-major) and geometry (SLAM) or the map used (localization).
    pub cells: Vec<i8>,
    /// Geometry of `cells`.
    pub geometry: GridGeometry,
    /// Seconds spent in the filter (prediction, scoring, map writes).
    pub filter_time_s: f64,
    /// Scans refused (no usable beam).
    pub skipped_scans: usize,
    /// Odometry poses refused (not finite): the prediction waits for the next good one.
    pub refused_odometry: usize,
    /// Ranges that were NaN or ±∞ in the processed scans (skipped beam by beam).
    pub non_finite_beams: usize,
}

/// Optional TOML overrides of the grid filter (`--config FILE`), every key optional:
/// `resolution`, `hit`, `miss`, `occupied_above`, `range_weight_exponent`,
/// `log_likelihood_per_unit`, `resample_neff_fraction`, `seed`, `shift_window_cells`,
/// `beam_decimation`, and the [`MotionNoise`] fields.
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
    distance_std: Option<f32>,
    distance_std_per_metre: Option<f32>,
    heading_std: Option<f32>,
    heading_std_per_radian: Option<f32>,
    heading_std_per_metre: Option<f32>,
    sideways_std_per_metre: Option<f32>,
    /// `"seed"` starts from [`GridPfConfig::SEED`], `"microcontroller"` from
    /// [`GridPfConfig::MICROCONTROLLER`], otherwise [`GridPfConfig::DEFAULT`].
    base: Option<String>,
}

impl GridToml {
    /// Reads a TOML file.
    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// The configuration these overrides give.
    pub fn apply(&self) -> Result<GridPfConfig> {
        let mut c = match self.base.as_deref() {
            None | Some("default") => GridPfConfig::DEFAULT,
            Some("seed") => GridPfConfig::SEED,
            Some("microcontroller") => GridPfConfig::MICROCONTROLLER,
            Some(other) => bail!("unknown base config `{other}` (default, seed, microcontroller)"),
        };
        let n: &mut MotionNoise = &mut c.filter.motion_noise;
        macro_rules! set {
            ($($field:ident => $target:expr),* $(,)?) => {$(if let Some(v) = self.$field { $target = v; })*};
        }
        set!(distance_std => n.distance_std, distance_std_per_metre => n.distance_std_per_metre,
            heading_std => n.heading_std, heading_std_per_radian => n.heading_std_per_radian,
            heading_std_per_metre => n.heading_std_per_metre, sideways_std_per_metre => n.sideways_std_per_metre);
        set!(resolution => c.resolution, hit => c.log_odds.hit, miss => c.log_odds.miss,
            occupied_above => c.log_odds.occupied_above, range_weight_exponent => c.range_weight_exponent,
            log_likelihood_per_unit => c.filter.log_likelihood_per_unit,
            resample_neff_fraction => c.filter.resample_neff_fraction, seed => c.filter.seed,
            shift_window_cells => c.filter.shift_window_cells, beam_decimation => c.beam_decimation);
        if !c.is_valid() {
            bail!("grid filter settings out of range: {c:?}");
        }
        Ok(c)
    }
}

/// The lidar geometry of a CARMEN log's front laser: `n` beams over 180° from −90°
/// (Intel, ACES: 180 × 1°), no return at ≥ 81.8 m.
pub fn carmen_lidar(beams: usize) -> LidarGeometry {
    LidarGeometry {
        angle_increment: core::f32::consts::PI / beams.max(1) as f32,
        ..LidarGeometry::CARMEN_SICK_180
    }
}

fn odom_pose(o: &[f64; 3]) -> Pose2<f32> {
    Pose2::new(o[0] as f32, o[1] as f32, o[2] as f32)
}

/// The odometry motion to predict before `laser`: from the last good odometry pose to this
/// message's. `None` for the first message and for a pose that is not finite, which is
/// refused and counted (the next good pose then predicts the whole motion).
fn odometry_step(
    previous: &mut Option<Pose2<f32>>,
    laser: &LaserMessage,
    run: &mut GridRun,
) -> Option<(Pose2<f32>, Pose2<f32>)> {
    let odom = odom_pose(&laser.odom);
    if !odom.is_finite() {
        run.refused_odometry += 1;
        return None;
    }
    previous.replace(odom).map(|from| (from, odom))
}

/// The scan of `laser`, its non-finite ranges counted (the filter skips them one by one).
fn counted_scan<'a>(
    laser: &'a LaserMessage,
    lidar: &LidarGeometry,
    run: &mut GridRun,
) -> LidarScan<'a> {
    let scan = LidarScan::new(&laser.ranges, *lidar);
    run.non_finite_beams += scan.census().1;
    scan
}

macro_rules! dispatch_particles {
    ($p:expr, $f:ident, $($arg:expr),*) => {
        match $p {
            8 => $f::<8>($($arg),*),
            16 => $f::<16>($($arg),*),
            32 => $f::<32>($($arg),*),
            64 => $f::<64>($($arg),*),
            100 => $f::<100>($($arg),*),
            128 => $f::<128>($($arg),*),
            200 => $f::<200>($($arg),*),
            400 => $f::<400>($($arg),*),
            other => bail!("--particles {other} is not compiled in; use one of {SUPPORTED_PARTICLES:?}"),
        }
    };
}

/// The front-laser messages of `log` in file order: what the grid filters process.
pub fn front_scans(log: &CarmenLog) -> Vec<&LaserMessage> {
    log.lasers().filter(|l| !l.rear).collect()
}

/// Grid SLAM over the front-laser scans of `log`, starting at the origin.
pub fn run_slam(
    log: &CarmenLog,
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<GridRun> {
    run_slam_scans(&front_scans(log), options, progress)
}

/// Grid SLAM over `scans` (laser messages in the order they arrive), starting at the
/// origin. An odometry pose that is not finite is refused and counted
/// ([`GridRun::refused_odometry`]), and the next good one predicts the whole motion.
///
/// Runs on a thread with a 64 MB stack: the 1 MB grid is built on the stack before it is
/// boxed in unoptimised builds.
pub fn run_slam_scans(
    scans: &[&LaserMessage],
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<GridRun> {
    std::thread::scope(|scope| {
        let worker = std::thread::Builder::new()
            .stack_size(64 << 20)
            .spawn_scoped(scope, || -> Result<GridRun> {
                dispatch_particles!(options.particles, slam_p, scans, options, progress)
            })?;
        worker
            .join()
            .map_err(|_| anyhow::anyhow!("grid SLAM thread panicked"))?
    })
}

fn slam_p<const P: usize>(
    scans: &[&LaserMessage],
    options: &GridRunOptions,
    progress: &dyn Fn(usize),
) -> Result<GridRun> {
    let c = options.config;
    let mut grid: Box<HostGrid> = Box::new(HostGrid::centred(c.resolution, c.log_odds));
    let mut run = GridRun {
        trajectory: Vec::new(),
        cells: Vec::new(),
        geometry: *grid.geometry(),
        filter_time_s: 0.0,
        skipped_scans: 0,
        refused_odometry: 0,
        non_finite_beams: 0,
    };
    let t0 = Instant::now();
    {
        let mut slam =
            GridSlam::<GRID_CELLS, GRID_CELLS, P, MAX_BEAMS>::new(&mut grid, c, Pose2::IDENTITY)
                .map_err(|e| anyhow::anyhow!("grid SLAM: {e}"))?;
        let mut previous: Option<Pose2<f32>> = None;
        for (i, laser) in scans.iter().enumerate() {
            if let Some((from, to)) = odometry_step(&mut previous, laser, &mut run) {
                slam.predict_odometry(&from, &to)
                    .map_err(|e| anyhow::anyhow!("scan {i}: {e}"))?;
            }
            let scan = counted_scan(laser, &options.lidar, &mut run);
            match slam.observe(&scan) {
                Ok(r) => run.trajectory.push((laser.stamp, r.pose)),
                Err(_) => {
                    run.skipped_scans += 1;
                    run.trajectory.push((laser.stamp, slam.pose()));
                }
            }
            progress(i);
        }
    }
    run.filter_time_s = t0.elapsed().as_secs_f64();
    run.cells = grid.cells().to_vec();
    Ok(run)
}

/// Localization on a fixed map over the front-laser scans of `log`, starting at
/// `start` (the map's frame; a SLAM map of the same log starts at its first scan).
pub fn run_localizer(
    log: &CarmenLog,
    map: &GridView<'_>,
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &dyn Fn(usize),
) -> Result<GridRun> {
    let scans = front_scans(log);
    dispatch_particles!(
        options.particles,
        localize_p,
        &scans,
        map,
        start,
        options,
        progress
    )
}

fn localize_p<const P: usize>(
    scans: &[&LaserMessage],
    map: &GridView<'_>,
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &dyn Fn(usize),
) -> Result<GridRun> {
    let mut run = GridRun {
        trajectory: Vec::new(),
        cells: map.cells().to_vec(),
        geometry: *map.geometry(),
        filter_time_s: 0.0,
        skipped_scans: 0,
        refused_odometry: 0,
        non_finite_beams: 0,
    };
    let t0 = Instant::now();
    let mut loc = GridLocalizer::<P, MAX_BEAMS>::new(*map, options.config, start)
        .map_err(|e| anyhow::anyhow!("grid localizer: {e}"))?;
    let mut previous: Option<Pose2<f32>> = None;
    for (i, laser) in scans.iter().enumerate() {
        if let Some((from, to)) = odometry_step(&mut previous, laser, &mut run) {
            loc.predict_odometry(&from, &to)
                .map_err(|e| anyhow::anyhow!("scan {i}: {e}"))?;
        }
        let scan = counted_scan(laser, &options.lidar, &mut run);
        match loc.observe(&scan) {
            Ok(r) => run.trajectory.push((laser.stamp, r.pose)),
            Err(_) => {
                run.skipped_scans += 1;
                run.trajectory.push((laser.stamp, loc.pose()));
            }
        }
        progress(i);
    }
    run.filter_time_s = t0.elapsed().as_secs_f64();
    Ok(run)
}

/// The relation error of a run's trajectory (stamps matched within 1 ms).
pub fn relation_error(run: &GridRun, rels: &[relations::Relation]) -> RelationError {
    let traj: Vec<(f64, [f64; 3])> = run
        .trajectory
        .iter()
        .map(|(t, p)| (*t, [f64::from(p.x), f64::from(p.y), f64::from(p.theta)]))
        .collect();
    relations::evaluate(&traj, rels, 1e-3)
}

/// The relations file to use: the one given, else a single `*.relations` file next to
/// the log, else none.
pub fn find_relations(log_path: &Path, given: Option<&Path>) -> Option<PathBuf> {
    if let Some(g) = given {
        return Some(g.to_path_buf());
    }
    let dir = log_path.parent()?;
    let mut found = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "relations"));
    let first = found.next()?;
    found.next().is_none().then_some(first)
}

/// A `carmen:<file>` location: the path itself when it exists, else relative to the
/// datasets folder.
pub fn resolve_log(spec: &str) -> Result<PathBuf> {
    let direct = PathBuf::from(spec);
    if direct.is_file() {
        return Ok(direct);
    }
    crate::datasets::dataset_path(spec)
}

/// Reads a CARMEN log.
pub fn read_log(path: &Path) -> Result<CarmenLog> {
    let log = carmen::read(path)?;
    if log.lasers().next().is_none() {
        bail!("{}: no laser scans", path.display());
    }
    Ok(log)
}

/// The beam count of a log's first front scan.
pub fn beam_count(log: &CarmenLog) -> usize {
    log.lasers()
        .find(|l| !l.rear)
        .map_or(180, |l| l.ranges.len())
}

/// `beams` wanted → decimation of an `n`-beam scan.
pub fn decimation_for(n: usize, beams: Option<usize>) -> usize {
    match beams {
        Some(b) if b > 0 => n.div_ceil(b).max(1),
        _ => 1,
    }
}

/// Writes the outputs of a run into `out`.
pub fn write_outputs(
    out: &Path,
    run: &GridRun,
    config: &GridPfConfig,
    metrics: &serde_json::Value,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    crate::output::grid_map::write_map(
        out,
        &run.cells,
        &run.geometry,
        &config.log_odds,
        &run.trajectory,
    )?;
    crate::output::grid_map::write_tum(&out.join("trajectory.tum"), &run.trajectory)?;
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(metrics)? + "\n",
    )?;
    Ok(())
}

pub(crate) fn progress_bar(len: usize, quiet: bool) -> indicatif::ProgressBar {
    if quiet {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "{bar:40} {pos}/{len} scans {elapsed_precise} ({per_sec})",
    ) {
        pb.set_style(style);
    }
    pb
}

pub(crate) fn options_from(
    config: Option<&Path>,
    grid: &crate::cli::GridArgs,
    log: &CarmenLog,
) -> Result<GridRunOptions> {
    let mut c = match config {
        Some(p) => GridToml::read(p)?.apply()?,
        None => GridPfConfig::DEFAULT,
    };
    if let Some(k) = grid.window {
        c.filter.shift_window_cells = k;
    }
    let n = beam_count(log);
    if grid.beams.is_some() {
        c.beam_decimation = decimation_for(n, grid.beams);
    }
    if !c.is_valid() {
        bail!(
            "grid filter settings out of range (window ≤ {})",
            microslam::pf::correlation::MAX_SHIFT_WINDOW
        );
    }
    Ok(GridRunOptions {
        particles: grid.particles,
        config: c,
        lidar: carmen_lidar(n),
    })
}

fn metrics_json(
    dataset: &str,
    run: &GridRun,
    options: &GridRunOptions,
    rel: Option<RelationError>,
    faults: Option<&FaultReport>,
    wall: f64,
) -> serde_json::Value {
    let scans = run.trajectory.len();
    serde_json::json!({
        "dataset": dataset,
        "scans": scans,
        "particles": options.particles,
        "relations": rel.map(|r| serde_json::json!({
            "used": r.used,
            "trans_mean_m": r.trans_mean_m,
            "trans_std_m": r.trans_std_m,
            "rot_mean_deg": r.rot_mean_deg,
            "rot_std_deg": r.rot_std_deg,
        })),
        "wall_time_s": wall,
        "filter_time_s": run.filter_time_s,
        "ms_per_scan": 1e3 * run.filter_time_s / scans.max(1) as f64,
        "skipped_scans": run.skipped_scans,
        "refused_odometry": run.refused_odometry,
        "non_finite_beams": run.non_finite_beams,
        "faults": faults,
        "window": 2 * u32::from(options.config.filter.shift_window_cells) + 1,
        "beam_decimation": options.config.beam_decimation,
        "range_weight_exponent": options.config.range_weight_exponent,
        "seed": options.config.filter.seed,
    })
}

fn report(quiet: bool, dataset: &str, metrics: &serde_json::Value, out: &Path) {
    if quiet {
        return;
    }
    println!(
        "{dataset}: {} scans, {} particles",
        metrics["scans"], metrics["particles"]
    );
    if let Some(r) = metrics.get("relations").filter(|r| !r.is_null()) {
        println!(
            "  relation error ({} used): {:.4} ± {:.4} m, {:.3} ± {:.3}°",
            r["used"],
            r["trans_mean_m"].as_f64().unwrap_or(f64::NAN),
            r["trans_std_m"].as_f64().unwrap_or(f64::NAN),
            r["rot_mean_deg"].as_f64().unwrap_or(f64::NAN),
            r["rot_std_deg"].as_f64().unwrap_or(f64::NAN)
        );
    }
    println!(
        "  wall {:.2} s, filter {:.2} s ({:.3} ms/scan); outputs in {}",
        metrics["wall_time_s"].as_f64().unwrap_or(f64::NAN),
        metrics["filter_time_s"].as_f64().unwrap_or(f64::NAN),
        metrics["ms_per_scan"].as_f64().unwrap_or(f64::NAN),
        out.display()
    );
}

/// `host-sim replay --filter grid-slam --dataset carmen:<file>` (and `thor:<dir>`).
pub fn replay_cli(args: &crate::cli::ReplayArgs, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let file = match &args.dataset {
        crate::readers::DatasetSpec::Carmen(f) => f,
        crate::readers::DatasetSpec::Thor(dir) => {
            return crate::readers::thor::replay_cli(dir, args.run, &args.out, quiet);
        }
        other => bail!(
            "grid SLAM needs a lidar dataset (carmen:<file>), not {}",
            other.family()
        ),
    };
    let path = resolve_log(file)?;
    let log = read_log(&path)?;
    let options = options_from(args.config.as_deref(), &args.grid, &log)?;
    let clean = front_scans(&log);
    // Faults (`--faults`) go into a copy of the laser messages.
    let (faulty, faults) = match args.faults.filter(|f| !f.is_none()) {
        Some(rates) => {
            let (scans, injected) = crate::faults::inject_scans(&clean, &rates, args.fault_seed);
            let report = FaultReport {
                rates,
                seed: args.fault_seed,
                injected,
            };
            (scans, Some(report))
        }
        None => (Vec::new(), None),
    };
    let scans: Vec<&LaserMessage> = if faults.is_some() {
        faulty.iter().collect()
    } else {
        clean
    };
    let pb = progress_bar(scans.len(), quiet);
    let run = run_slam_scans(&scans, &options, &|i| {
        if i % 64 == 0 {
            pb.set_position(i as u64);
        }
    })?;
    pb.finish_and_clear();
    let rel = match find_relations(&path, args.grid.relations.as_deref()) {
        Some(r) => Some(relation_error(&run, &relations::read(&r)?)),
        None => None,
    };
    let name = path
        .file_name()
        .map_or_else(|| file.clone(), |n| n.to_string_lossy().to_string());
    // Wall time: the whole replay (reading, filtering, metrics) before the files are written.
    let wall = start.elapsed().as_secs_f64();
    let metrics = metrics_json(&name, &run, &options, rel, faults.as_ref(), wall);
    write_outputs(&args.out, &run, &options.config, &metrics)?;
    report(quiet, &name, &metrics, &args.out);
    Ok(())
}

/// `host-sim localize --map map.yaml --dataset carmen:<file>`.
pub fn localize_cli(args: &crate::cli::LocalizeArgs, quiet: bool) -> Result<()> {
    let start = Instant::now();
    let crate::readers::DatasetSpec::Carmen(file) = &args.dataset else {
        bail!("localize needs a lidar dataset (carmen:<file>)");
    };
    let path = resolve_log(file)?;
    let log = read_log(&path)?;
    let options = options_from(args.config.as_deref(), &args.grid, &log)?;
    let (cells, geometry) = crate::output::grid_map::read_map(&args.map, &options.config.log_odds)?;
    if (geometry.resolution - options.config.resolution).abs() > 1e-6 {
        bail!(
            "map resolution {} differs from the configured {}",
            geometry.resolution,
            options.config.resolution
        );
    }
    let view = GridView::new(&cells, geometry, options.config.log_odds.occupied_above)
        .map_err(|e| anyhow::anyhow!("map: {e}"))?;
    let scans = log.lasers().filter(|l| !l.rear).count();
    let pb = progress_bar(scans, quiet);
    // The SLAM map's frame is the pose of the log's first scan.
    let run = run_localizer(&log, &view, Pose2::IDENTITY, &options, &|i| {
        if i % 64 == 0 {
            pb.set_position(i as u64);
        }
    })?;
    pb.finish_and_clear();
    let rel = match find_relations(&path, args.grid.relations.as_deref()) {
        Some(r) => Some(relation_error(&run, &relations::read(&r)?)),
        None => None,
    };
    let name = path
        .file_name()
        .map_or_else(|| file.clone(), |n| n.to_string_lossy().to_string());
    let wall = start.elapsed().as_secs_f64();
    let metrics = metrics_json(&name, &run, &options, rel, None, wall);
    write_outputs(&args.out, &run, &options.config, &metrics)?;
    report(quiet, &name, &metrics, &args.out);
    Ok(())
}
