//! `--animate FILE.gif`: an animated GIF of the grid map being built, with the estimated
//! path, the ground truth where known, the robot and its current scan.
//!
//! Frames are drawn with plotters (the embedded font of [`super::figure`]) and encoded
//! with the `gif` crate. All frames share one fixed palette (a 6 × 6 × 6 colour cube and
//! 39 greys), and each frame after the first holds only the rectangle that changed, with
//! unchanged pixels transparent: a long run stays a small file.

use super::figure::{self, ESTIMATE, TRUTH};
use super::grid_picture::{CellBox, map_rgb, points};
use crate::drivers::grid::{GridInput, GridRun};
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::grid::LogOdds;
use microslam::sensors::lidar::{LidarGeometry, LidarScan, robot_to_world};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// The lidar end points of the current scan.
const SCAN: RGBColor = RGBColor(0, 158, 115);
/// Height of the title strip above the map, pixels.
const HEADER: u32 = 30;
/// Height of the legend strip below the map, pixels.
const FOOTER: u32 = 28;
/// The palette index that means "unchanged" (transparent).
const TRANSPARENT_INDEX: u8 = 255;

/// Size and pace of an animation.
#[derive(Clone, Copy, Debug)]
pub struct AnimationSettings {
    /// Long side of the map in the animation, pixels.
    pub long_side: u32,
    /// Frames wanted (one map snapshot each; the run decides the exact count).
    pub frames: usize,
    /// Frames per second.
    pub fps: u16,
    /// How long the last frame stays, seconds.
    pub hold_s: f64,
}

impl Default for AnimationSettings {
    /// 480 pixels, 150 frames at 10 per second (15 s), the last held 3 s.
    fn default() -> Self {
        Self {
            long_side: 480,
            frames: 150,
            fps: 10,
            hold_s: 3.0,
        }
    }
}

impl AnimationSettings {
    /// Scans between two map snapshots for a run of `scans` scans.
    pub fn snapshot_every(&self, scans: usize) -> usize {
        scans.div_ceil(self.frames.max(1)).max(1)
    }
}

/// What an animation shows: a run recorded with snapshots
/// ([`crate::drivers::grid::run_slam_observed`] with `snapshot_every` > 0) and its inputs.
#[derive(Clone, Copy)]
pub struct Animation<'a> {
    /// The run, with [`GridRun::snapshots`].
    pub run: &'a GridRun,
    /// The scans the run consumed (for the current scan of each frame).
    pub inputs: &'a [GridInput<'a>],
    /// Geometry of the scans.
    pub lidar: &'a LidarGeometry,
    /// Log-odds quantisation of the cells (for the grey levels).
    pub log_odds: &'a LogOdds,
    /// The ground truth, when known.
    pub truth: Option<&'a [(f64, Pose2<f32>)]>,
    /// The title above the map.
    pub title: &'a str,
}

/// What was written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AnimationReport {
    /// Frames in the file.
    pub frames: usize,
    /// Width and height, pixels.
    pub size: (u32, u32),
    /// File size, bytes.
    pub bytes: u64,
}

/// The palette: a 6 × 6 × 6 colour cube (indices 0–215), 39 greys (216–254), and
/// index 255 (transparent; black).
fn palette() -> Vec<u8> {
    let mut p = Vec::with_capacity(768);
    for r in 0..6u32 {
        for g in 0..6u32 {
            for b in 0..6u32 {
                p.extend([r, g, b].map(|c| (c * 51) as u8));
            }
        }
    }
    for k in 0..39u32 {
        let v = ((k * 255 + 19) / 38) as u8;
        p.extend([v, v, v]);
    }
    p.extend([0, 0, 0]);
    p
}

/// The palette index nearest to an RGB colour (greys to the grey ramp).
fn index_of(r: u8, g: u8, b: u8) -> u8 {
    let (hi, lo) = (r.max(g).max(b), r.min(g).min(b));
    if hi - lo < 24 {
        let mean = (u32::from(r) + u32::from(g) + u32::from(b)) / 3;
        216 + ((mean * 38 + 127) / 255) as u8
    } else {
        let q = |c: u8| (u32::from(c) * 5 + 127) / 255;
        (36 * q(r) + 6 * q(g) + q(b)) as u8
    }
}

/// Writes the animation to `path` (a GIF that loops).
pub fn write_gif(
    path: &Path,
    animation: &Animation<'_>,
    settings: &AnimationSettings,
) -> Result<AnimationReport> {
    figure::register_font()?;
    let run = animation.run;
    if run.snapshots.is_empty() {
        bail!("{}: the run recorded no map snapshots", path.display());
    }
    let g = &run.geometry;
    let b = CellBox::known(&run.cells, g, 10);
    let (bw, bh) = b.size();
    // Scaled to the long side exactly (not by a whole factor): the size a README shows.
    let scale = f64::from(settings.long_side) / bw.max(bh).max(1) as f64;
    let (pw, ph) = (
        ((bw as f64 * scale).round() as u32).max(1),
        ((bh as f64 * scale).round() as u32).max(1),
    );
    let (w, h) = (pw.max(360), ph + HEADER + FOOTER);
    let (wu, hu) = (
        u16::try_from(w).context("animation too wide")?,
        u16::try_from(h).context("animation too tall")?,
    );
    let file =
        std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    // Every write names the file (a full disk included), and the end of the file is
    // written and flushed here, where its error is seen, not when the encoder is dropped.
    let writing = || format!("writing {}", path.display());
    let mut encoder = gif::Encoder::new(std::io::BufWriter::new(file), wu, hu, &palette())
        .with_context(writing)?;
    encoder
        .set_repeat(gif::Repeat::Infinite)
        .with_context(writing)?;
    let delay = (100 / settings.fps.max(1)).max(2);
    let hold = ((settings.hold_s * 100.0).round() as u16).max(delay);
    let mut cells = vec![0i8; run.cells.len()];
    let mut previous: Option<Vec<u8>> = None;
    let stamp0 = run.trajectory.first().map_or(0.0, |s| s.0);
    for (k, snapshot) in run.snapshots.iter().enumerate() {
        for &(i, v) in &snapshot.cells {
            if let Some(c) = cells.get_mut(i as usize) {
                *c = v;
            }
        }
        let rgb = frame(
            animation,
            &cells,
            b,
            (w, h),
            (pw, ph),
            snapshot.scans,
            stamp0,
        )?;
        let indexed: Vec<u8> = rgb
            .chunks_exact(3)
            .map(|p| index_of(p[0], p[1], p[2]))
            .collect();
        let last = k + 1 == run.snapshots.len();
        let mut f = delta(&indexed, previous.as_deref(), w, h);
        f.delay = if last { hold } else { delay };
        encoder.write_frame(&f).with_context(writing)?;
        previous = Some(indexed);
    }
    // The trailer, then the buffer flushed.
    let out = encoder.into_inner().with_context(writing)?;
    out.into_inner()
        .map_err(|e| e.into_error())
        .with_context(writing)?;
    let bytes = std::fs::metadata(path)
        .with_context(|| format!("reading the size of {}", path.display()))?
        .len();
    Ok(AnimationReport {
        frames: run.snapshots.len(),
        size: (w, h),
        bytes,
    })
}

/// The frame for `indexed` after `previous`: the rectangle that changed, unchanged pixels
/// transparent (the whole image for the first frame).
fn delta<'a>(indexed: &[u8], previous: Option<&[u8]>, w: u32, h: u32) -> gif::Frame<'a> {
    let (w, h) = (w as usize, h as usize);
    let Some(prev) = previous else {
        return gif::Frame {
            width: w as u16,
            height: h as u16,
            buffer: indexed.to_vec().into(),
            dispose: gif::DisposalMethod::Keep,
            ..gif::Frame::default()
        };
    };
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (i, (a, b)) in indexed.iter().zip(prev).enumerate() {
        if a != b {
            let (x, y) = (i % w, i / w);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
    }
    if x0 == usize::MAX {
        (x0, y0, x1, y1) = (0, 0, 1, 1);
    }
    let mut buffer = Vec::with_capacity((x1 - x0) * (y1 - y0));
    for y in y0..y1 {
        for x in x0..x1 {
            let i = y * w + x;
            buffer.push(if indexed[i] == prev[i] {
                TRANSPARENT_INDEX
            } else {
                indexed[i]
            });
        }
    }
    gif::Frame {
        left: x0 as u16,
        top: y0 as u16,
        width: (x1 - x0) as u16,
        height: (y1 - y0) as u16,
        buffer: buffer.into(),
        transparent: Some(TRANSPARENT_INDEX),
        dispose: gif::DisposalMethod::Keep,
        ..gif::Frame::default()
    }
}

/// One frame as RGB: the map after `scans` scans, the paths so far, the robot and its
/// scan, the title, the elapsed time, a scale bar and a one-line legend.
#[allow(clippy::too_many_arguments)]
fn frame(
    animation: &Animation<'_>,
    cells: &[i8],
    b: CellBox,
    (w, h): (u32, u32),
    (pw, ph): (u32, u32),
    scans: usize,
    stamp0: f64,
) -> Result<Vec<u8>> {
    let run = animation.run;
    let g = &run.geometry;
    let mut buf = vec![255u8; (w as usize) * (h as usize) * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let e = figure::plot_error;
        let (x, y) = b.extent(g);
        let left = (w - pw) / 2;
        let map_area = root.clone().shrink((left, HEADER), (pw, ph));
        let chart = ChartBuilder::on(&map_area)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)
            .map_err(e)?;
        let map = map_rgb(cells, g, b, pw, ph, animation.log_odds);
        let image = BitMapElement::with_owned_buffer((x.0, y.1), (pw, ph), map)
            .ok_or_else(|| anyhow::anyhow!("map image of the wrong size"))?;
        chart.plotting_area().draw(&image).map_err(e)?;
        let current = scans.checked_sub(1).and_then(|i| run.trajectory.get(i));
        let now = current.map_or(stamp0, |c| c.0);
        if let Some(truth) = animation.truth {
            let n = truth.iter().take_while(|(t, _)| *t <= now).count();
            let so_far = points(&truth[..n]);
            figure::path(&chart, &so_far, TRUTH, 4)?;
        }
        let estimate = points(&run.trajectory[..scans.min(run.trajectory.len())]);
        figure::path(&chart, &estimate, ESTIMATE, 2)?;
        if let Some((i, (_, pose))) = scans.checked_sub(1).zip(current) {
            if let Some(input) = animation.inputs.get(i) {
                let scan = LidarScan::new(input.ranges, *animation.lidar);
                let ends: Vec<(f64, f64)> = scan
                    .beams(1)
                    .map(|beam| {
                        let (px, py) = robot_to_world(pose, beam.robot_point);
                        (f64::from(px), f64::from(py))
                    })
                    .collect();
                for p in &ends {
                    chart
                        .plotting_area()
                        .draw(&Circle::new(*p, 2, SCAN.filled()))
                        .map_err(e)?;
                }
            }
            robot(&chart, pose)?;
        }
        figure::scale_bar(&chart)?;
        let font = (figure::FONT, 15).into_font();
        root.draw(&Text::new(
            animation.title.to_string(),
            (8, 7),
            font.clone(),
        ))
        .map_err(e)?;
        let clock = format!(
            "t = {:.0} s, scan {scans} of {}",
            now - stamp0,
            run.trajectory.len()
        );
        root.draw(&Text::new(
            clock,
            (w as i32 - 8, 7),
            TextStyle::from(font.clone()).pos(Pos::new(HPos::Right, VPos::Top)),
        ))
        .map_err(e)?;
        footer(
            &root,
            animation.truth.is_some(),
            h as i32 - FOOTER as i32 / 2,
        )?;
        root.present().map_err(e)?;
    }
    Ok(buf)
}

/// The robot: a triangle pointing along its heading, about 18 pixels long.
fn robot<DB: DrawingBackend>(chart: &figure::Chart<'_, DB>, pose: &Pose2<f32>) -> Result<()> {
    let plot = chart.plotting_area();
    let c = plot.map_coordinate(&(f64::from(pose.x), f64::from(pose.y)));
    let base = plot.get_base_pixel();
    let (cx, cy) = (f64::from(c.0 - base.0), f64::from(c.1 - base.1));
    let (s, co) = f64::from(pose.theta).sin_cos();
    // Pixel y grows downwards.
    let at = |fwd: f64, side: f64| {
        (
            (cx + fwd * co - side * s).round() as i32,
            (cy - fwd * s - side * co).round() as i32,
        )
    };
    let corners = vec![at(11.0, 0.0), at(-7.0, 7.0), at(-7.0, -7.0)];
    let area = plot.strip_coord_spec();
    area.draw(&Polygon::new(corners.clone(), ESTIMATE.filled()))
        .map_err(figure::plot_error)?;
    let mut outline = corners.clone();
    outline.push(corners[0]);
    area.draw(&PathElement::new(outline, BLACK.stroke_width(2)))
        .map_err(figure::plot_error)
}

/// The one-line legend under the map, centred on row `y`.
fn footer<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    truth: bool,
    y: i32,
) -> Result<()> {
    let e = figure::plot_error;
    let font =
        TextStyle::from((figure::FONT, 14).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    let mut x = 8;
    let mut entry = |mark: &dyn Fn(i32) -> Result<()>, text: &str| -> Result<()> {
        mark(x)?;
        root.draw(&Text::new(text.to_string(), (x + 26, y), font.clone()))
            .map_err(e)?;
        x += 34 + font.font.box_size(text).map_or(60, |b| b.0 as i32);
        Ok(())
    };
    let line = |colour: RGBColor, width: u32| {
        move |x: i32| {
            root.draw(&PathElement::new(
                vec![(x, y), (x + 20, y)],
                colour.stroke_width(width),
            ))
            .map_err(e)
        }
    };
    entry(&line(ESTIMATE, 2), "estimate")?;
    if truth {
        entry(&line(TRUTH, 4), "truth")?;
    }
    entry(
        &|x| {
            root.draw(&Polygon::new(
                vec![(x + 18, y), (x + 4, y - 6), (x + 4, y + 6)],
                ESTIMATE.filled(),
            ))
            .map_err(e)
        },
        "robot",
    )?;
    entry(
        &|x| {
            for dx in [4, 10, 16] {
                root.draw(&Circle::new((x + dx, y), 2, SCAN.filled()))
                    .map_err(e)?;
            }
            Ok(())
        },
        "scan",
    )?;
    entry(
        &|x| {
            for (dx, v) in [(2, 0u8), (9, 128), (16, 255)] {
                root.draw(&Rectangle::new(
                    [(x + dx, y - 5), (x + dx + 7, y + 5)],
                    RGBColor(v, v, v).filled(),
                ))
                .map_err(e)?;
            }
            root.draw(&Rectangle::new(
                [(x + 2, y - 5), (x + 23, y + 5)],
                RGBColor(120, 120, 120),
            ))
            .map_err(e)
        },
        "occupied / unknown / free",
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn palette_colours_map_to_themselves() {
        let p = palette();
        assert_eq!(p.len(), 256 * 3);
        for i in 0..255usize {
            let (r, g, b) = (p[3 * i], p[3 * i + 1], p[3 * i + 2]);
            let j = usize::from(index_of(r, g, b));
            // Exact, except the cube's six greys, which go to the nearest of the 39 greys.
            for (a, b) in [r, g, b].into_iter().zip(&p[3 * j..3 * j + 3]) {
                assert!(a.abs_diff(*b) <= 3, "index {i} maps to {j}");
            }
            if r != g || g != b {
                assert_eq!(i, j, "colour {i} maps to itself");
            }
        }
        assert_eq!(index_of(255, 255, 255), 254, "white is the last grey");
    }
}
