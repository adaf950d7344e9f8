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

use crate::inputs::readers::carmen::LaserMessage;

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

/// The messages for localizer mode over `scans`: the handshake
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
        let odom = Pose2::new(
            laser.odom[0] as f32,
            laser.odom[1] as f32,
            laser.odom[2] as f32,
        );
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
        let n = laser.ranges.len();
        let increment = core::f32::consts::PI / n.max(1) as f32;
        for offset in (0..n).step_by(SCAN_CHUNK_BEAMS) {
            let end = (offset + SCAN_CHUNK_BEAMS).min(n);
            let ranges_mm = laser.ranges[offset..end]
                .iter()
                .map(|&r| range_mm(r))
                .collect();
            out.push(ToDevice::Scan(ScanChunk {
                seq,
                stamp_us,
                scan_id: i as u16,
                beam_offset: offset as u16,
                beam_total: n as u16,
                angle_min: -core::f32::consts::FRAC_PI_2,
                angle_increment: increment,
                ranges_mm,
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
    host_localizer_session(bytes, image, None)
}

/// [`host_localizer_replies`] of a firmware that booted with a pose saved in this map
/// (`resume`): its session starts on the localizer there (`Session::localizing_from`).
pub fn host_localizer_session(
    bytes: &[u8],
    image: &[u8],
    resume: Option<Pose2<f32>>,
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
    let before_replies = host_localizer_session(&before_bytes, image, None)?;
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
    let after_replies = host_localizer_session(&after_bytes, image, Some(resumed))?;
    Ok((
        vec![(before_bytes, before_replies), (after_bytes, after_replies)],
        resumed,
    ))
}
