//! `host-sim export-landmarks`: any landmark recording host-sim reads (MRCLAM, a plain
//! landmark log, a ROS 2 bag of detections) written as a plain landmark log
//! (docs/guide.md), e.g. to edit it or to hand it to another tool.

use crate::inputs::readers::detections_bag;
use crate::inputs::readers::rosbag::BagOptions;
use crate::inputs::readers::{self, DatasetSpec};
use anyhow::{Context, Result};
use std::io::Write as _;
use std::path::Path;

/// `host-sim export-landmarks --dataset <spec> --out <file>`: the recording of `robot`
/// (or the one `spec` names) written to `out`. A bag's detections are written on the
/// robot's frame (the camera mounted through the bag's `/tf_static`): the log replays
/// with no sensor mount in its settings.
pub fn export_cli(
    dataset: &DatasetSpec,
    robot: u8,
    bag: &BagOptions,
    out: &Path,
    quiet: bool,
) -> Result<()> {
    crate::commands::replay::bag_options_apply(dataset, bag)?;
    let recording = match dataset {
        DatasetSpec::Rosbag(file) => {
            let path = crate::inputs::readers::carmen::resolve_log(file)?;
            detections_bag::recording(&path, bag, [0.0; 3])?
        }
        _ => readers::read(dataset, robot)?,
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let file =
        std::fs::File::create(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut writer = std::io::BufWriter::new(file);
    let left_out = crate::output::landmark_log::write(&recording, &mut writer)
        .and_then(|n| writer.flush().map(|()| n))
        .with_context(|| format!("cannot write {}", out.display()))?;
    if !quiet {
        println!(
            "{}: {} events, {} true poses, {} landmarks → {}{}",
            recording.name,
            recording.events.len() - left_out,
            recording.ground_truth.len(),
            recording.landmarks.len(),
            out.display(),
            if left_out > 0 {
                format!(" ({left_out} events the format has no record for left out)")
            } else {
                String::new()
            }
        );
    }
    Ok(())
}
