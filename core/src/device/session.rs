//! The device side of the serial protocol: bytes in, estimator steps, replies out.
//!
//! A [`Session`] owns the frame decoder and borrows the estimators (which live in
//! `static`s on a microcontroller). It is the whole firmware main loop minus the UART:
//! the firmware feeds it received bytes and writes the replies it returns; a host feeds
//! it the same bytes and gets the same replies, bit for bit when both use libm. Every
//! event frame is answered with exactly one [`ToHost::Estimate`] carrying the event's
//! sequence number, so a host can stream without waiting; every command with one
//! [`ToHost::Status`].

use crate::association::KnownIds;
use crate::association::{Observed, observe_known_supervised};
use crate::ekf::health::{HealthConfig, HealthStatus, Supervisor};
use crate::ekf::{EkfConfig, EkfSlam, UpdateOutcome};
use crate::geometry::Pose2;
use crate::motion::Ackermann;
use crate::pf::{GridEstimator, GridLocalizer, LocalizerState};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::sensors::range_bearing::RangeBearing;
use crate::sensors::wheel_odometry::{DiffDriveGeometry, WheelTicks};

use crate::wire::frame::{FrameDecoder, FrameError, MAX_FRAME_LEN};
use crate::wire::messages::{
    Command, Estimate, EstimatorKind, LocalizerReport, Odometry, Refusal, ScanChunk, Status,
    StepResult, ToDevice, ToHost, TrackingState,
};
use crate::wire::scan::ScanAssembler;

#[cfg(feature = "own-lidar")]
use super::lidar::LidarSource;

/// The most beams of one scan a [`Session`] reassembles (a 1° scanner); longer scans are
/// dropped and answered with [`StepResult::Rejected`].
pub const MAX_SCAN_BEAMS: usize = 360;

/// A localizer on a fixed map as a [`Session`] drives it: a [`GridEstimator`] (reset puts
/// every particle at the pose and the state to tracking) that can also be sent looking
/// for itself and reports where it stands. Implemented by [`GridLocalizer`].
pub trait LocalizerEstimator: GridEstimator {
    /// Forget the pose: lost, the global search starts on the next scan. Refused with
    /// [`Refusal::NoGlobalSearch`] when the map has no layers for it.
    fn relocalize(&mut self) -> Result<(), Refusal>;
    /// Tracking, lost or relocalized, with its counters.
    fn report(&self) -> LocalizerReport;
}

impl<const P: usize, const B: usize> LocalizerEstimator for GridLocalizer<'_, P, B> {
    fn relocalize(&mut self) -> Result<(), Refusal> {
        GridLocalizer::relocalize(self).map_err(|_| Refusal::NoGlobalSearch)
    }
    fn report(&self) -> LocalizerReport {
        let s = self.status();
        LocalizerReport {
            state: match s.state {
                LocalizerState::Tracking => TrackingState::Tracking,
                LocalizerState::Lost => TrackingState::Lost,
                LocalizerState::Relocalized => TrackingState::Relocalized,
            },
            hit_fraction: s.hit_fraction,
            lost_events: s.lost_events,
            relocalizations: s.relocalizations,
            search_scans: self.search_scans_run(),
        }
    }
}

/// What the grid estimator needs besides the wire messages.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSetup {
    /// Range limits and mount pose of the lidar; `first_angle` and `angle_increment` are
    /// taken from each scan. A range of 0 mm on the wire means "no return".
    pub lidar: LidarGeometry,
    /// Wheel geometry, for [`Odometry::EncoderTicks`] (the rear and front wheels of a
    /// side are averaged).
    pub wheels: DiffDriveGeometry<f32>,
}

impl GridSetup {
    /// The example firmware's setup, shared by the firmware and the host reference so
    /// that they cannot drift apart: a lidar at the robot centre keeping ranges in
    /// 0.1–30 m, THOR's wheels (0.0022 m per tick, 0.3937 m track).
    pub const EXAMPLE: Self = Self {
        lidar: LidarGeometry {
            first_angle: 0.0,
            angle_increment: 0.0,
            min_range: 0.1,
            max_range: 30.0,
            no_return_range: f32::INFINITY,
            mount: Pose2::new(0.0, 0.0, 0.0),
        },
        wheels: DiffDriveGeometry {
            metres_per_tick: 0.0022,
            track_width: 0.3937,
        },
    };
}

/// Error code in [`StepResult::Rejected`] for a scan the assembler dropped.
const SCAN_DROPPED: u8 = 0x80;
/// Error code in [`StepResult::Rejected`] for encoder ticks the wheel model refused.
const TICKS_REFUSED: u8 = 0x81;
/// Error code in [`StepResult::Rejected`] for a car's odometry before a car model was
/// configured ([`Command::ConfigureCar`]).
pub const NO_CAR: u8 = 0x82;
/// Error code in [`StepResult::Rejected`] for a [`Command::NextRevolution`] whose lidar
/// bus failed before a revolution was finished.
pub const LIDAR_FAILED: u8 = 0x83;

/// The device side of the protocol for an `f32` EKF of state dimension `N` with a
/// known-id table of `L` ids.
///
/// ```
/// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
/// use microslam::device::Session;
/// use microslam::wire::{encode_frame, Odometry, ToDevice, ToHost, MAX_FRAME_LEN};
///
/// let mut ekf = EkfSlam::<f32, { state_dim(8) }, { factor_len(8) }>::new(EkfConfig::DEFAULT_F32);
/// let mut session = Session::<_, _, 8>::new(&mut ekf, EkfConfig::DEFAULT_F32);
/// let msg = ToDevice::Odometry { seq: 1, stamp_us: 0, odometry: Odometry::Velocity { v: 1.0, omega: 0.0, dt: 0.5 } };
/// let mut buf = [0u8; MAX_FRAME_LEN];
/// let mut replies = 0;
/// for &b in encode_frame(&msg, &mut buf)? {
///     if let Some(ToHost::Estimate(e)) = session.receive(b) {
///         assert_eq!((e.seq, e.pose[0]), (1, 0.5));
///         replies += 1;
///     }
/// }
/// assert_eq!(replies, 1);
/// # Ok::<(), microslam::wire::EncodeError>(())
/// ```
///
/// With [`Session::with_grid`] it also drives a grid estimator: after
/// [`Command::SelectEstimator`]`(Grid)` odometry predicts the grid filter, scan chunks are
/// reassembled and observed (each chunk is answered; the one completing a scan with the
/// grid step's result), and estimates carry the grid pose (the heaviest particle), the
/// particle cloud's covariance and the resample count.
pub struct Session<'a, const N: usize, const P: usize, const L: usize> {
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    ekf: &'a mut EkfSlam<f32, N, P>,
    ekf_config: EkfConfig<f32>,
    /// Self-calibration priors applied at each reset ([`super::messages::EkfSettings::calibration`]).
    calibration: [f32; 4],
    /// The car [`Odometry::Ackermann`] moves through ([`Command::ConfigureCar`]).
    car: Option<Ackermann<f32>>,
    ids: KnownIds<L>,
    supervisor: Supervisor<f32>,
    grid: Option<&'a mut dyn GridEstimator>,
    grid_setup: Option<GridSetup>,
    localizer: Result<&'a mut dyn LocalizerEstimator, Refusal>,
    /// The lidar wired to the device, for [`Command::NextRevolution`].
    #[cfg(feature = "own-lidar")]
    lidar: Option<&'a mut dyn LidarSource>,
    /// The map image's CRC-32, reported in every status.
    map_checksum: Option<u32>,
    assembler: ScanAssembler<MAX_SCAN_BEAMS>,
    ranges: [f32; MAX_SCAN_BEAMS],
    active: EstimatorKind,
    status: Status,
    /// A [`Command::Restart`] was answered: the firmware resets the processor.
    restart_requested: bool,
}

impl<'a, const N: usize, const P: usize, const L: usize> Session<'a, N, P, L> {
    /// A session over `ekf`, which is re-initialised in place with `ekf_config` (robot at
    /// the origin). An invalid configuration leaves the filter's own configuration.
    pub fn new(ekf: &'a mut EkfSlam<f32, N, P>, ekf_config: EkfConfig<f32>) -> Self {
        let mut session = Self {
            decoder: FrameDecoder::new(),
            ekf,
            ekf_config,
            calibration: [0.0; 4],
            car: None,
            ids: KnownIds::new(),
            supervisor: Supervisor::new(HealthConfig::DEFAULT_F32),
            grid: None,
            grid_setup: None,
            localizer: Err(Refusal::NoMap),
            #[cfg(feature = "own-lidar")]
            lidar: None,
            map_checksum: None,
            assembler: ScanAssembler::new(),
            ranges: [0.0; MAX_SCAN_BEAMS],
            active: EstimatorKind::Ekf,
            status: Status::default(),
            restart_requested: false,
        };
        session.reset(Pose2::new(0.0, 0.0, 0.0));
        session
    }

    /// A session over `ekf` and a grid estimator `grid` (e.g. a [`GridSlam`](crate::pf::GridSlam) on a grid in
    /// a `static`); it starts on the EKF, and [`Command::SelectEstimator`] switches.
    pub fn with_grid(
        ekf: &'a mut EkfSlam<f32, N, P>,
        ekf_config: EkfConfig<f32>,
        grid: &'a mut dyn GridEstimator,
        setup: GridSetup,
    ) -> Self {
        let mut session = Self::new(ekf, ekf_config);
        session.grid = Some(grid);
        session.grid_setup = Some(setup);
        session
    }

    /// The same session with a localizer on a map in flash — or, when the map was
    /// refused at boot, the reason, which [`Command::SelectEstimator`]`(Localizer)` then
    /// answers with [`ToHost::Refused`]. Scans and odometry reach the localizer as they
    /// reach the grid estimator (`setup` replaces the grid's when both are given: one
    /// robot, one lidar).
    pub fn with_localizer(
        mut self,
        localizer: Result<&'a mut dyn LocalizerEstimator, Refusal>,
        setup: GridSetup,
    ) -> Self {
        self.localizer = localizer;
        self.grid_setup = Some(setup);
        self.reset(Pose2::new(0.0, 0.0, 0.0));
        self
    }

    /// The same session reading its own lidar: [`Command::NextRevolution`] observes the
    /// lidar's next revolution with the active grid estimator (refused with
    /// [`Refusal::NoLidar`] without one). Scans sent over the line are still taken.
    /// Feature `own-lidar`.
    #[cfg(feature = "own-lidar")]
    pub fn with_lidar(mut self, lidar: &'a mut dyn LidarSource) -> Self {
        self.lidar = Some(lidar);
        self
    }

    /// The same session naming its map: every [`ToHost::Status`] carries `checksum`
    /// (the map image's CRC-32, [`crate::grid::MapImage::checksum`], `None` when there
    /// is no valid image), so that a host can tell which map the device carries.
    pub fn with_map_checksum(mut self, checksum: Option<u32>) -> Self {
        self.map_checksum = checksum;
        self
    }

    /// The same session running the localizer from `pose` (a pose kept in flash across a
    /// reset, [`super::PoseStore`]) instead of the EKF: what a firmware that finds a
    /// saved map and pose at boot starts with. Without a localizer it stays on the EKF.
    pub fn localizing_from(mut self, pose: Pose2<f32>) -> Self {
        if self.localizer.is_ok() {
            self.active = EstimatorKind::Localizer;
            self.reset(pose);
        }
        self
    }

    /// `true` once a [`Command::Restart`] has been answered: the firmware sends the
    /// reply, then resets the processor (a host running the session starts a new one).
    pub fn restart_requested(&self) -> bool {
        self.restart_requested
    }

    /// The grid estimator or localizer the active mode feeds, with the setup.
    fn active_grid(&mut self) -> Option<(&mut dyn GridEstimator, GridSetup)> {
        let setup = self.grid_setup?;
        let grid: &mut dyn GridEstimator = match self.active {
            EstimatorKind::Grid => self.grid.as_deref_mut()?,
            EstimatorKind::Localizer => match &mut self.localizer {
                Ok(l) => &mut **l,
                Err(_) => return None,
            },
            EstimatorKind::Ekf => return None,
        };
        Some((grid, setup))
    }

    /// The counters.
    pub fn status(&self) -> Status {
        self.status
    }

    /// The estimator in use.
    pub fn active(&self) -> EstimatorKind {
        self.active
    }

    /// The supervision of the EKF's updates (its settings are
    /// [`HealthConfig::DEFAULT_F32`]).
    pub fn supervisor(&self) -> &Supervisor<f32> {
        &self.supervisor
    }

    /// The EKF.
    pub fn ekf(&self) -> &EkfSlam<f32, N, P> {
        self.ekf
    }

    /// Takes one received byte; returns the reply when the byte ends a frame holding a
    /// message. Bad frames are counted in [`Status::frames_bad`] and produce no reply.
    pub fn receive(&mut self, byte: u8) -> Option<ToHost> {
        let result: Option<Result<ToDevice, FrameError>> = self.decoder.push(byte);
        let c = self.decoder.counters();
        self.status.frames_ok = c.ok;
        self.status.frames_bad = c.bad();
        match result? {
            Ok(msg) => Some(self.handle(&msg)),
            Err(_) => None,
        }
    }

    /// Handles one decoded message and returns its reply.
    pub fn handle(&mut self, msg: &ToDevice) -> ToHost {
        let (seq, stamp_us, result) = match msg {
            ToDevice::Command { seq, command } => return self.command(*seq, command),
            ToDevice::Odometry {
                seq,
                stamp_us,
                odometry,
            } => (*seq, *stamp_us, self.odometry(odometry)),
            ToDevice::Landmark {
                seq,
                stamp_us,
                id,
                range,
                bearing,
            } => (*seq, *stamp_us, self.sighting(*id, *range, *bearing)),
            ToDevice::YawRate { seq, stamp_us, .. } => (*seq, *stamp_us, StepResult::Ignored),
            ToDevice::Scan(chunk) => (chunk.seq, chunk.stamp_us, self.scan(chunk)),
        };
        self.reply(seq, stamp_us, result)
    }

    /// Counts an event and its refusal, and answers it with the estimate after it.
    #[inline(never)]
    fn reply(&mut self, seq: u32, stamp_us: u64, result: StepResult) -> ToHost {
        self.status.events = self.status.events.saturating_add(1);
        if let StepResult::Rejected { .. } = result {
            self.status.rejected = self.status.rejected.saturating_add(1);
        }
        let estimate = self.estimate(seq, stamp_us, result);
        match (&self.localizer, self.active) {
            (Ok(l), EstimatorKind::Localizer) => ToHost::Localization {
                estimate,
                localizer: l.report(),
            },
            _ => ToHost::Estimate(estimate),
        }
    }

    /// [`Command::NextRevolution`]: the own lidar's next revolution through the active
    /// grid estimator (read and skipped while the EKF runs); refused without a lidar.
    fn revolution(&mut self, seq: u32, stamp_us: u64) -> ToHost {
        #[cfg(feature = "own-lidar")]
        if let Some(lidar) = self.lidar.take() {
            let reply = self.own_revolution(seq, stamp_us, &mut *lidar);
            self.lidar = Some(lidar);
            return reply;
        }
        let _ = stamp_us;
        ToHost::Refused {
            seq,
            reason: Refusal::NoLidar,
            estimator: self.active,
        }
    }

    /// What the own lidar's reader has seen (all 0 without one).
    fn lidar_counters(&self) -> crate::wire::LidarCounters {
        #[cfg(feature = "own-lidar")]
        if let Some(lidar) = self.lidar.as_deref() {
            return lidar.counters();
        }
        crate::wire::LidarCounters::default()
    }

    /// [`Session::revolution`] with the lidar.
    #[cfg(feature = "own-lidar")]
    fn own_revolution(&mut self, seq: u32, stamp_us: u64, lidar: &mut dyn LidarSource) -> ToHost {
        let grid: Option<&mut dyn GridEstimator> =
            match (self.active, &mut self.grid, &mut self.localizer) {
                (EstimatorKind::Grid, Some(g), _) => Some(&mut **g),
                (EstimatorKind::Localizer, _, Ok(l)) => Some(&mut **l),
                _ => None,
            };
        let result = match (lidar.next_revolution(), grid) {
            (None, _) => StepResult::Rejected {
                reason: LIDAR_FAILED,
            },
            (Some(_), None) => StepResult::Ignored,
            (Some(scan), Some(grid)) => observe(grid, &scan),
        };
        self.reply(seq, stamp_us, result)
    }

    fn grid_odometry(&mut self, odometry: &Odometry) -> StepResult {
        let Some((grid, setup)) = self.active_grid() else {
            return StepResult::Ignored;
        };
        let r = match *odometry {
            Odometry::Increment { dx, dy, dtheta } => {
                grid.predict_increment(&Pose2::new(dx, dy, dtheta))
            }
            Odometry::Velocity { v, omega, dt } => grid.predict_velocity(v, omega, dt),
            // A car's odometry moves the EKF only.
            Odometry::Ackermann { .. } => return StepResult::Ignored,
            Odometry::EncoderTicks {
                front_left,
                front_right,
                rear_left,
                rear_right,
                ..
            } => {
                let ticks = WheelTicks {
                    front_right,
                    front_left,
                    rear_right,
                    rear_left,
                };
                match setup.wheels.motion(&ticks) {
                    Ok(m) => grid.predict_arc(m.distance, m.heading_change),
                    Err(_) => {
                        return StepResult::Rejected {
                            reason: TICKS_REFUSED,
                        };
                    }
                }
            }
        };
        match r {
            Ok(()) => StepResult::Applied,
            Err(e) => StepResult::Rejected { reason: e as u8 },
        }
    }

    fn scan(&mut self, chunk: &ScanChunk) -> StepResult {
        let Some((_, setup)) = self.active_grid() else {
            return StepResult::Ignored;
        };
        let scan = match self.assembler.push(chunk) {
            Ok(Some(scan)) => scan,
            // More chunks to come: answered, nothing estimated yet.
            Ok(None) => return StepResult::Ignored,
            Err(_) => {
                return StepResult::Rejected {
                    reason: SCAN_DROPPED,
                };
            }
        };
        let n = scan.ranges_mm.len().min(MAX_SCAN_BEAMS);
        for (r, &mm) in self.ranges.iter_mut().zip(scan.ranges_mm) {
            // 0 mm = no return: not finite, so the filter skips the beam.
            *r = if mm == 0 {
                f32::NAN
            } else {
                f32::from(mm) * 0.001
            };
        }
        let geometry = LidarGeometry {
            first_angle: scan.angle_min,
            angle_increment: scan.angle_increment,
            ..setup.lidar
        };
        let ranges = self.ranges.get(..n).unwrap_or(&[]);
        let grid: &mut dyn GridEstimator = match (self.active, &mut self.grid, &mut self.localizer)
        {
            (EstimatorKind::Grid, Some(g), _) => &mut **g,
            (EstimatorKind::Localizer, _, Ok(l)) => &mut **l,
            _ => return StepResult::Ignored,
        };
        observe(grid, &LidarScan::new(ranges, geometry))
    }

    fn odometry(&mut self, odometry: &Odometry) -> StepResult {
        if self.active != EstimatorKind::Ekf {
            return self.grid_odometry(odometry);
        }
        let r = match *odometry {
            Odometry::Increment { dx, dy, dtheta } => {
                self.ekf.predict_increment(&Pose2::new(dx, dy, dtheta))
            }
            Odometry::Velocity { v, omega, dt } => self.ekf.predict_velocity(v, omega, dt),
            Odometry::Ackermann { v, steering, dt } => match &self.car {
                #[cfg(feature = "car")]
                Some(car) => self.ekf.predict_ackermann(car, v, steering, dt),
                _ => {
                    let _ = (v, steering, dt);
                    return StepResult::Rejected { reason: NO_CAR };
                }
            },
            // Ticks need the wheel geometry: used by the grid estimator only.
            Odometry::EncoderTicks { .. } => return StepResult::Ignored,
        };
        match r {
            Ok(()) => StepResult::Applied,
            Err(e) => StepResult::Rejected { reason: e as u8 },
        }
    }

    fn sighting(&mut self, id: u32, range: f32, bearing: f32) -> StepResult {
        if self.active != EstimatorKind::Ekf {
            return StepResult::Ignored;
        }
        let z = RangeBearing::new(range, bearing);
        match observe_known_supervised(self.ekf, &mut self.ids, id, &z, &mut self.supervisor) {
            Ok(Observed::Added { .. }) => StepResult::Added,
            Ok(Observed::Updated {
                outcome: UpdateOutcome::Accepted { .. },
                ..
            }) => StepResult::Applied,
            Ok(Observed::Updated {
                outcome: UpdateOutcome::Gated { .. },
                ..
            }) => StepResult::Gated,
            Err(e) => StepResult::Rejected { reason: e as u8 },
        }
    }

    // Not inlined: commands are rare, and inlined into the firmware's receive loop they
    // cost ~650 bytes more flash (measured with the map checksum added to `Status`).
    #[inline(never)]
    fn command(&mut self, seq: u32, command: &Command) -> ToHost {
        match *command {
            Command::Reset { x, y, theta } => self.reset(Pose2::new(x, y, theta)),
            Command::SelectEstimator(EstimatorKind::Localizer) => {
                if let Err(reason) = &self.localizer {
                    return ToHost::Refused {
                        seq,
                        reason: *reason,
                        estimator: self.active,
                    };
                }
                self.active = EstimatorKind::Localizer;
                self.reset(Pose2::new(0.0, 0.0, 0.0));
            }
            Command::SelectEstimator(kind) => {
                // Without a grid estimator the session stays on the EKF.
                self.active = if self.grid.is_some() {
                    kind
                } else {
                    EstimatorKind::Ekf
                };
                self.reset(Pose2::new(0.0, 0.0, 0.0));
            }
            Command::Relocalize => {
                let relocalized = match (&mut self.localizer, self.active) {
                    (Ok(l), EstimatorKind::Localizer) => l.relocalize(),
                    _ => Err(Refusal::NotLocalizing),
                };
                if let Err(reason) = relocalized {
                    return ToHost::Refused {
                        seq,
                        reason,
                        estimator: self.active,
                    };
                }
            }
            Command::SaveMap => {
                let refusal = match (self.active, self.grid.as_mut()) {
                    (EstimatorKind::Grid, Some(grid)) => match grid.save_map() {
                        Some(Ok(saved)) => {
                            return ToHost::MapSaved {
                                seq,
                                bytes: saved.bytes,
                                checksum: saved.checksum,
                                pose: [saved.pose.x, saved.pose.y, saved.pose.theta],
                            };
                        }
                        Some(Err(_)) => Refusal::MapNotWritten,
                        None => Refusal::NoMapStorage,
                    },
                    _ => Refusal::NoMapStorage,
                };
                return ToHost::Refused {
                    seq,
                    reason: refusal,
                    estimator: self.active,
                };
            }
            Command::ReadMap { offset } => {
                let mut bytes = crate::wire::MapBytes([0; crate::wire::MAP_CHUNK_BYTES]);
                let read = self
                    .grid
                    .as_ref()
                    .and_then(|grid| grid.read_map(offset, &mut bytes.0));
                return match read {
                    Some(len) => ToHost::MapChunk {
                        seq,
                        offset,
                        len: u8::try_from(len).unwrap_or(u8::MAX),
                        bytes,
                    },
                    None => ToHost::Refused {
                        seq,
                        reason: Refusal::NoSavedMap,
                        estimator: self.active,
                    },
                };
            }
            Command::NextRevolution { stamp_us } => return self.revolution(seq, stamp_us),
            Command::ReportStatus => {}
            Command::Restart => self.restart_requested = true,
            Command::ConfigureCar(settings) => {
                if !cfg!(feature = "car") {
                    return ToHost::Refused {
                        seq,
                        reason: Refusal::NoCarModel,
                        estimator: self.active,
                    };
                }
                let car = settings.to_model();
                if !car.is_valid() {
                    self.status.rejected = self.status.rejected.saturating_add(1);
                    return ToHost::Refused {
                        seq,
                        reason: Refusal::InvalidCar,
                        estimator: self.active,
                    };
                }
                self.car = Some(car);
            }
            Command::ConfigureEkf(settings) => {
                if let Some(field) = settings.invalid_field() {
                    self.status.rejected = self.status.rejected.saturating_add(1);
                    return ToHost::Refused {
                        seq,
                        reason: Refusal::InvalidEkfSetting { field },
                        estimator: self.active,
                    };
                }
                // Taken by the running filter and kept for every later reset (valid:
                // `invalid_field` holds the configuration's rules).
                let config = settings.to_config();
                if self.ekf.set_config(config).is_ok() {
                    self.ekf_config = config;
                    self.calibration = settings.calibration;
                }
            }
        }
        ToHost::Status {
            seq,
            protocol: crate::wire::PROTOCOL_VERSION,
            estimator: self.active,
            status: self.status,
            stack_peak_bytes: 0,
            map_checksum: self.map_checksum,
            lidar: self.lidar_counters(),
        }
    }

    fn reset(&mut self, pose: Pose2<f32>) {
        let config = if self.ekf_config.is_valid() {
            self.ekf_config
        } else {
            *self.ekf.config()
        };
        if self.ekf.init(config, pose).is_err() {
            // A non-finite pose: restart at the origin instead.
            let _ = self.ekf.init(config, Pose2::new(0.0, 0.0, 0.0));
        }
        let [speed, turn, offset, curvature] = self.calibration;
        let scale = (speed > 0.0 || turn > 0.0)
            .then(|| self.ekf.estimate_odometry_scale(speed, turn).is_ok());
        let bias = (offset > 0.0 || curvature > 0.0)
            .then(|| self.ekf.estimate_range_bias(offset, curvature).is_ok());
        if scale == Some(false) || bias == Some(false) {
            self.status.rejected = self.status.rejected.saturating_add(1);
        }
        self.ids.clear();
        self.supervisor.reset();
        self.assembler.clear();
        if let Some(grid) = self.grid.as_deref_mut()
            && grid.reset(pose).is_err()
        {
            let _ = grid.reset(Pose2::new(0.0, 0.0, 0.0));
        }
        if let Ok(localizer) = &mut self.localizer
            && localizer.reset(pose).is_err()
        {
            let _ = localizer.reset(Pose2::new(0.0, 0.0, 0.0));
        }
        let (ok, bad) = (self.status.frames_ok, self.status.frames_bad);
        self.status = Status {
            frames_ok: ok,
            frames_bad: bad,
            ..Status::default()
        };
    }

    fn estimate(&mut self, seq: u32, stamp_us: u64, result: StepResult) -> Estimate {
        let grid: Option<&dyn GridEstimator> = match (self.active, &self.grid, &self.localizer) {
            (EstimatorKind::Grid, Some(g), _) => Some(&**g),
            (EstimatorKind::Localizer, _, Ok(l)) => Some(&**l),
            _ => None,
        };
        if let Some(grid) = grid {
            let pose = grid.pose();
            self.status.resamples = grid.resamples();
            return Estimate {
                seq,
                stamp_us,
                estimator: self.active,
                result,
                pose: [pose.x, pose.y, pose.theta],
                covariance: grid.pose_covariance(),
                status: self.status,
                health: HealthStatus::default(),
            };
        }
        let pose = self.ekf.pose();
        let p = self.ekf.pose_covariance();
        self.status.landmarks = u16::try_from(self.ekf.landmark_count()).unwrap_or(u16::MAX);
        Estimate {
            seq,
            stamp_us,
            estimator: self.active,
            result,
            pose: [pose.x, pose.y, pose.theta],
            covariance: [
                p[(0, 0)],
                p[(0, 1)],
                p[(0, 2)],
                p[(1, 1)],
                p[(1, 2)],
                p[(2, 2)],
            ],
            status: self.status,
            health: self.supervisor.status(),
        }
    }
}

/// One scan through a grid estimator, as the wire reports it.
fn observe(grid: &mut dyn GridEstimator, scan: &LidarScan<'_>) -> StepResult {
    match grid.observe(scan) {
        Ok(_) => StepResult::Applied,
        Err(e) => StepResult::Rejected { reason: e as u8 },
    }
}

#[cfg(test)]
mod tests;
