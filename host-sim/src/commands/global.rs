//! Global localization trials: `host-sim localize --global` on a CARMEN log and
//! `host-sim sim --global` in the simulator's lidar world — wiring, progress, printing.

use super::replay::{options_from, scan_progress_bar};
use crate::domain::grid::{GlobalOptions, GridOptions};
use crate::drivers::global::{
    TrialSettings, build_layers, reference_run, run_trials, settings_from,
};
use crate::drivers::grid::{GridInput, carmen_inputs, f32_pose, sim_inputs};
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::carmen::{front_scans, read_log, resolve_log};
use crate::inputs::readers::map::LocalizationMap;
use crate::inputs::sim::lidar_world::LidarRecording;
use crate::metrics::global::metrics;
use anyhow::{Result, anyhow, bail};
use microslam::geometry::Pose2;
use microslam::grid::GridView;
use microslam::pf::GridPfConfig;
use std::path::Path;
use std::time::Instant;

/// `host-sim localize --global --map map.yaml --dataset carmen:<file>`: the trials on a
/// CARMEN log; the reference starts at the log's first scan (the map's origin).
#[allow(clippy::too_many_arguments)]
pub fn localize_cli(
    map: &Path,
    dataset: &DatasetSpec,
    config: Option<&Path>,
    grid: &GridOptions,
    global: &GlobalOptions,
    out: &Path,
    quiet: bool,
) -> Result<()> {
    let started = Instant::now();
    let DatasetSpec::Carmen(file) = dataset else {
        bail!("localize --global needs a lidar dataset (carmen:<file>)");
    };
    let path = resolve_log(file)?;
    let log = read_log(&path)?;
    let options = options_from(config, grid, &log)?;
    let loaded = LocalizationMap::read(map, &options.config)?;
    let view = loaded.view()?;
    let scans = front_scans(&log);
    let frames: Vec<GridInput<'_>> = carmen_inputs(&scans);
    let name = path
        .file_name()
        .map_or_else(|| file.clone(), |n| n.to_string_lossy().to_string());
    let settings = settings_from(global, options.particles, options.config, options.lidar)?;
    run_and_write(
        &name,
        &frames,
        &view,
        Pose2::IDENTITY,
        &settings,
        out,
        quiet,
        started,
    )
}

/// The occupied-cell bitmap of `view` (its own, or made from its cells).
fn occupancy_bits(view: &GridView<'_>) -> Result<Vec<u8>> {
    if let Some(bits) = view.occupancy_bits() {
        return Ok(bits.to_vec());
    }
    let g = view.geometry();
    let mut bits = vec![0u8; microslam::grid::occupancy_bytes(g.width, g.height)];
    microslam::grid::fill_occupancy_bits(
        view.cells(),
        g.width,
        g.height,
        view.occupied_above(),
        &mut bits,
    )
    .map_err(|e| anyhow!("occupancy bits: {e:?}"))?;
    Ok(bits)
}

/// Builds the layers, runs the reference and the trials, writes `out/metrics.json`.
#[allow(clippy::too_many_arguments)]
pub fn run_and_write(
    name: &str,
    frames: &[GridInput<'_>],
    view: &GridView<'_>,
    start: Pose2<f32>,
    settings: &TrialSettings,
    out: &Path,
    quiet: bool,
    started: Instant,
) -> Result<()> {
    let layers = build_layers(view, &settings.config, settings.levels)?;
    // The firmware's view of a map image: the occupied bits alone.
    let bits;
    let bitmap_view;
    let view = if settings.bitmap_only {
        bits = occupancy_bits(view)?;
        bitmap_view = GridView::from_occupancy_bits(&bits, *view.geometry(), view.occupied_above())
            .map_err(|e| anyhow!("bitmap view: {e:?}"))?;
        &bitmap_view
    } else {
        view
    };
    let reference = reference_run(frames, view, &layers, start, settings)?;
    let pb = scan_progress_bar(settings.trials, quiet);
    let trials = run_trials(frames, view, &layers, &reference.poses, settings, &|i| {
        pb.set_position(i as u64 + 1)
    })?;
    pb.finish_and_clear();
    let global = metrics(&trials, &reference, settings, layers.len());
    let g = view.geometry();
    let doc = serde_json::json!({
        "dataset": name,
        "map_cells": [g.width, g.height],
        "scans": frames.len(),
        "bitmap_only": settings.bitmap_only,
        "wall_time_s": started.elapsed().as_secs_f64(),
        "global": global,
    });
    crate::output::create_folder(out)?;
    crate::output::write_report(&out.join("metrics.json"), &doc)?;
    if !quiet {
        let g = &doc["global"];
        println!(
            "{name}: global localization {}/{} within {} m / {}° after ≤ {} scans (P = {}); scans to converge {}",
            g["successes"],
            g["trials"],
            settings.tolerance_m,
            settings.tolerance_deg,
            settings.max_scans,
            settings.particles,
            g["scans_to_converge"]
        );
        println!(
            "  searches complete {}/{}, ended without a hypothesis {}, most nodes {}, most estimated M4 instructions {} ({} in one scan); reference lost events {}",
            g["searches_complete"],
            g["trials"],
            g["failed_searches"],
            g["max_nodes"],
            g["max_estimated_m4_instructions"],
            g["max_estimated_m4_instructions_per_scan"],
            g["lost_detection"]["reference_lost_events"]
        );
        println!("  outputs in {}", out.display());
    }
    Ok(())
}

/// `host-sim sim --global`: the trials in the simulator's lidar world on the grid SLAM map
/// it wrote (`grid_out/slam/map.yaml`, read back as a user would), into
/// `grid_out/global/`; the reference starts at the true start pose.
pub fn sim_cli(
    rec: &LidarRecording,
    config: GridPfConfig,
    particles: usize,
    args: &GlobalOptions,
    grid_out: &Path,
    quiet: bool,
) -> Result<()> {
    let started = Instant::now();
    let map_path = grid_out.join("slam").join("map.yaml");
    let map = LocalizationMap::read(&map_path, &config)?;
    let view = map.view()?;
    let frames: Vec<GridInput<'_>> = sim_inputs(rec);
    let start = rec
        .scans
        .first()
        .map(|s| f32_pose(&s.truth))
        .ok_or_else(|| anyhow!("no scans"))?;
    let settings = settings_from(args, particles, config, rec.lidar)?;
    let name = format!("{} (grid SLAM map)", rec.name);
    run_and_write(
        &name,
        &frames,
        &view,
        start,
        &settings,
        &grid_out.join("global"),
        quiet,
        started,
    )
}
