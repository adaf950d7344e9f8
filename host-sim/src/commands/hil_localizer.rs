//! `host-sim hil --dataset carmen:<log> --map <map.yaml>` (or `rosbag:<bag>`): the firmware's localizer mode
//! in the loop (through [`crate::drivers::hil_localizer`]). The device (a firmware built
//! with `MICROSLAM_MAP=<map.yaml>`) is put in localizer mode at the log's first pose (the
//! map's frame: a grid-SLAM map of the same log starts at its first scan), then every
//! front scan is streamed; every reply is compared bit for bit with the host running the
//! firmware's session on the same map image, and the device's trajectory is scored with
//! the relation error when a relations file is found. Writes `hil.json` and
//! `firmware.tum`.
//!
//! `host-sim export-map --map <map.yaml> --out <map.bin>` writes the map image the
//! firmware's build script embeds.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::grid::MapImage;
use microslam::wire::{EstimatorKind, ToHost};
use serde::Serialize;

use crate::inputs::readers::lidar_recording::LidarRecording;

use crate::drivers::hil::{
    Device, Expected, Phase, QemuMachine, compare, encode_all, replies_across_restart, restart_cut,
    run_qemu_with_lidar,
};
use crate::drivers::hil_lidar::{Ld06Stream, LineFaults, ld06_packets};
use crate::drivers::hil_localizer::{
    ScanPath, WireLidar, host_localizer_replies, host_localizer_restart, host_localizer_session,
    lidar_messages_by, map_image_of, map_image_with_levels,
};
use crate::inputs::readers::carmen::LaserMessage;
use crate::output::tum_text;

/// `host-sim export-map`.
pub fn export_cli(map: &Path, out: &Path, levels: u8, quiet: bool) -> Result<()> {
    let image = map_image_with_levels(map, levels)?;
    let parsed = MapImage::parse(&image)?;
    std::fs::write(out, &image).with_context(|| format!("writing {}", out.display()))?;
    if !quiet {
        let g = parsed.geometry();
        println!(
            "{}: {} x {} cells of {} m, {} bytes, CRC-32 {:#010x}",
            out.display(),
            g.width,
            g.height,
            g.resolution,
            image.len(),
            parsed.checksum()
        );
    }
    Ok(())
}

/// What `hil.json` holds for a localizer run.
#[derive(Debug, Serialize)]
pub struct LocalizerHil {
    /// Replies equal to the host's bit for bit (the stack figure aside).
    pub replies_identical: usize,
    /// Replies expected (one per message).
    pub replies_expected: usize,
    /// Replies received.
    pub replies_received: usize,
    /// Scans streamed.
    pub scans: usize,
    /// Particles of the firmware's localizer.
    pub particles: usize,
    /// The device's stack high-water mark from its final status, bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stack_peak_bytes: Option<u32>,
    /// Wall time, s.
    pub seconds: f64,
    /// Relation error of the device's trajectory (when a relations file was found).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relation_error: Option<crate::metrics::relations::RelationError>,
    /// With `--restart-after`: the restart, and the same log's relation error without it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub restart: Option<LocalizerRestart>,
    /// The localizer's state after the last scan (lost events, relocalizations).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_localizer: Option<microslam::wire::LocalizerReport>,
    /// With `--own-lidar`: what was sent on the lidar's line and what the device's reader
    /// counted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub own_lidar: Option<OwnLidarReport>,
    /// The full comparison (pose and covariance differences).
    pub comparison: crate::drivers::hil::Comparison,
}

/// The lidar's line of a `--own-lidar` run.
#[derive(Debug, Serialize)]
pub struct OwnLidarReport {
    /// The line faults asked for.
    pub faults: LineFaults,
    /// What was sent.
    pub sent: Ld06Stream,
    /// The device reader's counters in its last status (after the last revolution).
    pub device: Option<microslam::wire::LidarCounters>,
}

/// A localizer run restarted part way (`--restart-after`).
#[derive(Debug, Serialize)]
pub struct LocalizerRestart {
    /// Scans before the restart.
    pub after_scans: usize,
    /// The pose the firmware kept before the reset and started from after it.
    pub resumed_from: [f32; 3],
    /// The relation error of the same log without the restart (the host's session, the
    /// same replies the device gives), for comparison.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub relation_error_uninterrupted: Option<crate::metrics::relations::RelationError>,
}

/// The device's trajectory: the estimate after each scan's last chunk (the reply of index
/// `scan_replies[k]` for scan `k`), at the scan's stamp.
fn trajectory(
    replies: &[ToHost],
    scans: &[&LaserMessage],
    scan_replies: &[usize],
    lidar: &WireLidar,
) -> Vec<(f64, [f64; 3])> {
    scans
        .iter()
        .zip(scan_replies)
        .filter_map(|(laser, &i)| {
            let estimate = replies.get(i)?.estimate()?;
            Some((laser.stamp, lidar.robot_pose(estimate.pose.map(f64::from))))
        })
        .collect()
}

/// Options of the localizer HIL (from `host-sim hil` with a `carmen:` dataset).
#[derive(Debug, Clone)]
pub struct LocalizerHilOptions<'a> {
    /// The device running the localizer firmware: under QEMU or a board.
    pub device: Device<'a>,
    /// The map it was built with (`MICROSLAM_MAP`).
    pub map: Option<&'a Path>,
    /// The lidar log (`carmen:<file>` or `rosbag:<bag>`).
    pub lidar: &'a LidarRecording,
    /// Stream only the first N scans.
    pub scans: Option<usize>,
    /// Output folder.
    pub out: &'a Path,
    /// Give up waiting for replies after this many seconds.
    pub timeout_s: u64,
    /// Record the device's estimates (with the scans) into this MCAP file.
    pub mcap: Option<&'a Path>,
    /// Restart the device after this many scans (`Restart`): it resumes from the pose it
    /// kept in flash.
    pub restart_after: Option<usize>,
    /// Send the scans to the device's own lidar (its second UART) with these line faults.
    pub own_lidar: Option<LineFaults>,
}

/// `host-sim hil --dataset carmen:<log> --map <map.yaml>`.
pub fn run_cli(args: &LocalizerHilOptions<'_>, quiet: bool) -> Result<()> {
    let Some(map_yaml) = args.map else {
        bail!("a lidar dataset runs the device's localizer: give --map <map.yaml>");
    };
    let path = &args.lidar.path;
    let scans = args.lidar.first(args.scans)?;
    let wire = WireLidar::of(args.lidar);
    let image = map_image_of(map_yaml)?;
    let own_lidar = match args.own_lidar {
        Some(faults) => Some(own_lidar_line(args, &scans, &faults)?),
        None => None,
    };
    let scan_path = match &own_lidar {
        Some(_) => ScanPath::OwnLidar,
        None => ScanPath::Link,
    };
    let (messages, last_chunks) = lidar_messages_by(
        &scans,
        &wire,
        Pose2::IDENTITY,
        EstimatorKind::Localizer,
        scan_path,
    );
    let (parts, scan_replies, resumed) = match args.restart_after {
        None => {
            let bytes = encode_all(&messages);
            let lidar = own_lidar.as_ref().map(|s| s.bytes.as_slice());
            let host = host_localizer_session(&bytes, &image, None, lidar)?;
            (vec![(bytes, host)], last_chunks.clone(), None)
        }
        Some(n) => {
            let (parts, resumed) = host_localizer_restart(&messages, &last_chunks, n, &image)?;
            let (cut, _) = restart_cut(&messages, &last_chunks, n)?;
            let index = replies_across_restart(&last_chunks, cut, parts[0].1.len());
            (parts, index, Some((n, resumed)))
        }
    };
    let host: Vec<ToHost> = parts.iter().flat_map(|(_, r)| r.iter().copied()).collect();
    if !quiet {
        println!(
            "{}: {} scans → {} frames ({} bytes), map image {} bytes{}",
            path.display(),
            scans.len(),
            host.len(),
            parts.iter().map(|(b, _)| b.len()).sum::<usize>(),
            image.len(),
            resumed.map_or_else(String::new, |(n, p)| format!(
                "; restarted after {n} scans, the localizer resuming from the pose it kept \
                 ({:.3}, {:.3}, {:.3})",
                p.x, p.y, p.theta
            ))
        );
    }
    let timeout = Duration::from_secs(args.timeout_s);
    let run = match (&own_lidar, args.device, parts.as_slice()) {
        (Some(stream), Device::Qemu(elf), [(bytes, host)]) => run_qemu_with_lidar(
            QemuMachine::Mps2An386,
            elf,
            bytes.clone(),
            stream.bytes.clone(),
            Expected::host(host),
            timeout,
        )?,
        (Some(_), _, _) => bail!("--own-lidar runs one part under QEMU (no restart, no board)"),
        (None, device, _) => device.run_phases(Phase::of(&parts), timeout)?,
    };
    let comparison = compare(host.len(), &run, &host);
    // With a restart: the same log without it, on the host, for comparison.
    let uninterrupted = match resumed {
        Some(_) => Some(trajectory(
            &host_localizer_replies(&encode_all(&messages), &image)?,
            &scans,
            &last_chunks,
            &wire,
        )),
        None => None,
    };
    let relation_error = match crate::metrics::relations::find_relations(path, None) {
        Ok(r) => {
            let rels = crate::metrics::relations::read(&r)?;
            let score = |traj: &[(f64, [f64; 3])]| {
                Some(crate::metrics::relations::evaluate(traj, &rels, 1e-3)).filter(|e| e.used > 0)
            };
            Some((
                score(&trajectory(&run.replies, &scans, &scan_replies, &wire)),
                uninterrupted.as_deref().and_then(score),
            ))
        }
        Err(note) => {
            eprintln!("note: {note}");
            None
        }
    };
    let (relation_error, relation_error_uninterrupted) = relation_error.unwrap_or((None, None));
    let report = LocalizerHil {
        replies_identical: comparison.identical,
        replies_expected: comparison.expected,
        replies_received: comparison.received,
        scans: scans.len(),
        particles: microslam::profile::LOCALIZER_PARTICLES,
        stack_peak_bytes: comparison.stack_peak_bytes,
        seconds: comparison.seconds,
        relation_error,
        restart: resumed.map(|(n, p)| LocalizerRestart {
            after_scans: n,
            resumed_from: [p.x, p.y, p.theta],
            relation_error_uninterrupted,
        }),
        final_localizer: run.replies.iter().rev().find_map(|r| match r {
            ToHost::Localization { localizer, .. } => Some(*localizer),
            _ => None,
        }),
        own_lidar: own_lidar
            .zip(args.own_lidar)
            .map(|(sent, faults)| OwnLidarReport {
                faults,
                sent,
                device: run.replies.iter().rev().find_map(|r| match r {
                    ToHost::Status { lidar, .. } => Some(*lidar),
                    _ => None,
                }),
            }),
        comparison,
    };
    crate::output::create_folder(args.out)?;
    let json = args.out.join("hil.json");
    crate::output::write_report(&json, &report)?;
    let poses = trajectory(&run.replies, &scans, &scan_replies, &wire)
        .into_iter()
        .map(|(t, [x, y, th])| (t, Pose2::new(x, y, th)));
    std::fs::write(args.out.join("firmware.tum"), tum_text(poses))?;
    if let Some(mut file) = super::open_mcap(args.mcap)? {
        // The estimate after each scan's last chunk, with its covariance and the scan.
        let (estimates, ranges): (Vec<_>, Vec<&[f32]>) = scans
            .iter()
            .zip(&scan_replies)
            .filter_map(|(laser, &i)| {
                let e = run.replies.get(i)?.estimate()?;
                let [x, y, th] = wire.robot_pose(e.pose.map(f64::from));
                let pose = Pose2::new(x, y, th);
                let cov = Some(e.covariance.map(f64::from));
                Some(((laser.stamp, pose, cov), laser.ranges.as_slice()))
            })
            .unzip();
        let lidar = args.lidar.lidar;
        crate::output::mcap::scene::record_estimates(
            &mut file,
            "",
            &estimates,
            &[],
            Some((&ranges, &lidar)),
            0.0,
        )?;
        super::close_mcap(Some(file), quiet)?;
    }
    if !quiet {
        println!(
            "{} of {} replies identical to the host bit for bit; relation error {}; {:.1} s; report in {}",
            report.replies_identical,
            report.replies_expected,
            report.relation_error.as_ref().map_or_else(
                || "–".to_string(),
                |r| format!(
                    "{:.4} ± {:.4} m over {}",
                    r.trans_mean_m, r.trans_std_m, r.used
                )
            ),
            report.seconds,
            json.display()
        );
    }
    if let Some(lidar) = &report.own_lidar {
        let counted = lidar.device.unwrap_or_default();
        if !quiet {
            println!(
                "lidar line: {} packets whole, {} corrupted, {} lost, {} bytes of noise; the \
                 device's reader: {} packets, {} bad packets, {} bytes skipped",
                lidar.sent.packets,
                lidar.sent.corrupted,
                lidar.sent.dropped,
                lidar.sent.noise_bytes,
                counted.packets,
                counted.bad_packets,
                counted.skipped_bytes,
            );
        }
    }
    crate::drivers::hil::check_protocol(&report.comparison)?;
    crate::drivers::hil::check_refusals(&run.replies)?;
    if report.replies_received != report.replies_expected
        || report.replies_identical != report.replies_expected
    {
        bail!(
            "the device's replies differ from the host's ({} of {} identical, {} received)",
            report.replies_identical,
            report.replies_expected,
            report.replies_received
        );
    }
    Ok(())
}

/// The lidar line of `--own-lidar`: the scans as LD06 packets with `faults` (checked by
/// `commands::hil`: a firmware under QEMU, no restart, fractions within 0–1).
fn own_lidar_line(
    args: &LocalizerHilOptions<'_>,
    scans: &[&LaserMessage],
    faults: &LineFaults,
) -> Result<Ld06Stream> {
    let path = &args.lidar.path;
    let (revolutions, _) = ld06_packets(scans, &args.lidar.lidar)
        .with_context(|| format!("{}: as LD06 packets", path.display()))?;
    Ld06Stream::new(&revolutions, faults)
        .with_context(|| format!("{}: the lidar's line", path.display()))
}
