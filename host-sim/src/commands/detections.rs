//! `host-sim detections`: sign detections (box centre + depth, noise, wrong classes) on
//! the simulator → `Camera::sighting` → EKF-SLAM with class ids as hints, in every
//! class-use mode; `metrics.json` and `map.png`.

use crate::domain::config::Settings;
use crate::domain::recording::Recording;
use crate::drivers::detections::{
    self, ChainRun, ClassReport, ClassUse, DetectorSettings, camera_recording,
};
use crate::inputs::camera::world::{Room, SimCamera};
use crate::metrics::Metrics;
use anyhow::{Context, Result};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Options of `host-sim detections`.
#[derive(Debug, Clone)]
pub struct DetectionsOptions {
    /// Seed of the simulation (trajectory, odometry noise, sign heights, detector noise).
    pub seed: u64,
    /// Share of detections with a wrong class id.
    pub wrong_class_share: f64,
    /// Number of signs (default: the `sim.toml` scenario's 24 landmarks).
    pub signs: Option<u32>,
    /// Smallest distance between two signs, metres (default: the scenario's 0.8 m).
    pub min_spacing: Option<f64>,
    /// Output folder: metrics.json, map.png (geometry with class hints).
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
    let base = crate::inputs::sim::simulate(&settings, seed)?;
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
pub fn detections_cli(args: &DetectionsOptions, quiet: bool) -> Result<()> {
    let detector = DetectorSettings {
        wrong_class_share: args.wrong_class_share,
        ..DetectorSettings::default()
    };
    let field = SignField {
        signs: args.signs,
        min_spacing_m: args.min_spacing,
    };
    let (report, recording, chain) = run_detections(args.seed, &detector, field)?;
    crate::output::create_folder(&args.out)?;
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

pub(crate) fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    crate::output::write_report(path, value)
}
