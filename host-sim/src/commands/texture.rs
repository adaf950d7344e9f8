//! `host-sim texture`: the coloured floor map from simulated RGB-D frames, built with
//! the true poses and with the EKF poses of the detection chain, scored against the
//! simulator's true floor texture.

use super::detections::{SignField, camera_scenario, write_json};
use crate::domain::recording::{TruePose, interpolate_pose};
use crate::drivers::detections::{self, ClassUse, DetectorSettings};
use crate::drivers::texture::{self, PointCounts, TextureError, TextureSettings};
use crate::output::floor_texture::draw_floor_maps;
use anyhow::Result;
use serde::Serialize;
use std::path::PathBuf;

/// Options of `host-sim texture`.
#[derive(Debug, Clone)]
pub struct TextureOptions {
    /// Dataset: only `sim` (the built-in simulator) is supported.
    pub dataset: String,
    /// Seed of the simulation.
    pub seed: u64,
    /// Floor height band, metres: points with a world height in [LOW, HIGH] are floor
    /// (Du n.d., the grid particle filter paper, used −0.5 0.25).
    pub band: Vec<f64>,
    /// Frames per second of the trajectory.
    pub frame_rate: f64,
    /// Output folder: texture.png, texture_truth.png, texture_ekf.png, texture.json.
    pub out: PathBuf,
}

/// `texture.json`.
#[derive(Clone, Debug, Serialize)]
pub struct TextureReport {
    /// Seed.
    pub seed: u64,
    /// Height band kept as floor, metres.
    pub band_m: (f64, f64),
    /// Map cell edge, metres.
    pub resolution_m: f64,
    /// Frames per second.
    pub frame_rate_hz: f64,
    /// Depth noise coefficient (σ = k · depth²), 1/m.
    pub depth_noise_per_m2: f64,
    /// Map built with the true poses: error against the true floor.
    pub true_poses: TextureError,
    /// Its point counts.
    pub true_pose_points: PointCounts,
    /// Map built with the EKF-SLAM poses of the detection chain (geometry with class
    /// hints).
    pub ekf_poses: TextureError,
    /// ATE of those EKF poses (SE(2)-aligned), metres; the map uses them unaligned.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ekf_ate_rmse_m: Option<f64>,
}

/// Builds the texture maps with true and EKF poses.
pub fn run_texture(
    seed: u64,
    settings: &TextureSettings,
) -> Result<(TextureReport, texture::TextureMap, texture::TextureMap)> {
    let detector = DetectorSettings::default();
    let (slam_settings, recording, dets, room, camera) =
        camera_scenario(seed, &detector, SignField::default())?;
    let truth = &recording.ground_truth;
    let (map, points) = texture::build(&camera, &room, truth, settings, seed, |t| {
        interpolate_pose(truth, t)
    });
    let chain = detections::run_chain(
        &recording,
        &dets,
        &slam_settings,
        ClassUse::GeometryWithHints,
    )?;
    let ekf: Vec<TruePose> = chain
        .run
        .trajectory
        .iter()
        .map(|s| TruePose {
            stamp: s.stamp,
            pose: s.pose,
        })
        .collect();
    let (ekf_map, _) = texture::build(&camera, &room, truth, settings, seed, |t| {
        interpolate_pose(&ekf, t)
    });
    let metrics = crate::metrics::evaluate(&recording, &chain.run);
    let report = TextureReport {
        seed,
        band_m: settings.band,
        resolution_m: settings.resolution_m,
        frame_rate_hz: settings.frame_rate_hz,
        depth_noise_per_m2: settings.depth_noise_per_m2,
        true_poses: map.error(&room),
        true_pose_points: points,
        ekf_poses: ekf_map.error(&room),
        ekf_ate_rmse_m: metrics.ate_rmse_m.se2,
    };
    Ok((report, map, ekf_map))
}

/// `host-sim texture`.
pub fn texture_cli(args: &TextureOptions, quiet: bool) -> Result<()> {
    if args.dataset != "sim" {
        anyhow::bail!(
            "texture: only `--dataset sim` is supported (the THOR RGB frames are not in the \
             shared datasets)"
        );
    }
    let band = match args.band.as_slice() {
        [lo, hi] if lo < hi => (*lo, *hi),
        _ => anyhow::bail!("--band needs LOW < HIGH"),
    };
    let settings = TextureSettings {
        band,
        frame_rate_hz: args.frame_rate,
        ..TextureSettings::default()
    };
    let (report, map, ekf_map) = run_texture(args.seed, &settings)?;
    let out = &args.out;
    crate::output::create_folder(out)?;
    let n = map.size as u32;
    let half = f64::from(n) * map.resolution_m / 2.0;
    let note =
        "Each cell: the mean colour of the floor points the camera saw in it; black: no point.";
    let (truth, seen, ekf) = (map.truth_rgb(), map.to_rgb(), ekf_map.to_rgb());
    let (from_truth, from_ekf) = (
        "mapped from the true poses",
        "mapped from the EKF-SLAM poses",
    );
    for (file, title, panels) in [
        (
            "texture.png",
            "Floor texture map",
            vec![(from_truth, seen.as_slice())],
        ),
        (
            "texture_truth.png",
            "Floor texture (truth)",
            vec![("the true floor", truth.as_slice())],
        ),
        (
            "texture_ekf.png",
            "Floor texture map",
            vec![(from_ekf, ekf.as_slice())],
        ),
        (
            "texture_side_by_side.png",
            "Floor texture: truth and maps",
            vec![
                ("the true floor", truth.as_slice()),
                (from_truth, seen.as_slice()),
                (from_ekf, ekf.as_slice()),
            ],
        ),
    ] {
        draw_floor_maps(&out.join(file), title, &panels, n, half, note)?;
    }
    write_json(&out.join("texture.json"), &report)?;
    if !quiet {
        println!(
            "texture: true poses: mean |ΔRGB| {:.2}, coverage {:.1} %; EKF poses (ATE {:.3} m): \
             mean |ΔRGB| {:.2}, coverage {:.1} %; wrote {}",
            report.true_poses.mean_abs_rgb_error.unwrap_or(f64::NAN),
            100.0 * report.true_poses.coverage,
            report.ekf_ate_rmse_m.unwrap_or(f64::NAN),
            report.ekf_poses.mean_abs_rgb_error.unwrap_or(f64::NAN),
            100.0 * report.ekf_poses.coverage,
            out.display()
        );
    }
    Ok(())
}
