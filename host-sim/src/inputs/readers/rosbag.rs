//! ROS 2 bag reader (`rosbag:<bag>`): `sensor_msgs/msg/LaserScan`,
//! `nav_msgs/msg/Odometry` and `sensor_msgs/msg/Imu` messages, CDR-encoded, in either of
//! rosbag2's storages — an MCAP file (read with the `mcap` crate), an SQLite 3 file
//! (`.db3`, read with `rusqlite`), or a bag folder of split files ([`super::bag_storage`])
//! — and decoded with `cdr-encoding` (serde).
//!
//! The scans become the same laser messages a CARMEN log gives ([`LaserMessage`]: ranges,
//! the odometry pose at the scan, the stamp), so a bag goes through the same drivers as a
//! CARMEN log. Messages are taken in the order rosbag2 plays them (the order it received
//! them: an MCAP file's order, an SQLite file's receive times);
//! the odometry pose of a scan is interpolated at the scan's header stamp between the
//! odometry messages received just before and just after it (an odometry message with
//! exactly the scan's stamp is taken as it is). The lidar geometry comes from the scans
//! (`angle_min`, `angle_increment`, `range_min`, `range_max`: a reading at or beyond
//! `range_max`, or +∞ (REP 117), is no return) and the lidar mount from `/tf_static` (the transform
//! chain from the odometry's `child_frame_id` to the scan's `frame_id`), unless the
//! settings give one.
//!
//! A truncated or corrupt file, a topic with another message type or encoding, a message
//! that does not decode, and a missing scan or odometry topic are errors naming the file
//! and the topic. Header stamps that go back are taken in the order received, as a CARMEN
//! log's are (the Intel log, written as a bag, has scans and odometry whose stamps go back
//! by a few milliseconds); a grid run counts its scans' in `metrics.json`
//! (`input_loss.scans.stamps_going_back`).

use super::bag_storage::{BagFiles, Channel};
use super::carmen::LaserMessage;
use anyhow::{Result, anyhow, bail};
use byteorder::{BigEndian, LittleEndian};
use microslam::geometry::{Pose2, wrap_angle};
use microslam::sensors::lidar::LidarGeometry;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// ROS 2 message types as serde structs, field for field in CDR order.
pub mod msg {
    use serde::{Deserialize, Serialize};

    /// `builtin_interfaces/msg/Time`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Time {
        /// Seconds.
        pub sec: i32,
        /// Nanoseconds, 0 ≤ nanosec < 10⁹.
        pub nanosec: u32,
    }

    impl Time {
        /// Seconds as a float.
        pub fn seconds(&self) -> f64 {
            f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
        }

        /// The time nearest to `t` seconds (saturating outside the `i32` range).
        pub fn from_seconds(t: f64) -> Self {
            let whole = t.floor();
            let mut sec = whole as i32;
            let mut nanosec = ((t - whole) * 1e9).round() as u32;
            if nanosec >= 1_000_000_000 {
                sec = sec.saturating_add(1);
                nanosec -= 1_000_000_000;
            }
            Self { sec, nanosec }
        }
    }

    /// `std_msgs/msg/Header`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Header {
        /// Time of the measurement.
        pub stamp: Time,
        /// Frame the data is in.
        pub frame_id: String,
    }

    /// `geometry_msgs/msg/Vector3` (and `Point`: the same fields).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Vector3 {
        /// x.
        pub x: f64,
        /// y.
        pub y: f64,
        /// z.
        pub z: f64,
    }

    /// `geometry_msgs/msg/Quaternion`.
    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    pub struct Quaternion {
        /// x.
        pub x: f64,
        /// y.
        pub y: f64,
        /// z.
        pub z: f64,
        /// w.
        pub w: f64,
    }

    impl Default for Quaternion {
        fn default() -> Self {
            Self::from_yaw(0.0)
        }
    }

    impl Quaternion {
        /// A rotation by `yaw` radians about z.
        pub fn from_yaw(yaw: f64) -> Self {
            let (s, c) = (0.5 * yaw).sin_cos();
            Self {
                x: 0.0,
                y: 0.0,
                z: s,
                w: c,
            }
        }

        /// The rotation's yaw (about z), radians in (−π, π].
        pub fn yaw(&self) -> f64 {
            let Self { x, y, z, w } = *self;
            (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
        }
    }

    /// `geometry_msgs/msg/Pose`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Pose {
        /// Position (a `Point`).
        pub position: Vector3,
        /// Orientation.
        pub orientation: Quaternion,
    }

    /// `geometry_msgs/msg/PoseWithCovariance` (covariance row-major, 6 × 6).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct PoseWithCovariance {
        /// Pose.
        pub pose: Pose,
        /// Covariance of (x, y, z, roll, pitch, yaw).
        pub covariance: [[f64; 6]; 6],
    }

    /// `geometry_msgs/msg/Twist`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Twist {
        /// Linear velocity, m/s.
        pub linear: Vector3,
        /// Angular velocity, rad/s.
        pub angular: Vector3,
    }

    /// `geometry_msgs/msg/TwistWithCovariance`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TwistWithCovariance {
        /// Twist.
        pub twist: Twist,
        /// Covariance, row-major 6 × 6.
        pub covariance: [[f64; 6]; 6],
    }

    /// `nav_msgs/msg/Odometry`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Odometry {
        /// Stamp and the odometry frame.
        pub header: Header,
        /// The robot's frame (e.g. `base_link`).
        pub child_frame_id: String,
        /// Pose of the robot in the odometry frame.
        pub pose: PoseWithCovariance,
        /// Velocity in the robot frame.
        pub twist: TwistWithCovariance,
    }

    /// `sensor_msgs/msg/LaserScan`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct LaserScan {
        /// Stamp of the first beam and the lidar frame.
        pub header: Header,
        /// Angle of the first beam, rad.
        pub angle_min: f32,
        /// Angle of the last beam, rad.
        pub angle_max: f32,
        /// Angle between beams, rad.
        pub angle_increment: f32,
        /// Time between beams, s.
        pub time_increment: f32,
        /// Time between scans, s.
        pub scan_time: f32,
        /// Shortest valid range, m.
        pub range_min: f32,
        /// Longest valid range, m.
        pub range_max: f32,
        /// Ranges, m.
        pub ranges: Vec<f32>,
        /// Intensities (may be empty).
        pub intensities: Vec<f32>,
    }

    /// `sensor_msgs/msg/Imu`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Imu {
        /// Stamp and frame.
        pub header: Header,
        /// Orientation.
        pub orientation: Quaternion,
        /// Its covariance, row-major 3 × 3.
        pub orientation_covariance: [f64; 9],
        /// Angular velocity, rad/s.
        pub angular_velocity: Vector3,
        /// Its covariance.
        pub angular_velocity_covariance: [f64; 9],
        /// Linear acceleration, m/s².
        pub linear_acceleration: Vector3,
        /// Its covariance.
        pub linear_acceleration_covariance: [f64; 9],
    }

    /// `geometry_msgs/msg/Transform`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Transform {
        /// Translation, m.
        pub translation: Vector3,
        /// Rotation.
        pub rotation: Quaternion,
    }

    /// `geometry_msgs/msg/TransformStamped`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TransformStamped {
        /// Stamp and the parent frame.
        pub header: Header,
        /// The child frame.
        pub child_frame_id: String,
        /// The child's pose in the parent frame.
        pub transform: Transform,
    }

    /// `tf2_msgs/msg/TFMessage`.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct TfMessage {
        /// Transforms.
        pub transforms: Vec<TransformStamped>,
    }

    /// The ROS 2 type names of the messages read and written.
    pub const LASER_SCAN: &str = "sensor_msgs/msg/LaserScan";
    /// `nav_msgs/msg/Odometry`.
    pub const ODOMETRY: &str = "nav_msgs/msg/Odometry";
    /// `sensor_msgs/msg/Imu`.
    pub const IMU: &str = "sensor_msgs/msg/Imu";
    /// `tf2_msgs/msg/TFMessage`.
    pub const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";
}

/// The 4-byte encapsulation header of a little-endian CDR message.
pub const CDR_LE_HEADER: [u8; 4] = [0, 1, 0, 0];

/// A message CDR-encoded, little-endian, with its encapsulation header.
pub fn encode_cdr<T: Serialize>(value: &T) -> Result<Vec<u8>> {
    let body =
        cdr_encoding::to_vec::<T, LittleEndian>(value).map_err(|e| anyhow!("CDR encoding: {e}"))?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    Ok(out)
}

/// A CDR message (with its encapsulation header: plain CDR, big or little endian).
pub fn decode_cdr<'de, T: Deserialize<'de>>(data: &'de [u8]) -> Result<T> {
    let (head, body) = data
        .split_at_checked(4)
        .ok_or_else(|| anyhow!("{} bytes: shorter than the CDR header", data.len()))?;
    let value = match (head[0], head[1]) {
        (0, 1) => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        (0, 0) => cdr_encoding::from_bytes::<T, BigEndian>(body),
        (a, b) => bail!("CDR representation {a:#04x}{b:02x} is not plain CDR (0x0000 or 0x0001)"),
    };
    value.map(|(v, _)| v).map_err(|e| anyhow!("{e}"))
}

/// Topics of a bag and the lidar mount when `/tf_static` has none.
#[derive(Clone, Debug, PartialEq)]
pub struct BagOptions {
    /// `sensor_msgs/msg/LaserScan` topic (required).
    pub scan_topic: String,
    /// `nav_msgs/msg/Odometry` topic (required).
    pub odom_topic: String,
    /// `sensor_msgs/msg/Imu` topic (read when present).
    pub imu_topic: String,
    /// `tf2_msgs/msg/TFMessage` topic of the static transforms (read when present).
    pub tf_static_topic: String,
    /// Lidar mount `(x, y, yaw)` in the robot frame: overrides `/tf_static` when given.
    pub lidar_mount: Option<[f64; 3]>,
    /// Landmark detections topic (`ArucoMarkers` or `Detection3DArray`); `None`: the one
    /// topic of either type.
    pub detections_topic: Option<String>,
    /// `nav_msgs/msg/Odometry` topic of the ground truth of a landmark run (read when
    /// present).
    pub truth_topic: String,
    /// What of the odometry drives a landmark run.
    pub odom_motion: super::detections_bag::OdomMotion,
}

impl Default for BagOptions {
    fn default() -> Self {
        Self {
            scan_topic: "/scan".into(),
            odom_topic: "/odom".into(),
            imu_topic: "/imu".into(),
            tf_static_topic: "/tf_static".into(),
            lidar_mount: None,
            detections_topic: None,
            truth_topic: "/ground_truth".into(),
            odom_motion: super::detections_bag::OdomMotion::Auto,
        }
    }
}

/// Where the lidar mount came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MountSource {
    /// The settings (`--lidar-mount`).
    Settings,
    /// The bag's static transforms.
    TfStatic,
    /// Neither: the lidar is taken to sit at the robot origin.
    Origin,
}

/// An IMU sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuSample {
    /// Stamp, s.
    pub stamp: f64,
    /// Angular velocity about z, rad/s.
    pub yaw_rate: f64,
    /// Linear acceleration (x, y, z), m/s².
    pub acceleration: [f64; 3],
}

/// A bag read into memory.
#[derive(Clone, Debug)]
pub struct RosBag {
    /// The file.
    pub path: PathBuf,
    /// The scans with the odometry pose at each, in file order (as from a CARMEN log).
    pub scans: Vec<LaserMessage>,
    /// The lidar geometry (from the first scan, the mount from `/tf_static` or settings).
    pub lidar: LidarGeometry,
    /// Where the mount came from.
    pub mount_source: MountSource,
    /// Odometry messages read.
    pub odometry_messages: usize,
    /// IMU samples (empty when the bag has no IMU topic).
    pub imu: Vec<ImuSample>,
}

impl RosBag {
    /// Beams per scan.
    pub fn lidar_beams(&self) -> usize {
        self.scans.first().map_or(0, |s| s.ranges.len())
    }
}

/// Checks that `topic` carries `expected` messages in CDR.
pub(crate) fn check_type(path: &Path, topic: &str, ch: &Channel, expected: &str) -> Result<()> {
    if ch.schema != expected {
        bail!(
            "{}: topic {topic} carries `{}`, expected `{expected}`",
            path.display(),
            ch.schema
        );
    }
    if ch.encoding != "cdr" {
        bail!(
            "{}: topic {topic} is `{}`-encoded; ROS 2 bags are `cdr`",
            path.display(),
            ch.encoding
        );
    }
    Ok(())
}

/// `/tf_static`'s transforms as a child → (parent, pose) table (2D: x, y, yaw).
fn static_transforms(msgs: &[msg::TfMessage]) -> BTreeMap<String, (String, Pose2<f64>)> {
    let mut table = BTreeMap::new();
    for t in msgs.iter().flat_map(|m| &m.transforms) {
        let tr = &t.transform;
        table.insert(
            t.child_frame_id.trim_start_matches('/').to_owned(),
            (
                t.header.frame_id.trim_start_matches('/').to_owned(),
                Pose2::new(tr.translation.x, tr.translation.y, tr.rotation.yaw()),
            ),
        );
    }
    table
}

/// The pose of `frame` in `base` by the chain of static transforms, if one leads there.
fn mount_from(
    table: &BTreeMap<String, (String, Pose2<f64>)>,
    base: &str,
    frame: &str,
) -> Option<Pose2<f64>> {
    let mut pose = Pose2::IDENTITY;
    let mut at = frame;
    for _ in 0..=table.len() {
        if at == base {
            return Some(pose);
        }
        let (parent, p) = table.get(at)?;
        pose = p.compose(&pose);
        at = parent;
    }
    None
}

/// The odometry pose at `t`: the message with exactly that stamp among the ones received
/// around `before` (the count received before the scan), else interpolated between two
/// consecutive ones around it whose stamps bracket `t`, else the nearest of the two
/// neighbours.
fn odometry_at(odom: &[(f64, Pose2<f64>)], before: usize, t: f64) -> Option<Pose2<f64>> {
    let lo = before.saturating_sub(2);
    let hi = (before + 1).min(odom.len());
    let near = odom.get(lo..hi)?;
    if let Some((_, p)) = near.iter().rev().find(|(s, _)| *s == t) {
        return Some(*p);
    }
    for w in near.windows(2) {
        let ((ta, a), (tb, b)) = (w[0], w[1]);
        if ta <= t && t <= tb && tb > ta {
            let s = (t - ta) / (tb - ta);
            return Some(Pose2::new(
                a.x + s * (b.x - a.x),
                a.y + s * (b.y - a.y),
                wrap_angle(a.theta + s * wrap_angle(b.theta - a.theta)),
            ));
        }
    }
    near.iter()
        .min_by(|x, y| (x.0 - t).abs().total_cmp(&(y.0 - t).abs()))
        .map(|(_, p)| *p)
}

/// Checks one `LaserScan` on its own: finite angles, an angle increment that is not 0,
/// ranges as many as its angle span holds (`(angle_max − angle_min) / angle_increment +
/// 1`, or one fewer: a full-turn lidar whose last beam would repeat its first; to half a
/// beam), `0 ≤ range_min < range_max`. The error names the field.
pub fn check_scan(s: &msg::LaserScan) -> std::result::Result<(), String> {
    for (name, v) in [
        ("angle_min", s.angle_min),
        ("angle_max", s.angle_max),
        ("angle_increment", s.angle_increment),
        ("range_min", s.range_min),
        ("range_max", s.range_max),
    ] {
        if !v.is_finite() {
            return Err(format!("{name} {v} is not finite"));
        }
    }
    if s.angle_increment == 0.0 {
        return Err("angle_increment is 0: the beams would all point one way".into());
    }
    if s.ranges.is_empty() {
        return Err("no ranges: a scan needs at least one".into());
    }
    let span = f64::from(s.angle_max) - f64::from(s.angle_min);
    let steps = span / f64::from(s.angle_increment);
    let n = s.ranges.len() as f64;
    if !((steps - 0.5)..=(steps + 1.5)).contains(&n) {
        return Err(format!(
            "{} ranges, but angle_min {} … angle_max {} by angle_increment {} holds {:.1} beams",
            s.ranges.len(),
            s.angle_min,
            s.angle_max,
            s.angle_increment,
            steps + 1.0
        ));
    }
    if !(s.range_min >= 0.0 && s.range_max > s.range_min) {
        return Err(format!(
            "range_min {} and range_max {}: need 0 ≤ range_min < range_max",
            s.range_min, s.range_max
        ));
    }
    Ok(())
}

/// The fields of a scan that make its geometry, compared scan by scan.
#[derive(Clone, Debug, PartialEq)]
struct ScanGeometry {
    angle_min: f32,
    angle_increment: f32,
    range_min: f32,
    range_max: f32,
    frame_id: String,
}

impl ScanGeometry {
    fn of(s: &msg::LaserScan) -> Self {
        Self {
            angle_min: s.angle_min,
            angle_increment: s.angle_increment,
            range_min: s.range_min,
            range_max: s.range_max,
            frame_id: s.header.frame_id.trim_start_matches('/').to_owned(),
        }
    }

    /// The first field in which `self` differs from `other`.
    fn differs_from(&self, other: &Self) -> Option<&'static str> {
        [
            ("angle_min", self.angle_min == other.angle_min),
            (
                "angle_increment",
                self.angle_increment == other.angle_increment,
            ),
            ("range_min", self.range_min == other.range_min),
            ("range_max", self.range_max == other.range_max),
            ("header.frame_id", self.frame_id == other.frame_id),
        ]
        .into_iter()
        .find(|(_, same)| !same)
        .map(|(name, _)| name)
    }

    fn value(&self, field: &str) -> String {
        match field {
            "angle_min" => self.angle_min.to_string(),
            "angle_increment" => self.angle_increment.to_string(),
            "range_min" => self.range_min.to_string(),
            "range_max" => self.range_max.to_string(),
            _ => self.frame_id.clone(),
        }
    }
}

/// Reads a ROS 2 bag (MCAP) for grid SLAM or localization.
pub fn read(path: &Path, options: &BagOptions) -> Result<RosBag> {
    let bag = BagFiles::open(path)?;
    let channels = bag.topics()?;
    let listed = || channels.keys().cloned().collect::<Vec<_>>().join(", ");
    for (topic, expected) in [
        (&options.scan_topic, msg::LASER_SCAN),
        (&options.odom_topic, msg::ODOMETRY),
    ] {
        let ch = channels.get(topic.as_str()).ok_or_else(|| {
            anyhow!(
                "{}: no messages on topic {topic} (`{expected}`); the bag has: {} (name the topic with --scan-topic / --odom-topic)",
                path.display(),
                listed()
            )
        })?;
        check_type(path, topic, ch, expected)?;
    }
    for (topic, expected) in [
        (&options.imu_topic, msg::IMU),
        (&options.tf_static_topic, msg::TF_MESSAGE),
    ] {
        if let Some(ch) = channels.get(topic.as_str()) {
            check_type(path, topic, ch, expected)?;
        }
    }

    let mut scans: Vec<(msg::LaserScan, usize)> = Vec::new();
    let mut odom: Vec<(f64, Pose2<f64>)> = Vec::new();
    let mut robot_frame: Option<String> = None;
    let mut imu = Vec::new();
    let mut tf = Vec::new();
    bag.for_each_message(|m| {
        let topic = m.topic;
        let bad = |e: anyhow::Error| {
            anyhow!(
                "{}: topic {topic}, message {} (log time {} ns): {e}",
                m.file.display(),
                m.index,
                m.log_time
            )
        };
        if topic == options.scan_topic {
            let s: msg::LaserScan = decode_cdr(m.data).map_err(bad)?;
            scans.push((s, odom.len()));
        } else if topic == options.odom_topic {
            let o: msg::Odometry = decode_cdr(m.data).map_err(bad)?;
            let p = &o.pose.pose;
            for (field, v) in [
                ("pose.pose.position.x", p.position.x),
                ("pose.pose.position.y", p.position.y),
            ] {
                // A non-finite one is kept: the replay refuses and counts it.
                if v.abs() > super::carmen::MAX_COORDINATE_M {
                    return Err(bad(anyhow!(
                        "{field} = {v} m is beyond {} km of the origin",
                        super::carmen::MAX_COORDINATE_M / 1e3
                    )));
                }
            }
            let stamp = o.header.stamp.seconds();
            odom.push((
                stamp,
                Pose2::new(p.position.x, p.position.y, p.orientation.yaw()),
            ));
            robot_frame.get_or_insert(o.child_frame_id.trim_start_matches('/').to_owned());
        } else if topic == options.imu_topic {
            let i: msg::Imu = decode_cdr(m.data).map_err(bad)?;
            let a = i.linear_acceleration;
            imu.push(ImuSample {
                stamp: i.header.stamp.seconds(),
                yaw_rate: i.angular_velocity.z,
                acceleration: [a.x, a.y, a.z],
            });
        } else if topic == options.tf_static_topic {
            tf.push(decode_cdr::<msg::TfMessage>(m.data).map_err(bad)?);
        }
        Ok(())
    })?;
    let (first, _) = scans.first().ok_or_else(|| {
        anyhow!(
            "{}: no messages on topic {}",
            path.display(),
            options.scan_topic
        )
    })?;
    if let Err(why) = check_scan(first) {
        bail!(
            "{}: topic {}, scan 0: {why}",
            path.display(),
            options.scan_topic
        );
    }
    let lidar_frame = first.header.frame_id.trim_start_matches('/').to_owned();
    let base = robot_frame.unwrap_or_else(|| "base_link".into());
    let table = static_transforms(&tf);
    let (mount, mount_source) = match (options.lidar_mount, mount_from(&table, &base, &lidar_frame))
    {
        (Some([x, y, yaw]), _) => (Pose2::new(x, y, yaw), MountSource::Settings),
        (None, Some(p)) => (p, MountSource::TfStatic),
        (None, None) => (Pose2::IDENTITY, MountSource::Origin),
    };
    let lidar = LidarGeometry {
        first_angle: first.angle_min,
        angle_increment: first.angle_increment,
        min_range: first.range_min,
        max_range: first.range_max,
        no_return_range: first.range_max,
        mount: Pose2::new(mount.x as f32, mount.y as f32, mount.theta as f32),
    };
    if !lidar.is_valid() {
        bail!(
            "{}: topic {}: the first scan's geometry is invalid (angle_min {}, angle_increment {}, range_min {}, range_max {})",
            path.display(),
            options.scan_topic,
            first.angle_min,
            first.angle_increment,
            first.range_min,
            first.range_max
        );
    }
    let beams = first.ranges.len();
    let first_geometry = ScanGeometry::of(first);
    let mut out = Vec::with_capacity(scans.len());
    for (i, (s, before)) in scans.into_iter().enumerate() {
        // Every scan's geometry is checked, not the first's only: on its own, then
        // against the first's (one lidar geometry for the whole run).
        let at = || format!("{}: topic {}, scan {i}", path.display(), options.scan_topic);
        if let Err(why) = check_scan(&s) {
            bail!("{}: {why}", at());
        }
        if s.ranges.len() != beams {
            bail!(
                "{}: {} ranges, the first scan has {beams}",
                at(),
                s.ranges.len()
            );
        }
        if let Some(field) = ScanGeometry::of(&s).differs_from(&first_geometry) {
            bail!(
                "{}: {field} {} differs from the first scan's {}: one lidar geometry a bag",
                at(),
                ScanGeometry::of(&s).value(field),
                first_geometry.value(field)
            );
        }
        let stamp = s.header.stamp.seconds();
        let Some(p) = odometry_at(&odom, before, stamp) else {
            bail!(
                "{}: topic {}: no odometry message before or after scan {i}",
                path.display(),
                options.odom_topic
            );
        };
        let pose = [p.x, p.y, p.theta];
        // REP 117: +∞ is "no object within range".
        let ranges = s
            .ranges
            .iter()
            .map(|r| {
                if *r == f32::INFINITY {
                    lidar.no_return_range
                } else {
                    *r
                }
            })
            .collect();
        out.push(LaserMessage {
            rear: false,
            ranges,
            pose,
            odom: pose,
            stamp,
        });
    }
    Ok(RosBag {
        path: path.to_path_buf(),
        scans: out,
        lidar,
        mount_source,
        odometry_messages: odom.len(),
        imu,
    })
}

#[cfg(test)]
mod tests;
