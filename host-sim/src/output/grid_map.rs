//! Occupancy maps as files: PGM + YAML in the ROS `map_server` convention, a PNG with the
//! trajectory, TUM trajectories — and reading a saved map back for localization.

use crate::drivers::grid::GridRun;
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use microslam::pf::GridPfConfig;
use std::fmt::Write as _;
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

/// A map read back from `map.yaml` + its PGM: log-odds cells (row 0 at the bottom) and
/// geometry. Grey levels become log-odds through `p = 1 − grey/255` (the inverse of
/// [`write_map`]), quantised with `log_odds`' unit and clamped to its limits.
pub fn read_map(yaml_path: &Path, log_odds: &LogOdds) -> Result<(Vec<i8>, GridGeometry)> {
    let text = std::fs::read_to_string(yaml_path)
        .with_context(|| format!("reading {}", yaml_path.display()))?;
    let mut image = None;
    let mut resolution = None;
    let mut origin = None;
    for line in text.lines() {
        let Some((k, v)) = line.split_once(':') else {
            continue;
        };
        let v = v.trim();
        match k.trim() {
            "image" => image = Some(v.trim_matches('"').to_string()),
            "resolution" => resolution = v.parse::<f32>().ok(),
            "origin" => {
                let n: Vec<f32> = v
                    .trim_matches(|c| c == '[' || c == ']')
                    .split(',')
                    .filter_map(|s| s.trim().parse().ok())
                    .collect();
                origin = (n.len() >= 2).then(|| (n[0], n[1]));
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
    // Binary PGM header: P5, width, height, maxval, one whitespace byte, then pixels.
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 && i < bytes.len() {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        if bytes.get(i) == Some(&b'#') {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        let s = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[s..i]).to_string());
    }
    i += 1;
    if fields.first().map(String::as_str) != Some("P5") || fields.len() < 4 {
        bail!("{}: not a binary PGM", pgm_path.display());
    }
    let w: usize = fields[1].parse()?;
    let h: usize = fields[2].parse()?;
    let pixels = bytes.get(i..i + w * h).context("PGM is truncated")?;
    let unit = f64::from(log_odds.nats_per_unit());
    let mut cells = vec![0i8; w * h];
    for y in 0..h {
        for x in 0..w {
            let grey = f64::from(pixels[(h - 1 - y) * w + x]);
            let p = (1.0 - grey / 255.0).clamp(1e-6, 1.0 - 1e-6);
            let l = (p / (1.0 - p)).ln() / unit;
            cells[y * w + x] =
                l.round()
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
    write_tum(&out.join("trajectory.tum"), &run.trajectory)?;
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(metrics)? + "\n",
    )?;
    Ok(())
}
