//! `host-sim export-rosbag`: a CARMEN log written as a ROS 2 bag (MCAP), the fixture for
//! `--dataset rosbag:<file.mcap>` from a dataset at hand.

use crate::domain::grid::carmen_lidar;
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::carmen::{beam_count, front_scans, read_log, resolve_log};
use crate::inputs::readers::rosbag::BagOptions;
use anyhow::{Result, bail};
use std::path::Path;

/// `host-sim export-rosbag --dataset carmen:<log> --out <file.mcap>`: the log's front
/// scans and their odometry on the topics of `topics`.
pub fn export_cli(
    dataset: &DatasetSpec,
    out: &Path,
    topics: &BagOptions,
    quiet: bool,
) -> Result<()> {
    let DatasetSpec::Carmen(file) = dataset else {
        bail!("export-rosbag reads a CARMEN log (carmen:<file>)");
    };
    let path = resolve_log(file)?;
    let log = read_log(&path)?;
    let mut lidar = carmen_lidar(beam_count(&log));
    if let Some([x, y, yaw]) = topics.lidar_mount {
        lidar.mount = microslam::geometry::Pose2::new(x as f32, y as f32, yaw as f32);
    }
    let scans = front_scans(&log);
    let n = crate::output::rosbag::export(out, &scans, &lidar, topics)?;
    if !quiet {
        println!(
            "{}: {} scans → {} ({n} messages on {}, {}, {})",
            path.display(),
            scans.len(),
            out.display(),
            topics.scan_topic,
            topics.odom_topic,
            topics.tf_static_topic
        );
    }
    Ok(())
}
