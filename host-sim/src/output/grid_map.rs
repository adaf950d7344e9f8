//! Occupancy maps as files: PGM + YAML in the ROS `map_server` convention, a PNG with the
//! trajectory, TUM trajectories — and reading a saved map back for localization.

use crate::drivers::grid::GridRun;
use anyhow::{Context, Result};
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use microslam::pf::GridPfConfig;
use std::path::Path;

/// Occupancy probability of a cell value.
fn probability(value: i8, log_odds: &LogOdds) -> f64 {
    let l = f64::from(value) * f64::from(log_odds.nats_per_unit());
    1.0 / (1.0 + (-l).exp())
}

/// The bounding box `(x0, y0, x1, y1)` (exclusive ends) of the known cells plus a margin.
fn known_box(cells: &[i8], g: &GridGeometry, margin: usize) -> (usize, usize, usize, usize) {
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, c) in cells.iter().enumerate() {
        if *c != 0 {
            let (x, y) = (i % g.width, i / g.width);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
    }
    if x0 == usize::MAX {
        return (0, 0, g.width, g.height);
    }
    (
        x0.saturating_sub(margin),
        y0.saturating_sub(margin),
        (x1 + margin).min(g.width),
        (y1 + margin).min(g.height),
    )
}

/// Writes `map.pgm` (grey = 255·(1 − p), north up), `map.yaml` (ROS `map_server`; the
/// thresholds are the grid's occupied/free log-odds as probabilities) and `map.png` (the
/// same with the trajectory in red), cropped to the known area.
pub fn write_map(
    out: &Path,
    cells: &[i8],
    g: &GridGeometry,
    log_odds: &LogOdds,
    traj: &[(f64, Pose2<f32>)],
) -> Result<()> {
    let (x0, y0, x1, y1) = known_box(cells, g, 10);
    let (w, h) = (x1 - x0, y1 - y0);
    let mut grey = Vec::with_capacity(w * h);
    for y in (y0..y1).rev() {
        for x in x0..x1 {
            let v = cells.get(y * g.width + x).copied().unwrap_or(0);
            grey.push((255.0 * (1.0 - probability(v, log_odds))).round() as u8);
        }
    }
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm.extend_from_slice(&grey);
    std::fs::write(out.join("map.pgm"), pgm)?;
    let origin_x = f64::from(g.origin_x) + x0 as f64 * f64::from(g.resolution);
    let origin_y = f64::from(g.origin_y) + y0 as f64 * f64::from(g.resolution);
    let yaml = format!(
        "image: map.pgm\nresolution: {}\norigin: [{origin_x:.6}, {origin_y:.6}, 0.0]\nnegate: 0\noccupied_thresh: {:.6}\nfree_thresh: {:.6}\n",
        g.resolution,
        probability(log_odds.occupied_above, log_odds),
        probability(log_odds.free_below, log_odds),
    );
    std::fs::write(out.join("map.yaml"), yaml)?;
    // PNG: grey map, trajectory in red.
    let mut rgb: Vec<u8> = grey.iter().flat_map(|v| [*v, *v, *v]).collect();
    for (_, p) in traj {
        let u = ((f64::from(p.x) - origin_x) / f64::from(g.resolution)).floor();
        let v = ((f64::from(p.y) - origin_y) / f64::from(g.resolution)).floor();
        if u >= 0.0 && v >= 0.0 && (u as usize) < w && (v as usize) < h {
            let i = ((h - 1 - v as usize) * w + u as usize) * 3;
            rgb[i..i + 3].copy_from_slice(&[220, 0, 0]);
        }
    }
    let png = out.join("map.png");
    super::write_png(&png, w as u32, h as u32, &rgb)
}

/// Writes the outputs of a run into `out`.
pub fn write_outputs(
    out: &Path,
    run: &GridRun,
    config: &GridPfConfig,
    metrics: &serde_json::Value,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_map(
        out,
        &run.cells,
        &run.geometry,
        &config.log_odds,
        &run.trajectory,
    )?;
    super::write_tum(
        &out.join("trajectory.tum"),
        run.trajectory.iter().map(|(t, p)| (*t, p.cast())),
    )?;
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(metrics)? + "\n",
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use microslam::grid::ros_map::RosMap;

    #[test]
    fn rows_are_flipped_and_a_written_map_reads_back() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let g = GridGeometry {
            width: 4,
            height: 3,
            resolution: 0.1,
            origin_x: 0.0,
            origin_y: 0.0,
        };
        let l = LogOdds::SEED;
        let mut cells = vec![0i8; 12];
        cells[0] = l.max; // bottom-left
        cells[11] = l.min; // top-right
        // A trajectory through the map marks the PNG only, not the PGM.
        write_map(dir.path(), &cells, &g, &l, &[]).expect("write");
        let RosMap {
            cells: back,
            geometry,
        } = RosMap::read(&dir.path().join("map.yaml"), &l).expect("read");
        assert_eq!(back.len(), geometry.width * geometry.height);
        let at = |x: usize, y: usize| {
            let gx = geometry.origin_x + (x as f32 + 0.5) * geometry.resolution;
            let gy = geometry.origin_y + (y as f32 + 0.5) * geometry.resolution;
            let ix = ((gx - g.origin_x) / g.resolution).floor() as usize;
            let iy = ((gy - g.origin_y) / g.resolution).floor() as usize;
            (ix, iy, back[y * geometry.width + x])
        };
        for y in 0..geometry.height {
            for x in 0..geometry.width {
                let (ix, iy, v) = at(x, y);
                if (ix, iy) == (0, 0) {
                    assert_eq!(v, l.max);
                }
                if (ix, iy) == (3, 2) {
                    assert_eq!(v, l.min);
                }
            }
        }
    }
}
