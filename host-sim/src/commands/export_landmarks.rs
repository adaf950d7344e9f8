//! `host-sim export-landmarks`: any landmark recording host-sim reads (MRCLAM, a plain
//! landmark log) written as a plain landmark log (docs/guide.md), e.g. to edit it or to
//! hand it to another tool.

use crate::inputs::readers::{self, DatasetSpec};
use anyhow::{Context, Result};
use std::io::Write as _;
use std::path::Path;

/// `host-sim export-landmarks --dataset <spec> --out <file>`: the recording of `robot`
/// (or the one `spec` names) written to `out`.
pub fn export_cli(dataset: &DatasetSpec, robot: u8, out: &Path, quiet: bool) -> Result<()> {
    let recording = readers::read(dataset, robot)?;
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
