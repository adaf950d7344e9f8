//! A lidar wired to the device itself, as a [`super::Session`] reads it.

use crate::sensors::lidar::LidarScan;
use crate::wire::LidarCounters;

/// A lidar the device reads on its own bus (a UART lidar's packet stream, decoded and
/// binned into revolutions), for [`crate::wire::Command::NextRevolution`]. Implemented
/// for the LD06 reader of `microslam-hal` (`Ld06Uart`, its feature `device`).
pub trait LidarSource {
    /// Reads until the lidar has finished its next revolution (blocking, as the bus
    /// read does) and returns it; `None` when the bus failed before one was finished.
    fn next_revolution(&mut self) -> Option<LidarScan<'_>>;

    /// What the reader has seen so far.
    fn counters(&self) -> LidarCounters;
}
