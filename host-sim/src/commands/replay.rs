//! `host-sim replay`: a recorded dataset through the landmark EKF-SLAM (`mrclam:`) or
//! grid SLAM (`carmen:`), scored against ground truth, with `metrics.json`, trajectories
//! and pictures; `thor:` runs give the encoder + IMU dead reckoning.

use crate::domain::config::Settings;
use crate::domain::grid::{
    GRID_BITMAP, GRID_BITMAP_LARGE, GRID_CELLS, GRID_CELLS_LARGE, GRID_MARGIN_M, GridOptions,
    GridPlacement, OdometryExtent, Preset, ScanSpacing, carmen_lidar, loop_closure_settings,
};
use crate::domain::recording::Recording;
use crate::domain::{AssociationMode, FilterKind, Precision};
use crate::drivers::ekf::{PoseSample, replay_with};
use crate::drivers::grid::{GridRun, GridRunOptions, carmen_inputs, run_slam_observed};
use crate::inputs::faults::{FaultRates, FaultReport};
use crate::inputs::readers::carmen::{
    CarmenLog, LaserMessage, beam_count, front_scans, read_log, resolve_log,
};
use crate::inputs::readers::detections_bag;
use crate::inputs::readers::rosbag::{self, BagOptions};
use crate::inputs::readers::{DatasetSpec, thor};
use crate::metrics::PosePairs;
use crate::metrics::relations::RelationError;
use crate::output::animation::{Animation, AnimationSettings, write_gif};
use crate::output::grid_map::write_outputs;
use crate::output::write_tum;
use anyhow::{Result, bail};
use microslam::geometry::Pose2;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `host-sim replay`.
#[derive(Debug, Clone)]
pub struct ReplayOptions {
    /// Dataset: `mrclam:<dir>`, `carmen:<file>` or `thor:<dir>`.
    pub dataset: DatasetSpec,
    /// Robot whose log is replayed.
    pub robot: u8,
    /// Data association (default: from the config file, `known` if none).
    pub association: Option<AssociationMode>,
    /// Estimator settings (TOML); default: the built-in defaults of the dataset.
    pub config: Option<PathBuf>,
    /// Output folder for metrics.json, trajectories and pictures.
    pub out: PathBuf,
    /// Scalar the filter runs on.
    pub precision: Precision,
    /// Skip the PNG pictures (faster).
    pub no_plots: bool,
    /// Animated GIF of the grid map being built (grid runs).
    pub animate: Option<PathBuf>,
    /// Estimator (default: grid SLAM for `carmen:` and `thor:`, else the EKF).
    pub filter: Option<FilterKind>,
    /// Grid filter options.
    pub grid: GridOptions,
    /// THOR run number (`thor:` datasets: 20 or 21).
    pub run: u32,
    /// Faults injected before the replay.
    pub faults: Option<FaultRates>,
    /// Seed of the fault generator.
    pub fault_seed: u64,
    /// Record the run into this MCAP file (Foxglove schemas).
    pub mcap: Option<PathBuf>,
    /// Topics and lidar mount of `rosbag:` datasets.
    pub bag: BagOptions,
}

/// `host-sim replay`.
pub fn run_cli(args: &ReplayOptions, quiet: bool) -> Result<()> {
    bag_options_apply(&args.dataset, &args.bag)?;
    // A bag with a detections topic is a landmark recording; one without is a lidar bag.
    let landmark_bag = if args.filter == Some(FilterKind::GridSlam) {
        None
    } else {
        detections_bag::landmark_bag(&args.dataset, &args.bag)?
    };
    let lidar = landmark_bag.is_none()
        && matches!(
            args.dataset,
            DatasetSpec::Carmen(_) | DatasetSpec::Thor(_) | DatasetSpec::Rosbag(_)
        );
    let grid = args.filter == Some(FilterKind::GridSlam) || (args.filter.is_none() && lidar);
    let lidar_log = matches!(
        args.dataset,
        DatasetSpec::Carmen(_) | DatasetSpec::Rosbag(_)
    );
    if args.animate.is_some() && !(grid && lidar_log) {
        bail!(
            "--animate draws grid SLAM on a lidar log (carmen:<file> or rosbag:<bag>), not a {} replay",
            args.dataset.family()
        );
    }
    options_apply(args, grid)?;
    if grid {
        return grid_replay(args, quiet);
    }
    if lidar {
        bail!(
            "the landmark EKF-SLAM needs range-bearing sightings (mrclam:<dir>, landmarks:<file>, or rosbag:<bag> with ArucoMarkers or Detection3DArray detections); a {} replay has none: use --filter grid-slam",
            args.dataset.family()
        );
    }
    let started = Instant::now();
    let family = args.dataset.landmark_settings_family();
    let settings = Settings::load_for(family, args.config.as_deref(), args.association)?;
    let mut recording = match &landmark_bag {
        Some(path) => detections_bag::recording(path, &args.bag, settings.sighting.mount)?,
        None => crate::inputs::readers::read(&args.dataset, args.robot)?,
    };
    let faults = args.faults.filter(|f| !f.is_none()).map(|rates| {
        let (events, counts) =
            crate::inputs::faults::inject(&recording.events, &rates, args.fault_seed);
        recording.events = events;
        crate::inputs::faults::FaultReport {
            rates,
            seed: args.fault_seed,
            injected: counts,
        }
    });
    let mode = settings.association.mode;
    let mut mcap = super::open_mcap(args.mcap.as_deref())?;
    run_and_report(
        &recording,
        &settings,
        mode,
        args.precision,
        &args.out,
        !args.no_plots,
        quiet,
        started,
        faults,
        mcap.as_mut().map(|f| (f, "")),
    )?;
    super::close_mcap(mcap, quiet)
}

/// Replays `recording`, scores it and writes `metrics.json`, the TUM trajectories and the
/// pictures into `out`. `started` is when the process began its work (for the wall time).
/// With `mcap` (a file and a topic prefix), the run is recorded there too.
#[allow(clippy::too_many_arguments)]
pub fn run_and_report(
    recording: &Recording,
    settings: &Settings,
    mode: AssociationMode,
    precision: Precision,
    out: &Path,
    plots: bool,
    quiet: bool,
    started: Instant,
    faults: Option<crate::inputs::faults::FaultReport>,
    mcap: Option<(&mut crate::output::mcap::McapFile, &str)>,
) -> Result<()> {
    let progress = (!quiet).then(|| super::progress_bar(recording.events.len() as u64));
    // While the filter runs, one thread on the core it leaves free writes the ground
    // truth, then takes the samples the filter hands over in chunks: it writes the
    // trajectory and pairs each pose with the ground truth for the metrics. One thread,
    // not one per file: on two cores a second one takes turns with the filter.
    let metrics = std::thread::scope(|s| -> Result<_> {
        let (chunks, received) = std::sync::mpsc::channel::<Vec<PoseSample>>();
        let writer = s.spawn(move || {
            crate::output::write_truth(out, recording)?;
            let mut pairs = PosePairs::new(recording, recording.events.len());
            let poses = received.into_iter().flat_map(|chunk| {
                pairs.extend(&chunk);
                chunk.into_iter().map(|p| (p.stamp, p.pose))
            });
            crate::output::write_trajectory(out, poses)?;
            Ok(pairs)
        });
        // A failed writer drops its receiver: the samples are then dropped here and its
        // error comes from joining it.
        let mut hand_over = |samples: &[PoseSample]| {
            let _ = chunks.send(samples.to_vec());
        };
        let run = replay_with(
            recording,
            settings,
            mode,
            precision,
            progress.as_ref(),
            &mut hand_over,
        );
        drop(chunks); // the writer's end of the samples
        let run = match run {
            Ok(run) => run,
            Err(e) => {
                // Refused before its first sample (settings): no trajectory to leave.
                let _ = crate::output::join_writer(writer);
                let _ = std::fs::remove_file(out.join("trajectory.tum"));
                return Err(e);
            }
        };
        if let Some(p) = &progress {
            p.finish_and_clear();
        }
        let pairs = crate::output::join_writer(writer)?;
        let mut metrics = crate::metrics::evaluate_paired(recording, &run, pairs);
        if let Err(e) = crate::metrics::inputs::check_scored(recording, &metrics) {
            // Nothing of a run that used nothing is left: the trajectory was written
            // while the filter ran.
            let _ = std::fs::remove_file(out.join("trajectory.tum"));
            let _ = std::fs::remove_file(out.join("groundtruth.tum"));
            return Err(e);
        }
        metrics.inputs.warn_above(settings.loss_warning_fraction);
        for warning in &metrics.inputs.warnings {
            eprintln!("warning: {}: {warning}", recording.name);
        }
        metrics.faults = faults;
        crate::output::write_all(out, recording, &run, &mut metrics, plots, started)?;
        if let Some((file, prefix)) = mcap {
            crate::output::mcap::scene::record_ekf_run(file, prefix, recording, &run, 0.1)?;
        }
        Ok(metrics)
    })?;
    if !quiet {
        println!("{}", super::summary(&metrics, out));
    }
    Ok(())
}

pub(crate) fn scan_progress_bar(len: usize, quiet: bool) -> indicatif::ProgressBar {
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
    grid: &GridOptions,
    log: &CarmenLog,
) -> Result<GridRunOptions> {
    options_for_beams(config, grid, beam_count(log))
}

/// The grid run's settings for a lidar of `n` beams (CARMEN geometry).
pub(crate) fn options_for_beams(
    config: Option<&Path>,
    grid: &GridOptions,
    n: usize,
) -> Result<GridRunOptions> {
    let mut c = grid
        .preset
        .unwrap_or_else(|| Preset::for_particles(grid.particles))
        .settings(config, grid.beams, n, grid.role)?;
    if let Some(k) = grid.window {
        c.filter.shift_window_cells = k;
    }
    if let Some(invalid) = c.invalid_setting() {
        match grid.window {
            Some(k) if invalid.name == "shift_window_cells" => {
                bail!("--window {k}: the half-width must be {}", invalid.rule)
            }
            _ => bail!("grid filter settings: {invalid}"),
        }
    }
    Ok(GridRunOptions {
        particles: grid.particles,
        config: c,
        lidar: carmen_lidar(n),
        loop_closure: loop_closure_settings(config, grid.loop_closure, grid.role)?,
        // Placed on the recording's odometry by grid SLAM's replay (`GridPlacement`).
        grid_origin: None,
        max_odometry_step_m: crate::domain::grid::max_odometry_step_m(config)?,
    })
}

pub(crate) fn metrics_json(
    dataset: &str,
    run: &GridRun,
    options: &GridRunOptions,
    rel: Option<RelationError>,
    faults: Option<&FaultReport>,
    wall: f64,
) -> serde_json::Value {
    let scans = run.trajectory.len();
    let mut doc = serde_json::json!({
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
        "recording_time_s": run.observer_time_s,
        "ms_per_scan": 1e3 * run.filter_time_s / scans.max(1) as f64,
        "skipped_scans": run.skipped_scans,
        "refused_odometry": run.refused_odometry,
        "non_finite_beams": run.non_finite_beams,
        "grid": serde_json::json!({
            "cells": [run.geometry.width, run.geometry.height],
            "resolution_m": run.geometry.resolution,
            "origin_m": [run.geometry.origin_x, run.geometry.origin_y],
            "off_grid_end_points": run.off_grid_end_points,
            "scans_with_off_grid_end_points": run.scans_off_grid,
        }),
        "scan_spacing": run.scan_spacing,
        "faults": faults,
        "window": 2 * u32::from(options.config.filter.shift_window_cells) + 1,
        "beam_decimation": options.config.beam_decimation,
        "range_weight_exponent": options.config.range_weight_exponent,
        "seed": options.config.filter.seed,
        "localizer": run.localizer,
        "loop_closure": run.loop_closure.map(|summary| serde_json::json!({
            "settings": options.loop_closure.map(|g| microslam::slam::GraphSlamConfig {
                grid: options.config,
                ..g
            }),
            "summary": summary,
        })),
    });
    // What does not apply to the run (no relations file, no faults, no localizer, no
    // loop closure) is left out, never written as `null`.
    crate::output::drop_absent(
        &mut doc,
        &[
            "relations",
            "scan_spacing",
            "faults",
            "localizer",
            "loop_closure",
        ],
    );
    doc
}

/// Where [`score_and_write`] writes a run's outputs.
pub(crate) struct RunOutputs<'a> {
    /// The output folder.
    pub dir: &'a Path,
    /// Draw `map.png`.
    pub plots: bool,
}

/// Refuses a run that used none of its scans or odometry ([`GridRun::check_used`]), then
/// scores a grid run over the lidar log `lidar` — the relation error when a relations file
/// is found ([`super::relation_error_for`]), the ATE against `--reference` when given —
/// writes its outputs ([`write_outputs`]) and returns `metrics.json`'s document. The wall
/// time is the command's since `started`, taken before the files are written.
pub(crate) fn score_and_write(
    lidar: &LidarLog,
    run: &GridRun,
    grid: &GridOptions,
    faults: Option<&FaultReport>,
    started: Instant,
    outputs: RunOutputs<'_>,
) -> Result<serde_json::Value> {
    run.check_used(&lidar.source)?;
    let rel = super::relation_error_for(&lidar.path, grid.relations.as_deref(), run)?;
    let wall = started.elapsed().as_secs_f64();
    let mut metrics = with_reference(
        metrics_json(&lidar.name, run, &lidar.options, rel, faults, wall),
        run,
        grid,
    )?;
    let loss = crate::metrics::inputs::input_loss(run, lidar.loss_warning, &lidar.log);
    for warning in loss["warnings"].as_array().into_iter().flatten() {
        eprintln!(
            "warning: {}: {}",
            lidar.source,
            warning.as_str().unwrap_or_default()
        );
    }
    metrics["input_loss"] = loss;
    write_outputs(
        outputs.dir,
        run,
        &lidar.options.config,
        &metrics,
        None,
        outputs.plots,
    )?;
    Ok(metrics)
}

/// `metrics` with the `reference` entry: the ATE against `--reference` when given.
pub(crate) fn with_reference(
    mut metrics: serde_json::Value,
    run: &GridRun,
    grid: &GridOptions,
) -> Result<serde_json::Value> {
    if let Some(path) = &grid.reference {
        let ate = crate::metrics::reference::grid_run_ate(run, path, grid.reference_offset)?;
        metrics["reference"] = serde_json::json!({
            "file": path.display().to_string(),
            "time_offset_s": grid.reference_offset,
            "ate": ate,
        });
    }
    Ok(metrics)
}

pub(crate) fn report(quiet: bool, dataset: &str, metrics: &serde_json::Value, out: &Path) {
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
    if let Some(a) = metrics.get("reference").map(|r| &r["ate"]) {
        println!(
            "  ATE vs reference ({} of {} poses matched, {} in the run's span, within {:.3} s): {:.4} m SE(2), {:.4} m first pose",
            a["matched"],
            a["reference_poses"],
            a["in_span"],
            a["tolerance_s"].as_f64().unwrap_or(f64::NAN),
            a["ate_m"]["se2"].as_f64().unwrap_or(f64::NAN),
            a["ate_m"]["first_pose"].as_f64().unwrap_or(f64::NAN)
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

/// Says on stderr where the grid goes when it is not the smaller one centred on the start
/// (with `quiet`, only when the odometry does not fit).
fn placement_note(
    extent: Option<&OdometryExtent>,
    placement: &GridPlacement,
    resolution: f32,
    quiet: bool,
) {
    let (Some(e), side) = (extent, placement.side_m(resolution)) else {
        return;
    };
    let [w, h] = e.size();
    if !placement.fits {
        eprintln!(
            "note: the odometry spans {w:.1} × {h:.1} m, more than the largest grid ({side:.1} m) \
             holds with {GRID_MARGIN_M} m to spare: what lies beyond it is not mapped \
             (a coarser `resolution` in --config covers more)"
        );
    } else if !quiet && (placement.cells != GRID_CELLS || !placement.centred) {
        eprintln!(
            "note: the odometry spans {w:.1} × {h:.1} m: a {} × {} grid ({side:.1} m), its \
             lower-left corner at ({:.2}, {:.2}) m from the start",
            placement.cells, placement.cells, placement.origin_m[0], placement.origin_m[1]
        );
    }
}

/// `host-sim replay --filter grid-slam --dataset carmen:<file>` (and `thor:<dir>`).
fn grid_replay(args: &ReplayOptions, quiet: bool) -> Result<()> {
    let start = Instant::now();
    if let DatasetSpec::Thor(dir) = &args.dataset {
        return thor_replay(dir, args.run, &args.out, !args.no_plots, quiet);
    }
    let lidar = lidar_log(&args.dataset, args.config.as_deref(), &args.grid, &args.bag)?;
    let options = &lidar.options;
    let clean = front_scans(&lidar.log);
    // Faults (`--faults`) go into a copy of the laser messages.
    let (faulty, faults) = match args.faults.filter(|f| !f.is_none()) {
        Some(rates) => {
            let (scans, injected) =
                crate::inputs::faults::inject_scans(&clean, &rates, args.fault_seed);
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
    let pb = scan_progress_bar(scans.len(), quiet);
    let inputs = carmen_inputs(&scans);
    let animation = AnimationSettings::default();
    let every = args
        .animate
        .as_ref()
        .map_or(0, |_| animation.snapshot_every(inputs.len()));
    let progress = |i: usize| {
        if i.is_multiple_of(64) {
            pb.set_position(i as u64);
        }
    };
    let extent = OdometryExtent::of(crate::drivers::scan_odometry::chained(
        inputs.iter().map(|input| input.odometry),
        options.max_odometry_step_m,
    ));
    let placement = GridPlacement::for_extent(extent.as_ref(), options.config.resolution);
    placement_note(
        extent.as_ref(),
        &placement,
        options.config.resolution,
        quiet,
    );
    let options = &GridRunOptions {
        grid_origin: Some(placement.origin_m),
        ..options.clone()
    };
    let mut mcap = super::open_mcap(args.mcap.as_deref())?;
    let log_odds = options.config.log_odds;
    let run =
        super::recorded_grid_run(mcap.as_mut(), "", inputs.len(), log_odds, &[], true, |o| {
            if placement.cells == GRID_CELLS {
                run_slam_observed::<GRID_CELLS, GRID_BITMAP>(
                    &inputs,
                    Pose2::IDENTITY,
                    options,
                    &progress,
                    o,
                    every,
                )
            } else {
                run_slam_observed::<GRID_CELLS_LARGE, GRID_BITMAP_LARGE>(
                    &inputs,
                    Pose2::IDENTITY,
                    options,
                    &progress,
                    o,
                    every,
                )
            }
        })?;
    pb.finish_and_clear();
    if let Some(spacing) = run.scan_spacing.filter(ScanSpacing::is_sparse) {
        eprintln!(
            "note: the scans are a median of {:.2} m and {:.2} rad apart; grid SLAM is built \
             for scans a few centimetres apart and loses the map on logs with scans 0.7–1 m \
             apart (docs/results-grid.md); give it every scan the lidar took",
            spacing.median_step_m, spacing.median_turn_rad
        );
    }
    if run.off_grid_end_points > 0 {
        eprintln!(
            "note: {} end points of {} scans fell off the {:.1} m grid and were not written \
             (metrics.json: grid)",
            run.off_grid_end_points,
            run.scans_off_grid,
            placement.side_m(options.config.resolution)
        );
    }
    let outputs = RunOutputs {
        dir: &args.out,
        plots: !args.no_plots,
    };
    let metrics = score_and_write(&lidar, &run, &args.grid, faults.as_ref(), start, outputs)?;
    if let Some(gif) = &args.animate {
        let title = format!("Grid SLAM: {}", lidar.name);
        write_gif(
            gif,
            &Animation {
                run: &run,
                inputs: &inputs,
                lidar: &options.lidar,
                log_odds: &options.config.log_odds,
                truth: None,
                title: &title,
            },
            &animation,
        )?;
    }
    report(quiet, &lidar.name, &metrics, &args.out);
    super::close_mcap(mcap, quiet)
}

/// A lidar dataset read for a grid run.
pub(crate) struct LidarLog {
    /// The file, resolved.
    pub path: PathBuf,
    /// The name reports give it: the file's name.
    pub name: String,
    /// The dataset as errors name it: its family and resolved path (`carmen:<path>`).
    pub source: String,
    /// Its laser messages.
    pub log: CarmenLog,
    /// The grid settings for it.
    pub options: GridRunOptions,
    /// Share of its scans or odometry poses a run may lose without a warning (the
    /// settings' `loss_warning_fraction`).
    pub loss_warning: f64,
}

/// The lidar dataset `spec` (its file found by [`resolve_log`]): a CARMEN log, or a ROS 2
/// bag (its scans as laser messages, its lidar geometry), with its grid settings.
/// Refuses the options of the estimator a replay does not run: the grid filter's on a
/// landmark EKF-SLAM replay, the EKF's (`--association`, `--precision f32`) on a grid
/// replay. They would be ignored without a word.
fn options_apply(args: &ReplayOptions, grid: bool) -> Result<()> {
    let g = &args.grid;
    let (given, applies_to): (Vec<&str>, &str) = if grid {
        let given = [
            ("--association", args.association.is_some()),
            ("--precision", args.precision != Precision::default()),
        ];
        (
            given
                .into_iter()
                .filter_map(|(n, s)| s.then_some(n))
                .collect(),
            "the landmark EKF-SLAM (`--filter ekf-slam`)",
        )
    } else {
        let given = [
            ("--particles", g.particles != 200),
            ("--window", g.window.is_some()),
            ("--beams", g.beams.is_some()),
            ("--relations", g.relations.is_some()),
            ("--preset", g.preset.is_some()),
            ("--reference", g.reference.is_some()),
            ("--reference-offset", g.reference_offset != 0.0),
            ("--loop-closure", g.loop_closure),
        ];
        (
            given
                .into_iter()
                .filter_map(|(n, s)| s.then_some(n))
                .collect(),
            "the grid filters (`--filter grid-slam`)",
        )
    };
    if !given.is_empty() {
        bail!(
            "{} applies to {applies_to}, which this replay of `{}:` does not run",
            given.join(", "),
            args.dataset.family()
        );
    }
    Ok(())
}

/// Refuses the options of a ROS 2 bag (`--lidar-mount`, the topics) on a dataset that is
/// not one: they would be ignored without a word.
pub(crate) fn bag_options_apply(spec: &DatasetSpec, bag: &BagOptions) -> Result<()> {
    if matches!(spec, DatasetSpec::Rosbag(_)) {
        return Ok(());
    }
    let d = BagOptions::default();
    let given: Vec<&str> = [
        ("--lidar-mount", bag.lidar_mount.is_some()),
        ("--scan-topic", bag.scan_topic != d.scan_topic),
        ("--odom-topic", bag.odom_topic != d.odom_topic),
        ("--imu-topic", bag.imu_topic != d.imu_topic),
        (
            "--tf-static-topic",
            bag.tf_static_topic != d.tf_static_topic,
        ),
        ("--detections-topic", bag.detections_topic.is_some()),
        ("--truth-topic", bag.truth_topic != d.truth_topic),
        ("--odom-motion", bag.odom_motion != d.odom_motion),
    ]
    .into_iter()
    .filter_map(|(name, set)| set.then_some(name))
    .collect();
    if !given.is_empty() {
        bail!(
            "{} applies to `rosbag:` datasets only, not to a `{}:` dataset, which has no topics and no lidar mount to set",
            given.join(", "),
            spec.family()
        );
    }
    Ok(())
}

pub(crate) fn lidar_log(
    spec: &DatasetSpec,
    config: Option<&Path>,
    grid: &GridOptions,
    bag: &BagOptions,
) -> Result<LidarLog> {
    let (DatasetSpec::Carmen(file) | DatasetSpec::Rosbag(file)) = spec else {
        bail!(
            "a grid run needs a lidar dataset (carmen:<file> or rosbag:<bag>), not {}",
            spec.family()
        );
    };
    let path = resolve_log(file)?;
    let name = path
        .file_name()
        .map_or_else(|| file.to_string(), |n| n.to_string_lossy().to_string());
    let (log, options) = read_lidar(spec, &path, config, grid, bag)?;
    Ok(LidarLog {
        loss_warning: crate::domain::grid::loss_warning_fraction(config)?,
        source: format!("{}:{}", spec.family(), path.display()),
        path,
        name,
        log,
        options,
    })
}

fn read_lidar(
    spec: &DatasetSpec,
    path: &Path,
    config: Option<&Path>,
    grid: &GridOptions,
    bag: &BagOptions,
) -> Result<(CarmenLog, GridRunOptions)> {
    if !matches!(spec, DatasetSpec::Rosbag(_)) {
        let log = read_log(path)?;
        let options = options_from(config, grid, &log)?;
        return Ok((log, options));
    }
    let bag = rosbag::read(path, bag)?;
    let mut options = options_for_beams(config, grid, bag.lidar_beams())?;
    options.lidar = bag.lidar;
    let log = CarmenLog {
        messages: bag
            .scans
            .into_iter()
            .map(crate::inputs::readers::carmen::Message::Laser)
            .collect(),
        ..CarmenLog::default()
    };
    Ok((log, options))
}

/// `host-sim replay --dataset thor:<dir> --run N`: trajectory.tum, trajectory.png (with a
/// 1 m grid; when `plots`), metrics.json (length, duration, end pose).
fn thor_replay(dir: &str, run: u32, out: &Path, plots: bool, quiet: bool) -> Result<()> {
    let start = std::time::Instant::now();
    let direct = Path::new(dir);
    let path = if direct.is_dir() {
        direct.to_path_buf()
    } else {
        crate::domain::datasets::resolve("", dir)?
    };
    let traj = thor::dead_reckoning(&path, run)?;
    crate::output::create_folder(out)?;
    write_tum(&out.join("trajectory.tum"), traj.iter().copied())?;
    let length: f64 = traj
        .windows(2)
        .map(|w| (w[1].1.x - w[0].1.x).hypot(w[1].1.y - w[0].1.y))
        .sum();
    let duration = traj.last().map_or(0.0, |l| l.0) - traj.first().map_or(0.0, |f| f.0);
    let picture = out.join("trajectory.png");
    if plots {
        crate::output::thor::draw_trajectory(
            &picture,
            &traj,
            &format!("THOR run {run}: encoder + IMU dead reckoning"),
        )?;
    } else {
        crate::output::remove_stale(&picture)?;
    }
    let end = traj.last().map_or(Pose2::IDENTITY, |l| l.1);
    let metrics = serde_json::json!({
        "dataset": format!("thor/run{run}"),
        "samples": traj.len(),
        "duration_s": duration,
        "path_length_m": length,
        "end_pose": [end.x, end.y, end.theta],
        "wall_time_s": start.elapsed().as_secs_f64(),
    });
    crate::output::write_report(&out.join("metrics.json"), &metrics)?;
    if !quiet {
        println!(
            "thor run {run}: {} encoder samples, {duration:.1} s, {length:.2} m driven; outputs in {}",
            traj.len(),
            out.display()
        );
    }
    Ok(())
}
