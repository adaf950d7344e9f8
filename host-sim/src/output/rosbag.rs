//! ROS 2 bags written from CARMEN logs (`host-sim export-rosbag`): what a robot running
//! ROS 2 would have recorded — `/scan` (`sensor_msgs/msg/LaserScan` in `laser`), `/odom`
//! (`nav_msgs/msg/Odometry`, `odom` → `base_link`, one message before each scan with the
//! scan's odometry pose and stamp) and `/tf_static` (`base_link` → `laser`), CDR-encoded
//! in an MCAP file with the `ros2` profile and `ros2msg` schemas, as rosbag2 writes them.
//! Ranges are written as the log has them (a reading at or beyond `range_max` is no
//! return, as drivers write them).

use super::mcap::{McapFile, SchemaDef};
use crate::inputs::readers::carmen::LaserMessage;
use crate::inputs::readers::rosbag::{BagOptions, encode_cdr, msg};
use anyhow::Result;
use microslam::sensors::lidar::LidarGeometry;
use std::path::Path;

pub(crate) const SEPARATOR: &str =
    "================================================================================\n";
pub(crate) const HEADER: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";
pub(crate) const TIME: &str = "int32 sec\nuint32 nanosec\n";
pub(crate) const QUATERNION: &str = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
pub(crate) const VECTOR3: &str = "float64 x\nfloat64 y\nfloat64 z\n";

/// A `ros2msg` schema: the type's definition followed by its dependencies'.
pub(crate) fn ros2msg(name: &str, text: &str, deps: &[(&str, &str)]) -> SchemaDef {
    let mut data = text.to_owned();
    for (dep, def) in deps {
        data.push_str(SEPARATOR);
        data.push_str(&format!("MSG: {dep}\n{def}"));
    }
    SchemaDef {
        name: name.to_owned(),
        encoding: "ros2msg".into(),
        data: data.into_bytes(),
    }
}

/// The `sensor_msgs/msg/LaserScan` schema.
pub fn laser_scan_schema() -> SchemaDef {
    ros2msg(
        msg::LASER_SCAN,
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
         float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
         float32[] ranges\nfloat32[] intensities\n",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
        ],
    )
}

/// The `nav_msgs/msg/Odometry` schema.
pub fn odometry_schema() -> SchemaDef {
    ros2msg(
        msg::ODOMETRY,
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            (
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
            ),
            (
                "geometry_msgs/Pose",
                "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
            ),
            ("geometry_msgs/Point", VECTOR3),
            ("geometry_msgs/Quaternion", QUATERNION),
            (
                "geometry_msgs/TwistWithCovariance",
                "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
            ),
            (
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
            ),
            ("geometry_msgs/Vector3", VECTOR3),
        ],
    )
}

/// The `sensor_msgs/msg/Imu` schema.
pub fn imu_schema() -> SchemaDef {
    ros2msg(
        msg::IMU,
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n\
         float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n\
         float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n\
         float64[9] linear_acceleration_covariance\n",
        &[
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            ("geometry_msgs/Quaternion", QUATERNION),
            ("geometry_msgs/Vector3", VECTOR3),
        ],
    )
}

/// The `tf2_msgs/msg/TFMessage` schema.
pub fn tf_message_schema() -> SchemaDef {
    ros2msg(
        msg::TF_MESSAGE,
        "geometry_msgs/TransformStamped[] transforms\n",
        &[
            (
                "geometry_msgs/TransformStamped",
                "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
            ),
            ("std_msgs/Header", HEADER),
            ("builtin_interfaces/Time", TIME),
            (
                "geometry_msgs/Transform",
                "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
            ),
            ("geometry_msgs/Vector3", VECTOR3),
            ("geometry_msgs/Quaternion", QUATERNION),
        ],
    )
}

/// Writes a ROS 2 message on `topic` of a bag.
pub fn write_ros<T: serde::Serialize>(
    bag: &mut McapFile,
    topic: &str,
    schema: fn() -> SchemaDef,
    stamp: f64,
    message: &T,
) -> Result<()> {
    bag.write_raw(topic, &schema, "cdr", stamp, &encode_cdr(message)?)
}

/// Writes `scans` (CARMEN laser messages with their odometry) as a ROS 2 bag at `path`
/// with the topics of `topics` and the lidar `lidar`. Returns the messages written.
pub fn export(
    path: &Path,
    scans: &[&LaserMessage],
    lidar: &LidarGeometry,
    topics: &BagOptions,
) -> Result<u64> {
    let mut bag = McapFile::create(path, "ros2")?;
    let header = |stamp: f64, frame: &str| msg::Header {
        stamp: msg::Time::from_seconds(stamp),
        frame_id: frame.to_owned(),
    };
    let first = scans.first().map_or(0.0, |s| s.stamp);
    let mount = lidar.mount;
    let tf = msg::TfMessage {
        transforms: vec![msg::TransformStamped {
            header: header(first, "base_link"),
            child_frame_id: "laser".into(),
            transform: msg::Transform {
                translation: msg::Vector3 {
                    x: f64::from(mount.x),
                    y: f64::from(mount.y),
                    z: 0.0,
                },
                rotation: msg::Quaternion::from_yaw(f64::from(mount.theta)),
            },
        }],
    };
    write_ros(
        &mut bag,
        &topics.tf_static_topic,
        tf_message_schema,
        first,
        &tf,
    )?;
    for s in scans {
        let [x, y, theta] = s.odom;
        let odom = msg::Odometry {
            header: header(s.stamp, "odom"),
            child_frame_id: "base_link".into(),
            pose: msg::PoseWithCovariance {
                pose: msg::Pose {
                    position: msg::Vector3 { x, y, z: 0.0 },
                    orientation: msg::Quaternion::from_yaw(theta),
                },
                covariance: [[0.0; 6]; 6],
            },
            twist: Default::default(),
        };
        write_ros(
            &mut bag,
            &topics.odom_topic,
            odometry_schema,
            s.stamp,
            &odom,
        )?;
        let n = s.ranges.len();
        let scan = msg::LaserScan {
            header: header(s.stamp, "laser"),
            angle_min: lidar.first_angle,
            angle_max: lidar.beam_angle(n.saturating_sub(1)),
            angle_increment: lidar.angle_increment,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: lidar.min_range,
            range_max: lidar.no_return_range.min(lidar.max_range),
            ranges: s.ranges.clone(),
            intensities: Vec::new(),
        };
        write_ros(
            &mut bag,
            &topics.scan_topic,
            laser_scan_schema,
            s.stamp,
            &scan,
        )?;
    }
    let n = bag.messages;
    bag.finish()?;
    Ok(n)
}
