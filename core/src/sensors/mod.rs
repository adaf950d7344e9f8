//! Sensor models: what a sensor measures, given the robot pose and the world.

pub mod camera;
pub mod range_bearing;
