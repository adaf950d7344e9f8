//! Sensor events: one time-stamped sample from one sensor.
//!
//! Readers (dataset files on the host, the wire decoder on the firmware) turn their input
//! into a time-ordered stream of [`Event`]s; [`crate::feed::EventFeed`] turns the stream
//! into estimator steps, so estimators never read files or ports. The set of sensor kinds is open ([`EventKind`] is `#[non_exhaustive]`).
//!
//! **Lidar scans are not events.** They travel beside this stream as a
//! [`LidarScan`](crate::sensors::lidar::LidarScan) that borrows its ranges, handed straight
//! to the grid filters (`GridSlam::observe`, `GridLocalizer::observe`) between the
//! odometry steps. An `EventKind` variant would have to either borrow the ranges — a
//! lifetime parameter on `Event` and on every estimator API that takes events, for one
//! sensor — or own them in a fixed-capacity `heapless::Vec<f32, N>`: then every `Event`
//! (odometry at 20–100 Hz, sightings, copied by value through queues and the wire
//! decoder) would be as large as the largest scan (720 bytes for 180 beams), `N` would be
//! one capacity for every user, and `Copy` would copy whole scans. On the serial line a
//! scan already arrives as several chunks reassembled into a buffer the device owns
//! (`wire::scan`), which is then lent to the filter: no copy, no oversized events.
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
    /// A car's odometry: the speed of its rear-axle centre and its front steering angle,
    /// held until the next odometry sample like [`EventKind::Velocity`]; moved through the
    /// bicycle model of [`crate::motion::Ackermann`] (the wheelbase is the vehicle's
    /// setting, not part of the event).
    Ackermann {
        /// Speed of the rear-axle centre, m/s (negative when reversing).
        v: T,
        /// Front steering angle, rad, counter-clockwise (left) positive.
        steering: T,
    },
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
