//! `host-sim hil --dataset carmen:<log> --map <map.yaml>`: the firmware's localizer mode
//! in the loop. The device (a firmware built with `MICROSLAM_MAP=<map.yaml>`) is put in
//! localizer mode at the log's first pose (the map's frame: a grid-SLAM map of the same
//! log starts at its first scan), then every front scan is streamed as its odometry
//! increment and its scan chunks; every reply is compared bit for bit with the host
//! running the firmware's [`Session`] on the same map image, and the device's trajectory
//! is scored with the relation error when a relations file is found.
//!
//! `host-sim export-map --map <map.yaml> --out <map.bin>` writes the same map image the
//! firmware's build script embeds.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use microslam::ekf::{EkfConfig, EkfSlam, state_dim};
use microslam::geometry::Pose2;
use microslam::grid::MapImage;
use microslam::grid::map_image::{DEFAULT_LAYER_LEVELS, encode_map_image_with_layers};
use microslam::grid::ros_map::RosMap;
use microslam::pf::{GridLocalizer, GridPfConfig, RelocalizationConfig};
use microslam::wire::{
    Command as WireCommand, EstimatorKind, LocalizerEstimator, Odometry, SCAN_CHUNK_BEAMS,
    ScanChunk, Session, ToDevice, ToHost,
};
use serde::Serialize;

use crate::cli::HilArgs;
use crate::hil::{FIRMWARE_GRID_SETUP, FIRMWARE_LANDMARKS, compare, encode_all, run_qemu};
use crate::readers::carmen::LaserMessage;

/// Particles of the firmware's localizer (`firmware_example::config::LOCALIZER_PARTICLES`).
pub const FIRMWARE_LOCALIZER_PARTICLES: usize = 64;
/// Beams of the firmware's localizer (`firmware_example::config::GRID_BEAMS`).
pub const FIRMWARE_LOCALIZER_BEAMS: usize = 90;
/// Settings of the firmware's localizer (`firmware_example::config::LOCALIZER_CONFIG`).
pub const FIRMWARE_LOCALIZER_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// The firmware's localizer type.
pub type FirmwareLocalizer<'m> =
    GridLocalizer<'m, FIRMWARE_LOCALIZER_PARTICLES, FIRMWARE_LOCALIZER_BEAMS>;

/// The map image of `yaml` as the firmware's build script makes it (with
/// [`DEFAULT_LAYER_LEVELS`] levels of layers).
pub fn map_image_of(yaml: &Path) -> Result<Vec<u8>> {
    map_image_with_levels(yaml, DEFAULT_LAYER_LEVELS)
}

/// The map image of `yaml` with `levels` levels of max-pooled layers (0: none).
pub fn map_image_with_levels(yaml: &Path, levels: u8) -> Result<Vec<u8>> {
    let config = FIRMWARE_LOCALIZER_CONFIG;
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

/// Wire range of one beam: millimetres, 0 for no return (not finite, or beyond what a
/// `u16` holds).
fn range_mm(r: f32) -> u16 {
    if r.is_finite() && r > 0.0 && r * 1000.0 < f32::from(u16::MAX) {
        (r * 1000.0).round() as u16
    } else {
        0
    }
}

/// The messages for localizer mode over `scans`: select the localizer, reset at
/// `start`, then per scan its odometry increment (from the previous finite odometry
/// pose) and its chunks, then a status request. Also the index of each scan's last
/// chunk in the messages.
pub fn localizer_messages(
    scans: &[&LaserMessage],
    start: Pose2<f32>,
) -> (Vec<ToDevice>, Vec<usize>) {
    let mut out = vec![
        ToDevice::Command {
            seq: 0,
            command: WireCommand::SelectEstimator(EstimatorKind::Localizer),
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
    let map = MapImage::parse(image)?;
    let mut ekf = Box::new(EkfSlam::<f32, { state_dim(FIRMWARE_LANDMARKS) }>::new(
        EkfConfig::MICROCONTROLLER,
    ));
    let mut localizer =
        FirmwareLocalizer::new(map.view(), FIRMWARE_LOCALIZER_CONFIG, Pose2::IDENTITY)
            .map_err(|e| anyhow::anyhow!("localizer: {e}"))?;
    if let Some(layers) = map.layers() {
        localizer = localizer
            .with_layers(layers?, RelocalizationConfig::DEFAULT)
            .map_err(|e| anyhow::anyhow!("localizer layers: {e}"))?;
    }
    let mut localizer = Box::new(localizer);
    let mut session = Session::<_, FIRMWARE_LANDMARKS>::new(&mut ekf, EkfConfig::MICROCONTROLLER)
        .with_localizer(
            Ok(&mut *localizer as &mut dyn LocalizerEstimator),
            FIRMWARE_GRID_SETUP,
        );
    Ok(bytes.iter().filter_map(|&b| session.receive(b)).collect())
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
    pub stack_peak_bytes: Option<u32>,
    /// Wall time, s.
    pub seconds: f64,
    /// Relation error of the device's trajectory (when a relations file was found).
    pub relation_error: Option<crate::metrics::relations::RelationError>,
    /// The localizer's state after the last scan (lost events, relocalizations).
    pub final_localizer: Option<microslam::wire::LocalizerReport>,
    /// The full comparison (pose and covariance differences).
    pub comparison: crate::hil::Comparison,
}

/// The device's trajectory: the estimate after each scan's last chunk, at the scan's
/// stamp.
fn trajectory(
    replies: &[ToHost],
    scans: &[&LaserMessage],
    last_chunks: &[usize],
) -> Vec<(f64, [f64; 3])> {
    scans
        .iter()
        .zip(last_chunks)
        .filter_map(|(laser, &i)| match replies.get(i) {
            Some(ToHost::Localization { estimate, .. }) => {
                Some((laser.stamp, estimate.pose.map(f64::from)))
            }
            _ => None,
        })
        .collect()
}

/// `host-sim hil --dataset carmen:<log> --map <map.yaml>`.
pub fn run_cli(args: &HilArgs, file: &str, quiet: bool) -> Result<()> {
    let Some(map_yaml) = &args.map else {
        bail!("a lidar dataset runs the device's localizer: give --map <map.yaml>");
    };
    let Some(elf) = &args.qemu else {
        bail!("the localizer HIL runs under QEMU: give --qemu <elf>");
    };
    let path = crate::grid_replay::resolve_log(file)?;
    let log = crate::grid_replay::read_log(&path)?;
    let mut scans = crate::grid_replay::front_scans(&log);
    if let Some(n) = args.scans {
        scans.truncate(n);
    }
    let image = map_image_of(map_yaml)?;
    let (messages, last_chunks) = localizer_messages(&scans, Pose2::IDENTITY);
    let bytes = encode_all(&messages);
    let host = host_localizer_replies(&bytes, &image)?;
    if !quiet {
        println!(
            "{}: {} scans → {} frames ({} bytes), map image {} bytes",
            path.display(),
            scans.len(),
            messages.len(),
            bytes.len(),
            image.len()
        );
    }
    let run = run_qemu(elf, bytes, host.len(), Duration::from_secs(args.timeout_s))?;
    let comparison = compare(messages.len(), &run, &host);
    let relation_error = crate::grid_replay::find_relations(&path, None)
        .map(|r| -> Result<_> {
            let rels = crate::metrics::relations::read(&r)?;
            Ok(crate::metrics::relations::evaluate(
                &trajectory(&run.replies, &scans, &last_chunks),
                &rels,
                1e-3,
            ))
        })
        .transpose()?;
    let report = LocalizerHil {
        replies_identical: comparison.identical,
        replies_expected: comparison.expected,
        replies_received: comparison.received,
        scans: scans.len(),
        particles: FIRMWARE_LOCALIZER_PARTICLES,
        stack_peak_bytes: comparison.stack_peak_bytes,
        seconds: comparison.seconds,
        relation_error,
        final_localizer: run.replies.iter().rev().find_map(|r| match r {
            ToHost::Localization { localizer, .. } => Some(*localizer),
            _ => None,
        }),
        comparison,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let json = args.out.join("hil.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    let mut tum = String::new();
    for (t, [x, y, th]) in trajectory(&run.replies, &scans, &last_chunks) {
        let (s, c) = (th / 2.0).sin_cos();
        tum.push_str(&format!("{t:.6} {x} {y} 0 0 0 {s} {c}\n"));
    }
    std::fs::write(args.out.join("firmware.tum"), tum)?;
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
