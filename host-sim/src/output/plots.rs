//! PNG pictures drawn with plotters' bitmap backend and encoded with the `png` crate.
//!
//! No text is drawn, so no font library is needed (CI machines have no fontconfig):
//! grid lines are 1 m apart on the map and 60 s / 0.1 m apart on the error plot.

use crate::domain::recording::Recording;
use crate::domain::recording::interpolate_pose;
use crate::drivers::ekf::ReplayRun;
use crate::metrics::apply;
use anyhow::{Result, anyhow};
use microslam::geometry::Pose2;
use nalgebra::{Matrix2, Vector2};
use plotters::prelude::*;
use std::path::Path;

/// A point of the plot, metres.
type Point = (f64, f64);

const MAP_PX: u32 = 900;
const ERR_W: u32 = 1200;
const ERR_H: u32 = 450;
/// χ²₂ quantile at 0.95: the 95 % ellipse is `√5.991 · σ`.
const CHI2_2_95: f64 = 5.991_464_547_107_979;
const MAX_PATH_POINTS: usize = 4000;

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plot: {e}")
}

/// Writes an 8-bit RGB image (`w · h · 3` bytes, rows top to bottom) as a PNG.
pub fn write_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut writer = enc.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(())
}

fn thin<T: Copy>(v: &[T]) -> Vec<T> {
    let step = v.len().div_ceil(MAX_PATH_POINTS).max(1);
    v.iter().step_by(step).copied().collect()
}

/// `map.png`: true path (blue), estimated path (red), true landmarks (black crosses),
/// estimated landmarks (red dots) with their 95 % ellipses (orange), 1 m grid. The
/// estimate is drawn through `alignment` (the SE(2) alignment onto ground truth, or the
/// identity).
pub fn draw_map(
    path: &Path,
    recording: &Recording,
    run: &ReplayRun,
    alignment: &Pose2<f64>,
) -> Result<()> {
    let t = *alignment;
    let est: Vec<(f64, f64)> = thin(&run.trajectory)
        .iter()
        .map(|s| {
            let p = apply(&t, &s.pose);
            (p.x, p.y)
        })
        .collect();
    let truth: Vec<(f64, f64)> = thin(&recording.ground_truth)
        .iter()
        .map(|p| (p.pose.x, p.pose.y))
        .collect();
    let (s, c) = t.theta.sin_cos();
    let rot = Matrix2::new(c, -s, s, c);
    let landmarks: Vec<(Point, Vec<Point>)> = run
        .landmarks
        .iter()
        .map(|l| {
            let p = t.transform_point(&Vector2::new(l.position[0], l.position[1]));
            let cov =
                rot * Matrix2::new(
                    l.covariance[0][0],
                    l.covariance[0][1],
                    l.covariance[1][0],
                    l.covariance[1][1],
                ) * rot.transpose();
            ((p[0], p[1]), ellipse(&Vector2::new(p[0], p[1]), &cov))
        })
        .collect();
    let true_lm: Vec<(f64, f64)> = recording
        .landmarks
        .iter()
        .map(|l| (l.position[0], l.position[1]))
        .collect();
    let all = est
        .iter()
        .chain(&truth)
        .chain(&true_lm)
        .chain(landmarks.iter().map(|(p, _)| p));
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    let half = ((x1 - x0).max(y1 - y0) / 2.0 + 0.5).max(1.0);
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let (x0, x1, y0, y1) = (cx - half, cx + half, cy - half, cy + half);

    let mut buf = vec![0u8; (MAP_PX * MAP_PX * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (MAP_PX, MAP_PX)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(err)?;
        let grid = RGBColor(225, 225, 225);
        let mut g = x0.ceil();
        while g <= x1 {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(g, y0), (g, y1)],
                    grid,
                )))
                .map_err(err)?;
            g += 1.0;
        }
        let mut g = y0.ceil();
        while g <= y1 {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x0, g), (x1, g)],
                    grid,
                )))
                .map_err(err)?;
            g += 1.0;
        }
        chart
            .draw_series(LineSeries::new(truth, BLUE.stroke_width(2)))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(est, RED.stroke_width(1)))
            .map_err(err)?;
        let orange = RGBColor(255, 140, 0);
        for (p, e) in &landmarks {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    e.clone(),
                    orange.stroke_width(2),
                )))
                .map_err(err)?;
            chart
                .draw_series(std::iter::once(Circle::new(*p, 3, RED.filled())))
                .map_err(err)?;
        }
        chart
            .draw_series(
                true_lm
                    .iter()
                    .map(|p| Cross::new(*p, 6, BLACK.stroke_width(2))),
            )
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    write_png(path, MAP_PX, MAP_PX, &buf)
}

/// Points of the 95 % ellipse of a 2-D Gaussian.
fn ellipse(center: &Vector2<f64>, cov: &Matrix2<f64>) -> Vec<(f64, f64)> {
    let Some(l) = cov.cholesky().map(|c| c.l()) else {
        return vec![(center[0], center[1])];
    };
    let k = CHI2_2_95.sqrt();
    (0..=48)
        .map(|i| {
            let a = std::f64::consts::TAU * f64::from(i) / 48.0;
            let p = center + l * Vector2::new(a.cos(), a.sin()) * k;
            (p[0], p[1])
        })
        .collect()
}

/// `errors.png`: position error of the estimate against ground truth over time (red) and
/// its 3σ bound `3·√(σx² + σy²)` from the filter's covariance (blue); grid every 60 s
/// and 0.1 m. Errors are in the filter's frame (it starts at the true pose) when the
/// recording gives the initial pose, otherwise through `alignment`.
pub fn draw_errors(
    path: &Path,
    recording: &Recording,
    run: &ReplayRun,
    alignment: &Pose2<f64>,
) -> Result<()> {
    let t = if recording.initial_pose.is_some() {
        Pose2::IDENTITY
    } else {
        *alignment
    };
    let t0 = run.trajectory.first().map_or(0.0, |s| s.stamp);
    let mut error = Vec::new();
    let mut bound = Vec::new();
    for s in thin(&run.trajectory) {
        let Some(g) = interpolate_pose(&recording.ground_truth, s.stamp) else {
            continue;
        };
        let p = apply(&t, &s.pose);
        let time = s.stamp - t0;
        error.push((time, (p.x - g.x).hypot(p.y - g.y)));
        bound.push((
            time,
            3.0 * (s.covariance[0][0] + s.covariance[1][1]).max(0.0).sqrt(),
        ));
    }
    let tmax = error.last().map_or(1.0, |e| e.0.max(1.0));
    let ymax = error
        .iter()
        .chain(&bound)
        .map(|e| e.1)
        .filter(|v| v.is_finite())
        .fold(0.1f64, f64::max)
        * 1.05;
    let mut buf = vec![0u8; (ERR_W * ERR_H * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (ERR_W, ERR_H)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .build_cartesian_2d(0.0..tmax, 0.0..ymax)
            .map_err(err)?;
        let grid = RGBColor(225, 225, 225);
        let mut x = 0.0;
        while x <= tmax {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(x, 0.0), (x, ymax)],
                    grid,
                )))
                .map_err(err)?;
            x += 60.0;
        }
        let mut y = 0.0;
        while y <= ymax {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(0.0, y), (tmax, y)],
                    grid,
                )))
                .map_err(err)?;
            y += 0.1;
        }
        chart
            .draw_series(LineSeries::new(bound, BLUE.stroke_width(2)))
            .map_err(err)?;
        chart
            .draw_series(LineSeries::new(error, RED.stroke_width(1)))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    write_png(path, ERR_W, ERR_H, &buf)
}
