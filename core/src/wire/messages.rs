//! The messages: sensor events and commands to the device, estimates and status to the host.
//!
//! All numbers on the wire are `f32` (the target's scalar) and integers; postcard encodes
//! integers as varints, so small sequence numbers and stamps cost few bytes. Every message
//! to the device carries a sequence number `seq` chosen by the host (usually counting up);
//! each estimate names the `seq` of the event it answers, so the host can stream without
//! waiting for replies.

use crate::ekf::EkfConfig;
use crate::ekf::health::HealthStatus;
use crate::gate::ChiSquareGate;
use crate::geometry::Pose2;
use crate::motion::{Ackermann, AckermannNoise, IncrementNoise, VelocityNoise};
use crate::sensors::range_bearing::RangeBearingSensor;
use heapless::Vec;
use serde::{Deserialize, Serialize};

/// Beams per [`ScanChunk`]: a 90-beam scan takes three frames.
pub const SCAN_CHUNK_BEAMS: usize = 32;

/// Odometry in one of the forms robots report.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Odometry {
    /// A pose increment in the previous robot frame: metres, metres, radians.
    Increment {
        /// Forward motion, m.
        dx: f32,
        /// Leftward motion, m.
        dy: f32,
        /// Turn, rad (counter-clockwise positive).
        dtheta: f32,
    },
    /// Velocities held over `dt`.
    Velocity {
        /// Forward speed, m/s.
        v: f32,
        /// Yaw rate, rad/s.
        omega: f32,
        /// Duration, s.
        dt: f32,
    },
    /// A car's speed and front steering angle held over `dt`, moved through the car
    /// model of [`Command::ConfigureCar`] (the EKF only; rejected before a car is
    /// configured, ignored by the grid estimators). Since protocol 6.
    Ackermann {
        /// Speed of the rear-axle centre, m/s.
        v: f32,
        /// Front steering angle, rad (counter-clockwise positive).
        steering: f32,
        /// Duration, s.
        dt: f32,
    },
    /// Wheel encoder ticks counted over `dt` (four-wheel differential drive).
    EncoderTicks {
        /// Front-left ticks.
        front_left: i32,
        /// Front-right ticks.
        front_right: i32,
        /// Rear-left ticks.
        rear_left: i32,
        /// Rear-right ticks.
        rear_right: i32,
        /// Duration, s.
        dt: f32,
    },
}

/// Which estimator the device runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EstimatorKind {
    /// Landmark EKF-SLAM (odometry + landmark sightings).
    #[default]
    Ekf,
    /// Grid particle filter (odometry + yaw rate + lidar).
    Grid,
    /// Grid localizer on the map in the device's flash (odometry + lidar): estimates come
    /// as [`ToHost::Localization`]. Refused with [`ToHost::Refused`] when the device
    /// has no valid map.
    Localizer,
}

/// Commands from the host.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Restart the active estimator with the robot at this pose, counters cleared.
    Reset {
        /// x, m.
        x: f32,
        /// y, m.
        y: f32,
        /// Heading, rad.
        theta: f32,
    },
    /// Switch to another estimator (which is reset at the origin).
    SelectEstimator(EstimatorKind),
    /// Answer with a [`ToHost::Status`].
    ReportStatus,
    /// Replace the EKF's settings (noise, gate, sensor mount, update form), for the running
    /// filter (its map and pose are kept) and for every later reset. Settings with a value
    /// out of its range ([`EkfSettings::invalid_field`]) are refused with
    /// [`ToHost::Refused`] ([`Refusal::InvalidEkfSetting`] names the value) and counted in
    /// [`Status::rejected`], the settings unchanged.
    ConfigureEkf(EkfSettings),
    /// Forget the localizer's pose: it is lost, and its next scan starts the global search
    /// over the whole map, one work budget a scan for up to
    /// [`crate::pf::RelocalizationConfig::search_scans`] scans (refused with
    /// [`ToHost::Refused`] unless the localizer is active).
    Relocalize,
    /// End the grid SLAM's run and write its whole map into the device's flash as a map
    /// image (`microslam::slam::GraphSlam::write_map_image`), answered with
    /// [`ToHost::MapSaved`]. Refused unless the grid estimator is active and keeps a map
    /// ([`Refusal::NoMapStorage`]), or when the write fails ([`Refusal::MapNotWritten`]);
    /// the run is over once the drawing started (reset the estimator to map again).
    /// Since protocol 4.
    SaveMap,
    /// Answer with [`ToHost::MapChunk`]: [`MAP_CHUNK_BYTES`] bytes of the saved map image
    /// from `offset` (fewer at its end). Refused with [`Refusal::NoSavedMap`] before a
    /// [`Command::SaveMap`] succeeded. Since protocol 4.
    ReadMap {
        /// Byte offset into the image.
        offset: u32,
    },
    /// Set the car model [`Odometry::Ackermann`] is moved through, kept across resets.
    /// A model that is not valid ([`crate::motion::Ackermann::invalid_setting`]) is
    /// refused with [`Refusal::InvalidCar`] and counted in [`Status::rejected`], the model
    /// unchanged. Since protocol 6.
    ConfigureCar(CarSettings),
    /// Restart the device, as its reset button would: answered with a
    /// [`ToHost::Status`], after which the firmware resets the processor
    /// ([`crate::device::Session::restart_requested`]). What it keeps in flash (a saved
    /// map and pose) decides what it runs after the reset. Since protocol 5.
    Restart,
    /// Observe the next revolution of the device's own lidar (a lidar wired to the
    /// board: [`crate::device::LidarSource`]) with the active grid estimator, stamped
    /// `stamp_us`: the device reads its lidar until a revolution is complete and answers
    /// as to the last chunk of a scan sent over the line, with the estimate after it
    /// ([`ToHost::Estimate`], or [`ToHost::Localization`] on the localizer), its `seq` the
    /// command's; [`ToHost::Status`] carries the reader's counters. The odometry sent before it is the motion up to that
    /// revolution, as a board would read its encoders when the revolution ends. With the
    /// EKF active the revolution is read and skipped ([`StepResult::Ignored`]), so the
    /// lidar stays in step. Refused with [`Refusal::NoLidar`] by a firmware without a
    /// lidar of its own. Since protocol 7.
    NextRevolution {
        /// Time stamp of the revolution, µs.
        stamp_us: u64,
    },
}

/// A car for [`Command::ConfigureCar`]: the fields of [`Ackermann`]`<f32>`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarSettings {
    /// Distance from the rear to the front axle, m.
    pub wheelbase: f32,
    /// Largest |steering angle| accepted, rad.
    pub max_steering: f32,
    /// Standard deviation of the 1-s mean speed, m/s.
    pub speed_std: f32,
    /// Additional standard deviation of the speed per m/s of speed.
    pub speed_std_per_mps: f32,
    /// Standard deviation of the 1-s mean steering angle, rad.
    pub steering_std: f32,
    /// Additional standard deviation of the steering angle per m/s of speed.
    pub steering_std_per_mps: f32,
}

impl CarSettings {
    /// The settings of `car`.
    pub fn from_model(car: &Ackermann<f32>) -> Self {
        Self {
            wheelbase: car.wheelbase,
            max_steering: car.max_steering,
            speed_std: car.noise.speed_std,
            speed_std_per_mps: car.noise.speed_std_per_mps,
            steering_std: car.noise.steering_std,
            steering_std_per_mps: car.noise.steering_std_per_mps,
        }
    }

    /// The car model.
    pub fn to_model(&self) -> Ackermann<f32> {
        Ackermann {
            wheelbase: self.wheelbase,
            max_steering: self.max_steering,
            noise: AckermannNoise {
                speed_std: self.speed_std,
                speed_std_per_mps: self.speed_std_per_mps,
                steering_std: self.steering_std,
                steering_std_per_mps: self.steering_std_per_mps,
            },
        }
    }
}

/// Bytes of the map image a [`ToHost::MapChunk`] carries at most.
pub const MAP_CHUNK_BYTES: usize = 64;

/// The [`MAP_CHUNK_BYTES`] bytes of a [`ToHost::MapChunk`], on the wire as a byte
/// string (postcard: a length, then the raw bytes, copied at once: serde's arrays stop at
/// 32 elements, and element-wise code unrolls into kilobytes of a firmware's flash). A
/// string of another length is refused when it is read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MapBytes(pub [u8; MAP_CHUNK_BYTES]);

impl Serialize for MapBytes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_bytes(&self.0)
    }
}

impl<'de> Deserialize<'de> for MapBytes {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Bytes;
        impl serde::de::Visitor<'_> for Bytes {
            type Value = MapBytes;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                write!(f, "{MAP_CHUNK_BYTES} bytes")
            }
            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<MapBytes, E> {
                v.try_into()
                    .map(MapBytes)
                    .map_err(|_| E::invalid_length(v.len(), &self))
            }
        }
        deserializer.deserialize_bytes(Bytes)
    }
}

/// The EKF's settings on the wire: [`EkfConfig<f32>`] field by field (see its fields for
/// the meaning and units of each).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EkfSettings {
    /// [`IncrementNoise`]: translation std (m), per metre, rotation std (rad), per
    /// radian, per metre.
    pub increment_noise: [f32; 5],
    /// [`VelocityNoise`]: linear std (m/s), per m/s, angular std (rad/s), per rad/s, per
    /// m/s.
    pub velocity_noise: [f32; 5],
    /// Standard deviation of measured ranges, m.
    pub range_std: f32,
    /// Standard deviation of measured bearings, rad.
    pub bearing_std: f32,
    /// Mount of the range-bearing sensor on the robot: x, y (m), yaw (rad).
    pub sensor_mount: [f32; 3],
    /// Gate on the squared Mahalanobis distance.
    pub gate_threshold: f32,
    /// Self-calibration priors, standard deviations (0: not estimated): odometry speed
    /// scale, turn-rate scale ([`EkfSlam::estimate_odometry_scale`]), range bias offset
    /// (m) and curvature (m/rad²) ([`EkfSlam::estimate_range_bias`]). Taken at the next
    /// reset.
    ///
    /// [`EkfSlam::estimate_odometry_scale`]: crate::ekf::EkfSlam::estimate_odometry_scale
    /// [`EkfSlam::estimate_range_bias`]: crate::ekf::EkfSlam::estimate_range_bias
    pub calibration: [f32; 4],
}

impl EkfSettings {
    /// The settings of `config`.
    pub fn from_config(config: &EkfConfig<f32>) -> Self {
        let (i, v, m) = (
            &config.increment_noise,
            &config.velocity_noise,
            &config.sensor.mount,
        );
        Self {
            increment_noise: [
                i.translation_std,
                i.translation_std_per_metre,
                i.rotation_std,
                i.rotation_std_per_radian,
                i.rotation_std_per_metre,
            ],
            velocity_noise: [
                v.linear_std,
                v.linear_std_per_mps,
                v.angular_std,
                v.angular_std_per_radps,
                v.angular_std_per_mps,
            ],
            range_std: config.range_std,
            bearing_std: config.bearing_std,
            sensor_mount: [m.x, m.y, m.theta],
            gate_threshold: config.gate.threshold,
            calibration: [0.0; 4],
        }
    }

    /// The same settings with self-calibration priors (see [`EkfSettings::calibration`]).
    pub fn with_calibration(self, calibration: [f32; 4]) -> Self {
        Self {
            calibration,
            ..self
        }
    }

    /// The names of the settings' values in wire order: [`EkfSettings::increment_noise`]'s
    /// five, [`EkfSettings::velocity_noise`]'s five (each by its [`IncrementNoise`] or
    /// [`VelocityNoise`] field's name), `range_std`, `bearing_std`, the mount's x, y and
    /// yaw, the gate's threshold, and the four [`EkfSettings::calibration`] priors.
    /// [`Refusal::InvalidEkfSetting`] names a value by its position here.
    pub const FIELD_NAMES: [&'static str; 20] = [
        "translation_std",
        "translation_std_per_metre",
        "rotation_std",
        "rotation_std_per_radian",
        "rotation_std_per_metre",
        "linear_std",
        "linear_std_per_mps",
        "angular_std",
        "angular_std_per_radps",
        "angular_std_per_mps",
        "range_std",
        "bearing_std",
        "sensor_mount.x",
        "sensor_mount.y",
        "sensor_mount.yaw",
        "gate_threshold",
        "speed_scale_std",
        "turn_scale_std",
        "range_bias_offset_std",
        "range_bias_curvature_std",
    ];

    /// The settings' values in wire order (named by [`EkfSettings::FIELD_NAMES`]).
    pub fn values(&self) -> [f32; 20] {
        let ([a, b, c, d, e], [f, g, h, i, j]) = (self.increment_noise, self.velocity_noise);
        let [mx, my, mt] = self.sensor_mount;
        let [s, t, o, k] = self.calibration;
        [
            a,
            b,
            c,
            d,
            e,
            f,
            g,
            h,
            i,
            j,
            self.range_std,
            self.bearing_std,
            mx,
            my,
            mt,
            self.gate_threshold,
            s,
            t,
            o,
            k,
        ]
    }

    /// The position in [`EkfSettings::FIELD_NAMES`] of the first value out of its range,
    /// `None` when the device takes the settings. The rules are the configuration's
    /// ([`EkfConfig::invalid_setting`]: noise figures finite and non-negative, the mount
    /// finite, the gate's threshold positive) and, for the calibration priors, finite and
    /// non-negative (0: not estimated); a test holds the two sets of rules together. Value
    /// by value, without the names, so that a firmware carries none of them.
    pub fn invalid_field(&self) -> Option<u8> {
        let holds = |(i, &v): (usize, &f32)| match i {
            12..=14 => v.is_finite(),
            15 => v > 0.0,
            _ => v.is_finite() && v >= 0.0,
        };
        let position = self.values().iter().enumerate().position(|iv| !holds(iv))?;
        u8::try_from(position).ok()
    }

    /// The configuration these settings describe (not checked: see
    /// [`EkfSettings::invalid_field`]).
    pub fn to_config(&self) -> EkfConfig<f32> {
        let [ts, tpm, rs, rpr, rpm] = self.increment_noise;
        let [ls, lpm, as_, apr, apm] = self.velocity_noise;
        let [mx, my, mt] = self.sensor_mount;
        EkfConfig {
            increment_noise: IncrementNoise {
                translation_std: ts,
                translation_std_per_metre: tpm,
                rotation_std: rs,
                rotation_std_per_radian: rpr,
                rotation_std_per_metre: rpm,
            },
            velocity_noise: VelocityNoise {
                linear_std: ls,
                linear_std_per_mps: lpm,
                angular_std: as_,
                angular_std_per_radps: apr,
                angular_std_per_mps: apm,
            },
            range_std: self.range_std,
            bearing_std: self.bearing_std,
            sensor: RangeBearingSensor::new(Pose2::new(mx, my, mt)),
            gate: ChiSquareGate::from_threshold(self.gate_threshold),
        }
    }
}

/// A part of one lidar scan: `ranges_mm[i]` is beam `beam_offset + i` of `beam_total`,
/// at angle `angle_min + (beam_offset + i) · angle_increment` in the lidar frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ScanChunk {
    /// Sequence number of this frame.
    pub seq: u32,
    /// Time stamp of the scan, µs.
    pub stamp_us: u64,
    /// Which scan the chunk belongs to (counts up per scan, wraps).
    pub scan_id: u16,
    /// Index of the first beam in this chunk.
    pub beam_offset: u16,
    /// Number of beams in the whole scan.
    pub beam_total: u16,
    /// Angle of beam 0, rad.
    pub angle_min: f32,
    /// Angle between beams, rad.
    pub angle_increment: f32,
    /// Ranges in millimetres; 0 means no return.
    pub ranges_mm: Vec<u16, SCAN_CHUNK_BEAMS>,
}

/// Messages from the host to the device: sensor events and commands.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ToDevice {
    /// Wheel odometry.
    Odometry {
        /// Sequence number.
        seq: u32,
        /// Time stamp, µs.
        stamp_us: u64,
        /// The odometry.
        odometry: Odometry,
    },
    /// A gyro sample.
    YawRate {
        /// Sequence number.
        seq: u32,
        /// Time stamp, µs.
        stamp_us: u64,
        /// Yaw rate, rad/s (counter-clockwise positive).
        yaw_rate: f32,
    },
    /// A sighting of a landmark with a known id.
    Landmark {
        /// Sequence number.
        seq: u32,
        /// Time stamp, µs.
        stamp_us: u64,
        /// The landmark's id (marker, sign class, barcode).
        id: u32,
        /// Range, m.
        range: f32,
        /// Bearing, rad, counter-clockwise positive.
        bearing: f32,
    },
    /// A part of a lidar scan.
    Scan(ScanChunk),
    /// A command.
    Command {
        /// Sequence number.
        seq: u32,
        /// The command.
        command: Command,
    },
}

impl ToDevice {
    /// The message's sequence number.
    pub fn seq(&self) -> u32 {
        match self {
            Self::Odometry { seq, .. }
            | Self::YawRate { seq, .. }
            | Self::Landmark { seq, .. }
            | Self::Command { seq, .. } => *seq,
            Self::Scan(chunk) => chunk.seq,
        }
    }
}

/// What the estimator did with an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepResult {
    /// The event was applied.
    Applied,
    /// A sighting added a new landmark.
    Added,
    /// A sighting failed the innovation gate; the state is unchanged.
    Gated,
    /// The event was refused; the state is unchanged. `reason` is the estimator's error
    /// code (for the EKF, the position of the variant in [`crate::EkfError`]).
    Rejected {
        /// Error code.
        reason: u8,
    },
    /// The event does not apply to the active estimator and was skipped.
    Ignored,
}

/// Counters of the device, sent with every estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Frames decoded.
    pub frames_ok: u32,
    /// Frames skipped: truncated, corrupt, oversize or unknown.
    pub frames_bad: u32,
    /// Events handed to an estimator.
    pub events: u32,
    /// Events refused by the estimator.
    pub rejected: u32,
    /// Landmarks in the map.
    pub landmarks: u16,
    /// Resampling steps of the particle filter.
    pub resamples: u32,
}

/// What the reader of a lidar wired to the device has seen ([`ToHost::Status`]):
/// every byte it was sent is in one of the packets or among the skipped bytes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LidarCounters {
    /// Packets that passed every check.
    pub packets: u32,
    /// Packets dropped for a wrong checksum or a field out of its range (an angle of a
    /// turn or more).
    pub bad_packets: u32,
    /// Bytes skipped while looking for a packet's start (noise, the rest of a bad
    /// packet).
    pub skipped_bytes: u32,
}

/// An estimate of the robot pose after one event.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Estimate {
    /// Sequence number of the event this answers.
    pub seq: u32,
    /// Time stamp of that event, µs.
    pub stamp_us: u64,
    /// The estimator that produced it.
    pub estimator: EstimatorKind,
    /// What the event did.
    pub result: StepResult,
    /// Pose `[x, y, θ]`: m, m, rad.
    pub pose: [f32; 3],
    /// Upper triangle of the 3 × 3 pose covariance, row by row:
    /// `[xx, xy, xθ, yy, yθ, θθ]`.
    pub covariance: [f32; 6],
    /// The device's counters after the event.
    pub status: Status,
    /// The EKF supervision's fault flags and counters after the event
    /// ([`crate::ekf::health`]; all zero on the grid estimator).
    pub health: HealthStatus,
}

/// Where the localizer stands (see [`crate::pf::GridLocalizer`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackingState {
    /// The scans fit the map at the estimate.
    #[default]
    Tracking,
    /// The scans stopped fitting, or a relocalization was asked for: the pose is not to be
    /// trusted; the global search runs on a coming scan.
    Lost,
    /// The particles were seeded by a global search and are not yet confirmed.
    Relocalized,
}

/// The localizer's side of an estimate in localizer mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LocalizerReport {
    /// Tracking, lost or relocalized.
    pub state: TrackingState,
    /// Share of the last scan's beam weight that ended in occupied cells at the estimate
    /// (0..1).
    pub hit_fraction: f32,
    /// Times the localizer declared itself lost.
    pub lost_events: u32,
    /// Global searches that seeded the particles.
    pub relocalizations: u32,
    /// Scans the global search under way has run (one work budget each, at most
    /// [`crate::pf::RelocalizationConfig::search_scans`]); 0 when none runs. While it is
    /// above 0 the estimate's pose is the last one before the search, not filtered. A
    /// search that found nothing ends with this back at 0, the state still
    /// [`TrackingState::Lost`] and `relocalizations` unchanged; the next scan searches
    /// again.
    pub search_scans: u8,
}

/// Why a command was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Refusal {
    /// The firmware carries no map (built without one): no localizer.
    NoMap,
    /// The map in flash failed its check at boot: `code` is the position of the variant in
    /// `microslam::grid::MapImageError` (feature `map-image`).
    BadMap {
        /// Error code.
        code: u8,
    },
    /// The command needs the localizer to be the active estimator.
    NotLocalizing,
    /// The map carries no max-pooled layers: the localizer cannot search globally.
    NoGlobalSearch,
    /// [`Command::ConfigureEkf`] carried a value out of its range: `field` is its position
    /// in [`EkfSettings::FIELD_NAMES`] ([`EkfSettings::invalid_field`]). The settings are
    /// unchanged (since protocol 3).
    InvalidEkfSetting {
        /// Position of the value in [`EkfSettings::FIELD_NAMES`].
        field: u8,
    },
    /// [`Command::SaveMap`]: the active estimator keeps no map of its own (not the
    /// grid SLAM, or a firmware without flash for it). Since protocol 4.
    NoMapStorage,
    /// [`Command::SaveMap`]: writing the map failed (no keyframe yet, a storage error, a
    /// map larger than its flash). Since protocol 4.
    MapNotWritten,
    /// [`Command::ReadMap`] before a map was saved. Since protocol 4.
    NoSavedMap,
    /// [`Command::ConfigureCar`] carried a model that is not valid
    /// ([`crate::motion::Ackermann::invalid_setting`]); the car is unchanged. Since
    /// protocol 6.
    InvalidCar,
    /// [`Command::ConfigureCar`] on a firmware built without the car model (`microslam`
    /// feature `car`). Since protocol 6.
    NoCarModel,
    /// [`Command::NextRevolution`] on a firmware that reads no lidar of its own. Since
    /// protocol 7.
    NoLidar,
}

impl core::fmt::Display for Refusal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::NoMap => f.write_str("the firmware carries no map"),
            Self::BadMap { code } => write!(f, "the map in flash failed its check (code {code})"),
            Self::NotLocalizing => f.write_str("the localizer is not the active estimator"),
            Self::NoGlobalSearch => f.write_str("the map carries no layers for a global search"),
            Self::InvalidEkfSetting { field } => {
                match EkfSettings::FIELD_NAMES.get(usize::from(field)) {
                    Some(name) => write!(f, "EKF setting `{name}` is out of its range"),
                    None => write!(f, "EKF setting number {field} is out of its range"),
                }
            }
            Self::NoMapStorage => f.write_str("the active estimator keeps no map to save"),
            Self::MapNotWritten => f.write_str("writing the map into flash failed"),
            Self::NoSavedMap => f.write_str("no map has been saved"),
            Self::InvalidCar => f.write_str("the car model is not valid"),
            Self::NoCarModel => f.write_str(
                "the firmware is built without the car model (firmware-example's feature `car`)",
            ),
            Self::NoLidar => f.write_str("the firmware reads no lidar of its own"),
        }
    }
}

/// Version of the messages' layout, sent in every [`ToHost::Status`]: raised whenever a
/// message of either direction changes. [`ToHost::Status`] keeps its variant index (1)
/// and its first two fields (`seq`, `protocol`) in every version, so a host can always
/// tell which version a device speaks.
pub const PROTOCOL_VERSION: u16 = 7;

/// Messages from the device to the host.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ToHost {
    /// An estimate after an event.
    Estimate(Estimate),
    /// The answer to a command that produces no estimate.
    Status {
        /// Sequence number of the command.
        seq: u32,
        /// The device's [`PROTOCOL_VERSION`].
        protocol: u16,
        /// The estimator now active.
        estimator: EstimatorKind,
        /// The counters.
        status: Status,
        /// Deepest use of the stack so far, bytes, where the device can measure it
        /// (a firmware that paints its stack at reset); 0 where it cannot.
        stack_peak_bytes: u32,
        /// The CRC-32 of the map image the localizer runs on (the map in flash,
        /// [`crate::grid::MapImage::checksum`]); `None` without a valid one. Tells which
        /// map a device carries (since protocol 2).
        map_checksum: Option<u32>,
        /// What the reader of the device's own lidar has seen (all 0 without one; since
        /// protocol 7).
        lidar: LidarCounters,
    },
    /// An estimate after an event in localizer mode, with the localizer's state.
    Localization {
        /// The estimate (pose, covariance of the particle cloud, counters).
        estimate: Estimate,
        /// Tracking, lost or relocalized.
        localizer: LocalizerReport,
    },
    /// The answer to a command the device cannot carry out; nothing changed.
    Refused {
        /// Sequence number of the command.
        seq: u32,
        /// Why.
        reason: Refusal,
        /// The estimator still active.
        estimator: EstimatorKind,
    },
    /// The answer to [`Command::SaveMap`]: the map image written (since protocol 4).
    MapSaved {
        /// Sequence number of the command.
        seq: u32,
        /// Length of the image, bytes.
        bytes: u32,
        /// Its CRC-32 (`microslam::grid::MapImage::checksum`).
        checksum: u32,
        /// Where the robot is in the map (x, y in m, heading in rad): where a localizer
        /// on it starts, and what a firmware keeps in flash beside it (since protocol 5).
        pose: [f32; 3],
    },
    /// The answer to [`Command::ReadMap`]: `len` bytes of the saved map image from
    /// `offset`, in `bytes` (row by row of 32; the rest zero). Since protocol 4.
    MapChunk {
        /// Sequence number of the command.
        seq: u32,
        /// Byte offset into the image.
        offset: u32,
        /// Bytes that belong to the image (0 past its end).
        len: u8,
        /// The bytes (the rest zero).
        bytes: MapBytes,
    },
}

impl ToHost {
    /// The estimate a reply carries ([`ToHost::Estimate`], [`ToHost::Localization`]);
    /// `None` for the answers to commands.
    pub fn estimate(&self) -> Option<&Estimate> {
        match self {
            Self::Estimate(e) | Self::Localization { estimate: e, .. } => Some(e),
            _ => None,
        }
    }
}
