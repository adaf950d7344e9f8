//! A run as Foxglove messages: [`RunRecorder`] writes, under a topic prefix,
//!
//! | topic | schema | what |
//! | --- | --- | --- |
//! | `/tf` | `foxglove.FrameTransforms` | `map` → `odom` → `base_link` → `laser`, each step |
//! | `/pose` | `foxglove.PoseInFrame` | the estimate in `map`, each step |
//! | `/odometry` | `foxglove.Odometry` | the estimate with its 6 × 6 covariance (x, y, yaw filled) |
//! | `/uncertainty` | `foxglove.SceneUpdate` | the 3σ ellipse of the position covariance |
//! | `/trajectory` | `foxglove.PosesInFrame` | the estimated path so far (throttled) |
//! | `/ground_truth` | `foxglove.PoseInFrame` | the true pose, when known |
//! | `/ground_truth/trajectory` | `foxglove.PosesInFrame` | the true path so far (throttled) |
//! | `/scan` | `foxglove.LaserScan` | the lidar scan in `laser` |
//! | `/particles` | `foxglove.PosesInFrame` | the particle cloud (throttled) |
//! | `/map` | `foxglove.Grid` | the occupancy grid, RGBA, cropped to the known area (throttled) |
//! | `/landmarks` | `foxglove.SceneUpdate` | estimated landmarks as the map grows: 3σ ellipses and ids |
//! | `/true_landmarks` | `foxglove.SceneUpdate` | true landmarks with their ids |
//!
//! Throttled topics get about [`Throttle`]'s number of messages over the run, and always
//! one at the last step, which keeps the Intel replay's file near 20 MB.

use super::McapFile;
use crate::domain::recording::{Recording, TruthCursor};
use crate::drivers::ekf::ReplayRun;
use crate::drivers::grid::{GridObserver, GridStep};
use anyhow::Result;
use foxglove::messages::{
    Color, CylinderPrimitive, FrameTransform, FrameTransforms, Grid, LaserScan, Odometry,
    PackedElementField, Pose, PoseInFrame, PosesInFrame, Quaternion, SceneEntity, SceneUpdate,
    SpherePrimitive, TextPrimitive, Timestamp, Vector2, Vector3, packed_element_field::NumericType,
};
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use microslam::sensors::lidar::LidarGeometry;

/// How many messages the throttled topics get over a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Throttle {
    /// `/trajectory` and `/ground_truth/trajectory` (each holds the whole path so far).
    pub trajectories: usize,
    /// `/particles` and `/uncertainty`.
    pub clouds: usize,
    /// `/map` (each a cropped copy of the grid).
    pub grids: usize,
}

impl Default for Throttle {
    fn default() -> Self {
        Self {
            trajectories: 200,
            clouds: 2000,
            grids: 60,
        }
    }
}

/// Every how many of `steps` steps a topic with `messages` messages is written.
pub fn every(steps: usize, messages: usize) -> usize {
    steps.div_ceil(messages.max(1)).max(1)
}

/// One step of a run (after a scan, or an odometry sample).
#[derive(Clone, Copy, Debug)]
pub struct Step<'a> {
    /// Time, s.
    pub stamp: f64,
    /// The estimate in the map frame.
    pub pose: Pose2<f64>,
    /// Its covariance (x, y, θ), when the estimator has one.
    pub covariance: Option<[[f64; 3]; 3]>,
    /// The odometry pose (the `odom` frame's `base_link`), when known.
    pub odometry: Option<Pose2<f64>>,
    /// The true pose, when known.
    pub truth: Option<Pose2<f64>>,
    /// The lidar scan and its geometry.
    pub scan: Option<(&'a [f32], &'a LidarGeometry)>,
    /// The particles (map frame).
    pub particles: &'a [Pose2<f32>],
}

/// A landmark to draw: id, position and its 2 × 2 covariance (none for true landmarks).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mark {
    /// Id shown next to it.
    pub id: u32,
    /// Position in the map frame, m.
    pub position: [f64; 2],
    /// Position covariance, m².
    pub covariance: Option<[[f64; 2]; 2]>,
}

/// A foxglove timestamp of `ns` nanoseconds.
pub fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

/// A planar pose as a foxglove pose (z = 0, rotation about z).
pub fn pose3(p: &Pose2<f64>) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        orientation: Some(rotation(p.theta)),
    }
}

fn rotation(yaw: f64) -> Quaternion {
    let (s, c) = (0.5 * yaw).sin_cos();
    Quaternion {
        x: 0.0,
        y: 0.0,
        z: s,
        w: c,
    }
}

fn f64_pose(p: &Pose2<f32>) -> Pose2<f64> {
    Pose2::new(f64::from(p.x), f64::from(p.y), f64::from(p.theta))
}

fn color(r: f64, g: f64, b: f64, a: f64) -> Option<Color> {
    Some(Color { r, g, b, a })
}

/// The 3σ ellipse of a 2 × 2 covariance at `centre` as a flat cylinder (semi-axes from the
/// eigenvalues, turned to the major axis), or `None` when the covariance is not finite.
pub fn ellipse(
    centre: [f64; 2],
    cov: [[f64; 2]; 2],
    c: Option<Color>,
) -> Option<CylinderPrimitive> {
    let [[a, b], [_, d]] = cov;
    if !(a.is_finite() && b.is_finite() && d.is_finite()) {
        return None;
    }
    let mean = 0.5 * (a + d);
    let r = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let (major, minor) = ((mean + r).max(0.0), (mean - r).max(0.0));
    let angle = 0.5 * (2.0 * b).atan2(a - d);
    Some(CylinderPrimitive {
        pose: Some(pose3(&Pose2::new(centre[0], centre[1], angle))),
        size: Some(Vector3 {
            x: 6.0 * major.sqrt(),
            y: 6.0 * minor.sqrt(),
            z: 0.01,
        }),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: c,
    })
}

/// Frame names of a run (`map`, `odom`, `base_link`, `laser`, with the prefix).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Frames {
    /// The map (world) frame.
    pub map: String,
    /// The odometry frame.
    pub odom: String,
    /// The robot.
    pub base_link: String,
    /// The lidar.
    pub laser: String,
}

impl Frames {
    /// The frames with `prefix` (`""`: `map`, …; `"sim"`: `sim/map`, …).
    pub fn with_prefix(prefix: &str) -> Self {
        let p = |f: &str| {
            if prefix.is_empty() {
                f.to_owned()
            } else {
                format!("{prefix}/{f}")
            }
        };
        Self {
            map: p("map"),
            odom: p("odom"),
            base_link: p("base_link"),
            laser: p("laser"),
        }
    }
}

/// Writes a run's steps into an [`McapFile`] under a topic prefix.
pub struct RunRecorder<'f> {
    file: &'f mut McapFile,
    prefix: String,
    frames: Frames,
    every_trajectory: usize,
    every_cloud: usize,
    every_grid: usize,
    steps: usize,
    index: usize,
    trajectory: Vec<Pose>,
    truth: Vec<Pose>,
}

impl<'f> RunRecorder<'f> {
    /// A recorder of a run of `steps` steps; topics `"{prefix}/pose"` etc. and frames
    /// `"{prefix}/map"` etc. (plain `/pose`, `map` for an empty prefix).
    pub fn new(file: &'f mut McapFile, prefix: &str, steps: usize, throttle: Throttle) -> Self {
        let prefix = prefix.trim_matches('/');
        Self {
            file,
            frames: Frames::with_prefix(prefix),
            prefix: if prefix.is_empty() {
                String::new()
            } else {
                format!("/{prefix}")
            },
            every_trajectory: every(steps, throttle.trajectories),
            every_cloud: every(steps, throttle.clouds),
            every_grid: every(steps, throttle.grids),
            steps,
            index: 0,
            trajectory: Vec::with_capacity(steps),
            truth: Vec::new(),
        }
    }

    fn topic(&self, name: &str) -> String {
        format!("{}/{name}", self.prefix)
    }

    /// Whether the step about to be recorded gets a grid (`/map`).
    pub fn wants_grid(&self) -> bool {
        self.is_due(self.every_grid)
    }

    fn is_due(&self, every: usize) -> bool {
        self.index.is_multiple_of(every) || self.index + 1 >= self.steps
    }

    /// Records one step.
    pub fn step(&mut self, s: &Step<'_>) -> Result<()> {
        let t = s.stamp;
        let ts = Some(timestamp(self.file.log_time_ns(t)));
        let f = self.frames.clone();
        let odom = s.odometry.unwrap_or(s.pose);
        let map_to_odom = s.pose.compose(&odom.inverse());
        let mount = s.scan.map_or(Pose2::IDENTITY, |(_, g)| f64_pose(&g.mount));
        let transform = |parent: &str, child: &str, p: &Pose2<f64>| FrameTransform {
            timestamp: ts,
            parent_frame_id: parent.to_owned(),
            child_frame_id: child.to_owned(),
            translation: Some(Vector3 {
                x: p.x,
                y: p.y,
                z: 0.0,
            }),
            rotation: Some(rotation(p.theta)),
        };
        let tf = FrameTransforms {
            transforms: vec![
                transform(&f.map, &f.odom, &map_to_odom),
                transform(&f.odom, &f.base_link, &odom),
                transform(&f.base_link, &f.laser, &mount),
            ],
        };
        self.file.log(&self.topic("tf"), t, &tf)?;
        let pose = pose3(&s.pose);
        let in_map = |pose: Pose| PoseInFrame {
            timestamp: ts,
            frame_id: f.map.clone(),
            pose: Some(pose),
        };
        self.file.log(&self.topic("pose"), t, &in_map(pose))?;
        self.trajectory.push(pose);
        let cloud_due = self.is_due(self.every_cloud);
        if let Some(c) = s.covariance {
            let mut cov = vec![0.0; 36];
            for (i, r) in [0, 1, 5].into_iter().enumerate() {
                for (j, k) in [0, 1, 5].into_iter().enumerate() {
                    cov[6 * r + k] = c[i][j];
                }
            }
            let odometry = Odometry {
                timestamp: ts,
                frame_id: f.map.clone(),
                body_frame_id: f.base_link.clone(),
                pose: Some(pose),
                pose_covariance: cov,
                ..Default::default()
            };
            self.file.log(&self.topic("odometry"), t, &odometry)?;
            if cloud_due {
                let xy = [[c[0][0], c[0][1]], [c[1][0], c[1][1]]];
                let entity = SceneEntity {
                    timestamp: ts,
                    frame_id: f.map.clone(),
                    id: "robot".into(),
                    cylinders: ellipse([s.pose.x, s.pose.y], xy, color(0.9, 0.3, 0.1, 0.4))
                        .into_iter()
                        .collect(),
                    ..Default::default()
                };
                self.file.log(
                    &self.topic("uncertainty"),
                    t,
                    &SceneUpdate {
                        entities: vec![entity],
                        ..Default::default()
                    },
                )?;
            }
        }
        if let Some(truth) = &s.truth {
            self.file
                .log(&self.topic("ground_truth"), t, &in_map(pose3(truth)))?;
            self.truth.push(pose3(truth));
        }
        if self.is_due(self.every_trajectory) {
            let path = |poses: &[Pose]| PosesInFrame {
                timestamp: ts,
                frame_id: f.map.clone(),
                poses: poses.to_vec(),
            };
            self.file
                .log(&self.topic("trajectory"), t, &path(&self.trajectory))?;
            if !self.truth.is_empty() {
                self.file.log(
                    &self.topic("ground_truth/trajectory"),
                    t,
                    &path(&self.truth),
                )?;
            }
        }
        if let Some((ranges, g)) = s.scan {
            let n = ranges.len();
            let scan = LaserScan {
                timestamp: ts,
                frame_id: f.laser.clone(),
                pose: Some(pose3(&Pose2::IDENTITY)),
                start_angle: f64::from(g.first_angle),
                end_angle: f64::from(g.beam_angle(n.saturating_sub(1))),
                ranges: ranges
                    .iter()
                    .map(|r| {
                        if *r >= g.no_return_range {
                            f64::INFINITY
                        } else {
                            f64::from(*r)
                        }
                    })
                    .collect(),
                intensities: Vec::new(),
            };
            self.file.log(&self.topic("scan"), t, &scan)?;
        }
        if !s.particles.is_empty() && cloud_due {
            let cloud = PosesInFrame {
                timestamp: ts,
                frame_id: f.map.clone(),
                poses: s.particles.iter().map(|p| pose3(&f64_pose(p))).collect(),
            };
            self.file.log(&self.topic("particles"), t, &cloud)?;
        }
        self.index += 1;
        Ok(())
    }

    /// Records the occupancy grid at `stamp`: RGBA cells (grey = 1 − occupancy
    /// probability, unknown cells transparent), cropped to the known area.
    pub fn grid(
        &mut self,
        stamp: f64,
        cells: &[i8],
        g: &GridGeometry,
        log_odds: &LogOdds,
    ) -> Result<()> {
        let t = stamp;
        let crate::output::grid_picture::CellBox { x0, y0, x1, y1 } =
            crate::output::grid_picture::CellBox::known(cells, g, 2);
        let (w, h) = (x1 - x0, y1 - y0);
        let mut data = Vec::with_capacity(4 * w * h);
        for y in y0..y1 {
            for x in x0..x1 {
                let v = cells.get(y * g.width + x).copied().unwrap_or(0);
                let grey = (255.0 * (1.0 - crate::output::grid_picture::probability(v, log_odds)))
                    .round() as u8;
                data.extend_from_slice(&[grey, grey, grey, if v == 0 { 0 } else { 255 }]);
            }
        }
        let res = f64::from(g.resolution);
        let field = |name: &str, offset: u32| PackedElementField {
            name: name.into(),
            offset,
            r#type: NumericType::Uint8 as i32,
        };
        let grid = Grid {
            timestamp: Some(timestamp(self.file.log_time_ns(t))),
            frame_id: self.frames.map.clone(),
            pose: Some(pose3(&Pose2::new(
                f64::from(g.origin_x) + x0 as f64 * res,
                f64::from(g.origin_y) + y0 as f64 * res,
                0.0,
            ))),
            column_count: w as u32,
            cell_size: Some(Vector2 { x: res, y: res }),
            row_stride: 4 * w as u32,
            cell_stride: 4,
            fields: vec![
                field("red", 0),
                field("green", 1),
                field("blue", 2),
                field("alpha", 3),
            ],
            data: data.into(),
        };
        self.file.log(&self.topic("map"), t, &grid)
    }

    /// Records landmarks at `stamp` on `/landmarks` (estimated: orange ellipses) or
    /// `/true_landmarks` (`truth`: green spheres), each with its id.
    pub fn landmarks(&mut self, stamp: f64, marks: &[Mark], truth: bool) -> Result<()> {
        let t = stamp;
        let ts = Some(timestamp(self.file.log_time_ns(t)));
        let (topic, rgb) = if truth {
            ("true_landmarks", (0.1, 0.7, 0.2))
        } else {
            ("landmarks", (1.0, 0.5, 0.0))
        };
        let entities = marks
            .iter()
            .map(|m| {
                let centre = Pose2::new(m.position[0], m.position[1], 0.0);
                SceneEntity {
                    timestamp: ts,
                    frame_id: self.frames.map.clone(),
                    id: format!("{topic}/{}", m.id),
                    spheres: vec![SpherePrimitive {
                        pose: Some(pose3(&centre)),
                        size: Some(Vector3 {
                            x: 0.08,
                            y: 0.08,
                            z: 0.08,
                        }),
                        color: color(rgb.0, rgb.1, rgb.2, 1.0),
                    }],
                    cylinders: m
                        .covariance
                        .and_then(|c| ellipse(m.position, c, color(rgb.0, rgb.1, rgb.2, 0.35)))
                        .into_iter()
                        .collect(),
                    texts: vec![TextPrimitive {
                        pose: Some(pose3(&Pose2::new(centre.x + 0.1, centre.y + 0.1, 0.0))),
                        billboard: true,
                        font_size: 14.0,
                        scale_invariant: true,
                        color: color(rgb.0, rgb.1, rgb.2, 1.0),
                        text: m.id.to_string(),
                    }],
                    ..Default::default()
                }
            })
            .collect();
        self.file.log(
            &self.topic(topic),
            t,
            &SceneUpdate {
                entities,
                ..Default::default()
            },
        )
    }
}

/// Records a landmark EKF-SLAM replay after the run: the estimate with its covariance,
/// dead reckoning as the odometry frame and the ground truth at most every `min_gap_s`
/// seconds of the recording (odometry comes at ~67 Hz in MRCLAM), the true landmarks at
/// the start, the map as it grew ([`ReplayRun::map_history`]) and the final map (ellipses,
/// ids) at the end.
pub fn record_ekf_run(
    file: &mut McapFile,
    prefix: &str,
    recording: &Recording,
    run: &ReplayRun,
    min_gap_s: f64,
) -> Result<()> {
    let mut kept = Vec::new();
    let mut last = f64::NEG_INFINITY;
    for (i, p) in run.trajectory.iter().enumerate() {
        if p.stamp - last >= min_gap_s || i + 1 == run.trajectory.len() {
            kept.push(i);
            last = p.stamp;
        }
    }
    let mut rec = RunRecorder::new(file, prefix, kept.len(), Throttle::default());
    let first = run.trajectory.first().map_or(0.0, |p| p.stamp);
    let true_marks: Vec<Mark> = recording
        .landmarks
        .iter()
        .map(|l| Mark {
            id: l.id,
            position: l.position,
            covariance: None,
        })
        .collect();
    if !true_marks.is_empty() {
        rec.landmarks(first, &true_marks, true)?;
    }
    let marks = |ls: &mut dyn Iterator<Item = ([f64; 2], [[f64; 2]; 2], Option<u32>)>| {
        ls.enumerate()
            .map(|(k, (position, covariance, id))| Mark {
                id: id.unwrap_or(k as u32),
                position,
                covariance: Some(covariance),
            })
            .collect::<Vec<_>>()
    };
    let mut snapshots = run.map_history.iter().peekable();
    let mut truth = TruthCursor::new(&recording.ground_truth);
    for i in kept {
        let Some(p) = run.trajectory.get(i) else {
            continue;
        };
        // The map snapshots up to this step, in time order with the steps.
        while let Some(m) = snapshots.next_if(|m| m.stamp <= p.stamp) {
            let ls = &mut m.landmarks.iter().map(|l| (l.position, l.covariance, l.id));
            rec.landmarks(m.stamp, &marks(ls), false)?;
        }
        rec.step(&Step {
            stamp: p.stamp,
            pose: p.pose,
            covariance: Some(p.covariance),
            odometry: run.dead_reckoning.get(i).map(|(_, d)| *d),
            truth: truth.at(p.stamp),
            scan: None,
            particles: &[],
        })?;
    }
    let end = run.trajectory.last().map_or(first, |p| p.stamp);
    let ls = &mut run
        .landmarks
        .iter()
        .map(|l| (l.position, l.covariance, l.id));
    rec.landmarks(end, &marks(ls), false)
}

/// An estimate a device sent: stamp, pose and (when it has one) the pose covariance
/// `[xx, xy, xθ, yy, yθ, θθ]`.
pub type DeviceEstimate = (f64, Pose2<f64>, Option<[f64; 6]>);

/// Records a device's estimates (`hil`), at most every `min_gap_s` seconds, with the
/// ground truth when known and the scans when given (one per estimate, same order).
pub fn record_estimates(
    file: &mut McapFile,
    prefix: &str,
    estimates: &[DeviceEstimate],
    truth: &[crate::domain::recording::TruePose],
    scans: Option<(&[&[f32]], &LidarGeometry)>,
    min_gap_s: f64,
) -> Result<()> {
    let mut kept = Vec::new();
    let mut last = f64::NEG_INFINITY;
    for (i, (t, _, _)) in estimates.iter().enumerate() {
        if (*t - last).abs() >= min_gap_s || i + 1 == estimates.len() {
            kept.push(i);
            last = *t;
        }
    }
    let mut rec = RunRecorder::new(file, prefix, kept.len(), Throttle::default());
    let mut cursor = TruthCursor::new(truth);
    for i in kept {
        let Some((t, pose, cov)) = estimates.get(i) else {
            continue;
        };
        let scan = scans.and_then(|(s, g)| s.get(i).map(|r| (*r, g)));
        rec.step(&Step {
            stamp: *t,
            pose: *pose,
            covariance: cov
                .map(|[xx, xy, xt, yy, yt, tt]| [[xx, xy, xt], [xy, yy, yt], [xt, yt, tt]]),
            odometry: None,
            truth: cursor.at(*t),
            scan,
            particles: &[],
        })?;
    }
    Ok(())
}

/// Records a grid run (SLAM or localization) as its driver runs it.
pub struct GridRecording<'f, 't> {
    /// Where the steps go.
    pub recorder: RunRecorder<'f>,
    /// The grid's log-odds (for the occupancy shades of `/map`).
    pub log_odds: LogOdds,
    /// The true pose at each step, when known (empty otherwise).
    pub truth: &'t [Pose2<f64>],
    /// Whether `/map` is recorded as it grows (SLAM) or once (localization).
    pub growing_map: bool,
}

impl GridObserver for GridRecording<'_, '_> {
    fn wants_map(&self, index: usize) -> bool {
        if self.growing_map {
            self.recorder.wants_grid()
        } else {
            index == 0
        }
    }

    fn step(&mut self, g: &GridStep<'_>) -> Result<()> {
        let [xx, xy, xt, yy, yt, tt] = g.covariance.map(f64::from);
        self.recorder.step(&Step {
            stamp: g.stamp,
            pose: f64_pose(&g.pose),
            covariance: Some([[xx, xy, xt], [xy, yy, yt], [xt, yt, tt]]),
            odometry: Some(f64_pose(&g.odometry)),
            truth: self.truth.get(g.index).copied(),
            scan: Some((g.ranges, g.lidar)),
            particles: g.particles,
        })?;
        if let Some(map) = &g.map {
            self.recorder
                .grid(g.stamp, map.cells(), map.geometry(), &self.log_odds)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ellipse_has_three_sigma_semi_axes_along_the_major_axis() {
        // σ² = 4 along x, 1 along y, turned by 90° → major axis along y.
        let e = ellipse([1.0, 2.0], [[1.0, 0.0], [0.0, 4.0]], None).unwrap();
        let size = e.size.unwrap();
        assert!((size.x - 12.0).abs() < 1e-12 && (size.y - 6.0).abs() < 1e-12);
        let q = e.pose.unwrap().orientation.unwrap();
        let yaw = 2.0 * q.z.atan2(q.w);
        assert!(
            (yaw.abs() - core::f64::consts::FRAC_PI_2).abs() < 1e-12,
            "{yaw}"
        );
        assert!(ellipse([0.0; 2], [[f64::NAN, 0.0], [0.0, 1.0]], None).is_none());
        assert_eq!(every(5505, 60), 92);
        assert_eq!(every(10, 60), 1);
    }
}
