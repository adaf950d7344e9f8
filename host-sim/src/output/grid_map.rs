//! Occupancy maps as files: PGM + YAML in the ROS `map_server` convention, the `map.png`
//! picture, TUM trajectories — and reading a saved map back for localization.

use super::grid_picture::{CellBox, GridPicture, draw_grid_map, grey as grey_level, probability};
use crate::drivers::grid::GridRun;
use anyhow::Result;
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use microslam::pf::GridPfConfig;
use std::path::Path;

/// Writes `map.pgm` (grey = 255·(1 − p), north up), `map.yaml` (ROS `map_server`; the
/// thresholds are the grid's occupied/free log-odds as probabilities) and `map.png` (the
/// map with axes, legend and the trajectory, [`draw_grid_map`]), cropped to the known area.
pub fn write_map(
    out: &Path,
    cells: &[i8],
    g: &GridGeometry,
    log_odds: &LogOdds,
    traj: &[(f64, Pose2<f32>)],
) -> Result<()> {
    write_map_server(out, cells, g, log_odds)?;
    draw_grid_map(
        &out.join("map.png"),
        &GridPicture {
            cells,
            geometry: g,
            log_odds,
            estimate: traj,
            truth: None,
            title: "Occupancy grid map",
        },
    )
}

/// Writes a map image (`microslam::grid::map_image`, e.g. the one a board saved) as
/// `map.bin` (its bytes) and, for `map_server` and the eye, `map.pgm`, `map.yaml` and
/// `map.png` ([`write_map`]) of its three states: occupied, free (where the image has a
/// free bitmap) and unknown. An image that does not parse is an error naming `out`.
pub fn write_map_image(
    out: &Path,
    image: &[u8],
    log_odds: &LogOdds,
    traj: &[(f64, Pose2<f32>)],
) -> Result<()> {
    let map = microslam::grid::MapImage::parse(image)
        .map_err(|e| anyhow::anyhow!("{}: map image: {e}", out.display()))?;
    let g = *map.geometry();
    let view = map.view();
    let free_below = map.free_below();
    let mut cells = Vec::with_capacity(g.width * g.height);
    for y in 0..g.height as i32 {
        for x in 0..g.width as i32 {
            cells.push(if view.is_occupied(x, y) {
                i8::MAX
            } else if view.is_free(x, y, free_below) {
                i8::MIN + 1
            } else {
                0
            });
        }
    }
    super::write_file(&out.join("map.bin"), image)?;
    write_map(out, &cells, &g, log_odds, traj)
}

/// Writes `map.pgm` and `map.yaml` (ROS `map_server`), cropped to the known area.
fn write_map_server(out: &Path, cells: &[i8], g: &GridGeometry, log_odds: &LogOdds) -> Result<()> {
    let CellBox { x0, y0, x1, y1 } = CellBox::known(cells, g, 10);
    let (w, h) = (x1 - x0, y1 - y0);
    let mut grey = Vec::with_capacity(w * h);
    for y in (y0..y1).rev() {
        for x in x0..x1 {
            let v = cells.get(y * g.width + x).copied().unwrap_or(0);
            grey.push(grey_level(v, log_odds));
        }
    }
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    pgm.extend_from_slice(&grey);
    super::write_file(&out.join("map.pgm"), pgm)?;
    let origin_x = f64::from(g.origin_x) + x0 as f64 * f64::from(g.resolution);
    let origin_y = f64::from(g.origin_y) + y0 as f64 * f64::from(g.resolution);
    let yaml = format!(
        "image: map.pgm\nresolution: {}\norigin: [{origin_x:.6}, {origin_y:.6}, 0.0]\nnegate: 0\noccupied_thresh: {:.6}\nfree_thresh: {:.6}\n",
        g.resolution,
        probability(log_odds.occupied_above, log_odds),
        probability(log_odds.free_below, log_odds),
    );
    super::write_file(&out.join("map.yaml"), yaml)?;
    Ok(())
}

/// Writes the outputs of a run into `out`: the map for `map_server` (`map.pgm`,
/// `map.yaml`), the board's map image `map.bin` when the run made one (an earlier run's
/// is removed otherwise), `trajectory.tum`, `metrics.json` and, when `plots`, the picture
/// `map.png` (the map with the trajectory, and `truth` under it when given; without
/// `plots`, an earlier run's `map.png` is removed).
pub fn write_outputs(
    out: &Path,
    run: &GridRun,
    config: &GridPfConfig,
    metrics: &serde_json::Value,
    truth: Option<&[(f64, Pose2<f32>)]>,
    plots: bool,
) -> Result<()> {
    super::create_folder(out)?;
    write_map_server(out, &run.cells, &run.geometry, &config.log_odds)?;
    match &run.map_image {
        Some(bytes) => super::write_file(&out.join("map.bin"), bytes)?,
        None => super::remove_stale(&out.join("map.bin"))?,
    }
    if plots {
        draw_map_picture(out, run, config, metrics, truth)?;
    } else {
        super::remove_stale(&out.join("map.png"))?;
    }
    super::write_tum(
        &out.join("trajectory.tum"),
        run.trajectory.iter().map(|(t, p)| (*t, p.cast())),
    )?;
    super::write_report(&out.join("metrics.json"), metrics)?;
    Ok(())
}

/// `map.png` of [`write_outputs`], titled after the run's estimator and dataset.
fn draw_map_picture(
    out: &Path,
    run: &GridRun,
    config: &GridPfConfig,
    metrics: &serde_json::Value,
    truth: Option<&[(f64, Pose2<f32>)]>,
) -> Result<()> {
    let estimator = metrics["estimator"].as_str().unwrap_or("grid SLAM");
    let mut letters = estimator.chars();
    let title = format!(
        "{}{}: {}",
        letters
            .next()
            .map(|c| c.to_uppercase().to_string())
            .unwrap_or_default(),
        letters.as_str(),
        metrics["dataset"].as_str().unwrap_or("run")
    );
    draw_grid_map(
        &out.join("map.png"),
        &GridPicture {
            cells: &run.cells,
            geometry: &run.geometry,
            log_odds: &config.log_odds,
            estimate: &run.trajectory,
            truth,
            title: &title,
        },
    )
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
        let l = LogOdds::SYMMETRIC;
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
