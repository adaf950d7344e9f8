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
use crate::pf::{GridEstimator, GridLocalizer, LocalizerState};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::sensors::range_bearing::RangeBearing;
use crate::sensors::wheel_odometry::{DiffDriveGeometry, WheelTicks};

use super::frame::{FrameDecoder, FrameError, MAX_FRAME_LEN};
use super::messages::{
    Command, Estimate, EstimatorKind, LocalizerReport, Odometry, Refusal, ScanChunk, Status,
    StepResult, ToDevice, ToHost, TrackingState,
};
use super::scan::ScanAssembler;

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

/// The device side of the protocol for an `f32` EKF of state dimension `N` with a
/// known-id table of `L` ids.
///
/// ```
/// use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
/// use microslam::wire::{encode_frame, Odometry, Session, ToDevice, ToHost, MAX_FRAME_LEN};
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
    ids: KnownIds<L>,
    supervisor: Supervisor<f32>,
    grid: Option<&'a mut dyn GridEstimator>,
    grid_setup: Option<GridSetup>,
    localizer: Result<&'a mut dyn LocalizerEstimator, Refusal>,
    /// The map image's CRC-32, reported in every status.
    map_checksum: Option<u32>,
    assembler: ScanAssembler<MAX_SCAN_BEAMS>,
    ranges: [f32; MAX_SCAN_BEAMS],
    active: EstimatorKind,
    status: Status,
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
            ids: KnownIds::new(),
            supervisor: Supervisor::new(HealthConfig::DEFAULT_F32),
            grid: None,
            grid_setup: None,
            localizer: Err(Refusal::NoMap),
            map_checksum: None,
            assembler: ScanAssembler::new(),
            ranges: [0.0; MAX_SCAN_BEAMS],
            active: EstimatorKind::Ekf,
            status: Status::default(),
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

    /// The same session naming its map: every [`ToHost::Status`] carries `checksum`
    /// (the map image's CRC-32, [`crate::grid::MapImage::checksum`], `None` when there
    /// is no valid image), so that a host can tell which map the device carries.
    pub fn with_map_checksum(mut self, checksum: Option<u32>) -> Self {
        self.map_checksum = checksum;
        self
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

    fn grid_odometry(&mut self, odometry: &Odometry) -> StepResult {
        let Some((grid, setup)) = self.active_grid() else {
            return StepResult::Ignored;
        };
        let r = match *odometry {
            Odometry::Increment { dx, dy, dtheta } => {
                grid.predict_increment(&Pose2::new(dx, dy, dtheta))
            }
            Odometry::Velocity { v, omega, dt } => grid.predict_velocity(v, omega, dt),
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
        match grid.observe(&LidarScan::new(ranges, geometry)) {
            Ok(_) => StepResult::Applied,
            Err(e) => StepResult::Rejected { reason: e as u8 },
        }
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
                let mut bytes = super::MapBytes([0; super::MAP_CHUNK_BYTES]);
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
            Command::ReportStatus => {}
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
            protocol: super::PROTOCOL_VERSION,
            estimator: self.active,
            status: self.status,
            stack_peak_bytes: 0,
            map_checksum: self.map_checksum,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::{factor_len, state_dim};
    use crate::wire::EkfSettings;
    use crate::wire::encode_frame;

    fn frames(msgs: &[ToDevice]) -> std::vec::Vec<u8> {
        let mut out = std::vec::Vec::new();
        let mut buf = [0u8; MAX_FRAME_LEN];
        for m in msgs {
            out.extend_from_slice(encode_frame(m, &mut buf).unwrap());
        }
        out
    }

    fn velocity(seq: u32, v: f32, omega: f32) -> ToDevice {
        ToDevice::Odometry {
            seq,
            stamp_us: u64::from(seq) * 100_000,
            odometry: Odometry::Velocity { v, omega, dt: 0.1 },
        }
    }

    fn sighting(seq: u32, id: u32, range: f32, bearing: f32) -> ToDevice {
        ToDevice::Landmark {
            seq,
            stamp_us: u64::from(seq) * 100_000,
            id,
            range,
            bearing,
        }
    }

    #[test]
    fn every_status_names_the_map_the_session_was_given() {
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let ask = frames(&[ToDevice::Command {
            seq: 1,
            command: Command::ReportStatus,
        }]);
        let map_of =
            |session: &mut Session<'_, _, _, 4>| match ask.iter().find_map(|&b| session.receive(b))
            {
                Some(ToHost::Status { map_checksum, .. }) => map_checksum,
                other => panic!("{other:?}"),
            };
        let mut plain = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        assert_eq!(map_of(&mut plain), None);
        drop(plain);
        let mut named = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
            .with_map_checksum(Some(0x1234_5678));
        assert_eq!(map_of(&mut named), Some(0x1234_5678));
        // A reset does not forget it.
        let reset = frames(&[ToDevice::Command {
            seq: 2,
            command: Command::Reset {
                x: 1.0,
                y: 0.0,
                theta: 0.0,
            },
        }]);
        assert_eq!(reset.iter().filter_map(|&b| named.receive(b)).count(), 1);
        assert_eq!(map_of(&mut named), Some(0x1234_5678));
    }

    #[test]
    fn a_map_is_saved_and_read_only_where_there_is_one() {
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        let replies: std::vec::Vec<ToHost> = frames(&[
            ToDevice::Command {
                seq: 1,
                command: Command::SaveMap,
            },
            ToDevice::Command {
                seq: 2,
                command: Command::ReadMap { offset: 0 },
            },
        ])
        .into_iter()
        .filter_map(|b| session.receive(b))
        .collect();
        // The EKF keeps no map image; nothing was saved to read.
        assert_eq!(
            replies,
            [
                ToHost::Refused {
                    seq: 1,
                    reason: Refusal::NoMapStorage,
                    estimator: EstimatorKind::Ekf,
                },
                ToHost::Refused {
                    seq: 2,
                    reason: Refusal::NoSavedMap,
                    estimator: EstimatorKind::Ekf,
                },
            ]
        );
    }

    #[test]
    fn replies_match_direct_calls_on_the_filter() {
        let msgs = [
            sighting(1, 40, 2.0, 0.3),
            velocity(2, 0.5, 0.1),
            sighting(3, 40, 1.95, 0.33),
            sighting(4, 41, 3.0, -0.5),
            velocity(5, 0.5, 0.1),
            sighting(6, 41, 2.9, -0.52),
            sighting(7, 40, f32::NAN, 0.0),
        ];
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        let mut replies = std::vec::Vec::new();
        for b in frames(&msgs) {
            replies.extend(session.receive(b));
        }
        let mut direct =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let a = direct.add_landmark(&RangeBearing::new(2.0, 0.3)).unwrap();
        direct.predict_velocity(0.5, 0.1, 0.1).unwrap();
        direct.update(a, &RangeBearing::new(1.95, 0.33)).unwrap();
        let b = direct.add_landmark(&RangeBearing::new(3.0, -0.5)).unwrap();
        direct.predict_velocity(0.5, 0.1, 0.1).unwrap();
        direct.update(b, &RangeBearing::new(2.9, -0.52)).unwrap();

        assert_eq!(replies.len(), msgs.len());
        let results: std::vec::Vec<_> = replies
            .iter()
            .map(|r| match r {
                ToHost::Estimate(e) => (e.seq, e.result),
                other => panic!("{other:?}"),
            })
            .collect();
        let nonfinite = StepResult::Rejected {
            reason: crate::EkfError::NonFiniteInput as u8,
        };
        assert_eq!(
            results,
            [
                (1, StepResult::Added),
                (2, StepResult::Applied),
                (3, StepResult::Applied),
                (4, StepResult::Added),
                (5, StepResult::Applied),
                (6, StepResult::Applied),
                (7, nonfinite),
            ]
        );
        let ToHost::Estimate(last) = replies[6] else {
            unreachable!()
        };
        let pose = direct.pose();
        assert_eq!(last.pose, [pose.x, pose.y, pose.theta]);
        let p = direct.pose_covariance();
        assert_eq!(last.covariance[0], p[(0, 0)]);
        assert_eq!(last.covariance[4], p[(1, 2)]);
        assert_eq!(last.status.landmarks, 2);
        assert_eq!(last.status.events, 7);
        assert_eq!(last.status.rejected, 1);
        assert_eq!(last.status.frames_ok, 7);
    }

    #[test]
    fn ekf_settings_from_the_wire_replace_the_configuration() {
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        let mut wanted = EkfConfig::MICROCONTROLLER;
        wanted.range_std = 0.123;
        wanted.gate = crate::gate::ChiSquareGate::from_threshold(7.5);
        wanted.sensor =
            crate::sensors::range_bearing::RangeBearingSensor::new(Pose2::new(0.1, -0.02, 0.05));
        let settings = EkfSettings::from_config(&wanted);
        assert_eq!(settings.to_config(), wanted);
        let mut bad = settings;
        bad.bearing_std = f32::NAN;
        let bytes = frames(&[
            ToDevice::Command {
                seq: 1,
                command: Command::ConfigureEkf(settings),
            },
            ToDevice::Command {
                seq: 2,
                command: Command::ConfigureEkf(bad),
            },
        ]);
        let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
        // The valid settings are taken; the NaN ones refused, the value named (the
        // bearing's standard deviation is the twelfth value on the wire) and counted.
        assert!(
            matches!(replies[0], ToHost::Status { seq: 1, status, .. } if status.rejected == 0),
            "{:?}",
            replies[0]
        );
        assert_eq!(
            replies[1],
            ToHost::Refused {
                seq: 2,
                reason: Refusal::InvalidEkfSetting { field: 11 },
                estimator: EstimatorKind::Ekf,
            }
        );
        let status = frames(&[ToDevice::Command {
            seq: 3,
            command: Command::ReportStatus,
        }]);
        let counted: std::vec::Vec<_> = status.iter().filter_map(|&b| session.receive(b)).collect();
        assert!(
            matches!(counted[..], [ToHost::Status { status, .. }] if status.rejected == 1),
            "{counted:?}"
        );
        // A reset keeps them.
        let reset = frames(&[ToDevice::Command {
            seq: 3,
            command: Command::Reset {
                x: 0.0,
                y: 0.0,
                theta: 0.0,
            },
        }]);
        assert_eq!(reset.iter().filter_map(|&b| session.receive(b)).count(), 1);
        drop(session);
        assert_eq!(*ekf.config(), wanted);
    }

    #[test]
    fn bad_frames_are_counted_and_commands_answered_with_status() {
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        let mut bytes = frames(&[sighting(1, 7, 2.0, 0.0)]);
        bytes.extend_from_slice(&[1, 2, 3, 0, 0xff, 0xfe, 0]);
        bytes.extend(frames(&[
            ToDevice::Command {
                seq: 2,
                command: Command::Reset {
                    x: 1.0,
                    y: 2.0,
                    theta: 0.5,
                },
            },
            ToDevice::Command {
                seq: 3,
                command: Command::SelectEstimator(EstimatorKind::Grid),
            },
            velocity(4, 0.0, 0.0),
        ]));
        let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
        assert_eq!(replies.len(), 4);
        match replies[1] {
            ToHost::Status { seq, status, .. } => {
                assert_eq!(seq, 2);
                assert_eq!(status.frames_bad, 2);
                assert_eq!(status.landmarks, 0);
                assert_eq!(status.events, 0);
            }
            other => panic!("{other:?}"),
        }
        // No grid in this session: it stays on the EKF, restarted at the origin.
        assert!(matches!(
            replies[2],
            ToHost::Status {
                seq: 3,
                estimator: EstimatorKind::Ekf,
                ..
            }
        ));
        match replies[3] {
            ToHost::Estimate(e) => {
                assert_eq!(e.seq, 4);
                assert_eq!(e.pose, [0.0, 0.0, 0.0]);
                assert_eq!(e.status.frames_ok, 4);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn grid_session_matches_direct_calls_on_the_grid_slam() {
        use crate::grid::OccupancyGrid;
        use crate::pf::{GridPfConfig, GridSlam};
        use crate::wire::ScanChunk;
        type Slam<'g> = GridSlam<'g, 64, 64, 8, 40>;
        let config = GridPfConfig::MICROCONTROLLER;
        let setup = GridSetup {
            wheels: DiffDriveGeometry {
                metres_per_tick: 0.002,
                track_width: 0.4,
            },
            ..GridSetup::EXAMPLE
        };
        // A square room 2.4 m wide seen from the centre: 40 beams, 0 mm = no return.
        let inc = core::f32::consts::TAU / 40.0;
        let ranges_mm: std::vec::Vec<u16> = (0..40)
            .map(|i| {
                let a = -core::f32::consts::PI + inc * i as f32;
                let r = 1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)));
                if i == 5 { 0 } else { (r * 1000.0) as u16 }
            })
            .collect();
        let chunk = |seq: u32, scan_id: u16, offset: usize| {
            let end = (offset + 32).min(40);
            ToDevice::Scan(ScanChunk {
                seq,
                stamp_us: 0,
                scan_id,
                beam_offset: offset as u16,
                beam_total: 40,
                angle_min: -core::f32::consts::PI,
                angle_increment: inc,
                ranges_mm: heapless::Vec::from_slice(&ranges_mm[offset..end]).unwrap(),
            })
        };
        let ticks = ToDevice::Odometry {
            seq: 9,
            stamp_us: 0,
            odometry: Odometry::EncoderTicks {
                front_left: 10,
                front_right: 14,
                rear_left: 10,
                rear_right: 14,
                dt: 0.1,
            },
        };
        let msgs = [
            chunk(1, 0, 0), // EKF active: ignored
            ToDevice::Command {
                seq: 2,
                command: Command::SelectEstimator(EstimatorKind::Grid),
            },
            chunk(3, 1, 0),
            chunk(4, 1, 32),
            velocity(5, 0.2, 0.1),
            chunk(6, 2, 32), // first chunk lost: dropped
            chunk(7, 3, 0),
            chunk(8, 3, 32),
            ticks,
            chunk(10, 4, 0),
            chunk(11, 4, 32),
        ];
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut grid = std::boxed::Box::new(OccupancyGrid::<64, 64>::centred(
            config.resolution,
            config.log_odds,
        ));
        let mut slam = Slam::new(&mut grid, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
        let mut session =
            Session::<_, _, 4>::with_grid(&mut ekf, EkfConfig::DEFAULT_F32, &mut slam, setup);
        let replies: std::vec::Vec<_> = frames(&msgs)
            .iter()
            .filter_map(|&b| session.receive(b))
            .collect();
        drop(session);

        let mut grid2 = std::boxed::Box::new(OccupancyGrid::<64, 64>::zeroed());
        grid2
            .init_centred(config.resolution, config.log_odds)
            .unwrap();
        let mut direct = Slam::new(&mut grid2, config, Pose2::new(0.0, 0.0, 0.0)).unwrap();
        let ranges: std::vec::Vec<f32> = ranges_mm
            .iter()
            .map(|&mm| {
                if mm == 0 {
                    f32::NAN
                } else {
                    f32::from(mm) * 0.001
                }
            })
            .collect();
        let lidar = LidarGeometry {
            first_angle: -core::f32::consts::PI,
            angle_increment: inc,
            ..setup.lidar
        };
        direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();
        direct.predict_velocity(0.2, 0.1, 0.1).unwrap();
        direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();
        // Left 10 ticks, right 14 ticks (front and rear averaged) of 2 mm on a 0.4 m track.
        let m = setup
            .wheels
            .motion(&WheelTicks {
                front_right: 14,
                front_left: 10,
                rear_right: 14,
                rear_left: 10,
            })
            .unwrap();
        assert!((m.distance - 0.024).abs() < 1e-6 && (m.heading_change - 0.02).abs() < 1e-6);
        direct.predict(m.distance, m.heading_change).unwrap();
        direct.observe(&LidarScan::new(&ranges, lidar)).unwrap();

        let results: std::vec::Vec<_> = replies
            .iter()
            .map(|r| match r {
                ToHost::Estimate(e) => (e.seq, e.estimator, e.result),
                ToHost::Status { seq, estimator, .. } => (*seq, *estimator, StepResult::Ignored),
                other => panic!("{other:?}"),
            })
            .collect();
        use EstimatorKind::{Ekf, Grid};
        use StepResult::{Applied, Ignored};
        assert_eq!(
            results,
            [
                (1, Ekf, Ignored),
                (2, Grid, Ignored),
                (3, Grid, Ignored),
                (4, Grid, Applied),
                (5, Grid, Applied),
                (
                    6,
                    Grid,
                    StepResult::Rejected {
                        reason: SCAN_DROPPED
                    }
                ),
                (7, Grid, Ignored),
                (8, Grid, Applied),
                (9, Grid, Applied),
                (10, Grid, Ignored),
                (11, Grid, Applied),
            ]
        );
        let ToHost::Estimate(last) = replies[10] else {
            unreachable!()
        };
        let pose = direct.pose();
        assert_eq!(last.pose, [pose.x, pose.y, pose.theta]);
        assert_eq!(last.status.resamples, direct.filter().resample_count());
        assert_eq!(last.covariance, direct.filter().pose_covariance());
        assert!(last.covariance[0] > 0.0 && last.covariance[3] > 0.0 && last.covariance[5] > 0.0);
    }

    #[test]
    fn localizer_mode_matches_direct_calls_and_refusals_are_explicit() {
        use crate::grid::{GridGeometry, GridView, MaxPoolLayers};
        use crate::pf::{GridPfConfig, RelocalizationConfig};
        use crate::wire::{LocalizerReport, Refusal, ScanChunk, TrackingState};
        let config = GridPfConfig::MICROCONTROLLER;
        // A square room, walls at ±1.2 m, on a 64 × 64 map of 5 cm cells.
        let g = GridGeometry::centred(64, 64, 0.05);
        let cells: std::vec::Vec<i8> = (0..64 * 64)
            .map(|i| {
                let (x, y) = g.cell_centre(i % 64, i / 64);
                let d = x.abs().max(y.abs());
                if (1.175..1.25).contains(&d) {
                    100
                } else if d < 1.175 {
                    -100
                } else {
                    0
                }
            })
            .collect();
        let view = GridView::new(&cells, g, config.log_odds.occupied_above).unwrap();
        let mut layers = vec![0u8; MaxPoolLayers::bytes_for(64, 64, 3).unwrap()];
        let layers =
            MaxPoolLayers::build(&view, config.log_odds.free_below, 3, &mut layers).unwrap();
        let inc = core::f32::consts::TAU / 40.0;
        let ranges_mm: std::vec::Vec<u16> = (0..40)
            .map(|i| {
                let a = -core::f32::consts::PI + inc * i as f32;
                let r = 1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)));
                (r * 1000.0) as u16
            })
            .collect();
        let chunk = |seq: u32, offset: usize| {
            ToDevice::Scan(ScanChunk {
                seq,
                stamp_us: 0,
                scan_id: seq as u16,
                beam_offset: offset as u16,
                beam_total: 40,
                angle_min: -core::f32::consts::PI,
                angle_increment: inc,
                ranges_mm: heapless::Vec::from_slice(&ranges_mm[offset..(offset + 32).min(40)])
                    .unwrap(),
            })
        };
        let command = |seq, command| ToDevice::Command { seq, command };
        let msgs = [
            command(1, Command::Relocalize),
            command(2, Command::SelectEstimator(EstimatorKind::Localizer)),
            command(
                3,
                Command::Reset {
                    x: 0.05,
                    y: 0.0,
                    theta: 0.0,
                },
            ),
            chunk(4, 0),
            chunk(4, 32),
            velocity(5, 0.0, 0.0),
            command(6, Command::Relocalize),
            chunk(7, 0),
            chunk(7, 32),
        ];
        let bytes = frames(&msgs);
        let setup = GridSetup::EXAMPLE;

        // Without a map: both commands refused, the EKF stays.
        let mut ekf =
            EkfSlam::<f32, { state_dim(4) }, { factor_len(4) }>::new(EkfConfig::DEFAULT_F32);
        let mut plain = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32);
        let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| plain.receive(b)).collect();
        let refused = |seq, reason| ToHost::Refused {
            seq,
            reason,
            estimator: EstimatorKind::Ekf,
        };
        assert_eq!(replies[0], refused(1, Refusal::NotLocalizing));
        assert_eq!(replies[1], refused(2, Refusal::NoMap));
        drop(plain);
        let mut bad = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
            .with_localizer(Err(Refusal::BadMap { code: 6 }), setup);
        let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| bad.receive(b)).collect();
        assert_eq!(replies[1], refused(2, Refusal::BadMap { code: 6 }));
        drop(bad);

        // With the map and its layers.
        let start = Pose2::new(0.0, 0.0, 0.0);
        let mut loc = GridLocalizer::<16, 40>::new(view, config, start)
            .unwrap()
            .with_layers(layers, RelocalizationConfig::DEFAULT)
            .unwrap();
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
            .with_localizer(Ok(&mut loc), setup);
        let replies: std::vec::Vec<_> = bytes.iter().filter_map(|&b| session.receive(b)).collect();
        drop(session);
        assert_eq!(replies.len(), msgs.len());
        assert_eq!(replies[0], refused(1, Refusal::NotLocalizing));
        assert!(matches!(
            replies[1],
            ToHost::Status {
                seq: 2,
                estimator: EstimatorKind::Localizer,
                ..
            }
        ));
        let localization = |r: &ToHost| match r {
            ToHost::Localization {
                estimate,
                localizer,
            } => (*estimate, *localizer),
            other => panic!("{other:?}"),
        };
        assert_eq!(localization(&replies[3]).0.result, StepResult::Ignored);
        let (after_scan, report) = localization(&replies[4]);
        assert_eq!(after_scan.result, StepResult::Applied);
        assert_eq!(report.state, TrackingState::Tracking);
        assert!(report.hit_fraction > 0.5, "{report:?}");

        // The same steps on a twin, called directly.
        let mut twin = GridLocalizer::<16, 40>::new(view, config, start).unwrap();
        twin.reset_around(Pose2::new(0.05, 0.0, 0.0), 0.0, 0.0)
            .unwrap();
        let ranges: std::vec::Vec<f32> =
            ranges_mm.iter().map(|&mm| f32::from(mm) * 0.001).collect();
        let lidar = LidarGeometry {
            first_angle: -core::f32::consts::PI,
            angle_increment: inc,
            ..setup.lidar
        };
        twin.observe(&LidarScan::new(&ranges, lidar)).unwrap();
        let pose = twin.pose();
        assert_eq!(after_scan.pose, [pose.x, pose.y, pose.theta]);
        assert_eq!(after_scan.covariance, twin.filter().pose_covariance());

        // Relocalize: answered with a status; the next scan runs the global search.
        assert!(matches!(replies[6], ToHost::Status { seq: 6, .. }));
        let (_, report) = localization(&replies[8]);
        assert_eq!(report.relocalizations, 1, "{report:?}");
        assert_eq!(
            report.search_scans, 0,
            "the search ended on its scan: {report:?}"
        );
        assert_ne!(report, LocalizerReport::default());

        // A search spanning scans (5 units of work, about a node, a scan; at most 3
        // scans): each estimate says
        // how many scans it has run, until it ends (seeded or failed) on the third.
        let slow = RelocalizationConfig {
            search: crate::pf::global::GlobalSearchConfig {
                work_budget: 5,
                ..crate::pf::global::GlobalSearchConfig::DEFAULT
            },
            search_scans: 3,
            ..RelocalizationConfig::DEFAULT
        };
        let mut loc = GridLocalizer::<16, 40>::new(view, config, start)
            .unwrap()
            .with_layers(layers, slow)
            .unwrap();
        let mut session = Session::<_, _, 4>::new(&mut ekf, EkfConfig::DEFAULT_F32)
            .with_localizer(Ok(&mut loc), setup);
        let msgs = [
            command(1, Command::SelectEstimator(EstimatorKind::Localizer)),
            command(2, Command::Relocalize),
            chunk(3, 0),
            chunk(3, 32),
            chunk(4, 0),
            chunk(4, 32),
            chunk(5, 0),
            chunk(5, 32),
        ];
        let replies: std::vec::Vec<_> = frames(&msgs)
            .iter()
            .filter_map(|&b| session.receive(b))
            .collect();
        drop(session);
        assert_eq!(replies.len(), msgs.len());
        let reports: std::vec::Vec<_> = [3, 5, 7].map(|i| localization(&replies[i]).1).to_vec();
        assert_eq!(reports[0].search_scans, 1, "{reports:?}");
        assert_eq!(reports[0].state, TrackingState::Lost);
        assert_eq!(reports[1].search_scans, 2, "{reports:?}");
        assert_eq!(reports[2].search_scans, 0, "{reports:?}");
        // Ended: seeded (relocalized), or failed and lost (the next scan searches again).
        let s = *loc.status();
        assert_eq!(s.relocalizations + s.failed_searches, 1, "{s:?}");
        assert_eq!(reports[2].relocalizations, s.relocalizations);
        assert_eq!(
            reports[2].state == TrackingState::Lost,
            s.failed_searches == 1,
            "{reports:?}"
        );
    }
}
