//! Sensor events: one time-stamped sample from one sensor.
//!
//! Readers (dataset files on the host, the wire decoder on the firmware) turn their input
//! into a time-ordered stream of [`Event`]s; estimators consume events and never read
//! files or ports. The set of sensor kinds is open ([`EventKind`] is `#[non_exhaustive]`):
//! wheel-tick odometry and lidar scans join the landmark-related kinds here.
//!
//! Time stamps are `f64` seconds on the sensor's clock (Unix time in the datasets): an
//! `f32` cannot hold a Unix time to better than two minutes. Estimators only use
//! differences of stamps.

use crate::geometry::Pose2;
use crate::sensors::range_bearing::RangeBearing;
use nalgebra::Matrix2;

/// One sensor sample with its time stamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Event<T: nalgebra::Scalar> {
    /// Time of the sample, seconds.
    pub stamp: f64,
    /// What was measured.
    pub kind: EventKind<T>,
}

impl<T: nalgebra::Scalar> Event<T> {
    /// An event from its stamp and content.
    pub const fn new(stamp: f64, kind: EventKind<T>) -> Self {
        Self { stamp, kind }
    }
}

/// The content of an [`Event`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum EventKind<T: nalgebra::Scalar> {
    /// Wheel odometry reported as velocities, held until the next odometry sample.
    Velocity {
        /// Forward speed, m/s.
        v: T,
        /// Turn rate, rad/s, counter-clockwise positive.
        omega: T,
    },
    /// Wheel odometry reported as a pose increment `(dx, dy, dθ)` in the previous robot
    /// frame, covering the time since the previous increment.
    Increment(Pose2<T>),
    /// Yaw rate of an IMU's gyroscope, rad/s, counter-clockwise positive.
    YawRate(T),
    /// A range-bearing sighting of a point landmark.
    Sighting(Sighting<T>),
}

/// What the perception front end says about which landmark it saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Identity {
    /// Nothing: data association must decide.
    Unknown,
    /// A unique identity (marker id, barcode): one id, one landmark.
    Unique(u32),
    /// A class shared by several landmarks (a traffic-sign type): a hint only; the
    /// association chooses among the landmarks and may override it.
    Class(u32),
}

/// A range-bearing sighting of a landmark.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sighting<T: nalgebra::Scalar> {
    /// Which landmark the front end believes it saw.
    pub identity: Identity,
    /// The measurement.
    pub z: RangeBearing<T>,
    /// Measurement covariance (range, bearing); `None` to use the estimator's setting.
    pub covariance: Option<Matrix2<T>>,
}
