//! `host-sim export-ld06`: a CARMEN log's front scans as the byte stream an LDROBOT LD06
//! lidar sends on its UART (`microslam::sensors::ld06`), one revolution a scan: what a
//! board's lidar input (a USB-serial adapter wired to its lidar UART, or a second UART
//! under QEMU) can be fed with to replay a recording through the board's own lidar path.

use crate::domain::grid::carmen_lidar;
use crate::drivers::hil_lidar::ld06_packets;
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::carmen::{beam_count, front_scans, read_log, resolve_log};
use anyhow::{Context, Result, bail};
use std::path::Path;

/// What [`export`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ld06Export {
    /// Scans (revolutions) written.
    pub scans: usize,
    /// Packets written (47 bytes each).
    pub packets: usize,
    /// The rotation speed written in every packet, degrees a second (from the log's median
    /// interval between scans).
    pub speed_deg_s: u16,
}

/// Writes the front scans of the CARMEN log `file` (the first `limit` when given) to
/// `out` as LD06 packets, the angles clockwise as the lidar's.
pub fn export(file: &str, out: &Path, limit: Option<usize>) -> Result<Ld06Export> {
    let path = resolve_log(file)?;
    let log = read_log(&path)?;
    let lidar = carmen_lidar(beam_count(&log));
    let mut scans = front_scans(&log);
    if let Some(n) = limit {
        scans.truncate(n);
    }
    if scans.is_empty() {
        bail!("{}: no front laser scan to write", path.display());
    }
    // One revolution a scan: the rotation speed from the median interval between scans.
    let (revolutions, speed_deg_s) =
        ld06_packets(&scans, &lidar).with_context(|| format!("{}", path.display()))?;
    let mut bytes = Vec::with_capacity(scans.len() * 30 * 47);
    let mut packets = 0;
    for p in revolutions.iter().flatten() {
        bytes.extend_from_slice(&p.encode());
        packets += 1;
    }
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        crate::output::create_folder(dir)?;
    }
    std::fs::write(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    Ok(Ld06Export {
        scans: scans.len(),
        packets,
        speed_deg_s,
    })
}

/// `host-sim export-ld06 --dataset carmen:<log> --out <file>`.
pub fn export_cli(
    dataset: &DatasetSpec,
    out: &Path,
    limit: Option<usize>,
    quiet: bool,
) -> Result<()> {
    let DatasetSpec::Carmen(file) = dataset else {
        bail!("export-ld06 reads a CARMEN log (carmen:<file>)");
    };
    let e = export(file, out, limit)?;
    if !quiet {
        println!(
            "{file}: {} scans → {} LD06 packets ({} bytes, {} °/s) in {}",
            e.scans,
            e.packets,
            e.packets * microslam::sensors::ld06::PACKET_BYTES,
            e.speed_deg_s,
            out.display()
        );
    }
    Ok(())
}
