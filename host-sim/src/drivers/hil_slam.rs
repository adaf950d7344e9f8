//! The firmware's building-scale grid SLAM in the loop (a firmware built with the
//! feature `building-slam`): the host reference the device must equal bit for bit
//! ([`host_slam_replies`]: the firmware's [`Session`] with the small EKF and
//! [`profile::Slam`] as its grid estimator, keyframes in memory), and the map of that
//! reference's keyframes at their final graph poses.

use anyhow::{Result, anyhow};
use microslam::geometry::Pose2;
use microslam::grid::GridGeometry;
use microslam::profile;
use microslam::slam::{GraphCounters, GraphSlam};
use microslam::wire::{Session, ToHost};

use super::graph_slam::{VecStorage, draw_map};

/// Cells along each edge of the grid the host draws the reference's map in (51.2 m at
/// 5 cm, centred on the start).
pub const MAP_CELLS: usize = crate::domain::grid::GRID_CELLS;

/// What the host reference computed.
pub struct HostSlam {
    /// Its replies, one per message.
    pub replies: Vec<ToHost>,
    /// Its keyframes' scans at their final graph poses (`None` when no scan made a
    /// keyframe), drawn on a [`MAP_CELLS`]² grid centred on the start.
    pub map: Option<(Vec<i8>, GridGeometry)>,
    /// The SLAM's counters at the end.
    pub counters: GraphCounters,
}

/// The replies of the host reference: the building-scale SLAM firmware's [`Session`]
/// ([`profile::SlamEkf`], [`profile::SlamEstimator`] with [`profile::SLAM_CONFIG`]), fed
/// the same bytes. Its keyframes go to [`profile::SLAM_KEYFRAME_BYTES`] of memory (the
/// device's flash stand-in programs 4-byte words, the host's bytes, so the slots are laid
/// out differently; the keyframes read back are the same, and both hold more than the
/// graph's [`profile::SLAM_NODES`]).
pub fn host_slam_replies(bytes: &[u8]) -> Result<HostSlam> {
    let mut ekf = Box::new(profile::SlamEkf::new(profile::EKF_CONFIG));
    let mut slam: Box<profile::Slam> = Box::new(GraphSlam::zeroed());
    let storage = VecStorage::new(profile::SLAM_KEYFRAME_BYTES as usize);
    let mut estimator = profile::SlamEstimator::new(
        &mut slam,
        storage,
        profile::SLAM_CONFIG,
        Pose2::new(0.0, 0.0, 0.0),
    )
    .map_err(|e| anyhow!("building-scale SLAM: {e}"))?;
    let replies = {
        let mut session = Session::<_, _, { profile::SLAM_EKF_LANDMARKS }>::with_grid(
            &mut ekf,
            profile::EKF_CONFIG,
            &mut estimator,
            profile::GRID_SETUP,
        );
        bytes.iter().filter_map(|&b| session.receive(b)).collect()
    };
    let map = match estimator.store() {
        Some(store) if !store.is_empty() => Some(draw_map::<
            MAP_CELLS,
            0,
            { profile::GRID_PARTICLES },
            _,
        >(estimator.slam(), store, None)?),
        _ => None,
    };
    Ok(HostSlam {
        replies,
        map,
        counters: estimator.slam().counters(),
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
        let host = host_slam_replies(&bytes).expect("the reference runs");
        assert_eq!(host.replies.len(), messages.len());
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
        // Keyframes every 0.5 m of the 3 m drive, and a map drawn of them.
        assert!(host.counters.keyframes >= 5, "{:?}", host.counters);
        let (cells, _) = host.map.as_ref().expect("a map");
        assert!(cells.iter().any(|&c| c > 0));
        // The same bytes give the same replies (what the device is held to), and the
        // 12.8 m GridSlam firmware's reference does not: the two are told apart.
        let again = host_slam_replies(&bytes).expect("the reference runs");
        assert_eq!(again.replies, host.replies);
        let small = host_replies(&bytes);
        assert_ne!(small, host.replies);
    }
}
