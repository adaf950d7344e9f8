//! The firmware's localizer mode in the loop: the map image a firmware built with
//! `MICROSLAM_MAP=<map.yaml>` embeds ([`map_image_of`], the build script's code), the wire
//! messages of a lidar log in localizer mode ([`localizer_messages`]: the handshake, select
//! the localizer, reset at a pose, then per front scan its odometry increment and its scan
//! chunks), and the host reference the device must equal bit for bit
//! ([`host_localizer_replies`]: the firmware's [`Session`] with its localizer on the same
//! map image).

use std::path::Path;

use anyhow::{Result, bail};
use microslam::device::{LocalizerEstimator, PoseKeeping, Session};
use microslam::geometry::Pose2;
use microslam::grid::MapImage;
use microslam::grid::map_image::{DEFAULT_LAYER_LEVELS, encode_map_image_with_layers};
use microslam::grid::ros_map::RosMap;
use microslam::profile;
use microslam::wire::{
    Command as WireCommand, EstimatorKind, Odometry, SCAN_CHUNK_BEAMS, ScanChunk, ToDevice, ToHost,
};

use crate::domain::grid::carmen_lidar;
use crate::inputs::readers::carmen::LaserMessage;
use microslam::device::MAX_SCAN_BEAMS;
use microslam::sensors::lidar::LidarGeometry;

/// The map image of `yaml` as the firmware's build script makes it (with
/// [`DEFAULT_LAYER_LEVELS`] levels of layers).
pub fn map_image_of(yaml: &Path) -> Result<Vec<u8>> {
    map_image_with_levels(yaml, DEFAULT_LAYER_LEVELS)
}

/// The map image of `yaml` with `levels` levels of max-pooled layers (0: none); `yaml`
/// may be a map image itself (a board's `map.bin`), which gets the layers as the
/// firmware's build script gives them (`microslam::grid::map_image::with_layers`).
pub fn map_image_with_levels(yaml: &Path, levels: u8) -> Result<Vec<u8>> {
    let config = profile::LOCALIZER_CONFIG;
    let bytes = std::fs::read(yaml).map_err(|e| anyhow::anyhow!("{}: {e}", yaml.display()))?;
    if bytes.starts_with(&microslam::grid::map_image::MAP_IMAGE_MAGIC) {
        if levels == 0 {
            microslam::grid::MapImage::parse(&bytes)
                .map_err(|e| anyhow::anyhow!("{}: {e}", yaml.display()))?;
            return Ok(bytes);
        }
        return microslam::grid::map_image::with_layers(&bytes, levels)
            .map_err(|e| anyhow::anyhow!("{}: {e}", yaml.display()));
    }
    let map = RosMap::read(yaml, &config.log_odds)?;
    if (map.geometry.resolution - config.resolution).abs() > 1e-6 {
        bail!(
            "{}: resolution {} m, the localizer runs at {} m",
            yaml.display(),
            map.geometry.resolution,
            config.resolution
        );
    }
    Ok(encode_map_image_with_layers(
        &map.cells,
        &map.geometry,
        config.log_odds.occupied_above,
        config.log_odds.free_below,
        levels,
    )?)
}

/// Wire range of one beam: millimetres, 0 for no return (not finite, or beyond what a
/// `u16` holds).
fn range_mm(r: f32) -> u16 {
    if r.is_finite() && r > 0.0 && r * 1000.0 < f32::from(u16::MAX) {
        (r * 1000.0).round() as u16
    } else {
        0
    }
}

/// How a lidar log's scans go to the device: the first beam's angle and the step between
/// beams on the wire, every `stride`-th beam of a scan (a lidar of more beams than the
/// device's scan assembler holds, [`MAX_SCAN_BEAMS`], is thinned to fit), and the lidar's
/// mount on the robot. The device's lidar sits at its robot's centre
/// ([`microslam::device::GridSetup::EXAMPLE`]); for a lidar mounted elsewhere the host
/// sends the lidar's own motion (the increments between the odometry poses of the lidar,
/// `R ⊕ M`: `M⁻¹ ⊕ d ⊕ M` for the robot's increment `d`), so the device estimates the
/// lidar's pose and draws the same map, and [`WireLidar::robot_pose`] turns its estimates
/// back into the robot's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WireLidar {
    /// Angle of the first beam sent, rad (in the lidar's frame).
    pub first_angle: f32,
    /// Angle between two beams sent, rad.
    pub angle_increment: f32,
    /// Every `stride`-th beam of a scan is sent.
    pub stride: usize,
    /// The lidar's pose on the robot.
    pub mount: Pose2<f32>,
}

impl WireLidar {
    /// For scans of `beams` beams of the lidar `geometry`.
    pub fn new(geometry: &LidarGeometry, beams: usize) -> Self {
        let stride = beams.div_ceil(MAX_SCAN_BEAMS).max(1);
        Self {
            first_angle: geometry.first_angle,
            angle_increment: geometry.angle_increment * stride as f32,
            stride,
            mount: geometry.mount,
        }
    }

    /// For the scans of a lidar recording (a CARMEN log's or a ROS 2 bag's).
    pub fn of(recording: &crate::inputs::readers::lidar_recording::LidarRecording) -> Self {
        Self::new(&recording.lidar, recording.beams())
    }

    /// For a CARMEN log's front scans of `beams` beams ([`carmen_lidar`]).
    pub fn carmen(beams: usize) -> Self {
        Self::new(&carmen_lidar(beams), beams)
    }

    /// Whether the lidar sits at the robot's centre (nothing to move).
    fn centred(&self) -> bool {
        self.mount == Pose2::IDENTITY
    }

    /// The lidar's pose when the robot stands at `robot`: `robot ⊕ M`.
    pub fn lidar_pose(&self, robot: Pose2<f32>) -> Pose2<f32> {
        if self.centred() {
            return robot;
        }
        robot.compose(&self.mount)
    }

    /// The robot's pose for the device's estimate of the lidar's, `[x, y, θ]`:
    /// `lidar ⊕ M⁻¹`.
    pub fn robot_pose(&self, lidar: [f64; 3]) -> [f64; 3] {
        if self.centred() {
            return lidar;
        }
        let p =
            Pose2::new(lidar[0], lidar[1], lidar[2]).compose(&self.mount.cast::<f64>().inverse());
        [p.x, p.y, p.theta]
    }
}

/// The messages for localizer mode over a CARMEN log's `scans`: the handshake
/// ([`super::hil::handshake`]), select the localizer, reset at `start`, then per scan its
/// odometry increment (from the previous finite odometry pose) and its chunks, then a
/// status request. Also the index of each scan's last chunk in the messages.
pub fn localizer_messages(
    scans: &[&LaserMessage],
    start: Pose2<f32>,
) -> (Vec<ToDevice>, Vec<usize>) {
    lidar_messages(scans, start, EstimatorKind::Localizer)
}

/// [`localizer_messages`] for the estimator `kind`: the localizer, or the grid SLAM
/// ([`super::hil_slam`]).
pub fn lidar_messages(
    scans: &[&LaserMessage],
    start: Pose2<f32>,
    kind: EstimatorKind,
) -> (Vec<ToDevice>, Vec<usize>) {
    let beams = scans.first().map_or(0, |s| s.ranges.len());
    wire_lidar_messages(scans, &WireLidar::carmen(beams), start, kind)
}

/// [`lidar_messages`] for scans of the lidar `lidar` (a CARMEN log's or a ROS 2 bag's):
/// `start` is the robot's pose; the device is reset at its lidar's.
pub fn wire_lidar_messages(
    scans: &[&LaserMessage],
    lidar: &WireLidar,
    start: Pose2<f32>,
    kind: EstimatorKind,
) -> (Vec<ToDevice>, Vec<usize>) {
    lidar_messages_by(scans, lidar, start, kind, ScanPath::Link)
}

/// How the scans reach the device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanPath {
    /// As scan chunks over the link.
    Link,
    /// Through the device's own lidar (its second UART, [`super::hil_lidar`]): a
    /// `NextRevolution` command where each scan's chunks would be, the scans themselves on
    /// the lidar's line.
    OwnLidar,
}

/// [`wire_lidar_messages`] with the scans sent along `path`.
pub fn lidar_messages_by(
    scans: &[&LaserMessage],
    lidar: &WireLidar,
    start: Pose2<f32>,
    kind: EstimatorKind,
    path: ScanPath,
) -> (Vec<ToDevice>, Vec<usize>) {
    let start = lidar.lidar_pose(start);
    let mut out = vec![
        super::hil::handshake(),
        ToDevice::Command {
            seq: 0,
            command: WireCommand::SelectEstimator(kind),
        },
        ToDevice::Command {
            seq: 1,
            command: WireCommand::Reset {
                x: start.x,
                y: start.y,
                theta: start.theta,
            },
        },
    ];
    let mut seq = 2u32;
    let mut last_chunks = Vec::with_capacity(scans.len());
    let mut previous: Option<Pose2<f32>> = None;
    for (i, laser) in scans.iter().enumerate() {
        let stamp_us = (laser.stamp * 1e6).max(0.0) as u64;
        // The odometry pose of the lidar (the robot's where it sits at the centre).
        let odom = lidar.lidar_pose(Pose2::new(
            laser.odom[0] as f32,
            laser.odom[1] as f32,
            laser.odom[2] as f32,
        ));
        // A pose that is not finite is skipped: the next good one predicts the whole motion.
        if odom.is_finite()
            && let Some(from) = previous.replace(odom)
        {
            let d = from.between(&odom);
            out.push(ToDevice::Odometry {
                seq,
                stamp_us,
                odometry: Odometry::Increment {
                    dx: d.x,
                    dy: d.y,
                    dtheta: d.theta,
                },
            });
            seq = seq.wrapping_add(1);
        }
        if path == ScanPath::OwnLidar {
            out.push(ToDevice::Command {
                seq,
                command: WireCommand::NextRevolution { stamp_us },
            });
            seq = seq.wrapping_add(1);
            last_chunks.push(out.len() - 1);
            continue;
        }
        let sent: Vec<u16> = laser
            .ranges
            .iter()
            .step_by(lidar.stride)
            .map(|&r| range_mm(r))
            .collect();
        let n = sent.len();
        for offset in (0..n).step_by(SCAN_CHUNK_BEAMS) {
            let end = (offset + SCAN_CHUNK_BEAMS).min(n);
            out.push(ToDevice::Scan(ScanChunk {
                seq,
                stamp_us,
                scan_id: i as u16,
                beam_offset: offset as u16,
                beam_total: n as u16,
                angle_min: lidar.first_angle,
                angle_increment: lidar.angle_increment,
                ranges_mm: sent[offset..end].iter().copied().collect(),
            }));
            seq = seq.wrapping_add(1);
        }
        last_chunks.push(out.len() - 1);
    }
    out.push(ToDevice::Command {
        seq,
        command: WireCommand::ReportStatus,
    });
    (out, last_chunks)
}

/// The replies of the host reference: the firmware's [`Session`] with its EKF and its
/// localizer on `image`, fed the same bytes.
pub fn host_localizer_replies(bytes: &[u8], image: &[u8]) -> Result<Vec<ToHost>> {
    host_localizer_session(bytes, image, None, None)
}

/// [`host_localizer_replies`] of a firmware that booted with a pose saved in this map
/// (`resume`): its session starts on the localizer there (`Session::localizing_from`);
/// with `lidar`, the bytes of its own lidar's line ([`super::hil_lidar`]), read by the
/// firmware's reader on `NextRevolution`.
pub fn host_localizer_session(
    bytes: &[u8],
    image: &[u8],
    resume: Option<Pose2<f32>>,
    lidar: Option<&[u8]>,
) -> Result<Vec<ToHost>> {
    let map = MapImage::parse(image)?;
    let mut ekf = Box::new(profile::Ekf::new(profile::EKF_CONFIG));
    let mut localizer =
        profile::Localizer::new(map.view(), profile::LOCALIZER_CONFIG, Pose2::IDENTITY)
            .map_err(|e| anyhow::anyhow!("localizer: {e}"))?;
    if let Some(layers) = map.layers() {
        localizer = localizer
            .with_layers(layers?, profile::RELOCALIZATION)
            .map_err(|e| anyhow::anyhow!("localizer layers: {e}"))?;
    }
    let mut localizer = Box::new(localizer);
    let mut session =
        Session::<_, _, { profile::EKF_LANDMARKS }>::new(&mut ekf, profile::EKF_CONFIG)
            .with_localizer(
                Ok(&mut *localizer as &mut dyn LocalizerEstimator),
                profile::GRID_SETUP,
            )
            .with_map_checksum(Some(map.checksum()));
    let mut reader = lidar.map(|l| Box::new(super::hil_lidar::host_reader(l)));
    if let Some(reader) = reader.as_deref_mut() {
        session = session.with_lidar(reader);
    }
    if let Some(pose) = resume {
        session = session.localizing_from(pose);
    }
    Ok(bytes.iter().filter_map(|&b| session.receive(b)).collect())
}

/// One part of a run: the bytes sent and the host's replies to them.
pub type RunPart = (Vec<u8>, Vec<ToHost>);

/// The host reference of a localizer run restarted after `restart_after` scans: the
/// bytes and replies of each part (the first ends with `Restart`; the second opens with
/// the handshake), and the pose the firmware kept before the reset (`PoseKeeping`), from
/// which it starts again.
pub fn host_localizer_restart(
    messages: &[ToDevice],
    last_chunks: &[usize],
    restart_after: usize,
    image: &[u8],
) -> Result<(Vec<RunPart>, Pose2<f32>)> {
    let (cut, next_seq) = super::hil::restart_cut(messages, last_chunks, restart_after)?;
    let mut before = messages[..cut].to_vec();
    before.push(ToDevice::Command {
        seq: next_seq,
        command: WireCommand::Restart,
    });
    let before_bytes = super::hil::encode_all(&before);
    let before_replies = host_localizer_session(&before_bytes, image, None, None)?;
    let map = MapImage::parse(image)?;
    let mut keeping = PoseKeeping::new(Some(map.checksum()), None);
    let mut kept = None;
    for reply in &before_replies {
        kept = keeping.after(reply).map(|(pose, _)| pose).or(kept);
    }
    let resumed = keeping
        .before_restart()
        .map(|(pose, _)| pose)
        .or(kept)
        .ok_or_else(|| {
            anyhow::anyhow!(
                "the localizer tracked no scan in the first {restart_after}: no pose is kept"
            )
        })?;
    let mut after = vec![super::hil::handshake()];
    after.extend_from_slice(&messages[cut..]);
    let after_bytes = super::hil::encode_all(&after);
    let after_replies = host_localizer_session(&after_bytes, image, Some(resumed), None)?;
    Ok((
        vec![(before_bytes, before_replies), (after_bytes, after_replies)],
        resumed,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A mount ahead, to the left and turned: nothing about it cancels.
    const MOUNT: Pose2<f32> = Pose2::new(0.3, 0.1, 0.4);

    fn close(a: Pose2<f32>, b: Pose2<f32>) -> bool {
        (a.x - b.x).abs() < 1e-5
            && (a.y - b.y).abs() < 1e-5
            && microslam::geometry::wrap_angle(a.theta - b.theta).abs() < 1e-5
    }

    #[test]
    fn the_lidar_moves_as_the_robot_carries_it() {
        let lidar = WireLidar {
            mount: MOUNT,
            ..WireLidar::carmen(180)
        };
        let path = [
            Pose2::new(0.0, 0.0, 0.0),
            Pose2::new(0.5, 0.1, 0.3),
            Pose2::new(0.9, 0.6, 1.2),
            Pose2::new(0.4, 1.1, 2.9),
            Pose2::new(-0.2, 0.8, -2.8),
        ];
        for w in path.windows(2) {
            let d = w[0].between(&w[1]);
            // The lidar's motion is the robot's seen from the mount: M⁻¹ ⊕ d ⊕ M.
            let moved = lidar.lidar_pose(w[0]).between(&lidar.lidar_pose(w[1]));
            let expected = MOUNT.inverse().compose(&d).compose(&MOUNT);
            assert!(close(moved, expected), "{moved:?} vs {expected:?}");
            // The robot's pose back from the lidar's.
            let l = lidar.lidar_pose(w[1]);
            let [x, y, th] = lidar.robot_pose([l.x, l.y, l.theta].map(f64::from));
            let r = Pose2::new(x as f32, y as f32, th as f32);
            assert!(close(r, w[1]), "{r:?} vs {:?}", w[1]);
        }
        // A lidar at the centre changes nothing, bit for bit.
        let centred = WireLidar::carmen(180);
        let p = Pose2::new(0.123, -0.01, 0.07);
        assert_eq!(centred.lidar_pose(p), p);
        assert_eq!(centred.robot_pose([1.0, 2.0, 3.0]), [1.0, 2.0, 3.0]);
    }

    #[test]
    fn a_carmen_scan_keeps_its_geometry_and_a_dense_one_is_thinned_to_fit() {
        let carmen = WireLidar::carmen(180);
        assert_eq!(carmen.first_angle, -core::f32::consts::FRAC_PI_2);
        assert_eq!(carmen.angle_increment, core::f32::consts::PI / 180.0);
        assert_eq!(carmen.stride, 1);
        // A Hokuyo of 1 081 beams: every 4th (271 beams ≤ 360), four steps apart.
        let hokuyo = LidarGeometry::THOR_HOKUYO;
        let thinned = WireLidar::new(&hokuyo, 1081);
        assert_eq!(thinned.stride, 4);
        assert_eq!(thinned.angle_increment, hokuyo.angle_increment * 4.0);
        assert_eq!(WireLidar::new(&hokuyo, 360).stride, 1);
        assert_eq!(WireLidar::new(&hokuyo, 361).stride, 2);
        let scan = LaserMessage {
            rear: false,
            ranges: (0..1081).map(|i| 1.0 + i as f32 * 0.001).collect(),
            pose: [0.0; 3],
            odom: [0.0; 3],
            stamp: 1.0,
        };
        let (messages, last) =
            wire_lidar_messages(&[&scan], &thinned, Pose2::IDENTITY, EstimatorKind::Grid);
        let chunks: Vec<&ScanChunk> = messages
            .iter()
            .filter_map(|m| match m {
                ToDevice::Scan(c) => Some(c),
                _ => None,
            })
            .collect();
        assert_eq!(last, vec![messages.len() - 2]);
        assert_eq!(chunks.len(), 271usize.div_ceil(SCAN_CHUNK_BEAMS));
        assert!(chunks.iter().all(|c| c.beam_total == 271));
        let sent: Vec<u16> = chunks.iter().flat_map(|c| c.ranges_mm.clone()).collect();
        let expected: Vec<u16> = (0..1081).step_by(4).map(|i| 1000 + i as u16).collect();
        assert_eq!(sent, expected);
    }
}
