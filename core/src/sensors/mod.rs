//! Sensor models: what a sensor measures, given the robot pose and the world.

pub mod camera;
pub mod encoder;
pub mod imu;
pub mod ld06;
pub mod lidar;
pub mod range_bearing;
pub mod wheel_odometry;
