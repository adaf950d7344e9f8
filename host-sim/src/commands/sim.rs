//! `host-sim sim`: the built-in deterministic simulator — the landmark field through the
//! landmark EKF-SLAM, then grid SLAM (from the true start pose) and the grid localizer (on
//! the true map, the wall segments rasterised) in the lidar world, scored against ground
//! truth.

use super::replay::run_and_report;
use crate::domain::AssociationMode;
use crate::domain::Precision;
use crate::domain::config::Settings;
use crate::domain::grid::{FilterRole, GlobalOptions, Preset};
use crate::drivers::grid::{
    GridRunOptions, f32_pose, run_localizer_observed, run_slam_observed, sim_inputs,
};
use crate::inputs::sim::lidar_world::{LidarRecording, SIM_GRID_BITMAP, SIM_GRID_CELLS, true_map};
use crate::inputs::sim::simulate;
use crate::metrics::grid::{ate_m, ate_se2_m, odometry_ate_m, yaw_rmse_deg};
use crate::output::animation::{Animation, AnimationSettings, write_gif};
use crate::output::grid_map::write_outputs;
use crate::output::write_tum;
use anyhow::{Result, anyhow, bail};
use microslam::geometry::Pose2;
use microslam::pf::GridPfConfig;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `host-sim sim`.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Seed of the noise generator: the same seed gives the same run.
    pub seed: u64,
    /// Output folder.
    pub out: PathBuf,
    /// Data association.
    pub association: AssociationMode,
    /// Estimator and scenario settings (TOML); default `host-sim/configs/sim.toml`.
    pub config: Option<PathBuf>,
    /// Scalar the filter runs on.
    pub precision: Precision,
    /// Skip the PNG pictures.
    pub no_plots: bool,
    /// Animated GIF of grid SLAM building the lidar world's map.
    pub animate: Option<PathBuf>,
    /// Particles of the grid filters in the lidar world (one of [`SIM_PARTICLES`]; 0
    /// skips the grid scenario).
    pub grid_particles: usize,
    /// Settings of the grid filters (default: [`Preset::for_particles`]).
    pub grid_preset: Option<Preset>,
    /// Grid filter settings (TOML, [`crate::domain::grid::GridToml`]) laid over the
    /// preset.
    pub grid_config: Option<PathBuf>,
    /// Global localization trials on the grid SLAM map (when enabled).
    pub global: GlobalOptions,
    /// Record the runs into this MCAP file (topics under `/ekf`, `/grid_slam`,
    /// `/grid_localize`).
    pub mcap: Option<PathBuf>,
    /// Drive the landmark field with the settings' car (`[vehicle]`, its sensor
    /// `[scenario] car_sensor_ahead_m` ahead of the rear axle) instead of the
    /// differential-drive robot.
    pub car: bool,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            seed: 1,
            out: PathBuf::from("out/sim"),
            association: AssociationMode::Known,
            config: None,
            precision: Precision::F64,
            no_plots: false,
            animate: None,
            grid_particles: 200,
            grid_preset: None,
            grid_config: None,
            global: GlobalOptions::default(),
            mcap: None,
            car: false,
        }
    }
}

/// `host-sim sim`: simulate, replay, score, write the results — the landmark EKF-SLAM
/// scenario into `out/`, then (unless `--grid-particles 0`) grid SLAM and the grid
/// localizer in the lidar world into `out/grid/slam/` and `out/grid/localize/`.
pub fn run_cli(args: &SimOptions, quiet: bool) -> Result<()> {
    let started = std::time::Instant::now();
    let mut settings = Settings::load_for("sim", args.config.as_deref(), Some(args.association))?;
    let recording = if args.car {
        let ahead = settings
            .scenario
            .as_ref()
            .map_or(0.0, |s| s.car_sensor_ahead_m);
        settings.sighting.mount = [ahead, 0.0, 0.0];
        crate::inputs::sim::simulate_car(&settings, args.seed)?
    } else {
        simulate(&settings, args.seed)?
    };
    let mut mcap = super::open_mcap(args.mcap.as_deref())?;
    run_and_report(
        &recording,
        &settings,
        args.association,
        args.precision,
        &args.out,
        !args.no_plots,
        quiet,
        started,
        None,
        mcap.as_mut().map(|f| (f, "ekf")),
    )?;
    if args.grid_particles == 0 {
        return super::close_mcap(mcap, quiet);
    }
    let world = crate::inputs::sim::lidar_world::LidarWorld::office();
    let rec = crate::inputs::sim::lidar_world::simulate(&world, args.seed)?;
    let preset = args
        .grid_preset
        .unwrap_or_else(|| Preset::for_particles(args.grid_particles));
    // SLAM's settings and the localizer's (the same but for the shift window), the
    // filter seeded with the world's seed.
    let [config, localizer] = [FilterRole::Slam, FilterRole::Localizer].map(|role| {
        preset
            .settings(args.grid_config.as_deref(), None, rec.lidar_beams(), role)
            .map(|c| microslam::pf::GridPfConfig {
                filter: microslam::pf::FilterConfig {
                    seed: args.seed,
                    ..c.filter
                },
                ..c
            })
    });
    let (config, localizer) = (config?, localizer?);
    let loop_closure = crate::domain::grid::loop_closure_settings(
        args.grid_config.as_deref(),
        false,
        FilterRole::Slam,
    )?;
    let out = args.out.join("grid");
    let (slam, loc) = run_and_write(
        &rec,
        [config, localizer],
        loop_closure,
        args.grid_particles,
        SimGridOutputs {
            dir: &out,
            mcap: mcap.as_mut(),
            animate: args.animate.as_deref(),
            plots: !args.no_plots,
        },
    )?;
    if args.global.enabled {
        super::global::sim_cli(
            &rec,
            localizer,
            args.grid_particles,
            &args.global,
            &out,
            quiet,
        )?;
    }
    if !quiet {
        println!(
            "{}: {} scans, {} particles, dead reckoning ATE {:.3} m",
            rec.name,
            rec.scans.len(),
            args.grid_particles,
            slam["odometry_ate_rmse_m"].as_f64().unwrap_or(f64::NAN)
        );
        for (what, m) in [("grid SLAM", &slam), ("grid localizer (true map)", &loc)] {
            println!(
                "  {what}: ATE {:.3} m (se2-aligned {:.3} m), yaw {:.2}°, {:.2} ms/scan",
                m["ate_rmse_m"].as_f64().unwrap_or(f64::NAN),
                m["ate_se2_m"].as_f64().unwrap_or(f64::NAN),
                m["yaw_rmse_deg"].as_f64().unwrap_or(f64::NAN),
                m["ms_per_scan"].as_f64().unwrap_or(f64::NAN)
            );
        }
        println!("  outputs in {}", out.display());
    }
    super::close_mcap(mcap, quiet)
}

/// Particle counts `host-sim sim --grid-particles` accepts.
pub const SIM_PARTICLES: [usize; 4] = [16, 32, 64, 200];

/// Where [`run_and_write`] puts what the grid runs of the simulator produce.
pub struct SimGridOutputs<'a> {
    /// The folder of `slam/` and `localize/`.
    pub dir: &'a Path,
    /// The MCAP file both runs are recorded into (under `/grid_slam` and `/grid_localize`).
    pub mcap: Option<&'a mut crate::output::mcap::McapFile>,
    /// An animated GIF of SLAM building the map.
    pub animate: Option<&'a Path>,
    /// Draw each run's `map.png`.
    pub plots: bool,
}

/// Runs SLAM (closing loops with `loop_closure` when given) and the localizer with
/// `particles` particles and their settings `configs` (SLAM's, the localizer's), writing
/// `slam/` and `localize/` into `outputs.dir` (map.pgm, map.yaml, trajectory.tum,
/// groundtruth.tum, metrics.json, and map.png when `outputs.plots`), recording both into
/// `outputs.mcap` and drawing `outputs.animate` when given. Returns the two metrics
/// documents.
pub fn run_and_write(
    rec: &LidarRecording,
    configs: [GridPfConfig; 2],
    loop_closure: Option<microslam::slam::GraphSlamConfig>,
    particles: usize,
    outputs: SimGridOutputs<'_>,
) -> Result<(serde_json::Value, serde_json::Value)> {
    let SimGridOutputs {
        dir: out,
        mut mcap,
        animate,
        plots,
    } = outputs;
    let started = Instant::now();
    if !SIM_PARTICLES.contains(&particles) {
        bail!("--grid-particles {particles} is not compiled in; use one of {SIM_PARTICLES:?}");
    }
    let first = rec.scans.first().ok_or_else(|| anyhow!("no scans"))?;
    let start = f32_pose(&first.truth);
    let inputs = sim_inputs(rec);
    let [config, localizer] = configs;
    let options = GridRunOptions {
        particles,
        config,
        lidar: rec.lidar,
        loop_closure,
        // The simulated world lies around its start.
        grid_origin: None,
        max_odometry_step_m: crate::domain::grid::MAX_ODOMETRY_STEP_M,
    };
    let animation = AnimationSettings::default();
    let every = animate.map_or(0, |_| animation.snapshot_every(inputs.len()));
    let truth_poses: Vec<Pose2<f64>> = rec.scans.iter().map(|s| s.truth).collect();
    let n = inputs.len();
    let lo = config.log_odds;
    let slam = super::recorded_grid_run(
        mcap.as_deref_mut(),
        "grid_slam",
        n,
        lo,
        &truth_poses,
        true,
        |o| {
            run_slam_observed::<SIM_GRID_CELLS, SIM_GRID_BITMAP>(
                &inputs,
                start,
                &options,
                &|_| {},
                o,
                every,
            )
        },
    )?;
    let slam_wall = started.elapsed().as_secs_f64();
    let map = true_map(&rec.world.walls, &config);
    let view = map.view();
    let started = Instant::now();
    let localizer_options = GridRunOptions {
        config: localizer,
        loop_closure: None,
        ..options.clone()
    };
    let loc = super::recorded_grid_run(mcap, "grid_localize", n, lo, &truth_poses, false, |o| {
        run_localizer_observed(&inputs, &view, start, &localizer_options, &|_| {}, o)
    })?;
    let loc_wall = started.elapsed().as_secs_f64();
    let truth: Vec<(f64, Pose2<f32>)> = rec
        .scans
        .iter()
        .map(|s| (s.stamp, f32_pose(&s.truth)))
        .collect();
    let odometry_ate = odometry_ate_m(rec);
    let mut docs = Vec::new();
    for (name, run, wall, what, config) in [
        (
            "slam",
            &slam,
            slam_wall,
            "grid SLAM from the true start pose",
            config,
        ),
        (
            "localize",
            &loc,
            loc_wall,
            "grid localizer on the true map (walls rasterised)",
            localizer,
        ),
    ] {
        let dir = out.join(name);
        let scans = run.trajectory.len();
        let mut metrics = serde_json::json!({
            "dataset": rec.name,
            "estimator": what,
            "scans": scans,
            "particles": particles,
            "beams": rec.lidar_beams(),
            "ate_rmse_m": ate_m(rec, &run.trajectory),
            "ate_alignment": "none (the filter starts at the true start pose)",
            "ate_se2_m": ate_se2_m(rec, &run.trajectory),
            "yaw_rmse_deg": yaw_rmse_deg(rec, &run.trajectory),
            "odometry_ate_rmse_m": odometry_ate,
            "wall_time_s": wall,
            "filter_time_s": run.filter_time_s,
            "ms_per_scan": 1e3 * run.filter_time_s / scans.max(1) as f64,
            "skipped_scans": run.skipped_scans,
            "window": 2 * u32::from(config.filter.shift_window_cells) + 1,
            "beam_decimation": config.beam_decimation,
            "range_weight_exponent": config.range_weight_exponent,
            "seed": config.filter.seed,
            "localizer": run.localizer,
            "loop_closure": run.loop_closure.map(|summary| serde_json::json!({
                "settings": options.loop_closure.map(|g| microslam::slam::GraphSlamConfig {
                grid: options.config,
                ..g
            }),
                "summary": summary,
            })),
        });
        crate::output::drop_absent(&mut metrics, &["localizer", "loop_closure"]);
        write_outputs(&dir, run, &config, &metrics, Some(&truth), plots)?;
        write_tum(
            &dir.join("groundtruth.tum"),
            truth.iter().map(|(t, p)| (*t, p.cast())),
        )?;
        docs.push(metrics);
    }
    if let Some(path) = animate {
        let title = format!("Grid SLAM: {}", rec.name);
        write_gif(
            path,
            &Animation {
                run: &slam,
                inputs: &inputs,
                lidar: &rec.lidar,
                log_odds: &config.log_odds,
                truth: Some(&truth),
                title: &title,
            },
            &animation,
        )?;
    }
    let loc_doc = docs.pop().unwrap_or_default();
    let slam_doc = docs.pop().unwrap_or_default();
    Ok((slam_doc, loc_doc))
}
