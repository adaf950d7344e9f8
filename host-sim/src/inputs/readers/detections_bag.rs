//! ROS 2 bags with landmark detections (`rosbag:<bag>` for the landmark EKF-SLAM): the
//! same storages as the lidar reader ([`super::rosbag`], [`super::bag_storage`]), with
//!
//! - detections: `ros2_aruco_interfaces/msg/ArucoMarkers` (marker ids and 3-D poses in the
//!   camera frame: [`Identity::Unique`]) or `vision_msgs/msg/Detection3DArray` (3-D
//!   detections with class hypotheses: the best-scored class is an [`Identity::Class`]
//!   label, the association decides which landmark; the position is the bounding box
//!   centre, or the best hypothesis' pose when the box has no size);
//! - motion: `nav_msgs/msg/Odometry`, its twist (`v` = `twist.linear.x`, `ω` =
//!   `twist.angular.z`, [`EventKind::Velocity`]) or the increments between consecutive
//!   poses ([`EventKind::Increment`], noise from the settings' `[increment]`);
//! - the camera mount: the chain of `/tf_static` transforms from the odometry's
//!   `child_frame_id` (the robot frame, `base_link`) to the detections' frame, composed in
//!   3-D (an optical frame, z forward, x right, y down, turns through it), unless the
//!   settings give a `[sighting] mount`; the detection's position in the robot frame
//!   becomes range `hypot(x, y)` and bearing `atan2(y, x)`;
//! - ground truth (optional): a `nav_msgs/msg/Odometry` topic (`/ground_truth`) in the
//!   world frame, for the ATE.
//!
//! Every bad input is an error naming the file, the topic and the message.

use super::bag_storage::{BagFiles, Channel};
use super::rosbag::{BagOptions, MountSource, check_type, decode_cdr, msg as ros};
use crate::domain::recording::{Recording, TruePose, interpolate_pose};
use anyhow::{Result, anyhow, bail};
use microslam::event::{Event, EventKind, Identity, Sighting};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// ROS 2 detection message types as serde structs, field for field in CDR order.
pub mod msg {
    use super::ros::{Header, Pose, PoseWithCovariance, Vector3};
    use serde::{Deserialize, Serialize};

    /// `ros2_aruco_interfaces/msg/ArucoMarkers`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ArucoMarkers {
        /// Stamp of the image and the camera frame.
        pub header: Header,
        /// Marker ids, one per pose.
        pub marker_ids: Vec<i64>,
        /// Marker poses in the camera frame.
        pub poses: Vec<Pose>,
    }

    /// `vision_msgs/msg/ObjectHypothesis`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ObjectHypothesis {
        /// The class (a label, not an instance).
        pub class_id: String,
        /// Its score.
        pub score: f64,
    }

    /// `vision_msgs/msg/ObjectHypothesisWithPose`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct ObjectHypothesisWithPose {
        /// Class and score.
        pub hypothesis: ObjectHypothesis,
        /// Pose of the object under this hypothesis.
        pub pose: PoseWithCovariance,
    }

    /// `vision_msgs/msg/BoundingBox3D`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct BoundingBox3D {
        /// Centre and orientation of the box.
        pub center: Pose,
        /// Size, m.
        pub size: Vector3,
    }

    /// `vision_msgs/msg/Detection3D` (vision_msgs 3 and later: Humble, Iron, Jazzy).
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Detection3D {
        /// Stamp and frame (an empty frame: the array's).
        pub header: Header,
        /// Class hypotheses.
        pub results: Vec<ObjectHypothesisWithPose>,
        /// Bounding box.
        pub bbox: BoundingBox3D,
        /// Tracking id (may be empty; not used).
        pub id: String,
    }

    /// `vision_msgs/msg/Detection3DArray`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Detection3DArray {
        /// Stamp and frame.
        pub header: Header,
        /// Detections.
        pub detections: Vec<Detection3D>,
    }

    /// `ros2_aruco_interfaces/msg/ArucoMarkers`.
    pub const ARUCO_MARKERS: &str = "ros2_aruco_interfaces/msg/ArucoMarkers";
    /// `vision_msgs/msg/Detection3DArray`.
    pub const DETECTION3D_ARRAY: &str = "vision_msgs/msg/Detection3DArray";
}

/// What of `nav_msgs/msg/Odometry` drives a landmark run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OdomMotion {
    /// The twist, unless every message's twist is zero while the poses move: then the
    /// velocities between consecutive poses (the arc each step draws), so that the
    /// settings' latency and scale states act on them as on a twist.
    #[default]
    Auto,
    /// The twist: velocities `v`, `ω` held until the next message.
    Twist,
    /// The poses: the increment between consecutive ones.
    Pose,
    /// The poses: the speed and turn rate of the arc between consecutive ones, held from
    /// the first's stamp as a twist is (what `auto` takes when the twist is all zero).
    PoseRates,
}

impl std::str::FromStr for OdomMotion {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "twist" => Ok(Self::Twist),
            "pose" => Ok(Self::Pose),
            "pose-rates" => Ok(Self::PoseRates),
            _ => Err(format!("`{s}`: expected auto, twist, pose or pose-rates")),
        }
    }
}

/// A bag's landmark detections read into a [`Recording`].
#[derive(Clone, Debug)]
pub struct DetectionsBag {
    /// The file.
    pub path: PathBuf,
    /// The events, ground truth and initial pose.
    pub recording: Recording,
    /// The detections topic and its type.
    pub topic: (String, &'static str),
    /// Where the camera mount came from.
    pub mount_source: MountSource,
    /// What of the odometry drove the run.
    pub motion: OdomMotion,
    /// `Detection3D` class names and the [`Identity::Class`] number each became.
    pub classes: Vec<(String, u32)>,
}

fn listed(channels: &BTreeMap<String, Channel>) -> String {
    channels
        .iter()
        .map(|(t, c)| format!("{t} ({})", c.schema))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The detections topic of the bag at `path` and its type: the one `--detections-topic`
/// names, else the one topic of either detection type; `None` when it has none (a lidar
/// bag).
pub fn detections_topic(
    path: &Path,
    options: &BagOptions,
) -> Result<Option<(String, &'static str)>> {
    let channels = BagFiles::open(path)?.topics()?;
    topic_in(path, &channels, options)
}

/// The bag `spec` names when it is a landmark recording (a `rosbag:` dataset with a
/// detections topic, [`detections_topic`]); `None` for any other dataset and for a bag
/// without detections (a lidar bag).
pub fn landmark_bag(
    spec: &super::DatasetSpec,
    options: &BagOptions,
) -> Result<Option<std::path::PathBuf>> {
    let super::DatasetSpec::Rosbag(file) = spec else {
        return Ok(None);
    };
    let path = super::carmen::resolve_log(file)?;
    Ok(detections_topic(&path, options)?.map(|_| path))
}

fn kind_of(schema: &str) -> Option<&'static str> {
    [msg::ARUCO_MARKERS, msg::DETECTION3D_ARRAY]
        .into_iter()
        .find(|k| *k == schema)
}

fn topic_in(
    path: &Path,
    channels: &BTreeMap<String, Channel>,
    options: &BagOptions,
) -> Result<Option<(String, &'static str)>> {
    if let Some(topic) = &options.detections_topic {
        let ch = channels.get(topic.as_str()).ok_or_else(|| {
            anyhow!(
                "{}: no messages on topic {topic} (--detections-topic); the bag has: {}",
                path.display(),
                listed(channels)
            )
        })?;
        let Some(kind) = kind_of(&ch.schema) else {
            bail!(
                "{}: topic {topic} carries `{}`, expected `{}` or `{}`",
                path.display(),
                ch.schema,
                msg::ARUCO_MARKERS,
                msg::DETECTION3D_ARRAY
            );
        };
        check_type(path, topic, ch, kind)?;
        return Ok(Some((topic.clone(), kind)));
    }
    let found: Vec<(&String, &'static str)> = channels
        .iter()
        .filter_map(|(t, c)| kind_of(&c.schema).map(|k| (t, k)))
        .collect();
    match found.as_slice() {
        [] => Ok(None),
        [(topic, kind)] => {
            if let Some(ch) = channels.get(topic.as_str()) {
                check_type(path, topic, ch, kind)?;
            }
            Ok(Some(((*topic).clone(), kind)))
        }
        more => bail!(
            "{}: {} topics carry detections ({}): name one with --detections-topic",
            path.display(),
            more.len(),
            more.iter()
                .map(|(t, _)| t.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The odometry topic: `options.odom_topic` when the bag has it; else, with the default
/// name, the one `nav_msgs/msg/Odometry` topic that is not the ground truth's.
fn odometry_topic(
    path: &Path,
    channels: &BTreeMap<String, Channel>,
    options: &BagOptions,
) -> Result<String> {
    let topic = &options.odom_topic;
    if let Some(ch) = channels.get(topic.as_str()) {
        check_type(path, topic, ch, ros::ODOMETRY)?;
        return Ok(topic.clone());
    }
    let by_type: Vec<&String> = channels
        .iter()
        .filter(|(t, c)| c.schema == ros::ODOMETRY && **t != options.truth_topic)
        .map(|(t, _)| t)
        .collect();
    match by_type.as_slice() {
        [one] if *topic == BagOptions::default().odom_topic => {
            if let Some(ch) = channels.get(one.as_str()) {
                check_type(path, one, ch, ros::ODOMETRY)?;
            }
            Ok((*one).clone())
        }
        _ => bail!(
            "{}: no odometry: no messages on topic {topic} (`{}`); the bag has: {} (name the topic with --odom-topic)",
            path.display(),
            ros::ODOMETRY,
            listed(channels)
        ),
    }
}

/// One odometry message as read.
struct Odom {
    order: usize,
    stamp: f64,
    pose: Pose2<f64>,
    v: f64,
    omega: f64,
}

/// One detection: the message it came in, its identity and position in its frame.
struct Detected {
    order: usize,
    index: u64,
    stamp: f64,
    frame: String,
    item: usize,
    identity: Identity,
    position: [f64; 3],
}

/// Checks an odometry message's numbers (finite, within 100 km).
fn odom_numbers(o: &ros::Odometry) -> Result<Odom> {
    let p = &o.pose.pose;
    let q = p.orientation;
    for (field, v) in [
        ("pose.pose.position.x", p.position.x),
        ("pose.pose.position.y", p.position.y),
        ("pose.pose.orientation.x", q.x),
        ("pose.pose.orientation.y", q.y),
        ("pose.pose.orientation.z", q.z),
        ("pose.pose.orientation.w", q.w),
        ("twist.twist.linear.x", o.twist.twist.linear.x),
        ("twist.twist.angular.z", o.twist.twist.angular.z),
    ] {
        if !v.is_finite() {
            bail!("{field} = {v} is not finite");
        }
    }
    for (field, v) in [
        ("pose.pose.position.x", p.position.x),
        ("pose.pose.position.y", p.position.y),
    ] {
        if v.abs() > super::carmen::MAX_COORDINATE_M {
            bail!(
                "{field} = {v} m is beyond {} km of the origin",
                super::carmen::MAX_COORDINATE_M / 1e3
            );
        }
    }
    if q.x == 0.0 && q.y == 0.0 && q.z == 0.0 && q.w == 0.0 {
        bail!("pose.pose.orientation is the zero quaternion, not a rotation");
    }
    Ok(Odom {
        order: 0,
        stamp: o.header.stamp.seconds(),
        pose: Pose2::new(p.position.x, p.position.y, q.yaw()),
        v: o.twist.twist.linear.x,
        omega: o.twist.twist.angular.z,
    })
}

/// A transform as an isometry, refusing non-finite numbers and a zero quaternion.
/// The constant speed and turn rate that drive `a`'s pose to `b`'s on an arc in the time
/// between their stamps (the inverse of the arc model the velocity path integrates:
/// forward `Δx = v/ω · sin(ωΔt)`, so `v = Δx · Δθ / (Δt · sin Δθ)`); an increment when the
/// stamps are equal or the step turns more than 3 rad (no plausible arc between two
/// odometry messages; near half a turn `sin Δθ` vanishes).
fn arc_rates(a: &Odom, b: &Odom) -> EventKind<f64> {
    let d = a.pose.between(&b.pose);
    let dt = b.stamp - a.stamp;
    let turn = microslam::geometry::wrap_angle(d.theta);
    if dt.is_nan() || dt <= 0.0 || turn.abs() > 3.0 {
        return EventKind::Increment(d);
    }
    // Δθ / sin Δθ, → 1 for a straight step.
    let stretch = if turn.abs() < 1e-6 {
        1.0 + turn * turn / 6.0
    } else {
        turn / turn.sin()
    };
    EventKind::Velocity {
        v: d.x * stretch / dt,
        omega: turn / dt,
    }
}

fn isometry(t: &ros::Transform) -> Option<Isometry3<f64>> {
    let (v, q) = (t.translation, t.rotation);
    let all = [v.x, v.y, v.z, q.x, q.y, q.z, q.w];
    let norm = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
    if all.iter().any(|x| !x.is_finite()) || norm <= 1e-9 {
        return None;
    }
    let rotation = UnitQuaternion::from_quaternion(Quaternion::new(q.w, q.x, q.y, q.z));
    Some(Isometry3::from_parts(
        Translation3::new(v.x, v.y, v.z),
        rotation,
    ))
}

/// `/tf_static` as a child → (parent, transform) table; a transform with non-finite
/// numbers or a zero quaternion is kept as `None` (an error when a chain uses it).
type Table = BTreeMap<String, (String, Option<Isometry3<f64>>)>;

fn static_transforms_3d(msgs: &[ros::TfMessage]) -> Table {
    let mut table = BTreeMap::new();
    for t in msgs.iter().flat_map(|m| &m.transforms) {
        table.insert(
            t.child_frame_id.trim_start_matches('/').to_owned(),
            (
                t.header.frame_id.trim_start_matches('/').to_owned(),
                isometry(&t.transform),
            ),
        );
    }
    table
}

/// The pose of `frame` in `base` through the chain of static transforms (3-D).
fn mount_3d(table: &Table, base: &str, frame: &str) -> Result<Option<Isometry3<f64>>> {
    let mut pose = Isometry3::identity();
    let mut at = frame;
    for _ in 0..=table.len() {
        if at == base {
            return Ok(Some(pose));
        }
        let Some((parent, t)) = table.get(at) else {
            return Ok(None);
        };
        let Some(t) = t else {
            bail!("the transform {parent} → {at} has a non-finite number or a zero quaternion");
        };
        pose = t * pose;
        at = parent;
    }
    Ok(None)
}

/// An optical frame (REP 103: z forward, x right, y down), by its name.
fn is_optical(frame: &str) -> bool {
    frame.contains("optical")
}

/// A position in an optical frame in the body convention (x forward, y left, z up).
fn optical_to_body(p: [f64; 3]) -> [f64; 3] {
    [p[2], -p[0], -p[1]]
}

/// The recording of a landmark bag replayed with the settings' `[sighting] mount`: the
/// camera mount when it is not zero, else the bag's (`read`).
pub fn recording(path: &Path, options: &BagOptions, mount: [f64; 3]) -> Result<Recording> {
    let given = mount.iter().any(|v| *v != 0.0).then_some(mount);
    Ok(read(path, options, given)?.recording)
}

/// Reads a bag's landmark detections and odometry. `settings_mount` is the settings'
/// `[sighting] mount` when it is not zero: the detections are then taken in the camera's
/// frame (turned from an optical frame to x forward) and the EKF mounts them; otherwise
/// `/tf_static` mounts them on the robot frame.
pub fn read(
    path: &Path,
    options: &BagOptions,
    settings_mount: Option<[f64; 3]>,
) -> Result<DetectionsBag> {
    let bag = BagFiles::open(path)?;
    let channels = bag.topics()?;
    let Some((topic, kind)) = topic_in(path, &channels, options)? else {
        bail!(
            "{}: no topic carries `{}` or `{}`: no landmark detections; the bag has: {}",
            path.display(),
            msg::ARUCO_MARKERS,
            msg::DETECTION3D_ARRAY,
            listed(&channels)
        );
    };
    let odom_topic = odometry_topic(path, &channels, options)?;
    for (t, expected) in [
        (&options.truth_topic, ros::ODOMETRY),
        (&options.tf_static_topic, ros::TF_MESSAGE),
    ] {
        if let Some(ch) = channels.get(t.as_str()) {
            check_type(path, t, ch, expected)?;
        }
    }
    let mut odom: Vec<Odom> = Vec::new();
    let mut truth: Vec<TruePose> = Vec::new();
    let mut detected: Vec<Detected> = Vec::new();
    let mut tf = Vec::new();
    let mut robot_frame: Option<String> = None;
    let mut classes: Vec<(String, u32)> = Vec::new();
    let mut last_detection: Option<(u64, f64)> = None;
    let mut order = 0usize;
    bag.for_each_message(|m| {
        order += 1;
        let t = m.topic;
        let bad = |e: anyhow::Error| {
            anyhow!(
                "{}: topic {t}, message {} (log time {} ns): {e}",
                m.file.display(),
                m.index,
                m.log_time
            )
        };
        if t == odom_topic || t == options.truth_topic {
            let o: ros::Odometry = decode_cdr(m.data).map_err(bad)?;
            let mut read = odom_numbers(&o).map_err(bad)?;
            read.order = order;
            if t == options.truth_topic {
                truth.push(TruePose {
                    stamp: read.stamp,
                    pose: read.pose,
                });
                return Ok(());
            }
            if let Some(last) = odom.last()
                && read.stamp < last.stamp
            {
                return Err(bad(anyhow!(
                    "stamp {} s goes back before the previous odometry message's {} s",
                    read.stamp,
                    last.stamp
                )));
            }
            let child = o.child_frame_id.trim_start_matches('/');
            if !child.is_empty() {
                robot_frame.get_or_insert(child.to_owned());
            }
            odom.push(read);
        } else if t == topic {
            let (stamp, frame, items) = if kind == msg::ARUCO_MARKERS {
                let a: msg::ArucoMarkers = decode_cdr(m.data).map_err(bad)?;
                if a.marker_ids.len() != a.poses.len() {
                    return Err(bad(anyhow!(
                        "{} marker_ids but {} poses: one pose per marker",
                        a.marker_ids.len(),
                        a.poses.len()
                    )));
                }
                let mut items = Vec::with_capacity(a.poses.len());
                for (i, (id, pose)) in a.marker_ids.iter().zip(&a.poses).enumerate() {
                    let id = u32::try_from(*id).map_err(|_| {
                        bad(anyhow!(
                            "marker {i}: id {id} is not a landmark id (0 to 4294967295)"
                        ))
                    })?;
                    let p = pose.position;
                    items.push((Identity::Unique(id), [p.x, p.y, p.z], String::new()));
                }
                (a.header.stamp.seconds(), a.header.frame_id, items)
            } else {
                let a: msg::Detection3DArray = decode_cdr(m.data).map_err(bad)?;
                let mut items = Vec::with_capacity(a.detections.len());
                for d in &a.detections {
                    let best = d
                        .results
                        .iter()
                        .max_by(|x, y| x.hypothesis.score.total_cmp(&y.hypothesis.score));
                    let identity = match best {
                        None => Identity::Unknown,
                        Some(h) => {
                            let name = &h.hypothesis.class_id;
                            let number = match name.trim().parse::<u32>() {
                                Ok(n) => n,
                                Err(_) => match classes.iter().find(|(c, _)| c == name) {
                                    Some((_, n)) => *n,
                                    None => {
                                        let n = u32::try_from(classes.len()).unwrap_or(u32::MAX);
                                        classes.push((name.clone(), n));
                                        n
                                    }
                                },
                            };
                            Identity::Class(number)
                        }
                    };
                    let s = d.bbox.size;
                    let c = match best {
                        Some(h) if s.x == 0.0 && s.y == 0.0 && s.z == 0.0 => {
                            h.pose.pose.position
                        }
                        _ => d.bbox.center.position,
                    };
                    items.push((identity, [c.x, c.y, c.z], d.header.frame_id.clone()));
                }
                (a.header.stamp.seconds(), a.header.frame_id, items)
            };
            if let Some((index, last)) = last_detection
                && stamp < last
            {
                return Err(bad(anyhow!(
                    "stamp {stamp} s goes back before message {index}'s {last} s: the detections' stamps never decrease"
                )));
            }
            last_detection = Some((m.index, stamp));
            for (item, (identity, position, own_frame)) in items.into_iter().enumerate() {
                let own = own_frame.trim_start_matches('/');
                let frame = if own.is_empty() {
                    frame.trim_start_matches('/')
                } else {
                    own
                };
                detected.push(Detected {
                    order,
                    index: m.index,
                    stamp,
                    frame: frame.to_owned(),
                    item,
                    identity,
                    position,
                });
            }
        } else if t == options.tf_static_topic {
            tf.push(decode_cdr::<ros::TfMessage>(m.data).map_err(bad)?);
        }
        Ok(())
    })?;
    if odom.is_empty() {
        bail!(
            "{}: no odometry: no messages on topic {odom_topic} (`{}`)",
            path.display(),
            ros::ODOMETRY
        );
    }
    let motion = match options.odom_motion {
        OdomMotion::Auto => {
            let still = odom.iter().all(|o| o.v == 0.0 && o.omega == 0.0);
            let moves = odom.windows(2).any(|w| w[0].pose != w[1].pose);
            if still && moves {
                OdomMotion::PoseRates
            } else {
                OdomMotion::Twist
            }
        }
        m => m,
    };
    let mut events: Vec<(usize, Event<f64>)> = Vec::with_capacity(odom.len() + detected.len());
    for (k, o) in odom.iter().enumerate() {
        let previous = k.checked_sub(1).and_then(|j| odom.get(j));
        let kind = match motion {
            OdomMotion::Pose => {
                EventKind::Increment(previous.map_or(Pose2::IDENTITY, |p| p.pose.between(&o.pose)))
            }
            // The velocity that drives this pose to the next one, held from this stamp
            // (as a twist is); the last message stops the robot.
            OdomMotion::PoseRates => match odom.get(k + 1) {
                Some(next) => arc_rates(o, next),
                None => EventKind::Velocity { v: 0.0, omega: 0.0 },
            },
            OdomMotion::Auto | OdomMotion::Twist => EventKind::Velocity {
                v: o.v,
                omega: o.omega,
            },
        };
        events.push((o.order, Event::new(o.stamp, kind)));
    }
    let base = robot_frame.unwrap_or_else(|| "base_link".into());
    let table = static_transforms_3d(&tf);
    let mut mounts: BTreeMap<String, Isometry3<f64>> = BTreeMap::new();
    let start = odom.first().map_or(0.0, |o| o.stamp);
    let mut skipped = 0usize;
    let mut sightings = 0usize;
    for d in &detected {
        let at = || {
            format!(
                "{}: topic {topic}, message {}, detection {}",
                path.display(),
                d.index,
                d.item
            )
        };
        let p = d.position;
        if p.iter().any(|v| !v.is_finite()) {
            bail!(
                "{}: position ({}, {}, {}) is not finite",
                at(),
                p[0],
                p[1],
                p[2]
            );
        }
        let ahead = if is_optical(&d.frame) { p[2] } else { p[0] };
        if ahead <= 0.0 {
            bail!(
                "{}: position ({}, {}, {}) in {} is behind the camera ({} {ahead} m ≤ 0)",
                at(),
                p[0],
                p[1],
                p[2],
                d.frame,
                if is_optical(&d.frame) { "z" } else { "x" }
            );
        }
        let in_robot = if settings_mount.is_some() {
            if is_optical(&d.frame) {
                optical_to_body(p)
            } else {
                p
            }
        } else {
            let mount = match mounts.get(&d.frame) {
                Some(m) => *m,
                None => {
                    let m = mount_3d(&table, &base, &d.frame)
                        .map_err(|e| anyhow!("{}: {e}", at()))?
                        .ok_or_else(|| {
                            anyhow!(
                                "{}: no transform from {base} to {} in {} (the camera's mount on the robot; or give it as the settings' [sighting] mount)",
                                at(),
                                d.frame,
                                options.tf_static_topic
                            )
                        })?;
                    mounts.insert(d.frame.clone(), m);
                    m
                }
            };
            let q = mount * Point3::new(p[0], p[1], p[2]);
            [q.x, q.y, q.z]
        };
        let range = in_robot[0].hypot(in_robot[1]);
        if !(range.is_finite() && range > 0.0) {
            bail!(
                "{}: no finite range in the robot's plane (x {}, y {} m in {base})",
                at(),
                in_robot[0],
                in_robot[1]
            );
        }
        if d.stamp < start {
            skipped += 1;
            continue;
        }
        sightings += 1;
        let bearing = in_robot[1].atan2(in_robot[0]);
        events.push((
            d.order,
            Event::new(
                d.stamp,
                EventKind::Sighting(Sighting {
                    identity: d.identity,
                    z: RangeBearing::new(range, bearing),
                    covariance: None,
                }),
            ),
        ));
    }
    if sightings == 0 {
        let mut why = format!("{}: topic {topic}: no detection to use", path.display());
        if skipped > 0 {
            why.push_str(&format!(
                ": all {skipped} come before the first odometry message at {start} s"
            ));
        }
        bail!(why);
    }
    events.sort_by_key(|(o, _)| *o);
    let mut events: Vec<Event<f64>> = events.into_iter().map(|(_, e)| e).collect();
    super::sort_events(&mut events).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    truth.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
    let initial_pose = events
        .first()
        .and_then(|e| interpolate_pose(&truth, e.stamp));
    let name = format!(
        "rosbag/{}",
        path.file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    );
    let mount_source = if settings_mount.is_some() {
        MountSource::Settings
    } else {
        MountSource::TfStatic
    };
    Ok(DetectionsBag {
        path: path.to_path_buf(),
        recording: Recording {
            name,
            events,
            ground_truth: truth,
            landmarks: Vec::new(),
            initial_pose,
            dropped_sightings: skipped,
            dropped_reason: if skipped > 0 {
                format!("{skipped} before the first odometry message")
            } else {
                String::new()
            },
        },
        topic: (topic, kind),
        mount_source,
        motion,
        classes,
    })
}
