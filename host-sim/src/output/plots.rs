//! PNG pictures of landmark runs drawn with plotters' bitmap backend and encoded with the
//! `png` crate; labels in the embedded font ([`super::figure`]).

use super::figure::{self, ELLIPSE, ESTIMATE, ESTIMATE_WIDTH, MapLayout, Mark, TRUTH, TRUTH_WIDTH};
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

const ERR_W: u32 = 1200;
const ERR_H: u32 = 500;
/// χ²₂ quantile at 0.95: the 95 % ellipse is `√5.991 · σ`.
const CHI2_2_95: f64 = 5.991_464_547_107_979;
const MAX_PATH_POINTS: usize = 4000;

fn err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow!("plot: {e}")
}

/// Writes an 8-bit RGB image (`w · h · 3` bytes, rows top to bottom) as a PNG.
pub fn write_png(path: &Path, w: u32, h: u32, rgb: &[u8]) -> Result<()> {
    let file = super::create_file(path)?;
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

/// Size of the plotting area of `map.png` (square), pixels.
const MAP_PLOT_PX: u32 = 820;

/// `map.png`: the landmark map with axes in metres, a legend, a scale bar, the true path
/// (blue, wide, underneath) and the estimated path (vermillion, on top) with start and end
/// markers, true landmarks (black crosses), estimated landmarks (vermillion dots) with
/// their 95 % ellipses (purple). The estimate is drawn through `alignment` (the SE(2)
/// alignment onto ground truth, or the identity).
pub fn draw_map(
    path: &Path,
    recording: &Recording,
    run: &ReplayRun,
    alignment: &Pose2<f64>,
) -> Result<()> {
    figure::register_font()?;
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
    let [x0, x1, y0, y1] = figure::bounds(all).unwrap_or([-1.0, 1.0, -1.0, 1.0]);
    let pad = 0.04 * (x1 - x0).max(y1 - y0).max(1.0);
    let layout = MapLayout::MAP;
    let (x, y) = figure::equal_aspect(
        (x0 - pad, x1 + pad),
        (y0 - pad, y1 + pad),
        MAP_PLOT_PX,
        MAP_PLOT_PX,
    );
    let (w, h) = layout.image_size(MAP_PLOT_PX, MAP_PLOT_PX);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        let title = format!("Landmark EKF-SLAM: {}", recording.name);
        let (mut chart, side) = figure::map_chart(&root, &layout, &title, x, y)?;
        figure::grid_lines(&mut chart)?;
        figure::path(&chart, &truth, TRUTH, TRUTH_WIDTH)?;
        figure::path(&chart, &est, ESTIMATE, ESTIMATE_WIDTH)?;
        for (_, e) in &landmarks {
            chart
                .draw_series(std::iter::once(PathElement::new(
                    e.clone(),
                    ELLIPSE.stroke_width(2),
                )))
                .map_err(err)?;
        }
        chart
            .draw_series(
                true_lm
                    .iter()
                    .map(|p| Cross::new(*p, 6, BLACK.stroke_width(2))),
            )
            .map_err(err)?;
        chart
            .draw_series(
                landmarks
                    .iter()
                    .map(|(p, _)| Circle::new(*p, 4, ESTIMATE.filled())),
            )
            .map_err(err)?;
        figure::start_end(&chart, if truth.is_empty() { &est } else { &truth })?;
        figure::scale_bar(&chart)?;
        let mut entries = Vec::new();
        if !truth.is_empty() {
            entries.push((Mark::Line(TRUTH, TRUTH_WIDTH), "true path"));
        }
        entries.push((Mark::Line(ESTIMATE, ESTIMATE_WIDTH), "estimated path"));
        entries.push((Mark::Start, "start"));
        entries.push((Mark::End, "end"));
        if !true_lm.is_empty() {
            entries.push((Mark::Cross(BLACK), "true landmark"));
        }
        entries.push((Mark::Dot(ESTIMATE), "estimated landmark"));
        entries.push((Mark::Ellipse(ELLIPSE), "95 % ellipse"));
        figure::legend(
            &side,
            (6, i32::try_from(layout.title + layout.margin).unwrap_or(0)),
            &entries,
        )?;
        root.present().map_err(err)?;
    }
    write_png(path, w, h, &buf)
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

/// `errors.png`: position error of the estimate against ground truth over time
/// (vermillion) and its 3σ bound `3·√(σx² + σy²)` from the filter's covariance (blue), with
/// axes in seconds and metres, a legend naming both and a title naming the recording. Errors are in the filter's frame (it starts at the true pose) when the
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
    figure::register_font()?;
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
            .margin(14)
            .caption(
                format!("Position error against ground truth: {}", recording.name),
                (figure::FONT, 22),
            )
            .x_label_area_size(52)
            .y_label_area_size(76)
            .build_cartesian_2d(0.0..tmax, 0.0..ymax)
            .map_err(err)?;
        chart
            .configure_mesh()
            .bold_line_style(figure::GRID_LINE)
            .light_line_style(TRANSPARENT)
            .x_desc("time since the first estimate (s)")
            .y_desc("error (m)")
            .x_label_formatter(&figure::tick)
            .y_label_formatter(&figure::tick)
            .label_style((figure::FONT, 15))
            .axis_desc_style((figure::FONT, 17))
            .x_labels(12)
            .y_labels(8)
            .draw()
            .map_err(err)?;
        figure::path(&chart, &bound, TRUTH, 2)?;
        figure::path(&chart, &error, ESTIMATE, 2)?;
        // Empty series carry the legend entries.
        chart
            .draw_series(LineSeries::new(std::iter::empty(), TRUTH))
            .map_err(err)?
            .label("3σ bound: 3·√(σx² + σy²) of the filter's covariance")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], TRUTH.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(std::iter::empty(), ESTIMATE))
            .map_err(err)?
            .label("position error |estimate − truth|")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], ESTIMATE.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((figure::FONT, 16))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(150, 150, 150))
            .draw()
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    write_png(path, ERR_W, ERR_H, &buf)
}
