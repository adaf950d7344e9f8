//! `host-sim hil --dataset carmen:<log>` (or `rosbag:<bag>`) without `--map`: the firmware's building-scale
//! grid SLAM in the loop (through [`crate::drivers::hil_slam`]). The device (a firmware
//! built with the feature `building-slam`) is put in grid mode at the origin, then every
//! front scan of the log is streamed (its odometry increment, then its chunks); every
//! reply is compared bit for bit with the host running the firmware's session on the
//! same bytes. Writes `hil.json`, `firmware.tum` (the device's estimate after each scan)
//! and `device-map/` (`map.bin`, PGM + YAML + PNG: the map image the device writes into
//! its flash at the end of the run, `SaveMap`, and sends back chunk by chunk, `ReadMap`;
//! bit-identical to the host's, as every reply is). The device's trajectory is scored with the relation error when a relations
//! file is found, and against `--reference` (ATE, with the number of poses matched).

use std::path::Path;
use std::time::Duration;

use anyhow::{Result, bail};
use microslam::geometry::Pose2;
use microslam::wire::{EstimatorKind, ToDevice, ToHost};
use serde::Serialize;

use crate::drivers::hil::{Device, Phase, compare, replies_across_restart, restart_cut};
use crate::drivers::hil_localizer::WireLidar;
use crate::drivers::hil_localizer::wire_lidar_messages;
use crate::drivers::hil_slam::{host_restart_replies, host_slam_replies};
use crate::inputs::readers::carmen::LaserMessage;
use crate::inputs::readers::lidar_recording::LidarRecording;
use crate::metrics::reference::ReferenceAte;
use crate::output::tum_text;

/// What `hil.json` holds for a building-scale SLAM run.
#[derive(Debug, Serialize)]
pub struct SlamHil {
    /// Replies equal to the host's bit for bit (the stack figure aside).
    pub replies_identical: usize,
    /// Replies expected (one per message).
    pub replies_expected: usize,
    /// Replies received.
    pub replies_received: usize,
    /// Scans streamed.
    pub scans: usize,
    /// Particles, beams, keyframes and loop edges of the firmware's SLAM.
    pub particles: usize,
    /// Beams a scan the filter scores at most.
    pub beams: usize,
    /// Keyframes the pose graph holds.
    pub graph_nodes: usize,
    /// The host reference's counters at the end (keyframes, loop closures tried and
    /// accepted), which the device's, bit-identical in every reply, shares.
    pub host_counters: HostCounters,
    /// The device's stack high-water mark from its final status, bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stack_peak_bytes: Option<u32>,
    /// Wall time, s.
    pub seconds: f64,
    /// Relation error of the device's trajectory (when a relations file was found).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relation_error: Option<crate::metrics::relations::RelationError>,
    /// ATE of the device's trajectory against `--reference`, with the poses matched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceReport>,
    /// The map written: whose copy it is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub map: Option<String>,
    /// With `--restart-after`: the restart and the localizer's part.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restart: Option<RestartReport>,
    /// The full comparison (pose and covariance differences, first differing message).
    pub comparison: crate::drivers::hil::Comparison,
}

/// The host reference's SLAM counters.
#[derive(Debug, Serialize)]
pub struct HostCounters {
    /// Keyframes made.
    pub keyframes: u32,
    /// Keyframes refused (graph or store full).
    pub keyframes_refused: u32,
    /// Loop closures tried.
    pub closure_attempts: u32,
    /// Loop edges added.
    pub closures: u32,
}

/// `--reference` and what it gave.
#[derive(Debug, Serialize)]
pub struct ReferenceReport {
    /// The reference file.
    pub file: String,
    /// Seconds added to its stamps.
    pub time_offset_s: f64,
    /// The ATE.
    pub ate: ReferenceAte,
}

/// Options of the building-scale SLAM HIL (from `host-sim hil` with a `carmen:` dataset
/// and no `--map`).
#[derive(Debug, Clone)]
pub struct SlamHilOptions<'a> {
    /// The device running the `building-slam` firmware: under QEMU or a board.
    pub device: Device<'a>,
    /// The lidar log (`carmen:<file>` or `rosbag:<bag>`).
    pub lidar: &'a LidarRecording,
    /// Stream only the first N scans.
    pub scans: Option<usize>,
    /// Output folder.
    pub out: &'a Path,
    /// Give up waiting for replies after this many seconds.
    pub timeout_s: u64,
    /// Reference trajectory for ATE (TUM or a corrected CARMEN log).
    pub reference: Option<&'a Path>,
    /// Seconds added to the reference's stamps.
    pub reference_offset: f64,
    /// Save the map and restart the device after this many scans: it then localizes in
    /// its saved map from its saved pose for the rest.
    pub restart_after: Option<usize>,
}

/// The device's trajectory: the estimate after each scan's last chunk (the reply of
/// index `scan_replies[k]` for scan `k`: the SLAM's, or after a restart the
/// localizer's), at the scan's stamp.
fn trajectory(
    replies: &[ToHost],
    scans: &[&LaserMessage],
    scan_replies: &[usize],
    lidar: &WireLidar,
) -> Vec<(f64, [f64; 3])> {
    scans
        .iter()
        .zip(scan_replies)
        .filter_map(|(laser, &i)| match replies.get(i) {
            Some(ToHost::Estimate(estimate) | ToHost::Localization { estimate, .. }) => {
                Some((laser.stamp, lidar.robot_pose(estimate.pose.map(f64::from))))
            }
            _ => None,
        })
        .collect()
}

/// The run's bytes in parts and the host's replies, with the reply that ends each scan:
/// one part, or with `--restart-after` two (the device restarts between them).
struct Plan {
    parts: Vec<(Vec<u8>, Vec<ToHost>)>,
    scan_replies: Vec<usize>,
    counters: microslam::slam::GraphCounters,
    restart: Option<RestartReport>,
}

/// What `--restart-after` did.
#[derive(Debug, Serialize)]
pub struct RestartReport {
    /// Scans mapped before the map was saved and the device restarted.
    pub after_scans: usize,
    /// Where the localizer started after the restart: the pose saved with the map, m, m,
    /// rad.
    pub resumed_from: [f32; 3],
    /// Scans the localizer tracked after the restart.
    pub localized_scans: usize,
    /// Poses the firmware wrote into its flash while localizing (every half metre or
    /// half radian).
    pub poses_kept: usize,
}

fn plan(
    messages: &[ToDevice],
    last_chunks: &[usize],
    restart_after: Option<usize>,
) -> Result<Plan> {
    let Some(n) = restart_after else {
        let host = host_slam_replies(messages, true)?;
        return Ok(Plan {
            parts: vec![(host.bytes, host.replies)],
            scan_replies: last_chunks.to_vec(),
            counters: host.counters,
            restart: None,
        });
    };
    let host = host_restart_replies(messages, last_chunks, n)?;
    let (cut, _) = restart_cut(messages, last_chunks, n)?;
    let scan_replies = replies_across_restart(last_chunks, cut, host.mapping.replies.len());
    let p = host.resumed_from;
    Ok(Plan {
        restart: Some(RestartReport {
            after_scans: n,
            resumed_from: [p.x, p.y, p.theta],
            localized_scans: last_chunks.len() - n,
            poses_kept: host.poses_kept,
        }),
        counters: host.mapping.counters,
        parts: vec![
            (host.mapping.bytes, host.mapping.replies),
            (host.localizing_bytes, host.localizing_replies),
        ],
        scan_replies,
    })
}

/// `host-sim hil --dataset carmen:<log>` or `rosbag:<bag>` (no `--map`).
pub fn run_cli(args: &SlamHilOptions<'_>, quiet: bool) -> Result<()> {
    let path = &args.lidar.path;
    let scans = args.lidar.first(args.scans)?;
    let wire = WireLidar::of(args.lidar);
    let (messages, last_chunks) =
        wire_lidar_messages(&scans, &wire, Pose2::IDENTITY, EstimatorKind::Grid);
    let plan = plan(&messages, &last_chunks, args.restart_after)?;
    let host_replies: Vec<ToHost> = plan.parts.iter().flat_map(|(_, r)| r.clone()).collect();
    if !quiet {
        println!(
            "{}: {} scans → {} frames ({} bytes, the map read back included), building-scale \
             grid SLAM{}",
            path.display(),
            scans.len(),
            host_replies.len(),
            plan.parts.iter().map(|(b, _)| b.len()).sum::<usize>(),
            plan.restart.as_ref().map_or_else(String::new, |r| format!(
                "; the map saved and the device restarted after {} scans, the localizer on \
                 it from the saved pose for the other {}",
                r.after_scans, r.localized_scans
            )),
        );
    }
    let run = args
        .device
        .run_phases(Phase::of(&plan.parts), Duration::from_secs(args.timeout_s))?;
    let comparison = compare(host_replies.len(), &run, &host_replies);
    let traj = trajectory(&run.replies, &scans, &plan.scan_replies, &wire);
    let relation_error = match crate::metrics::relations::find_relations(path, None) {
        Ok(r) => {
            let rels = crate::metrics::relations::read(&r)?;
            Some(crate::metrics::relations::evaluate(&traj, &rels, 1e-3)).filter(|e| e.used > 0)
        }
        Err(note) => {
            eprintln!("note: {note}");
            None
        }
    };
    let poses: Vec<(f64, Pose2<f64>)> = traj
        .iter()
        .map(|&(t, [x, y, th])| (t, Pose2::new(x, y, th)))
        .collect();
    let reference = match args.reference {
        Some(file) => Some(ReferenceReport {
            file: file.display().to_string(),
            time_offset_s: args.reference_offset,
            ate: crate::metrics::reference::trajectory_ate(&poses, file, args.reference_offset)?,
        }),
        None => None,
    };
    crate::output::create_folder(args.out)?;
    let map = match crate::drivers::hil_slam::map_from_replies(&run.replies)? {
        Some(image) => {
            let dir = args.out.join("device-map");
            crate::output::create_folder(&dir)?;
            let est: Vec<(f64, Pose2<f32>)> = traj
                .iter()
                .map(|&(t, [x, y, th])| (t, Pose2::new(x as f32, y as f32, th as f32)))
                .collect();
            crate::output::grid_map::write_map_image(
                &dir,
                &image,
                &microslam::profile::SLAM_CONFIG.grid.log_odds,
                &est,
            )?;
            Some(format!(
                "{}: the map image the device wrote into its flash at the end of the run and \
                 sent back ({} bytes; PGM + YAML beside it)",
                dir.join("map.bin").display(),
                image.len()
            ))
        }
        None => None,
    };
    let c = plan.counters;
    let report = SlamHil {
        replies_identical: comparison.identical,
        replies_expected: comparison.expected,
        replies_received: comparison.received,
        scans: scans.len(),
        particles: microslam::profile::GRID_PARTICLES,
        beams: microslam::profile::GRID_BEAMS,
        graph_nodes: microslam::profile::SLAM_NODES,
        host_counters: HostCounters {
            keyframes: c.keyframes,
            keyframes_refused: c.keyframes_refused,
            closure_attempts: c.attempts,
            closures: c.closures,
        },
        stack_peak_bytes: comparison.stack_peak_bytes,
        seconds: comparison.seconds,
        relation_error,
        reference,
        map,
        restart: plan.restart,
        comparison,
    };
    let json = args.out.join("hil.json");
    crate::output::write_report(&json, &report)?;
    std::fs::write(
        args.out.join("firmware.tum"),
        tum_text(poses.iter().copied()),
    )?;
    if !quiet {
        println!(
            "{} of {} replies identical to the host bit for bit; {} keyframes, {} of {} loop \
             closures accepted; relation error {}; ATE vs reference {}; {:.1} s; report in {}",
            report.replies_identical,
            report.replies_expected,
            c.keyframes,
            c.closures,
            c.attempts,
            report.relation_error.as_ref().map_or_else(
                || "–".to_string(),
                |r| format!(
                    "{:.4} ± {:.4} m over {}",
                    r.trans_mean_m, r.trans_std_m, r.used
                )
            ),
            report.reference.as_ref().map_or_else(
                || "–".to_string(),
                |r| format!(
                    "{:.4} m SE(2) over {} matched poses of {} in span",
                    r.ate.ate_m.se2.unwrap_or(f64::NAN),
                    r.ate.matched,
                    r.ate.in_span
                )
            ),
            report.seconds,
            json.display()
        );
        if let Some(map) = &report.map {
            println!("map: {map}");
        }
    }
    crate::drivers::hil::check_protocol(&report.comparison)?;
    crate::drivers::hil::check_refusals(&run.replies)?;
    if report.replies_received != report.replies_expected
        || report.replies_identical != report.replies_expected
    {
        let first = report.comparison.first_difference.map_or_else(
            || format!("{} received", report.replies_received),
            |i| {
                format!(
                    "the first difference is the reply to message {i} of {}: is the firmware \
                     built with --features building-slam?",
                    host_replies.len()
                )
            },
        );
        bail!(
            "the device's replies differ from the host's ({} of {} identical): {first}",
            report.replies_identical,
            report.replies_expected,
        );
    }
    Ok(())
}
