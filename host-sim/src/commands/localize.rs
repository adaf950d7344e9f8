//! `host-sim localize`: the grid localizer on a saved map (`map.yaml` + PGM) over a
//! CARMEN log, scored with the relation metric when a relations file is found.

use super::replay::{RunOutputs, lidar_log, report, scan_progress_bar, score_and_write};
use crate::domain::grid::{GlobalOptions, GridOptions};
use crate::drivers::grid::{carmen_inputs, run_localizer_observed};
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::carmen::front_scans;
use crate::inputs::readers::map::LocalizationMap;
use crate::inputs::readers::rosbag::BagOptions;
use anyhow::Result;
use microslam::geometry::Pose2;
use std::path::PathBuf;
use std::time::Instant;

/// Options of `host-sim localize`.
#[derive(Debug, Clone)]
pub struct LocalizeOptions {
    /// The map: `map.yaml` (ROS map_server) next to its PGM.
    pub map: PathBuf,
    /// Dataset: `carmen:<file>`.
    pub dataset: DatasetSpec,
    /// Grid filter settings (TOML).
    pub config: Option<PathBuf>,
    /// Grid filter options.
    pub grid: GridOptions,
    /// Output folder.
    pub out: PathBuf,
    /// Global localization trials instead of one tracked run (when enabled).
    pub global: GlobalOptions,
    /// Record the run into this MCAP file (Foxglove schemas).
    pub mcap: Option<PathBuf>,
    /// Topics and lidar mount of `rosbag:` datasets.
    pub bag: BagOptions,
    /// Skip the picture (`map.png`).
    pub no_plots: bool,
}

/// `host-sim localize --map map.yaml --dataset carmen:<file>`.
pub fn localize_cli(args: &LocalizeOptions, quiet: bool) -> Result<()> {
    super::replay::bag_options_apply(&args.dataset, &args.bag)?;
    if args.global.enabled {
        return super::global::localize_cli(
            &args.map,
            &args.dataset,
            args.config.as_deref(),
            &args.grid,
            &args.global,
            &args.out,
            quiet,
        );
    }
    let start = Instant::now();
    let lidar = lidar_log(&args.dataset, args.config.as_deref(), &args.grid, &args.bag)?;
    let options = &lidar.options;
    let map = LocalizationMap::read(&args.map, &options.config)?;
    let view = map.view()?;
    let scans = front_scans(&lidar.log);
    let inputs = carmen_inputs(&scans);
    let pb = scan_progress_bar(scans.len(), quiet);
    // The SLAM map's frame is the pose of the log's first scan.
    let mut mcap = super::open_mcap(args.mcap.as_deref())?;
    let log_odds = options.config.log_odds;
    let run =
        super::recorded_grid_run(mcap.as_mut(), "", inputs.len(), log_odds, &[], false, |o| {
            run_localizer_observed(
                &inputs,
                &view,
                Pose2::IDENTITY,
                options,
                &|i| {
                    if i % 64 == 0 {
                        pb.set_position(i as u64);
                    }
                },
                o,
            )
        })?;
    pb.finish_and_clear();
    if run.off_grid_end_points > 0 {
        eprintln!(
            "note: {} end points of {} scans, seen from the estimate, lie outside the map \
             (the robot at or beyond its edge; metrics.json: grid)",
            run.off_grid_end_points, run.scans_off_grid
        );
    }
    let outputs = RunOutputs {
        dir: &args.out,
        plots: !args.no_plots,
    };
    let metrics = score_and_write(&lidar, &run, &args.grid, None, start, outputs)?;
    report(quiet, &lidar.name, &metrics, &args.out);
    super::close_mcap(mcap, quiet)
}
