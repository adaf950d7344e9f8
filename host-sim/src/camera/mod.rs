//! Camera front ends on the simulator (issue 6): rendered RGB-D frames, the coloured floor
//! map (`host-sim texture`), and sign detections through the landmark EKF-SLAM
//! (`host-sim detections`).
//!
//! - [`world`]: the room (procedural floor texture, walls, sign plates), the camera and
//!   the ray caster that renders RGB-D frames.
//! - [`texture`]: pixels + depth + poses → floor colour map, scored against the true
//!   texture.
//! - [`detections`]: sign detections (box centre + depth, noise, wrong classes) →
//!   `Camera::sighting` → EKF-SLAM with class ids as hints.
//!
//! The camera geometry itself (pinhole, mount, sighting conversion and covariance) is
//! `microslam::sensors::camera`; this module only does image work and bookkeeping.

pub mod detections;
pub mod texture;
pub mod world;

use crate::config::Settings;
use crate::metrics::Metrics;
use crate::readers::Recording;
use anyhow::{Context, Result};
use detections::{ChainRun, ClassReport, ClassUse, DetectorSettings, camera_recording};
use serde::Serialize;
use std::path::{Path, PathBuf};
use texture::{PointCounts, TextureError, TextureSettings};
use world::{Room, SimCamera};

/// Options of `host-sim detections`.
#[derive(Debug, Clone, clap::Args)]
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
#[derive(Debug, Clone, clap::Args)]
pub struct TextureArgs {
    /// Dataset: only `sim` (the built-in simulator) is supported.
    #[arg(long, short, default_value = "sim")]
    pub dataset: String,
    /// Seed of the simulation.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Floor height band, metres: points with a world height in [LOW, HIGH] are floor
    /// (the seed used −0.5 0.25).
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

/// One class-use mode of the detection chain in `metrics.json`.
#[derive(Clone, Debug, Serialize)]
pub struct ModeReport {
    /// How the classes were used.
    pub class_use: ClassUse,
    /// What happened to the wrong class ids.
    pub classes: ClassReport,
    /// The usual replay metrics (ATE, landmark error, NEES, NIS, association counts).
    pub ekf: Metrics,
}

/// `metrics.json` of `host-sim detections`.
#[derive(Clone, Debug, Serialize)]
pub struct DetectionsReport {
    /// Seed.
    pub seed: u64,
    /// Camera: image size, intrinsics, mount.
    pub camera: String,
    /// Detector settings.
    pub detector: String,
    /// Signs in the room.
    pub signs: usize,
    /// One entry per class-use mode.
    pub modes: Vec<ModeReport>,
}

/// The sign field: how many signs and how far apart (`None`: the `sim.toml` scenario's).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SignField {
    /// Number of signs.
    pub signs: Option<u32>,
    /// Smallest distance between two signs, metres.
    pub min_spacing_m: Option<f64>,
}

/// What [`camera_scenario`] builds.
pub type CameraScenario = (
    Settings,
    Recording,
    Vec<detections::Detection>,
    Room,
    SimCamera,
);

/// The simulated drive of `sim.toml` with seed `seed`, the camera, the signs and the
/// detections converted to sightings; the settings carry the camera's planar mount.
pub fn camera_scenario(
    seed: u64,
    detector: &DetectorSettings,
    field: SignField,
) -> Result<CameraScenario> {
    let mut settings = Settings::load("sim", None)?;
    if let Some(sc) = settings.scenario.as_mut() {
        sc.landmarks = field.signs.unwrap_or(sc.landmarks);
        sc.min_landmark_spacing_m = field.min_spacing_m.unwrap_or(sc.min_landmark_spacing_m);
    }
    let camera = SimCamera::default();
    let m = camera.camera.planar_mount();
    settings.sighting.mount = [m.x, m.y, m.theta];
    let base = crate::sim::simulate(&settings, seed)?;
    let signs = detections::place_signs(&base, detector, seed);
    let (recording, dets) = camera_recording(&base, &settings, &camera, &signs, detector, seed)?;
    let room = Room {
        signs,
        ..Room::default()
    };
    Ok((settings, recording, dets, room, camera))
}

/// Runs the chain in every class-use mode; also returns the recording and the run of
/// [`ClassUse::GeometryWithHints`] (for pictures).
pub fn run_detections(
    seed: u64,
    detector: &DetectorSettings,
    field: SignField,
) -> Result<(DetectionsReport, Recording, ChainRun)> {
    let (settings, recording, dets, room, camera) = camera_scenario(seed, detector, field)?;
    let mut modes = Vec::new();
    let mut hinted = None;
    for class_use in [
        ClassUse::Dictionary,
        ClassUse::Geometry,
        ClassUse::GeometryWithHints,
    ] {
        let chain = detections::run_chain(&recording, &dets, &settings, class_use)?;
        modes.push(ModeReport {
            class_use,
            classes: chain.classes,
            ekf: crate::metrics::evaluate(&recording, &chain.run),
        });
        if class_use == ClassUse::GeometryWithHints {
            hinted = Some(chain);
        }
    }
    let report = DetectionsReport {
        seed,
        camera: format!("{:?}", camera),
        detector: format!("{detector:?}"),
        signs: room.signs.len(),
        modes,
    };
    let hinted = hinted.context("the hinted mode did not run")?;
    Ok((report, recording, hinted))
}

/// `host-sim detections`.
pub fn detections_cli(args: &DetectionsArgs, quiet: bool) -> Result<()> {
    let detector = DetectorSettings {
        wrong_class_share: args.wrong_class_share,
        ..DetectorSettings::default()
    };
    let field = SignField {
        signs: args.signs,
        min_spacing_m: args.min_spacing,
    };
    let (report, recording, chain) = run_detections(args.seed, &detector, field)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    // The picture of the mode the estimator is meant to run in.
    let metrics = crate::metrics::evaluate(&recording, &chain.run);
    let alignment = metrics
        .se2_alignment
        .map_or(microslam::geometry::Pose2::IDENTITY, |[x, y, t]| {
            microslam::geometry::Pose2::new(x, y, t)
        });
    crate::output::draw_map(
        &args.out.join("map.png"),
        &recording,
        &chain.run,
        &alignment,
    )?;
    write_json(&args.out.join("metrics.json"), &report)?;
    if !quiet {
        for m in &report.modes {
            println!(
                "{:?}: ATE {:.3} m, wrong classes {} of {}, corrected {} ({:.1} %), landmarks {}",
                m.class_use,
                m.ekf.ate_rmse_m.se2.unwrap_or(f64::NAN),
                m.classes.wrong_class,
                m.classes.detections,
                m.classes.corrected,
                100.0 * m.classes.corrected_share.unwrap_or(f64::NAN),
                m.ekf.landmarks_created,
            );
        }
        println!("wrote {}", args.out.display());
    }
    Ok(())
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
        crate::metrics::interpolate_pose(truth, t)
    });
    let chain = detections::run_chain(
        &recording,
        &dets,
        &slam_settings,
        ClassUse::GeometryWithHints,
    )?;
    let ekf: Vec<crate::readers::TruePose> = chain
        .run
        .trajectory
        .iter()
        .map(|s| crate::readers::TruePose {
            stamp: s.stamp,
            pose: s.pose,
        })
        .collect();
    let (ekf_map, _) = texture::build(&camera, &room, truth, settings, seed, |t| {
        crate::metrics::interpolate_pose(&ekf, t)
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
pub fn texture_cli(args: &TextureArgs, quiet: bool) -> Result<()> {
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
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let n = map.size as u32;
    crate::output::write_png(&out.join("texture.png"), n, n, &map.to_rgb())?;
    crate::output::write_png(&out.join("texture_truth.png"), n, n, &map.truth_rgb())?;
    crate::output::write_png(&out.join("texture_ekf.png"), n, n, &ekf_map.to_rgb())?;
    // Side by side: truth | true poses | EKF poses, 4-pixel white gaps.
    let gap = 4u32;
    let w = 3 * n + 2 * gap;
    let parts = [map.truth_rgb(), map.to_rgb(), ekf_map.to_rgb()];
    let mut side = vec![255u8; (w * n * 3) as usize];
    for (k, part) in parts.iter().enumerate() {
        let x0 = k as u32 * (n + gap);
        for r in 0..n {
            let src = (r * n * 3) as usize..((r + 1) * n * 3) as usize;
            let dst = ((r * w + x0) * 3) as usize;
            if let (Some(s), Some(d)) = (part.get(src), side.get_mut(dst..dst + (n * 3) as usize)) {
                d.copy_from_slice(s);
            }
        }
    }
    crate::output::write_png(&out.join("texture_side_by_side.png"), w, n, &side)?;
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

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let json = serde_json::to_string_pretty(value)?;
    std::fs::write(path, json + "\n").with_context(|| format!("cannot write {}", path.display()))
}
