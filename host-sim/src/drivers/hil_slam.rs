//! The firmware's building-scale grid SLAM in the loop (a firmware built with the
//! feature `building-slam`): the host reference the device must equal bit for bit
//! ([`host_slam_replies`]: the firmware's [`Session`] with the small EKF and
//! [`profile::Slam`] as its grid estimator, keyframes and map image in memory), and the
//! commands that end the run and read the device's map image back over the link
//! ([`Command::SaveMap`], [`Command::ReadMap`]).

use anyhow::{Result, anyhow, bail};
use microslam::device::{PoseKeeping, Session};
use microslam::geometry::Pose2;
use microslam::grid::MapImage;
use microslam::profile;
use microslam::slam::{GraphCounters, GraphSlam};
use microslam::wire::{Command, MAP_CHUNK_BYTES, ToDevice, ToHost};

use super::graph_slam::VecStorage;
use super::hil::encode_all;

/// What the host reference computed.
pub struct HostSlam {
    /// The bytes to send the device: the messages given, then (with `save_map`)
    /// [`Command::SaveMap`], a [`Command::ReadMap`] for every chunk of the image and a
    /// closing [`Command::ReportStatus`].
    pub bytes: Vec<u8>,
    /// Its replies, one per message.
    pub replies: Vec<ToHost>,
    /// The map image the run saved, read back through the session (`None` without
    /// `save_map`).
    pub map_image: Option<Vec<u8>>,
    /// The SLAM's counters at the end.
    pub counters: GraphCounters,
}

/// The map image of a run's [`ToHost::MapChunk`] replies, in the order they came
/// (`None` without any); an error when a chunk is missing or out of place.
pub fn map_from_replies(replies: &[ToHost]) -> Result<Option<Vec<u8>>> {
    let mut image = Vec::new();
    for r in replies {
        if let ToHost::MapChunk {
            offset, len, bytes, ..
        } = r
        {
            if *offset as usize != image.len() {
                bail!(
                    "map chunk at byte {offset} where byte {} was expected",
                    image.len()
                );
            }
            let len = usize::from(*len).min(MAP_CHUNK_BYTES);
            image.extend_from_slice(&bytes.0[..len]);
        }
    }
    Ok((!image.is_empty()).then_some(image))
}

/// The replies of the host reference: the building-scale SLAM firmware's [`Session`]
/// ([`profile::SlamEkf`], [`profile::SlamEstimator`] with [`profile::SLAM_CONFIG`]), fed
/// `messages`. Its keyframes go to [`profile::SLAM_KEYFRAME_BYTES`] of memory (the
/// device's flash stand-in programs 4-byte words, the host's bytes, so the slots are laid
/// out differently; the keyframes read back are the same, and both hold more than the
/// graph's [`profile::SLAM_NODES`]). With `save_map`, the run is then ended with
/// [`Command::SaveMap`] and its image read back chunk by chunk ([`HostSlam::bytes`] holds
/// every message sent).
pub fn host_slam_replies(messages: &[ToDevice], save_map: bool) -> Result<HostSlam> {
    let next_seq = messages
        .iter()
        .map(|m| m.seq().wrapping_add(1))
        .max()
        .unwrap_or(0);
    host_slam_session(encode_all(messages), save_map.then_some(next_seq))
}

/// [`host_slam_replies`] for a byte stream as given (e.g. with line noise): the replies
/// to `bytes`, then, with `save_map_seq`, the map saved and read back with commands
/// numbered from it.
pub fn host_slam_session(bytes: Vec<u8>, save_map_seq: Option<u32>) -> Result<HostSlam> {
    host_slam_session_then(bytes, save_map_seq, false)
}

/// [`host_slam_session`], ending with [`Command::Restart`] when `restart` (after the map
/// was saved and read back, with the next sequence number).
fn host_slam_session_then(
    bytes: Vec<u8>,
    save_map_seq: Option<u32>,
    restart: bool,
) -> Result<HostSlam> {
    let mut ekf = Box::new(profile::SlamEkf::new(profile::EKF_CONFIG));
    let mut slam: Box<profile::Slam> = Box::new(GraphSlam::zeroed());
    let storage = VecStorage::new(profile::SLAM_KEYFRAME_BYTES as usize);
    let mut estimator = profile::SlamEstimator::new(
        &mut slam,
        storage,
        profile::SLAM_CONFIG,
        Pose2::new(0.0, 0.0, 0.0),
    )
    .map_err(|e| anyhow!("building-scale SLAM: {e}"))?
    .with_map_storage(VecStorage::new(profile::SLAM_MAP_BYTES as usize));
    let mut bytes = bytes;
    let mut replies: Vec<ToHost>;
    {
        let mut session = Session::<_, _, { profile::SLAM_EKF_LANDMARKS }>::with_grid(
            &mut ekf,
            profile::EKF_CONFIG,
            &mut estimator,
            profile::GRID_SETUP,
        );
        replies = bytes.iter().filter_map(|&b| session.receive(b)).collect();
        if let Some(mut seq) = save_map_seq {
            let save = encode_all(&[ToDevice::Command {
                seq,
                command: Command::SaveMap,
            }]);
            seq = seq.wrapping_add(1);
            replies.extend(save.iter().filter_map(|&b| session.receive(b)));
            bytes.extend_from_slice(&save);
            if let Some(ToHost::MapSaved { bytes: len, .. }) = replies.last() {
                let reads: Vec<ToDevice> = (0..*len)
                    .step_by(MAP_CHUNK_BYTES)
                    .enumerate()
                    .map(|(k, offset)| ToDevice::Command {
                        seq: seq.wrapping_add(k as u32),
                        command: Command::ReadMap { offset },
                    })
                    .collect();
                let read = encode_all(&reads);
                replies.extend(read.iter().filter_map(|&b| session.receive(b)));
                bytes.extend_from_slice(&read);
                seq = seq.wrapping_add(reads.len() as u32);
            }
            // The stream ends with a status, as every stream does (the device's stack
            // peak, now with the map's drawing in it); then, when asked, the restart.
            let mut last = vec![ToDevice::Command {
                seq,
                command: Command::ReportStatus,
            }];
            if restart {
                last.push(ToDevice::Command {
                    seq: seq.wrapping_add(1),
                    command: Command::Restart,
                });
            }
            let last = encode_all(&last);
            replies.extend(last.iter().filter_map(|&b| session.receive(b)));
            bytes.extend_from_slice(&last);
        }
    }
    let map_image = map_from_replies(&replies)?;
    Ok(HostSlam {
        bytes,
        replies,
        map_image,
        counters: estimator.slam().counters(),
    })
}

/// The host reference of a run with a restart ([`host_restart_replies`]): the
/// building-scale SLAM on the first scans, its map saved, the device restarted, and the
/// localizer on that map from the saved pose on the rest.
pub struct HostRestart {
    /// Before the restart: the SLAM's part (ends with the map read back, a status and
    /// [`Command::Restart`]).
    pub mapping: HostSlam,
    /// After it: the bytes (the [`super::hil::handshake`], then the rest of the scans
    /// and a closing status) and the localizer's replies.
    pub localizing_bytes: Vec<u8>,
    /// Its replies, one per message.
    pub localizing_replies: Vec<ToHost>,
    /// Where the localizer starts: the pose [`ToHost::MapSaved`] gave (kept in flash).
    pub resumed_from: Pose2<f32>,
    /// Poses the firmware writes into its flash after the restart ([`PoseKeeping`]).
    pub poses_kept: usize,
}

/// The reference for `messages` (from [`super::hil_localizer::lidar_messages`], with
/// `last_chunks`) cut after `restart_after` scans: the SLAM's part with `SaveMap`, the
/// map read back and `Restart`; then the firmware's boot on the saved map and pose (the
/// session starts on the localizer there: `Session::localizing_from`), fed the rest.
pub fn host_restart_replies(
    messages: &[ToDevice],
    last_chunks: &[usize],
    restart_after: usize,
) -> Result<HostRestart> {
    let (cut, next_seq) = super::hil::restart_cut(messages, last_chunks, restart_after)?;
    let mapping = host_slam_session_then(encode_all(&messages[..cut]), Some(next_seq), true)?;
    let resumed_from = mapping
        .replies
        .iter()
        .find_map(|r| match r {
            ToHost::MapSaved { pose, .. } => Some(Pose2::new(pose[0], pose[1], pose[2])),
            _ => None,
        })
        .ok_or_else(|| anyhow!("the SLAM did not save its map after {restart_after} scans"))?;
    let image = mapping
        .map_image
        .as_deref()
        .ok_or_else(|| anyhow!("no map image was read back"))?;
    let map = MapImage::parse(image).map_err(|e| anyhow!("the saved map image: {e}"))?;
    let mut localizing = vec![super::hil::handshake()];
    localizing.extend_from_slice(&messages[cut..]);
    let localizing_bytes = encode_all(&localizing);
    let mut ekf = Box::new(profile::SlamEkf::new(profile::EKF_CONFIG));
    let mut localizer = Box::new(
        profile::Localizer::new(map.view(), profile::LOCALIZER_CONFIG, resumed_from)
            .map_err(|e| anyhow!("the localizer on the saved map: {e}"))?,
    );
    let localizing_replies: Vec<ToHost> = {
        let mut session =
            Session::<_, _, { profile::SLAM_EKF_LANDMARKS }>::new(&mut ekf, profile::EKF_CONFIG)
                .with_localizer(Ok(&mut *localizer), profile::GRID_SETUP)
                .with_map_checksum(Some(map.checksum()))
                .localizing_from(resumed_from);
        localizing_bytes
            .iter()
            .filter_map(|&b| session.receive(b))
            .collect()
    };
    let mut keeping = PoseKeeping::new(Some(map.checksum()), Some(resumed_from));
    let poses_kept = localizing_replies
        .iter()
        .filter(|r| keeping.after(r).is_some())
        .count();
    Ok(HostRestart {
        mapping,
        localizing_bytes,
        localizing_replies,
        resumed_from,
        poses_kept,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::hil::{encode_all, host_replies};
    use crate::drivers::hil_localizer::lidar_messages;
    use crate::inputs::readers::carmen::LaserMessage;
    use microslam::wire::{EstimatorKind, StepResult};

    /// A robot driving 3 m along a 6 m × 4 m room with boxes along its walls, a front
    /// scan of 180 beams every 5 cm, its raw odometry turning 2 % too much.
    fn scans() -> Vec<LaserMessage> {
        let walls: Vec<[f32; 4]> = [
            [-3.0, -2.0, 3.0, -2.0],
            [3.0, -2.0, 3.0, 2.0],
            [3.0, 2.0, -3.0, 2.0],
            [-3.0, 2.0, -3.0, -2.0],
            [-1.0, 2.0, -1.0, 1.6],
            [-1.0, 1.6, -0.5, 1.6],
            [0.5, -2.0, 0.5, -1.5],
            [0.5, -1.5, 1.2, -1.5],
            [2.6, -0.3, 2.6, 0.4],
        ]
        .to_vec();
        (0..60)
            .map(|i| {
                let t = i as f32 * 0.05;
                let (x, y, th) = (-1.5 + t, 0.1 * t.sin(), 0.05 * t.sin());
                let ranges = (0..180)
                    .map(|b| {
                        let a = th - core::f32::consts::FRAC_PI_2
                            + core::f32::consts::PI / 180.0 * b as f32;
                        microslam::geometry::ray_to_segments(
                            (x, y),
                            (a.cos(), a.sin()),
                            walls.iter().copied(),
                        )
                        .unwrap_or(f32::INFINITY)
                    })
                    .collect();
                LaserMessage {
                    rear: false,
                    ranges,
                    pose: [f64::from(x), f64::from(y), f64::from(th)],
                    odom: [f64::from(x), f64::from(y), f64::from(th * 1.02)],
                    stamp: 100.0 + f64::from(i) * 0.2,
                }
            })
            .collect()
    }

    #[test]
    fn the_host_reference_runs_the_building_scale_slam_through_the_wire_session() {
        let scans = scans();
        let refs: Vec<&LaserMessage> = scans.iter().collect();
        let (messages, last_chunks) = lidar_messages(&refs, Pose2::IDENTITY, EstimatorKind::Grid);
        let bytes = encode_all(&messages);
        let host = host_slam_replies(&messages, true).expect("the reference runs");
        assert_eq!(&host.bytes[..bytes.len()], &bytes[..]);
        // Every scan's last chunk is answered with the SLAM's step, applied, in grid mode.
        let mut last = None;
        for (k, &i) in last_chunks.iter().enumerate() {
            match &host.replies[i] {
                ToHost::Estimate(e) => {
                    assert_eq!(e.estimator, EstimatorKind::Grid, "scan {k}");
                    assert_eq!(e.result, StepResult::Applied, "scan {k}");
                    last = Some(e.pose);
                }
                other => panic!("scan {k}: {other:?}"),
            }
        }
        // It tracks the robot (the start is the origin: the truth's first pose).
        let [x, y, _] = last.expect("estimates");
        let truth = &scans[scans.len() - 1].pose;
        let (dx, dy) = (
            f64::from(x) - (truth[0] - scans[0].pose[0]),
            f64::from(y) - (truth[1] - scans[0].pose[1]),
        );
        assert!(dx.hypot(dy) < 0.15, "{x} {y} vs {truth:?}");
        // Keyframes every 0.65 m of the 3 m drive, and the map image saved at the end,
        // read back through the session: one tile of 128 cells (6.4 m) a side covers the
        // 6 m × 4 m room.
        assert!(host.counters.keyframes >= 5, "{:?}", host.counters);
        let image = host.map_image.as_ref().expect("a map image");
        let map = microslam::grid::MapImage::parse(image).expect("a valid image");
        assert_eq!((map.geometry().width, map.geometry().height), (128, 128));
        let saved = host.replies.iter().find_map(|r| match r {
            ToHost::MapSaved {
                bytes, checksum, ..
            } => Some((*bytes, *checksum)),
            _ => None,
        });
        assert_eq!(saved, Some((image.len() as u32, map.checksum())));
        let occupied = map
            .occupied_bits()
            .iter()
            .map(|b| b.count_ones())
            .sum::<u32>();
        assert!(occupied > 100, "{occupied}");
        // The same bytes give the same replies (what the device is held to), and the
        // 12.8 m GridSlam firmware's reference does not: the two are told apart.
        let again = host_slam_replies(&messages, true).expect("the reference runs");
        assert_eq!(again.replies, host.replies);
        let small = host_replies(&bytes);
        assert_ne!(small[..messages.len()], host.replies[..messages.len()]);
    }
}
