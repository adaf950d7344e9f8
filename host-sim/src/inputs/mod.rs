//! Layer 1: where events come from — dataset readers, the built-in simulator's worlds,
//! fault injection into event streams and laser scans, stress recordings made from shared
//! ones, and the camera world.

pub mod camera;
pub mod faults;
pub mod readers;
pub mod sim;
pub mod stress;
