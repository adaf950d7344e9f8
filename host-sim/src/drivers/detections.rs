//! The whole chain of El Masri El Chaarani et al. (n.d.) on the simulator: a sign
//! detector's bounding-box centre pixel and the depth sampled there (with pixel and depth
//! noise, and a share of wrong class ids, as their detector made) → [`Camera::sighting`](microslam::sensors::camera::Camera::sighting) → landmark EKF-SLAM with the class ids.
//!
//! Three ways to use the class id are compared:
//! - [`ClassUse::Dictionary`]: their class-id dictionary (§II-A) — the class names the
//!   landmark (a [`KnownIds`] table); a wrong class updates the wrong landmark;
//! - [`ClassUse::Geometry`]: the class is ignored, ICNN decides;
//! - [`ClassUse::GeometryWithHints`]: ICNN decides; among several individually compatible
//!   landmarks the one whose label (majority of the classes it was seen with) equals the
//!   detection's class is preferred. The geometry always wins over the class: a detection
//!   compatible with one landmark only is paired with it whatever its class says
//!   (El Masri El Chaarani et al. n.d., §III-C: the data association overrides a
//!   misclassified sign).
//!
//! A detection with a wrong class is *corrected* when it was associated with the map
//! landmark of its true sign (the landmark most of whose sightings came from that sign).
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The detector-to-EKF chain, the class-id
//!   dictionary (§II-A) and the misclassified sign corrected by the association (§III-C).

use crate::domain::config::Settings;
use crate::domain::recording::Recording;
use crate::domain::{AssociationMode, Precision};
use crate::drivers::ekf::{AssociationCounts, MapLandmark, PoseSample, ReplayRun};
use crate::inputs::camera::world::{Sign, SimCamera};
use anyhow::{Result, bail};
use microslam::association::{Candidates, KnownIds, LabelCheck, LandmarkLabels, Pairing};
use microslam::ekf::{EkfSlam, UpdateOutcome, factor_len, state_dim};
use microslam::event::{Event, EventKind, Identity, Sighting};
use microslam::geometry::Pose2;
use microslam::sensors::camera::DetectionNoise;
use nalgebra::{Vector2, Vector3};
use rand_core::SeedableRng;
use rand_distr::{Distribution, Normal, Uniform};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

const MAX_LANDMARKS: usize = 64;
type Slam = EkfSlam<f64, { state_dim(MAX_LANDMARKS) }, { factor_len(MAX_LANDMARKS) }>;

/// The simulated detector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorSettings {
    /// Share of detections whose class id is replaced by another sign's.
    pub wrong_class_share: f64,
    /// Pixel and depth noise (also the noise the sighting covariance is computed from).
    pub noise: DetectionNoise<f64>,
    /// Signs nearer than this (depth) are not detected, metres.
    pub min_depth_m: f64,
    /// Signs deeper than this are not detected, metres.
    pub max_depth_m: f64,
    /// Sign centres stand at heights drawn uniformly from this interval, metres.
    pub sign_height_m: (f64, f64),
    /// Half the edge of a sign plate, metres.
    pub sign_half_size_m: f64,
}

impl Default for DetectorSettings {
    fn default() -> Self {
        Self {
            wrong_class_share: 0.15,
            noise: DetectionNoise {
                u_std: 1.0,
                v_std: 1.0,
                depth_std: 0.01,
                depth_std_per_m2: 0.003,
            },
            min_depth_m: 0.3,
            max_depth_m: 5.0,
            sign_height_m: (0.15, 0.45),
            sign_half_size_m: 0.1,
        }
    }
}

/// One detection as the detector reports it, with its truth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// Time, s.
    pub stamp: f64,
    /// Class id reported (maybe wrong).
    pub class: u32,
    /// The sign really seen.
    pub true_id: u32,
    /// Box centre, pixels.
    pub u: f64,
    /// Box centre, pixels.
    pub v: f64,
    /// Depth sampled at the box centre, metres.
    pub depth: f64,
}

/// The signs: one per landmark of the simulated field, class = landmark id, at a height
/// drawn from the settings (seeded).
pub fn place_signs(recording: &Recording, settings: &DetectorSettings, seed: u64) -> Vec<Sign> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x5165_u64);
    let (lo, hi) = settings.sign_height_m;
    let heights = Uniform::new_inclusive(lo.min(hi), hi.max(lo)).ok();
    recording
        .landmarks
        .iter()
        .map(|l| Sign {
            id: l.id,
            position: [
                l.position[0],
                l.position[1],
                heights.map_or(lo, |h| h.sample(&mut rng)),
            ],
            half_size: settings.sign_half_size_m,
        })
        .collect()
}

/// The noiseless pixel and depth of a sign's centre seen from `pose`, when the whole
/// plate's centre is inside the image and within the depth limits.
pub fn project_sign(
    camera: &SimCamera,
    sign: &Sign,
    pose: &Pose2<f64>,
    settings: &DetectorSettings,
) -> Option<(f64, f64, f64)> {
    let [x, y, z] = sign.position;
    let local = pose.inverse_transform_point(&Vector2::new(x, y));
    let (u, v, depth) = camera
        .camera
        .robot_to_pixel(&Vector3::new(local[0], local[1], z))?;
    (camera.contains(u, v) && depth >= settings.min_depth_m && depth <= settings.max_depth_m)
        .then_some((u, v, depth))
}

/// Simulates the detector along the recording's true trajectory at the scenario's
/// sighting rate, and returns the recording's odometry with the detections converted to
/// class-labelled sightings ([`Camera::sighting`](microslam::sensors::camera::Camera::sighting),
/// with covariance), plus the detections themselves (in the same order as the sightings).
pub fn camera_recording(
    base: &Recording,
    settings: &Settings,
    camera: &SimCamera,
    signs: &[Sign],
    detector: &DetectorSettings,
    seed: u64,
) -> Result<(Recording, Vec<Detection>)> {
    let Some(sc) = settings.scenario.as_ref() else {
        bail!("the settings have no [scenario] section");
    };
    let every = (sc.odometry_rate_hz / sc.sighting_rate_hz).round().max(1.0) as usize;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x00de_7ec7_u64);
    let unit = Normal::new(0.0, 1.0)?;
    let share = Uniform::new(0.0, 1.0)?;
    let n = &detector.noise;
    let mut events = Vec::with_capacity(base.events.len());
    let mut detections = Vec::new();
    let mut step = 0usize;
    let mut truth = crate::domain::recording::TruthCursor::new(&base.ground_truth);
    for e in &base.events {
        let EventKind::Velocity { .. } = e.kind else {
            continue;
        };
        events.push(*e);
        let pose = truth.at(e.stamp);
        if step.is_multiple_of(every)
            && let Some(pose) = pose
        {
            for sign in signs {
                let Some((u, v, depth)) = project_sign(camera, sign, &pose, detector) else {
                    continue;
                };
                let u = u + n.u_std * unit.sample(&mut rng);
                let v = v + n.v_std * unit.sample(&mut rng);
                let sd = n.depth_std + n.depth_std_per_m2 * depth * depth;
                let depth = (depth + sd * unit.sample(&mut rng)).max(0.05);
                let mut class = sign.id;
                if signs.len() > 1 && share.sample(&mut rng) < detector.wrong_class_share {
                    // Another sign's class, uniformly.
                    let k = Uniform::new(0, signs.len() - 1)?.sample(&mut rng);
                    let others: Vec<u32> = signs
                        .iter()
                        .map(|s| s.id)
                        .filter(|&i| i != sign.id)
                        .collect();
                    class = others.get(k).copied().unwrap_or(sign.id);
                }
                let Ok(s) = camera.camera.sighting(u, v, depth, n) else {
                    continue;
                };
                events.push(Event::new(
                    e.stamp,
                    EventKind::Sighting(Sighting {
                        identity: Identity::Class(class),
                        z: s.z,
                        covariance: Some(s.covariance),
                    }),
                ));
                detections.push(Detection {
                    stamp: e.stamp,
                    class,
                    true_id: sign.id,
                    u,
                    v,
                    depth,
                });
            }
        }
        step += 1;
    }
    let recording = Recording {
        name: format!("{}/camera", base.name),
        events,
        ground_truth: base.ground_truth.clone(),
        landmarks: base.landmarks.clone(),
        initial_pose: base.initial_pose,
        dropped_sightings: 0,
        dropped_reason: String::new(),
    };
    Ok((recording, detections))
}

/// How the estimator uses the detector's class ids.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum ClassUse {
    /// The dictionary of El Masri El Chaarani et al. (n.d., §II-A): the class names the
    /// landmark.
    Dictionary,
    /// ICNN alone; classes ignored.
    Geometry,
    /// ICNN; the class breaks ties among compatible landmarks, never overrides geometry.
    GeometryWithHints,
}

/// What happened to the detections with a wrong class id.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ClassReport {
    /// Detections offered.
    pub detections: usize,
    /// Of them, with a wrong class id.
    pub wrong_class: usize,
    /// Wrong-class detections associated with their true sign's landmark.
    pub corrected: usize,
    /// Wrong-class detections associated with another sign's landmark.
    pub misassociated: usize,
    /// Wrong-class detections that created a landmark.
    pub created_landmark: usize,
    /// Wrong-class detections dropped (ambiguous, refused).
    pub dropped: usize,
    /// `corrected / wrong_class`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corrected_share: Option<f64>,
    /// Right-class detections associated with another sign's landmark.
    pub right_class_misassociated: usize,
    /// Association decisions where the landmark's label disagreed with the detection's
    /// class and the geometry's choice was kept ([`LabelCheck::Overridden`]).
    pub labels_overridden: usize,
}

/// The estimator's run and the class report.
#[derive(Clone, Debug)]
pub struct ChainRun {
    /// What the replay produced (for the shared metrics and pictures).
    pub run: ReplayRun,
    /// Class-id outcome.
    pub classes: ClassReport,
}

/// Runs the EKF-SLAM over a camera recording from [`camera_recording`]; `detections` are
/// the truths of its sightings, in order.
pub fn run_chain(
    recording: &Recording,
    detections: &[Detection],
    settings: &Settings,
    class_use: ClassUse,
) -> Result<ChainRun> {
    let config = settings.ekf_config::<f64>();
    let mut slam = Box::new(Slam::new(config));
    if let Err(e) = slam.init(config, recording.initial_pose.unwrap_or(Pose2::IDENTITY)) {
        bail!("filter settings refused: {e}");
    }
    let assoc = settings.association_config::<f64>();
    let max_gap = settings.odometry.max_gap_s;
    let mut ids = KnownIds::<MAX_LANDMARKS>::new();
    let mut labels = LandmarkLabels::<MAX_LANDMARKS>::new();
    let mut votes: Vec<BTreeMap<u32, usize>> = Vec::new();
    let mut true_ids: Vec<BTreeMap<u32, usize>> = Vec::new();
    // (landmark chosen, or None when dropped/created; created flag) per detection.
    let mut decisions: Vec<(Option<usize>, bool)> = Vec::with_capacity(detections.len());
    let mut counts = AssociationCounts::default();
    let mut classes = ClassReport::default();
    let mut nis = Vec::new();
    let mut trajectory = Vec::new();
    let mut filter_time = Duration::ZERO;
    let mut velocity = (0.0, 0.0);
    let mut last: Option<f64> = None;
    let mut detection = detections.iter();
    let mut sightings = 0;
    for e in &recording.events {
        if let Some(prev) = last {
            let dt = (e.stamp - prev).min(max_gap);
            if dt > 0.0 {
                let clock = Instant::now();
                let r = slam.predict_velocity(velocity.0, velocity.1, dt);
                filter_time += clock.elapsed();
                if let Err(err) = r {
                    bail!("prediction at t = {} refused: {err}", e.stamp);
                }
            }
        }
        last = Some(last.map_or(e.stamp, |p: f64| p.max(e.stamp)));
        match e.kind {
            EventKind::Velocity { v, omega } => {
                // As the replay does: an implausible sample is skipped, the last one held.
                if v.abs() <= settings.odometry.max_speed_mps
                    && omega.abs() <= settings.odometry.max_turn_rate_radps
                {
                    velocity = (v, omega);
                } else {
                    counts.odometry_refused += 1;
                }
                trajectory.push(sample(&slam, e.stamp));
            }
            EventKind::Sighting(s) => {
                let Some(det) = detection.next() else {
                    bail!("more sightings than detections");
                };
                sightings += 1;
                let Identity::Class(class) = s.identity else {
                    bail!("camera sightings carry a class");
                };
                let r = s
                    .covariance
                    .unwrap_or_else(|| config.measurement_covariance());
                let clock = Instant::now();
                let pairing = match class_use {
                    ClassUse::Dictionary => match ids.get(class) {
                        Some(j) => Pairing::Landmark(j),
                        None => Pairing::New,
                    },
                    ClassUse::Geometry | ClassUse::GeometryWithHints => {
                        // Compatibility with this sighting's own noise: the filter's
                        // configured noise is set to its diagonal for the association.
                        let mut with_r = config;
                        with_r.range_std = r[(0, 0)].max(0.0).sqrt();
                        with_r.bearing_std = r[(1, 1)].max(0.0).sqrt();
                        if slam.set_config(with_r).is_err() {
                            let _ = slam.set_config(config);
                        }
                        let c = Candidates::<f64, 4>::of(&slam, &s.z, &assoc.individual_gate);
                        let hinted = (class_use == ClassUse::GeometryWithHints)
                            .then(|| {
                                c.nearest
                                    .iter()
                                    .find(|k| labels.get(k.landmark) == s.identity)
                            })
                            .flatten();
                        match hinted.or(c.best()) {
                            Some(k) => Pairing::Landmark(k.landmark),
                            None => c.unpaired_decision(&assoc),
                        }
                    }
                };
                let decision = match pairing {
                    Pairing::Landmark(j) => {
                        if labels.check(j, s.identity) == LabelCheck::Overridden {
                            classes.labels_overridden += 1;
                        }
                        match slam.update_with_covariance(j, &s.z, &r) {
                            Ok(UpdateOutcome::Accepted { nis: v }) => {
                                counts.updates += 1;
                                nis.push(v);
                                credit(&mut true_ids, j, det.true_id);
                            }
                            Ok(UpdateOutcome::Gated { .. }) => counts.gated += 1,
                            Err(_) => counts.refused += 1,
                        }
                        (Some(j), false)
                    }
                    Pairing::New => {
                        let added = slam.add_landmark_with_covariance(&s.z, &r);
                        if class_use == ClassUse::Dictionary
                            && let Ok(j) = added
                        {
                            // The dictionary: the class now names this landmark.
                            let _ = ids.insert(class, j);
                        }
                        match added {
                            Ok(j) => {
                                counts.added += 1;
                                credit(&mut true_ids, j, det.true_id);
                                (Some(j), true)
                            }
                            Err(_) => {
                                counts.refused += 1;
                                (None, false)
                            }
                        }
                    }
                    Pairing::Ambiguous => {
                        counts.ambiguous += 1;
                        (None, false)
                    }
                    Pairing::Invalid => {
                        counts.dropped += 1;
                        (None, false)
                    }
                };
                filter_time += clock.elapsed();
                // The landmark's label: the majority of the classes it was paired with.
                if let (Some(j), _) = decision {
                    if votes.len() <= j {
                        votes.resize(j + 1, BTreeMap::new());
                    }
                    if let Some(v) = votes.get_mut(j) {
                        *v.entry(class).or_default() += 1;
                        if let Some((&best, _)) = v.iter().max_by_key(|(_, n)| **n) {
                            labels.set(j, Identity::Class(best));
                        }
                    }
                }
                decisions.push(decision);
            }
            _ => {}
        }
    }
    // Score: the true sign of each map landmark is the majority of its sightings.
    let owner: Vec<Option<u32>> = true_ids
        .iter()
        .map(|m| m.iter().max_by_key(|(_, n)| **n).map(|(&id, _)| id))
        .collect();
    classes.detections = decisions.len();
    for (det, &(chosen, created)) in detections.iter().zip(&decisions) {
        let wrong = det.class != det.true_id;
        let right_place = chosen.and_then(|j| owner.get(j).copied().flatten()) == Some(det.true_id);
        if wrong {
            classes.wrong_class += 1;
            match chosen {
                None => classes.dropped += 1,
                Some(_) if created => classes.created_landmark += 1,
                Some(_) if right_place => classes.corrected += 1,
                Some(_) => classes.misassociated += 1,
            }
        } else if chosen.is_some() && !created && !right_place {
            classes.right_class_misassociated += 1;
        }
    }
    classes.corrected_share =
        (classes.wrong_class > 0).then(|| classes.corrected as f64 / classes.wrong_class as f64);
    let landmarks = (0..slam.landmark_count())
        .map(|j| {
            let p = slam.landmark(j).unwrap_or_default();
            let c = slam.landmark_covariance(j).unwrap_or_default();
            MapLandmark {
                position: [p[0], p[1]],
                covariance: [[c[(0, 0)], c[(0, 1)]], [c[(1, 0)], c[(1, 1)]]],
                id: ids.id_of(j),
                true_ids: true_ids.get(j).cloned().unwrap_or_default(),
            }
        })
        .collect();
    let run = ReplayRun {
        mode: match class_use {
            ClassUse::Dictionary => AssociationMode::Known,
            _ => AssociationMode::Icnn,
        },
        precision: Precision::F64,
        steps: trajectory.len(),
        trajectory,
        dead_reckoning: crate::drivers::ekf::dead_reckoning(
            recording,
            max_gap,
            (
                settings.odometry.max_speed_mps,
                settings.odometry.max_turn_rate_radps,
            ),
        ),
        landmarks,
        map_history: Vec::new(),
        nis,
        sightings,
        counts,
        calibration: crate::drivers::ekf::Calibration::default(),
        filter_time,
    };
    Ok(ChainRun { run, classes })
}

fn credit(true_ids: &mut Vec<BTreeMap<u32, usize>>, landmark: usize, id: u32) {
    if true_ids.len() <= landmark {
        true_ids.resize(landmark + 1, BTreeMap::new());
    }
    if let Some(m) = true_ids.get_mut(landmark) {
        *m.entry(id).or_default() += 1;
    }
}

fn sample(slam: &Slam, stamp: f64) -> PoseSample {
    let c = slam.pose_covariance();
    let mut covariance = [[0.0; 3]; 3];
    for (r, row) in covariance.iter_mut().enumerate() {
        for (k, v) in row.iter_mut().enumerate() {
            *v = c[(r, k)];
        }
    }
    PoseSample {
        stamp,
        pose: slam.pose(),
        covariance,
        lost: false,
    }
}
