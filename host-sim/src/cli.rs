//! Layer 6, the top: the command line (`host-sim [replay|localize|sim|hil|sweep|texture|detections|export-rosbag]
//! …`), clap only. Each subcommand's arguments are converted into the options struct of
//! its module in [`crate::commands`]; nothing below this file imports it.

use crate::commands::detections::DetectionsOptions;
use crate::commands::localize::LocalizeOptions;
use crate::commands::replay::ReplayOptions;
use crate::commands::sim::SimOptions;
use crate::commands::sweep::SweepOptions;
use crate::commands::texture::TextureOptions;
use crate::commands::{detections, hil, localize, replay, sim, sweep, texture};
use crate::domain::grid::{FilterRole, GlobalOptions, GridOptions, SUPPORTED_PARTICLES};
use crate::domain::{AssociationMode, FilterKind, Precision};
use crate::inputs::faults::FaultRates;
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::rosbag::BagOptions;
use anyhow::Result;
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

mod hil_args;
pub use hil_args::HilArgs;

/// Replay recorded datasets and simulations through the microslam estimators.
///
/// Without a subcommand, runs the built-in simulator scenario (`host-sim sim`) and writes
/// its results to `out/sim`.
#[derive(Debug, Parser)]
#[command(name = "host-sim", version, about, long_about = None)]
pub struct Cli {
    /// No progress bar and no summary: for scripts.
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// What to do (default: `sim`).
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Replay a recorded dataset and score it against ground truth: MRCLAM through the
    /// landmark EKF-SLAM, CARMEN lidar logs through grid SLAM, THOR encoders + IMU as
    /// dead reckoning.
    Replay(ReplayArgs),
    /// Run the built-in deterministic simulator: a landmark field through the landmark
    /// EKF-SLAM, and a world of walls with a lidar through grid SLAM and the grid
    /// localizer; score both against ground truth.
    Sim(SimArgs),
    /// Stream a dataset to the firmware (under QEMU or on a board) and compare its
    /// estimates with the host's, bit for bit.
    Hil(HilArgs),
    /// Replay a grid of settings (a settings file whose keys may hold lists) on a list of
    /// recordings in parallel, e.g. `sweep -g grid.toml -r mrclam:dataset6/robot1-5`;
    /// writes sweep.csv and sweep.json (one row per settings × recording, mean and worst
    /// per settings).
    Sweep(SweepArgs),
    /// Localize on a saved grid map (`map.yaml` from `replay --filter grid-slam`) with the
    /// grid particle filter.
    Localize(LocalizeArgs),
    /// Convert a ROS map (`map.yaml` + PGM) into the firmware's map image (what
    /// `MICROSLAM_MAP=<map.yaml>` embeds in the firmware).
    ExportMap(ExportMapArgs),
    /// Coloured floor map from simulated RGB-D frames (`--dataset sim`), scored against the
    /// simulator's true floor texture.
    Texture(TextureArgs),
    /// Sign detections (box centre + depth, wrong class ids) → range/bearing → EKF-SLAM on
    /// the simulator; ATE and the share of wrong class ids the association corrected.
    Detections(DetectionsArgs),
    /// Write a CARMEN log as a ROS 2 bag (MCAP: LaserScan, Odometry, /tf_static), e.g.
    /// for `replay --dataset rosbag:<file.mcap>`.
    ExportRosbag(ExportRosbagArgs),
    /// Write a landmark recording (`mrclam:<dir>/robotN`, `landmarks:<file>`) as a plain
    /// landmark log (docs/guide.md), for `replay --dataset landmarks:<file>`.
    ExportLandmarks(ExportLandmarksArgs),
    /// Write a CARMEN log's front scans as the byte stream of an LDROBOT LD06 lidar (one
    /// revolution a scan), to feed a board's lidar UART with a recording.
    ExportLd06(ExportLd06Args),
}

/// Options of `host-sim export-ld06`.
#[derive(Debug, Clone, Args)]
pub struct ExportLd06Args {
    /// The CARMEN log: `carmen:<log>`, e.g. `carmen:intel/intel-raw-part.clf` (beams 1° or
    /// 0.5° apart).
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// The byte stream to write.
    #[arg(long, short, default_value = "out/ld06.bin")]
    pub out: PathBuf,
    /// Write only the first N scans.
    #[arg(long)]
    pub scans: Option<usize>,
}

/// Options of `host-sim export-landmarks`.
#[derive(Debug, Clone, Args)]
pub struct ExportLandmarksArgs {
    /// The recording: `mrclam:<dir>` (e.g. `mrclam:dataset6/robot3`), `landmarks:<file>`
    /// or `rosbag:<bag>` (ArucoMarkers or Detection3DArray detections, mounted on the
    /// robot through the bag's `/tf_static`).
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// Robot whose log is written (MRCLAM; a `/robotN` in the dataset wins).
    #[arg(long, default_value_t = 1)]
    pub robot: u8,
    /// The plain landmark log to write.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Topics of a `rosbag:` dataset.
    #[command(flatten)]
    pub bag: BagArgs,
}

/// Topics and lidar mount of a ROS 2 bag (`rosbag:<bag>`, `export-rosbag`).
#[derive(Debug, Clone, Args)]
pub struct BagArgs {
    /// `sensor_msgs/msg/LaserScan` topic.
    #[arg(long, default_value = "/scan")]
    pub scan_topic: String,
    /// `nav_msgs/msg/Odometry` topic.
    #[arg(long, default_value = "/odom")]
    pub odom_topic: String,
    /// `sensor_msgs/msg/Imu` topic (read when the bag has it).
    #[arg(long, default_value = "/imu")]
    pub imu_topic: String,
    /// Static transforms topic (the lidar mount, when the bag has it).
    #[arg(long, default_value = "/tf_static")]
    pub tf_static_topic: String,
    /// Lidar mount `x,y,yaw` (m, m, rad) in the robot frame; overrides /tf_static.
    #[arg(long, value_parser = mount, allow_negative_numbers = true)]
    pub lidar_mount: Option<[f64; 3]>,
    /// Landmark detections topic (`ros2_aruco_interfaces/msg/ArucoMarkers` or
    /// `vision_msgs/msg/Detection3DArray`); default: the one topic of either type.
    #[arg(long)]
    pub detections_topic: Option<String>,
    /// Ground-truth topic of a landmark bag (`nav_msgs/msg/Odometry`, read when present).
    #[arg(long, default_value = "/ground_truth")]
    pub truth_topic: String,
    /// What of the odometry drives a landmark bag's run: `twist` (velocities), `pose`
    /// (increments between poses), `pose-rates` (the velocities between poses) or `auto`
    /// (the twist, unless it is always zero: then `pose-rates`).
    #[arg(long, default_value = "auto")]
    pub odom_motion: crate::inputs::readers::detections_bag::OdomMotion,
}

fn mount(text: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{e}"))?;
    <[f64; 3]>::try_from(v).map_err(|_| "expected x,y,yaw".to_owned())
}

impl From<&BagArgs> for BagOptions {
    fn from(a: &BagArgs) -> Self {
        Self {
            scan_topic: a.scan_topic.clone(),
            odom_topic: a.odom_topic.clone(),
            imu_topic: a.imu_topic.clone(),
            tf_static_topic: a.tf_static_topic.clone(),
            lidar_mount: a.lidar_mount,
            detections_topic: a.detections_topic.clone(),
            truth_topic: a.truth_topic.clone(),
            odom_motion: a.odom_motion,
        }
    }
}

/// Options of `host-sim export-rosbag`.
#[derive(Debug, Clone, Args)]
pub struct ExportRosbagArgs {
    /// The CARMEN log: `carmen:<log>`, e.g. `carmen:intel/intel-raw-part.clf`.
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// The bag to write.
    #[arg(long, short, default_value = "out/rosbag.mcap")]
    pub out: PathBuf,
    /// Topics (and lidar mount) of the bag.
    #[command(flatten)]
    pub bag: BagArgs,
}

/// A particle count the grid filters are compiled for ([`SUPPORTED_PARTICLES`]).
fn particle_count(text: &str) -> Result<usize, String> {
    let n: usize = text.parse().map_err(|e| format!("{e}"))?;
    if SUPPORTED_PARTICLES.contains(&n) {
        Ok(n)
    } else {
        Err(format!(
            "{n} particles are not compiled in; use one of {SUPPORTED_PARTICLES:?}"
        ))
    }
}

/// [`particle_count`], or 0 for none.
fn particle_count_or_none(text: &str) -> Result<usize, String> {
    if text.trim() == "0" {
        return Ok(0);
    }
    particle_count(text)
}

/// Options of the grid particle filter shared by `replay` and `localize`.
#[derive(Debug, Clone, Args)]
pub struct GridArgs {
    /// Particles of the grid filter: 8, 16, 32, 64, 100, 128, 200 or 400.
    #[arg(long, default_value_t = 200, value_parser = particle_count)]
    pub particles: usize,
    /// Half-width k of the (2k+1)² shift window, cells (default: 4, a 9 × 9 window, for
    /// SLAM; 1, 3 × 3, for `localize`).
    #[arg(long)]
    pub window: Option<u8>,
    /// Beams used per scan, 1 up to the log's (every n-th beam is kept; default all).
    #[arg(long)]
    pub beams: Option<usize>,
    /// Benchmark relations file (default: the `*.relations` file next to the log; without
    /// one, a note says the relation error is not computed).
    #[arg(long)]
    pub relations: Option<PathBuf>,
    /// Named settings (default: `microcontroller` below 100 particles, `default` from
    /// 100 on); a `--config` file's `base` key takes precedence.
    #[arg(long, value_enum)]
    pub preset: Option<crate::domain::grid::Preset>,
    /// Reference trajectory for ATE (global consistency): a TUM file or a corrected
    /// CARMEN log (e.g. `intel/intel.gfs.log`), matched to the scans by stamp.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Seconds added to the reference's stamps (976052857.337 for `intel.gfs.log`
    /// against `intel-raw-part.clf`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub reference_offset: f64,
    /// Grid SLAM closes loops: keyframes, a match of each against the map built near it
    /// long before, a pose graph; the trajectory written is the graph's. Settings: the
    /// `[loop_closure]` table of `--config` (which also turns it on).
    #[arg(long)]
    pub loop_closure: bool,
}

/// Options of `host-sim localize`.
#[derive(Debug, Clone, Args)]
pub struct LocalizeArgs {
    /// The map: `map.yaml` (ROS map_server) next to its PGM.
    #[arg(long)]
    pub map: PathBuf,
    /// Dataset: `carmen:<log>` (a CARMEN log file, or a path under `$SLAM_DATASETS/carmen`,
    /// e.g. `carmen:intel/intel-raw-part.clf`) or `rosbag:<bag>` (a ROS 2 bag: an `.mcap`
    /// or `.db3` file, plain or zstd-compressed, or a rosbag2 bag folder; its topics:
    /// `--scan-topic`, `--odom-topic`).
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// Grid filter settings (TOML): `base = "default" | "untuned" | "microcontroller"` and any
    /// field to override, e.g. `shift_window_cells = 3` (see docs/guide.md).
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Grid filter options.
    #[command(flatten)]
    pub grid: GridArgs,
    /// Output folder.
    #[arg(long, short, default_value = "out/localize")]
    pub out: PathBuf,
    /// Skip the picture of the map with the trajectory (`map.png`).
    #[arg(long)]
    pub no_plots: bool,
    /// Global localization trials instead of one tracked run.
    #[command(flatten)]
    pub global: GlobalArgs,
    /// Record the run into this MCAP file (Foxglove schemas).
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    /// ROS 2 bag topics (`rosbag:` datasets).
    #[command(flatten)]
    pub bag: BagArgs,
}

/// Options of global localization trials (`host-sim localize --global`,
/// `host-sim sim --global`).
#[derive(Debug, Clone, Args)]
pub struct GlobalArgs {
    /// Run global localizations from random start scans without a pose, scored against
    /// the localizer tracked from the true start; writes `metrics.json` with `global`.
    #[arg(long)]
    pub global: bool,
    /// Number of trials.
    #[arg(long, default_value_t = 20)]
    pub trials: usize,
    /// Seed of the random start scans.
    #[arg(long, default_value_t = 1)]
    pub trial_seed: u64,
    /// Scans a trial may take to converge.
    #[arg(long, default_value_t = 10)]
    pub max_scans: usize,
    /// Levels of the max-pooled map layers (windows up to 2^levels cells).
    #[arg(long, default_value_t = 6)]
    pub levels: u8,
    /// Work budget of the global search, in beams looked at plus `NODE_WORK` per node
    /// (default: the core's); with `--search-scans`, of each scan's slice of it.
    #[arg(long)]
    pub work_budget: Option<u32>,
    /// Scans one global search may span, a work budget each (default: the core's).
    #[arg(long)]
    pub search_scans: Option<u8>,
    /// Smallest score of a hypothesis, a fraction of the beams' total weight (default:
    /// the core's).
    #[arg(long)]
    pub min_score: Option<f32>,
    /// Beams farther than this are left out of the search, metres (default: the core's).
    #[arg(long)]
    pub search_range: Option<f32>,
    /// Beams the search uses at most (default: the core's).
    #[arg(long)]
    pub search_beams: Option<u16>,
    /// Particles spread over this many hypotheses (default: the core's).
    #[arg(long)]
    pub hypotheses: Option<u8>,
    /// Peaks of the wall-direction correlation whose headings the search visits; 0:
    /// every heading (default: the core's).
    #[arg(long)]
    pub heading_peaks: Option<u8>,
    /// Half-width of the heading window around each peak, degrees (default: the core's).
    #[arg(long)]
    pub heading_window: Option<f32>,
    /// Minimum score of the search's first pass, a fraction of the beams' total weight
    /// (default: the core's).
    #[arg(long)]
    pub first_pass: Option<f32>,
    /// Search every heading when the windows find no hypothesis scoring this fraction of
    /// the beams' total weight; 0: never (default: the core's).
    #[arg(long)]
    pub full_turn_below: Option<f32>,
    /// Run the reference and the trials on the map's occupied-cell bitmap alone, as the
    /// firmware holds it (a map image carries no log-odds: its search takes the cells
    /// that are not occupied in a free 2 × 2 block as free); the layers are made from
    /// the cells as `host-sim export-map` makes them.
    #[arg(long)]
    pub bitmap_only: bool,
}

impl From<&GlobalArgs> for GlobalOptions {
    fn from(a: &GlobalArgs) -> Self {
        Self {
            enabled: a.global,
            trials: a.trials,
            trial_seed: a.trial_seed,
            max_scans: a.max_scans,
            levels: a.levels,
            work_budget: a.work_budget,
            search_scans: a.search_scans,
            min_score: a.min_score,
            search_range: a.search_range,
            search_beams: a.search_beams,
            hypotheses: a.hypotheses,
            heading_peaks: a.heading_peaks,
            heading_window_deg: a.heading_window,
            first_pass: a.first_pass,
            full_turn_below: a.full_turn_below,
            bitmap_only: a.bitmap_only,
        }
    }
}

/// Options of `host-sim replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// Dataset: `mrclam:<dir>` (landmarks), `carmen:<log>` or `rosbag:<bag>` (lidar; a
    /// ROS 2 bag: an `.mcap` or `.db3` file, plain or zstd-compressed, or a rosbag2 bag
    /// folder, its topics:
    /// `--scan-topic`, `--odom-topic`; a bag with ArucoMarkers or Detection3DArray
    /// detections is a landmark recording: `--detections-topic`) or `thor:<dir>`
    /// (encoders + IMU): a path, or a name under `$SLAM_DATASETS/<family>`, e.g.
    /// `mrclam:dataset6`, `carmen:intel/intel-raw-part.clf`, `thor:thor`;
    /// `mrclam:dataset6/robot3` picks the robot (overrides `--robot`).
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// Robot whose log is replayed (1–5 in MRCLAM).
    #[arg(long, default_value_t = 1)]
    pub robot: u8,
    /// Data association (default: from the config file, `known` if none).
    #[arg(long, short)]
    pub association: Option<AssociationMode>,
    /// Estimator settings (TOML); default: the built-in defaults of the dataset
    /// (`host-sim/configs/<family>.toml`).
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Output folder for metrics.json, trajectories and pictures.
    #[arg(long, short, default_value = "out/replay")]
    pub out: PathBuf,
    /// Scalar the filter runs on.
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Skip the PNG pictures (faster).
    #[arg(long)]
    pub no_plots: bool,
    /// Write an animated GIF of the grid map being built (grid runs; docs/guide.md).
    #[arg(long, value_name = "FILE.gif")]
    pub animate: Option<PathBuf>,
    /// Estimator: `ekf-slam` (landmark datasets) or `grid-slam` (lidar datasets; the
    /// default for `carmen:` and `thor:`).
    #[arg(long, value_enum)]
    pub filter: Option<FilterKind>,
    /// Grid filter options.
    #[command(flatten)]
    pub grid: GridArgs,
    /// THOR run number (`thor:` datasets: 20 or 21).
    #[arg(long, default_value_t = 20)]
    pub run: u32,
    /// Inject faults before the replay, e.g.
    /// `drop=0.01,duplicate=0.01,reorder=0.01,nan=0.01,spike=0.01,backwards=0.01,stuck=0.01`
    /// or `all=0.01`: into the event stream (landmark datasets) or the laser messages
    /// (`carmen:` logs; `stuck` repeats the previous scan, for lidar logs only); what was
    /// injected is reported in `metrics.json`.
    #[arg(long)]
    pub faults: Option<FaultRates>,
    /// Seed of the fault generator.
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
    /// Record the run into this MCAP file (Foxglove schemas; open it in Foxglove).
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    /// ROS 2 bag topics (`rosbag:` datasets).
    #[command(flatten)]
    pub bag: BagArgs,
}

/// Options of `host-sim sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The grid: a settings file whose keys may hold lists of values (their Cartesian
    /// product is replayed). Without it, the built-in settings alone.
    #[arg(long, short)]
    pub grid: Option<PathBuf>,
    /// Recordings, comma-separated: `mrclam:dataset6/robot1,mrclam:dataset6/robot2`;
    /// `mrclam:dataset6/robot1-5` names a range of robots.
    #[arg(long, short, value_delimiter = ',', required = true)]
    pub runs: Vec<String>,
    /// Data association (default: from the settings, `known` if none).
    #[arg(long, short)]
    pub association: Option<AssociationMode>,
    /// Scalar the filter runs on.
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Output folder: sweep.csv, sweep.json.
    #[arg(long, short, default_value = "out/sweep")]
    pub out: PathBuf,
}

impl From<&SweepArgs> for SweepOptions {
    fn from(a: &SweepArgs) -> Self {
        Self {
            grid: a.grid.clone(),
            runs: a.runs.clone(),
            association: a.association,
            precision: a.precision,
            out: a.out.clone(),
        }
    }
}

/// Options of `host-sim sim`.
#[derive(Debug, Clone, Args)]
pub struct SimArgs {
    /// Seed of the noise generator: the same seed gives the same run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder.
    #[arg(long, short, default_value = "out/sim")]
    pub out: PathBuf,
    /// Data association.
    #[arg(long, short, value_enum, default_value_t = AssociationMode::Known)]
    pub association: AssociationMode,
    /// Estimator and scenario settings (TOML); default `host-sim/configs/sim.toml`.
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Scalar the filter runs on.
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Skip the PNG pictures.
    #[arg(long)]
    pub no_plots: bool,
    /// Write an animated GIF of grid SLAM building the lidar world's map.
    #[arg(long, value_name = "FILE.gif")]
    pub animate: Option<PathBuf>,
    /// Particles of the grid filters in the lidar world: 8, 16, 32, 64, 100, 128, 200 or
    /// 400; 0 skips the grid scenario.
    #[arg(long, default_value_t = 200, value_parser = particle_count_or_none)]
    pub grid_particles: usize,
    /// Settings of the grid filters in the lidar world (default: by particle count, as
    /// for `replay --preset`).
    #[arg(long, value_enum)]
    pub grid_preset: Option<crate::domain::grid::Preset>,
    /// Grid filter settings for the lidar world (TOML, see `GridToml`), laid over the
    /// preset.
    #[arg(long)]
    pub grid_config: Option<PathBuf>,
    /// Global localization trials on the grid SLAM map of the lidar world (written to
    /// `out/grid/global/`).
    #[command(flatten)]
    pub global: GlobalArgs,
    /// Record the runs into this MCAP file (topics under /ekf, /grid_slam, /grid_localize).
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    /// Drive the landmark field with a car (speed and steering, `[vehicle]` of the
    /// settings) whose sensor sits `[scenario] car_sensor_ahead_m` ahead of the rear axle,
    /// instead of the differential-drive robot.
    #[arg(long)]
    pub car: bool,
}

/// Options of `host-sim export-map`.
#[derive(Debug, Clone, Args)]
pub struct ExportMapArgs {
    /// The map: `map.yaml` (ROS map_server) next to its PGM.
    #[arg(long)]
    pub map: PathBuf,
    /// The map image to write.
    #[arg(long, short, default_value = "out/map.bin")]
    pub out: PathBuf,
    /// Levels of the global search's max-pooled layers in the image (0: none).
    #[arg(long, default_value_t = microslam::grid::map_image::DEFAULT_LAYER_LEVELS)]
    pub levels: u8,
}

/// Options of `host-sim detections`.
#[derive(Debug, Clone, Args)]
pub struct DetectionsArgs {
    /// Seed of the simulation (trajectory, odometry noise, sign heights, detector noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Share of detections with a wrong class id.
    #[arg(long, default_value_t = 0.15)]
    pub wrong_class_share: f64,
    /// Number of signs (default: the `sim.toml` scenario's 24 landmarks).
    #[arg(long)]
    pub signs: Option<u32>,
    /// Smallest distance between two signs, metres (default: the scenario's 0.8 m).
    #[arg(long)]
    pub min_spacing: Option<f64>,
    /// Output folder: metrics.json, map.png (geometry with class hints).
    #[arg(long, short, default_value = "out/detections")]
    pub out: PathBuf,
}

/// Options of `host-sim texture`.
#[derive(Debug, Clone, Args)]
pub struct TextureArgs {
    /// Dataset: only `sim` (the built-in simulator) is supported.
    #[arg(long, short, default_value = "sim")]
    pub dataset: String,
    /// Seed of the simulation.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Floor height band, metres: points with a world height in [LOW, HIGH] are floor
    /// (Du n.d., the grid particle filter paper, used −0.5 0.25).
    #[arg(long, num_args = 2, value_names = ["LOW", "HIGH"], allow_negative_numbers = true,
          default_values_t = [-0.1, 0.1])]
    pub band: Vec<f64>,
    /// Frames per second of the trajectory.
    #[arg(long, default_value_t = 2.0)]
    pub frame_rate: f64,
    /// Output folder: texture.png, texture_truth.png, texture_ekf.png, texture.json.
    #[arg(long, short, default_value = "out/texture")]
    pub out: PathBuf,
}

impl From<&GridArgs> for GridOptions {
    fn from(a: &GridArgs) -> Self {
        Self {
            particles: a.particles,
            window: a.window,
            beams: a.beams,
            relations: a.relations.clone(),
            preset: a.preset,
            reference: a.reference.clone(),
            reference_offset: a.reference_offset,
            loop_closure: a.loop_closure,
            role: FilterRole::Slam,
        }
    }
}

impl From<&ReplayArgs> for ReplayOptions {
    fn from(a: &ReplayArgs) -> Self {
        Self {
            dataset: a.dataset.clone(),
            robot: a.robot,
            association: a.association,
            config: a.config.clone(),
            out: a.out.clone(),
            precision: a.precision,
            no_plots: a.no_plots,
            animate: a.animate.clone(),
            filter: a.filter,
            grid: (&a.grid).into(),
            run: a.run,
            faults: a.faults,
            fault_seed: a.fault_seed,
            mcap: a.mcap.clone(),
            bag: (&a.bag).into(),
        }
    }
}

impl From<&LocalizeArgs> for LocalizeOptions {
    fn from(a: &LocalizeArgs) -> Self {
        Self {
            map: a.map.clone(),
            dataset: a.dataset.clone(),
            config: a.config.clone(),
            grid: GridOptions {
                role: FilterRole::Localizer,
                ..(&a.grid).into()
            },
            out: a.out.clone(),
            global: (&a.global).into(),
            mcap: a.mcap.clone(),
            bag: (&a.bag).into(),
            no_plots: a.no_plots,
        }
    }
}

impl From<&SimArgs> for SimOptions {
    fn from(a: &SimArgs) -> Self {
        Self {
            seed: a.seed,
            out: a.out.clone(),
            association: a.association,
            config: a.config.clone(),
            precision: a.precision,
            no_plots: a.no_plots,
            animate: a.animate.clone(),
            grid_particles: a.grid_particles,
            grid_preset: a.grid_preset,
            grid_config: a.grid_config.clone(),
            global: (&a.global).into(),
            mcap: a.mcap.clone(),
            car: a.car,
        }
    }
}

impl From<&TextureArgs> for TextureOptions {
    fn from(a: &TextureArgs) -> Self {
        Self {
            dataset: a.dataset.clone(),
            seed: a.seed,
            band: a.band.clone(),
            frame_rate: a.frame_rate,
            out: a.out.clone(),
        }
    }
}

impl From<&DetectionsArgs> for DetectionsOptions {
    fn from(a: &DetectionsArgs) -> Self {
        Self {
            seed: a.seed,
            wrong_class_share: a.wrong_class_share,
            signs: a.signs,
            min_spacing: a.min_spacing,
            out: a.out.clone(),
        }
    }
}

/// Runs what the command line asks for.
pub fn run(cli: &Cli) -> Result<()> {
    match &cli.command {
        Some(Command::Replay(args)) => replay::run_cli(&args.into(), cli.quiet),
        Some(Command::Sim(args)) => sim::run_cli(&args.into(), cli.quiet),
        Some(Command::Hil(args)) => hil::run_cli(&args.into(), cli.quiet),
        Some(Command::Sweep(args)) => sweep::run_cli(&args.into(), cli.quiet),
        Some(Command::Localize(args)) => localize::localize_cli(&args.into(), cli.quiet),
        Some(Command::ExportMap(args)) => {
            crate::commands::hil_localizer::export_cli(&args.map, &args.out, args.levels, cli.quiet)
        }
        Some(Command::Texture(args)) => texture::texture_cli(&args.into(), cli.quiet),
        Some(Command::Detections(args)) => detections::detections_cli(&args.into(), cli.quiet),
        Some(Command::ExportLandmarks(a)) => crate::commands::export_landmarks::export_cli(
            &a.dataset,
            a.robot,
            &(&a.bag).into(),
            &a.out,
            cli.quiet,
        ),
        Some(Command::ExportLd06(a)) => {
            crate::commands::ld06::export_cli(&a.dataset, &a.out, a.scans, cli.quiet)
        }
        Some(Command::ExportRosbag(a)) => {
            crate::commands::rosbag::export_cli(&a.dataset, &a.out, &(&a.bag).into(), cli.quiet)
        }
        None => sim::run_cli(&SimOptions::default(), cli.quiet),
    }
}
