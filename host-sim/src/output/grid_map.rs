//! Occupancy maps as files: PGM + YAML in the ROS `map_server` convention, the `map.png`
//! picture, TUM trajectories — and reading a saved map back for localization.

use super::grid_picture::{CellBox, GridPicture, draw_grid_map, grey as grey_level, probability};
use crate::drivers::grid::GridRun;
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use microslam::pf::GridPfConfig;
use std::fmt::Write as _;
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
    Ok(())
}
/// Writes a trajectory in TUM format: `t x y z qx qy qz qw` (planar: z = 0, yaw only).
pub fn write_tum(path: &Path, traj: &[(f64, Pose2<f32>)]) -> Result<()> {
    let mut s = String::from("# t x y z qx qy qz qw\n");
    for (t, p) in traj {
        let half = 0.5 * f64::from(p.theta);
        writeln!(
            s,
            "{t:.6} {:.6} {:.6} 0 0 0 {:.9} {:.9}",
            p.x,
            p.y,
            half.sin(),
            half.cos()
        )?;
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

/// Largest map [`read_map`] accepts, cells (a 16 384 × 16 384 grid: 256 MB of `i8`).
pub const MAX_MAP_CELLS: usize = 1 << 28;

/// A map read back from `map.yaml` + its PGM: log-odds cells (row 0 at the bottom) and
/// geometry. Grey levels become log-odds through `p = 1 − grey/maxval` (the inverse of
/// [`write_map`]), quantised with `log_odds`' unit and clamped to its limits. Every error
/// names the file it is about.
pub fn read_map(yaml_path: &Path, log_odds: &LogOdds) -> Result<(Vec<i8>, GridGeometry)> {
    let text = std::fs::read_to_string(yaml_path)
        .with_context(|| format!("reading {}", yaml_path.display()))?;
    let mut image = None;
    let mut resolution = None;
    let mut origin = None;
    for (number, line) in text.lines().enumerate() {
        let Some((k, v)) = line.split_once(':') else {
            continue;
        };
        let v = v.trim();
        let at = || format!("{}:{}", yaml_path.display(), number + 1);
        match k.trim() {
            "image" => image = Some(v.trim_matches('"').to_string()),
            "resolution" => {
                let r = v
                    .parse::<f32>()
                    .ok()
                    .filter(|r| r.is_finite() && *r > 0.0)
                    .with_context(|| {
                        format!("{}: resolution `{v}` is not a positive number", at())
                    })?;
                resolution = Some(r);
            }
            "origin" => {
                let n = v
                    .trim_matches(|c| c == '[' || c == ']')
                    .split(',')
                    .map(|s| s.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
                    .collect::<Option<Vec<f32>>>()
                    .filter(|n| n.len() >= 2)
                    .with_context(|| format!("{}: origin `{v}` is not [x, y, yaw]", at()))?;
                origin = Some((n[0], n[1]));
            }
            _ => {}
        }
    }
    let (Some(image), Some(resolution), Some((ox, oy))) = (image, resolution, origin) else {
        bail!(
            "{}: needs image, resolution and origin",
            yaml_path.display()
        );
    };
    let pgm_path = yaml_path.parent().unwrap_or(Path::new(".")).join(image);
    let bytes =
        std::fs::read(&pgm_path).with_context(|| format!("reading {}", pgm_path.display()))?;
    let pgm = parse_pgm(&bytes).with_context(|| format!("{}", pgm_path.display()))?;
    let (w, h) = (pgm.width, pgm.height);
    let unit = f64::from(log_odds.nats_per_unit());
    let maxval = f64::from(pgm.maxval);
    let mut cells = vec![0i8; w * h];
    // PGM rows run top to bottom, grid rows bottom to top.
    for (row, cells_row) in pgm
        .pixels
        .chunks_exact(w)
        .rev()
        .zip(cells.chunks_exact_mut(w))
    {
        for (grey, cell) in row.iter().zip(cells_row.iter_mut()) {
            let p = (1.0 - f64::from(*grey) / maxval).clamp(1e-6, 1.0 - 1e-6);
            let l = (p / (1.0 - p)).ln() / unit;
            *cell = l
                .round()
                .clamp(f64::from(log_odds.min), f64::from(log_odds.max)) as i8;
        }
    }
    Ok((
        cells,
        GridGeometry {
            width: w,
            height: h,
            resolution,
            origin_x: ox,
            origin_y: oy,
        },
    ))
}

/// A binary 8-bit PGM image.
#[derive(Debug, PartialEq)]
pub struct Pgm<'a> {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The grey level of white (1 ..= 255).
    pub maxval: u8,
    /// `width · height` grey levels, row by row from the top.
    pub pixels: &'a [u8],
}

/// Parses a binary PGM (`P5`, 8-bit): the header (magic, width, height, maxval, with
/// `#` comments) and exactly `width · height` pixel bytes after it. Refused: another
/// magic, a missing or non-numeric field, a size of zero or above [`MAX_MAP_CELLS`],
/// `maxval` outside 1 ..= 255 (16-bit PGMs are not read), too few pixel bytes.
pub fn parse_pgm(bytes: &[u8]) -> Result<Pgm<'_>> {
    let mut fields: Vec<&[u8]> = Vec::with_capacity(4);
    let mut i = 0;
    while fields.len() < 4 && i < bytes.len() {
        match bytes[i] {
            b if b.is_ascii_whitespace() => i += 1,
            b'#' => {
                while i < bytes.len() && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            _ => {
                let start = i;
                while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
                    i += 1;
                }
                fields.push(&bytes[start..i]);
            }
        }
    }
    if fields.first().copied() != Some(b"P5".as_slice()) {
        bail!("not a binary PGM (no P5 magic)");
    }
    if fields.len() < 4 {
        bail!("PGM header ends early: needs width, height and maxval");
    }
    let number = |field: &[u8], what: &str| -> Result<usize> {
        std::str::from_utf8(field)
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
            .with_context(|| {
                format!(
                    "PGM {what} `{}` is not a whole number",
                    String::from_utf8_lossy(field)
                )
            })
    };
    let width = number(fields[1], "width")?;
    let height = number(fields[2], "height")?;
    let maxval = number(fields[3], "maxval")?;
    let cells = width
        .checked_mul(height)
        .filter(|&n| n > 0 && n <= MAX_MAP_CELLS)
        .with_context(|| {
            format!("PGM size {width} × {height} is empty or larger than {MAX_MAP_CELLS} cells")
        })?;
    let maxval = u8::try_from(maxval)
        .ok()
        .filter(|&m| m > 0)
        .with_context(|| format!("PGM maxval {maxval} is not in 1 ..= 255 (8-bit PGMs only)"))?;
    // One whitespace byte separates the header from the pixels.
    let start = i + 1;
    let pixels = bytes
        .get(start..)
        .and_then(|rest| rest.get(..cells))
        .with_context(|| {
            format!(
                "PGM is truncated: {} pixel bytes for {width} × {height}",
                bytes.len().saturating_sub(start)
            )
        })?;
    Ok(Pgm {
        width,
        height,
        maxval,
        pixels,
    })
}

/// Writes the outputs of a run into `out`: `map.pgm`, `map.yaml`, `map.png` (with
/// `truth` when given; titled with the metrics' `estimator` and `dataset`),
/// `trajectory.tum` and `metrics.json`.
pub fn write_outputs(
    out: &Path,
    run: &GridRun,
    config: &GridPfConfig,
    metrics: &serde_json::Value,
    truth: Option<&[(f64, Pose2<f32>)]>,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    write_map_server(out, &run.cells, &run.geometry, &config.log_odds)?;
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
    )?;
    write_tum(&out.join("trajectory.tum"), &run.trajectory)?;
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(metrics)? + "\n",
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `map.yaml` + `map.pgm` in a temporary folder; returns the folder and the YAML path.
    fn map_files(yaml: &str, pgm: &[u8]) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().expect("temporary folder");
        std::fs::write(dir.path().join("map.yaml"), yaml).expect("write yaml");
        std::fs::write(dir.path().join("map.pgm"), pgm).expect("write pgm");
        let yaml = dir.path().join("map.yaml");
        (dir, yaml)
    }

    const YAML: &str = "image: map.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\n";

    fn pgm(header: &str, pixels: &[u8]) -> Vec<u8> {
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(pixels);
        bytes
    }

    #[test]
    fn maxval_is_white() {
        // maxval 100: grey 100 is white (free), 0 black (occupied), 50 unknown.
        let (_dir, yaml) = map_files(YAML, &pgm("P5\n3 1\n100\n", &[100, 0, 50]));
        let (cells, geometry) = read_map(&yaml, &LogOdds::SEED).expect("a valid map");
        assert_eq!((geometry.width, geometry.height), (3, 1));
        assert_eq!((geometry.origin_x, geometry.origin_y), (-1.0, -2.0));
        assert_eq!(cells[0], LogOdds::SEED.min);
        assert_eq!(cells[1], LogOdds::SEED.max);
        assert_eq!(cells[2], 0, "half of maxval is p = 0.5");
    }

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
        let (back, geometry) = read_map(&dir.path().join("map.yaml"), &l).expect("read");
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

    #[test]
    fn bad_headers_are_refused_with_the_file_name() {
        let cases: [(&[u8], &str); 7] = [
            (b"P2\n1 1\n255\n\0", "no P5"),
            (b"P5\n1 1\n", "ends early"),
            (b"P5\n18446744073709551615 2\n255\n", "larger than"),
            (b"P5\n0 5\n255\n", "empty"),
            (b"P5\n2 2\n65535\n\0\0\0\0\0\0\0\0", "maxval 65535"),
            (b"P5\n2 2\n0\n\0\0\0\0", "maxval 0"),
            (b"P5\n4 4\n255\n\0\0\0", "truncated"),
        ];
        for (bytes, why) in cases {
            let (_dir, yaml) = map_files(YAML, bytes);
            let error = format!("{:#}", read_map(&yaml, &LogOdds::SEED).expect_err(why));
            assert!(error.contains("map.pgm"), "{why}: {error}");
            assert!(error.contains(why), "{why}: {error}");
        }
    }

    #[test]
    fn bad_yaml_is_refused_with_the_file_and_line() {
        for (yaml, why) in [
            (
                "image: map.pgm\nresolution: -1\norigin: [0, 0, 0]\n",
                "map.yaml:2: resolution",
            ),
            (
                "image: map.pgm\nresolution: 0.05\norigin: [0, nan, 0]\n",
                "map.yaml:3: origin",
            ),
            (
                "image: map.pgm\nresolution: 0.05\n",
                "needs image, resolution and origin",
            ),
        ] {
            let (_dir, path) = map_files(yaml, &pgm("P5\n1 1\n255\n", &[0]));
            let error = format!("{:#}", read_map(&path, &LogOdds::SEED).expect_err(why));
            assert!(error.contains(why), "{why}: {error}");
        }
    }
}
