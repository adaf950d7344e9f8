//! ROS 2 bags of landmark detections written from a landmark recording (an MRCLAM run):
//! what a marker-reading robot running ROS 2 would have recorded — `/odom`
//! (`nav_msgs/msg/Odometry`, `odom` → `base_link`: the pose integrated from the
//! recording's velocities, and the velocity as the twist), the detections of each camera
//! frame as one `ros2_aruco_interfaces/msg/ArucoMarkers` or
//! `vision_msgs/msg/Detection3DArray` message on `/detections`, their 3-D positions in
//! `camera_optical_frame` (z forward, x right, y down; landmarks on the floor, z = 0 in
//! `base_link`), `/tf_static` (`base_link` → `camera_link` → `camera_optical_frame`) and
//! `/ground_truth` (`nav_msgs/msg/Odometry` in the world frame).

use super::mcap::{McapFile, SchemaDef};
use super::rosbag::{
    HEADER, QUATERNION, TIME, VECTOR3, odometry_schema, ros2msg, tf_message_schema, write_ros,
};
use crate::domain::recording::Recording;
use crate::inputs::readers::detections_bag::msg;
use crate::inputs::readers::rosbag::msg as ros;
use anyhow::{Result, bail};
use microslam::event::{EventKind, Identity};
use microslam::geometry::Pose2;
use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion};
use std::path::Path;

const POSE: &str = "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";

/// The `ros2_aruco_interfaces/msg/ArucoMarkers` schema.
pub fn aruco_markers_schema() -> SchemaDef {
    ros2msg(
        msg::ARUCO_MARKERS,
        "std_msgs/Header header\nint64[] marker_ids\ngeometry_msgs/Pose[] poses\n",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            ("geometry_msgs/Pose", POSE),
            ("geometry_msgs/Point", VECTOR3),
            ("geometry_msgs/Quaternion", QUATERNION),
        ],
    )
}

/// The `vision_msgs/msg/Detection3DArray` schema.
pub fn detection3d_array_schema() -> SchemaDef {
    ros2msg(
        msg::DETECTION3D_ARRAY,
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            (
                "vision_msgs/Detection3D",
                "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n\
                 vision_msgs/BoundingBox3D bbox\nstring id\n",
            ),
            (
                "vision_msgs/ObjectHypothesisWithPose",
                "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n",
            ),
            (
                "vision_msgs/ObjectHypothesis",
                "string class_id\nfloat64 score\n",
            ),
            (
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
            ),
            (
                "vision_msgs/BoundingBox3D",
                "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
            ),
            ("geometry_msgs/Pose", POSE),
            ("geometry_msgs/Point", VECTOR3),
            ("geometry_msgs/Quaternion", QUATERNION),
            ("geometry_msgs/Vector3", VECTOR3),
        ],
    )
}

/// How the detections are written.
#[derive(Clone, Debug, PartialEq)]
pub enum DetectionFormat {
    /// `ArucoMarkers` with the recording's landmark ids.
    Aruco,
    /// `Detection3DArray`, every detection of this one class (the ids are not written).
    Detection3d {
        /// The class of every landmark.
        class: String,
    },
}

/// The camera's mount on `base_link`: position (m) and roll, pitch, yaw (rad) of
/// `camera_link` (x forward); the optical frame turns from it as REP 103 says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraMount {
    /// x, y, z, m.
    pub position: [f64; 3],
    /// Roll, pitch, yaw, rad.
    pub rpy: [f64; 3],
}

/// `camera_optical_frame` in `camera_link`: z forward, x right, y down.
pub fn optical_rotation() -> UnitQuaternion<f64> {
    // Columns: the optical frame's axes in the link frame.
    let m = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
}

fn quaternion(q: &UnitQuaternion<f64>) -> ros::Quaternion {
    ros::Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn header(stamp: f64, frame: &str) -> ros::Header {
    ros::Header {
        stamp: ros::Time::from_seconds(stamp),
        frame_id: frame.to_owned(),
    }
}

fn odometry(stamp: f64, frame: &str, pose: Pose2<f64>, v: f64, omega: f64) -> ros::Odometry {
    ros::Odometry {
        header: header(stamp, frame),
        child_frame_id: "base_link".into(),
        pose: ros::PoseWithCovariance {
            pose: ros::Pose {
                position: ros::Vector3 {
                    x: pose.x,
                    y: pose.y,
                    z: 0.0,
                },
                orientation: ros::Quaternion::from_yaw(pose.theta),
            },
            covariance: [[0.0; 6]; 6],
        },
        twist: ros::TwistWithCovariance {
            twist: ros::Twist {
                linear: ros::Vector3 {
                    x: v,
                    ..Default::default()
                },
                angular: ros::Vector3 {
                    z: omega,
                    ..Default::default()
                },
            },
            covariance: [[0.0; 6]; 6],
        },
    }
}

/// The pose after driving `v`, `ω` for `dt` from `p` (on the arc).
fn drive(p: Pose2<f64>, v: f64, omega: f64, dt: f64) -> Pose2<f64> {
    let d = omega * dt;
    let (dx, dy) = if d.abs() < 1e-9 {
        (v * dt, 0.0)
    } else {
        (v / omega * d.sin(), v / omega * (1.0 - d.cos()))
    };
    p.compose(&Pose2::new(dx, dy, d))
}

/// Writes `recording` (velocity odometry and sightings) as a ROS 2 bag of detections at
/// `path`; with `twist` the odometry messages carry the velocities too, else their poses
/// only (as an odometry source that publishes no twist). Returns the messages written.
pub fn export(
    path: &Path,
    recording: &Recording,
    format: &DetectionFormat,
    mount: &CameraMount,
    twist: bool,
) -> Result<u64> {
    let mut bag = McapFile::create(path, "ros2")?;
    let first = recording.events.first().map_or(0.0, |e| e.stamp);
    let [x, y, z] = mount.position;
    let [roll, pitch, yaw] = mount.rpy;
    let link = Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    );
    let optical = Isometry3::from_parts(Translation3::identity(), optical_rotation());
    let camera_in_base = link * optical;
    let base_to_camera = camera_in_base.inverse();
    let transform = |iso: &Isometry3<f64>| ros::Transform {
        translation: ros::Vector3 {
            x: iso.translation.x,
            y: iso.translation.y,
            z: iso.translation.z,
        },
        rotation: quaternion(&iso.rotation),
    };
    let tf = ros::TfMessage {
        transforms: vec![
            ros::TransformStamped {
                header: header(first, "base_link"),
                child_frame_id: "camera_link".into(),
                transform: transform(&link),
            },
            ros::TransformStamped {
                header: header(first, "camera_link"),
                child_frame_id: "camera_optical_frame".into(),
                transform: transform(&optical),
            },
        ],
    };
    write_ros(&mut bag, "/tf_static", tf_message_schema, first, &tf)?;
    let mut truth = recording.ground_truth.iter().peekable();
    let mut pose = Pose2::IDENTITY;
    let mut last: Option<(f64, f64, f64)> = None;
    let events = &recording.events;
    let mut i = 0;
    while let Some(e) = events.get(i) {
        while let Some(t) = truth.next_if(|t| t.stamp <= e.stamp) {
            let o = odometry(t.stamp, "world", t.pose, 0.0, 0.0);
            write_ros(&mut bag, "/ground_truth", odometry_schema, t.stamp, &o)?;
        }
        match e.kind {
            EventKind::Velocity { v, omega } => {
                if let Some((t0, v0, w0)) = last {
                    pose = drive(pose, v0, w0, e.stamp - t0);
                }
                last = Some((e.stamp, v, omega));
                let (v, omega) = if twist { (v, omega) } else { (0.0, 0.0) };
                let o = odometry(e.stamp, "odom", pose, v, omega);
                write_ros(&mut bag, "/odom", odometry_schema, e.stamp, &o)?;
                i += 1;
            }
            EventKind::Sighting(_) => {
                // The sightings of one stamp: one camera frame.
                let mut positions = Vec::new();
                while let Some(s) = events.get(i) {
                    let EventKind::Sighting(s_) = s.kind else {
                        break;
                    };
                    if s.stamp != e.stamp {
                        break;
                    }
                    let (r, b) = (s_.z.range, s_.z.bearing);
                    let p = base_to_camera * Point3::new(r * b.cos(), r * b.sin(), 0.0);
                    if !p.z.is_finite() || p.z <= 0.0 {
                        bail!("a sighting at {} s is behind the camera", s.stamp);
                    }
                    positions.push((s_.identity, p));
                    i += 1;
                }
                write_frame(&mut bag, e.stamp, &positions, format)?;
            }
            _ => bail!("only velocity odometry and sightings are written to a detections bag"),
        }
    }
    for t in truth {
        let o = odometry(t.stamp, "world", t.pose, 0.0, 0.0);
        write_ros(&mut bag, "/ground_truth", odometry_schema, t.stamp, &o)?;
    }
    let n = bag.messages;
    bag.finish()?;
    Ok(n)
}

fn write_frame(
    bag: &mut McapFile,
    stamp: f64,
    positions: &[(Identity, Point3<f64>)],
    format: &DetectionFormat,
) -> Result<()> {
    let pose = |p: &Point3<f64>| ros::Pose {
        position: ros::Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        },
        orientation: ros::Quaternion::default(),
    };
    let h = header(stamp, "camera_optical_frame");
    match format {
        DetectionFormat::Aruco => {
            let mut m = msg::ArucoMarkers {
                header: h,
                ..Default::default()
            };
            for (identity, p) in positions {
                let id = match identity {
                    Identity::Unique(id) | Identity::Class(id) => i64::from(*id),
                    Identity::Unknown => bail!("a sighting at {stamp} s has no marker id"),
                };
                m.marker_ids.push(id);
                m.poses.push(pose(p));
            }
            write_ros(bag, "/detections", aruco_markers_schema, stamp, &m)
        }
        DetectionFormat::Detection3d { class } => {
            let detections = positions
                .iter()
                .map(|(_, p)| msg::Detection3D {
                    header: h.clone(),
                    results: vec![msg::ObjectHypothesisWithPose {
                        hypothesis: msg::ObjectHypothesis {
                            class_id: class.clone(),
                            score: 0.9,
                        },
                        pose: ros::PoseWithCovariance {
                            pose: pose(p),
                            covariance: [[0.0; 6]; 6],
                        },
                    }],
                    bbox: msg::BoundingBox3D {
                        center: pose(p),
                        size: ros::Vector3 {
                            x: 0.1,
                            y: 0.3,
                            z: 0.1,
                        },
                    },
                    id: String::new(),
                })
                .collect();
            let m = msg::Detection3DArray {
                header: h,
                detections,
            };
            write_ros(bag, "/detections", detection3d_array_schema, stamp, &m)
        }
    }
}
