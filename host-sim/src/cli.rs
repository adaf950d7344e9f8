//! The command line: `host-sim [replay|sim] …`. Each subcommand's work lives in its own
//! module; this file only parses and dispatches.

use crate::readers::DatasetSpec;
use anyhow::Result;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

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
    /// Replay a recorded dataset through the landmark EKF-SLAM and score it against
    /// ground truth.
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
    Sweep(crate::sweep::SweepArgs),
    /// Localize on a saved grid map (`map.yaml` from `replay --filter grid-slam`) with the
    /// grid particle filter.
    Localize(LocalizeArgs),
    /// Coloured floor map from simulated RGB-D frames (`--dataset sim`), scored against the
    /// simulator's true floor texture.
    Texture(crate::camera::TextureArgs),
    /// Sign detections (box centre + depth, wrong class ids) → range/bearing → EKF-SLAM on
    /// the simulator; ATE and the share of wrong class ids the association corrected.
    Detections(crate::camera::DetectionsArgs),
}

/// Which estimator a replay drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum FilterKind {
    /// Landmark EKF-SLAM (landmark datasets).
    #[default]
    EkfSlam,
    /// Grid particle-filter SLAM (lidar datasets).
    GridSlam,
}

/// Options of the grid particle filter shared by `replay` and `localize`.
#[derive(Debug, Clone, Args)]
pub struct GridArgs {
    /// Particles (grid filter).
    #[arg(long, default_value_t = 200)]
    pub particles: usize,
    /// Half-width k of the (2k+1)² shift window, cells (default 4: 9 × 9).
    #[arg(long)]
    pub window: Option<u8>,
    /// Beams used per scan (decimated from the log's; default all).
    #[arg(long)]
    pub beams: Option<usize>,
    /// Benchmark relations file (default: a `*.relations` file next to the log).
    #[arg(long)]
    pub relations: Option<PathBuf>,
}

/// Options of `host-sim localize`.
#[derive(Debug, Clone, Args)]
pub struct LocalizeArgs {
    /// The map: `map.yaml` (ROS map_server) next to its PGM.
    #[arg(long)]
    pub map: PathBuf,
    /// Dataset: `carmen:<file>`.
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// Grid filter settings (TOML, see `grid_replay::GridToml`).
    #[arg(long, short)]
    pub config: Option<PathBuf>,
    /// Grid filter options.
    #[command(flatten)]
    pub grid: GridArgs,
    /// Output folder.
    #[arg(long, short, default_value = "out/localize")]
    pub out: PathBuf,
}

/// How sightings are associated with landmarks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AssociationMode {
    /// The sighting's id (barcode) names the landmark.
    Known,
    /// Ids hidden; individual compatibility nearest neighbour (seed 1, Fig. 11).
    Icnn,
    /// Ids hidden; joint compatibility branch and bound over each batch of sightings.
    Jcbb,
}

/// Scalar the filter runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum Precision {
    /// Single precision, as on the microcontroller.
    F32,
    /// Double precision.
    #[default]
    F64,
}

/// Options of `host-sim replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// Dataset: `mrclam:<dir>` (a folder, or a name under `$SLAM_DATASETS/mrclam`, e.g.
    /// `mrclam:dataset6`); `mrclam:dataset6/robot3` picks the robot (overrides `--robot`).
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
    pub faults: Option<crate::faults::FaultRates>,
    /// Seed of the fault generator.
    #[arg(long, default_value_t = 1)]
    pub fault_seed: u64,
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
    /// Particles of the grid filters in the lidar world (16, 32, 64 or 200; 0 skips the
    /// grid scenario).
    #[arg(long, default_value_t = 200)]
    pub grid_particles: usize,
}

impl Default for SimArgs {
    fn default() -> Self {
        Self {
            seed: 1,
            out: PathBuf::from("out/sim"),
            association: AssociationMode::Known,
            config: None,
            precision: Precision::F64,
            no_plots: false,
            grid_particles: 200,
        }
    }
}

/// Options of `host-sim hil`.
#[derive(Debug, Clone, Args)]
#[command(group(clap::ArgGroup::new("link").required(true).args(["qemu", "serial"])))]
pub struct HilArgs {
    /// Run this firmware ELF under `qemu-system-arm` (mps2-an386).
    #[arg(long)]
    pub qemu: Option<PathBuf>,
    /// Talk to a board on this serial port (e.g. /dev/ttyACM0).
    #[arg(long)]
    pub serial: Option<String>,
    /// Baud rate of the serial port.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Dataset: `mrclam:<dir>` or `mrclam:<dir>/robot<k>`, as for `replay`.
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// Robot whose log is streamed (1–5 in MRCLAM).
    #[arg(long, default_value_t = 1)]
    pub robot: u8,
    /// Output folder: hil.json (the comparison) and firmware.tum (the device's trajectory).
    #[arg(long, short, default_value = "out/hil")]
    pub out: PathBuf,
    /// Give up waiting for replies after this many seconds.
    #[arg(long, default_value_t = 900)]
    pub timeout_s: u64,
    /// Corrupt this fraction of the frames sent (one byte each): the device must count
    /// exactly that many bad frames and still answer every other frame like the host.
    #[arg(long, default_value_t = 0.0)]
    pub corrupt_frames: f64,
    /// Seed of the frame corruption.
    #[arg(long, default_value_t = 1)]
    pub corrupt_seed: u64,
    /// Send the dataset's tuned EKF settings (`host-sim/configs/<dataset>.toml`, or
    /// `--config`) to the device first (`ConfigureEkf`), instead of running the
    /// firmware's own (`EkfConfig::MICROCONTROLLER`).
    #[arg(long)]
    pub dataset_settings: bool,
    /// EKF settings (TOML) laid over the dataset's defaults, with `--dataset-settings`.
    #[arg(long)]
    pub config: Option<PathBuf>,
}

/// Runs what the command line asks for.
pub fn run(cli: &Cli) -> Result<()> {
    match &cli.command {
        Some(Command::Replay(args)) => crate::replay::run_cli(args, cli.quiet),
        Some(Command::Sim(args)) => crate::sim::run_cli(args, cli.quiet),
        Some(Command::Hil(args)) => crate::hil::run_cli(args, cli.quiet),
        Some(Command::Sweep(args)) => crate::sweep::run_cli(args, cli.quiet),
        Some(Command::Localize(args)) => crate::grid_replay::localize_cli(args, cli.quiet),
        Some(Command::Texture(args)) => crate::camera::texture_cli(args, cli.quiet),
        Some(Command::Detections(args)) => crate::camera::detections_cli(args, cli.quiet),
        None => crate::sim::run_cli(&SimArgs::default(), cli.quiet),
    }
}
