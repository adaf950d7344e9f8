//! `map.png` of a grid run: the occupancy grid scaled up to a readable size under axes in
//! metres, with the estimated path, the ground truth where known, start and end markers,
//! a scale bar and a legend that explains the cell colours.

use super::figure::{self, ESTIMATE, ESTIMATE_WIDTH, MapLayout, Mark, TRUTH, TRUTH_WIDTH};
use anyhow::Result;
use microslam::geometry::Pose2;
use microslam::grid::{GridGeometry, LogOdds};
use plotters::prelude::*;
use std::path::Path;

/// Long side of the plotting area of a grid `map.png`, pixels (maps smaller than this are
/// scaled up by a whole factor, larger ones down to it).
pub const MAP_LONG_SIDE_PX: u32 = 900;

/// What a grid `map.png` shows.
#[derive(Clone, Copy, Debug)]
pub struct GridPicture<'a> {
    /// Map cells, row-major from the bottom row.
    pub cells: &'a [i8],
    /// Geometry of `cells`.
    pub geometry: &'a GridGeometry,
    /// Log-odds quantisation of the cells (for the grey levels).
    pub log_odds: &'a LogOdds,
    /// The estimate, `(stamp, pose)` per scan.
    pub estimate: &'a [(f64, Pose2<f32>)],
    /// The ground truth, when known.
    pub truth: Option<&'a [(f64, Pose2<f32>)]>,
    /// The title above the map.
    pub title: &'a str,
}

/// A rectangle of cells: `x0 .. x1` × `y0 .. y1` (exclusive ends).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CellBox {
    /// First column.
    pub x0: usize,
    /// First row (bottom).
    pub y0: usize,
    /// Column after the last.
    pub x1: usize,
    /// Row after the last.
    pub y1: usize,
}

impl CellBox {
    /// The known cells (non-zero) plus `margin` cells around them, or the whole grid.
    pub fn known(cells: &[i8], g: &GridGeometry, margin: usize) -> Self {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, c) in cells.iter().enumerate() {
            if *c != 0 {
                let (x, y) = (i % g.width.max(1), i / g.width.max(1));
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x + 1);
                y1 = y1.max(y + 1);
            }
        }
        if x0 == usize::MAX {
            return Self {
                x0: 0,
                y0: 0,
                x1: g.width,
                y1: g.height,
            };
        }
        Self {
            x0: x0.saturating_sub(margin),
            y0: y0.saturating_sub(margin),
            x1: (x1 + margin).min(g.width),
            y1: (y1 + margin).min(g.height),
        }
    }

    /// Columns and rows.
    pub fn size(&self) -> (usize, usize) {
        (self.x1 - self.x0, self.y1 - self.y0)
    }

    /// World extent `((x0, x1), (y0, y1))`, metres.
    pub fn extent(&self, g: &GridGeometry) -> ((f64, f64), (f64, f64)) {
        let r = f64::from(g.resolution);
        let (ox, oy) = (f64::from(g.origin_x), f64::from(g.origin_y));
        (
            (ox + self.x0 as f64 * r, ox + self.x1 as f64 * r),
            (oy + self.y0 as f64 * r, oy + self.y1 as f64 * r),
        )
    }
}

/// Occupancy probability of a cell value.
pub fn probability(value: i8, log_odds: &LogOdds) -> f64 {
    let l = f64::from(value) * f64::from(log_odds.nats_per_unit());
    1.0 / (1.0 + (-l).exp())
}

/// The grey level of a cell: 255 · (1 − p) (free white, occupied black, unknown mid-grey).
pub fn grey(value: i8, log_odds: &LogOdds) -> u8 {
    (255.0 * (1.0 - probability(value, log_odds))).round() as u8
}

/// The cells of `b` as a `w` × `h` RGB image (north up): each pixel shows the most
/// occupied cell under it, so thin walls survive scaling down.
pub fn map_rgb(
    cells: &[i8],
    g: &GridGeometry,
    b: CellBox,
    w: u32,
    h: u32,
    lo: &LogOdds,
) -> Vec<u8> {
    let (bw, bh) = b.size();
    let (w, h) = (w.max(1) as usize, h.max(1) as usize);
    let span = |i: usize, n: usize, cells: usize| {
        let a = i * cells / n;
        (a, ((i + 1) * cells / n).max(a + 1).min(cells))
    };
    let xs: Vec<(usize, usize)> = (0..w).map(|u| span(u, w, bw)).collect();
    let mut rgb = Vec::with_capacity(w * h * 3);
    for v in 0..h {
        // Image rows run top to bottom, grid rows bottom to top.
        let (r0, r1) = span(h - 1 - v, h, bh);
        for &(c0, c1) in &xs {
            let mut most = i8::MIN;
            let mut known = false;
            for y in r0..r1 {
                let row = (b.y0 + y) * g.width + b.x0;
                for c in cells.get(row + c0..row + c1).unwrap_or(&[]) {
                    most = most.max(*c);
                    known = true;
                }
            }
            let k = grey(if known { most } else { 0 }, lo);
            rgb.extend_from_slice(&[k, k, k]);
        }
    }
    rgb
}

/// The plotting area for a box of `bw` × `bh` cells whose long side becomes about `long`
/// pixels: a whole scale factor ≥ 1 when the box is smaller, else scaled down to `long`.
pub fn plot_size(bw: usize, bh: usize, long: u32) -> (u32, u32) {
    let (bw, bh) = (bw.max(1) as f64, bh.max(1) as f64);
    let side = bw.max(bh);
    let scale = if side <= f64::from(long) {
        (f64::from(long) / side).floor()
    } else {
        f64::from(long) / side
    };
    (
        (bw * scale).round().max(1.0) as u32,
        (bh * scale).round().max(1.0) as u32,
    )
}

/// `(x, y)` of each pose, metres.
pub fn points(path: &[(f64, Pose2<f32>)]) -> Vec<(f64, f64)> {
    let step = path.len().div_ceil(6000).max(1);
    let mut p: Vec<(f64, f64)> = path
        .iter()
        .step_by(step)
        .map(|(_, p)| (f64::from(p.x), f64::from(p.y)))
        .collect();
    if let Some((_, last)) = path
        .last()
        .filter(|_| !(path.len() - 1).is_multiple_of(step))
    {
        p.push((f64::from(last.x), f64::from(last.y)));
    }
    p
}

/// Writes the grid `map.png` of `picture` to `path`.
pub fn draw_grid_map(path: &Path, picture: &GridPicture<'_>) -> Result<()> {
    figure::register_font()?;
    let g = picture.geometry;
    let b = CellBox::known(picture.cells, g, 10);
    let (bw, bh) = b.size();
    let (pw, ph) = plot_size(bw, bh, MAP_LONG_SIDE_PX);
    let layout = MapLayout::MAP;
    // The legend needs about 260 pixels of height: small maps get a taller canvas.
    let (w, h) = layout.image_size(pw, ph.max(300));
    let (x, y) = b.extent(g);
    let mut buf = vec![0u8; (w as usize) * (h as usize) * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(figure::plot_error)?;
        let (chart_area, _) =
            root.split_vertically(ph + layout.title + layout.x_labels + 2 * layout.margin);
        let title = format!(
            "{} ({} cm cells)",
            picture.title,
            (100.0 * g.resolution).round()
        );
        let (chart, side) = figure::map_chart(&chart_area, &layout, &title, x, y)?;
        let map = map_rgb(picture.cells, g, b, pw, ph, picture.log_odds);
        let image = BitMapElement::with_owned_buffer((x.0, y.1), (pw, ph), map)
            .ok_or_else(|| anyhow::anyhow!("map image of the wrong size"))?;
        chart
            .plotting_area()
            .draw(&image)
            .map_err(figure::plot_error)?;
        let estimate = points(picture.estimate);
        let truth = picture.truth.map(points).unwrap_or_default();
        figure::path(&chart, &truth, TRUTH, TRUTH_WIDTH)?;
        figure::path(&chart, &estimate, ESTIMATE, ESTIMATE_WIDTH)?;
        figure::start_end(&chart, if truth.is_empty() { &estimate } else { &truth })?;
        figure::scale_bar(&chart)?;
        let mut entries: Vec<(Mark, &str)> = Vec::new();
        if !truth.is_empty() {
            entries.push((Mark::Line(TRUTH, TRUTH_WIDTH), "true path"));
        }
        entries.extend([
            (Mark::Line(ESTIMATE, ESTIMATE_WIDTH), "estimated path"),
            (Mark::Start, "start"),
            (Mark::End, "end"),
            (Mark::Swatch(BLACK), "occupied"),
            (Mark::Swatch(RGBColor(128, 128, 128)), "unknown"),
            (Mark::Swatch(WHITE), "free"),
        ]);
        let top = i32::try_from(layout.title + layout.margin).unwrap_or(0);
        figure::legend(&side, (6, top), &entries)?;
        root.present().map_err(figure::plot_error)?;
    }
    super::write_png(path, w, h, &buf)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::figure::check::Rgb;
    use crate::output::figure::{END, START};

    fn rgb(c: RGBColor) -> [u8; 3] {
        [c.0, c.1, c.2]
    }

    /// Stamped poses.
    type Path = Vec<(f64, Pose2<f32>)>;

    /// A 120 × 80-cell room (5 cm cells) with walls, free inside, and a path around it.
    fn room() -> (Vec<i8>, GridGeometry, Path) {
        let g = GridGeometry {
            width: 160,
            height: 120,
            resolution: 0.05,
            origin_x: -4.0,
            origin_y: -3.0,
        };
        let lo = LogOdds::SYMMETRIC;
        let mut cells = vec![0i8; g.width * g.height];
        for y in 20..100 {
            for x in 20..140 {
                let wall = y == 20 || y == 99 || x == 20 || x == 139;
                cells[y * g.width + x] = if wall { lo.max } else { lo.min };
            }
        }
        // Three quarters of a lap: start and end markers apart.
        let lap = (0..=150)
            .map(|i| {
                let a = std::f32::consts::TAU * i as f32 / 200.0;
                (f64::from(i), Pose2::new(2.0 * a.cos(), 1.2 * a.sin(), a))
            })
            .collect();
        (cells, g, lap)
    }

    #[test]
    fn a_grid_map_explains_itself() {
        let (cells, g, lap) = room();
        let dir = tempfile::tempdir().expect("temporary folder");
        let path = dir.path().join("map.png");
        // The truth is the estimate itself: drawn under it and wider, both stay visible.
        draw_grid_map(
            &path,
            &GridPicture {
                cells: &cells,
                geometry: &g,
                log_odds: &LogOdds::SYMMETRIC,
                estimate: &lap,
                truth: Some(&lap),
                title: "Test room",
            },
        )
        .expect("drawn");
        let img = Rgb::read(&path);
        // Known box 120 × 80 + 10 cells around: 140 × 100 cells, scaled 6× to 840 × 600.
        let layout = MapLayout::MAP;
        assert_eq!((img.w, img.h), layout.image_size(840, 600));
        let (px0, py0) = (
            layout.margin + layout.y_labels,
            layout.margin + layout.title,
        );
        let (px1, py1) = (px0 + 840, py0 + 600);
        let plot = ((px0, px1), (py0, py1));
        assert!(
            img.count(rgb(TRUTH), plot.0, plot.1) > 1000,
            "truth visible"
        );
        assert!(
            img.count(rgb(ESTIMATE), plot.0, plot.1) > 1000,
            "estimate visible"
        );
        assert!(img.count(rgb(START), plot.0, plot.1) > 50, "start marker");
        assert!(img.count(rgb(END), plot.0, plot.1) > 50, "end marker");
        assert!(img.dark(plot.0, plot.1) > 6 * 6 * 300, "walls scaled up");
        // Text: title above, x tick labels and "x (m)" below, y labels left, legend right.
        assert!(img.dark((px0, px1), (0, py0)) > 150, "title");
        assert!(
            img.dark((px0, px1), (py1 + 8, img.h)) > 120,
            "x axis labels"
        );
        assert!(img.dark((0, px0 - 8), (py0, py1)) > 120, "y axis labels");
        let legend = ((img.w - layout.legend, img.w), (0, img.h));
        assert!(img.dark(legend.0, legend.1) > 500, "legend text");
        for (what, c) in [("truth", TRUTH), ("estimate", ESTIMATE), ("start", START)] {
            assert!(img.count(rgb(c), legend.0, legend.1) > 10, "legend {what}");
        }
        // Scale bar: a black bar on a light plate in the lower left of the plot.
        assert!(
            img.dark((px0 + 16, px0 + 60), (py1 - 22, py1 - 16)) > 100,
            "scale bar"
        );
    }

    #[test]
    fn large_maps_are_scaled_down_keeping_walls() {
        let g = GridGeometry {
            width: 3000,
            height: 10,
            resolution: 0.05,
            origin_x: 0.0,
            origin_y: 0.0,
        };
        let mut cells = vec![LogOdds::SYMMETRIC.min; g.width * g.height];
        cells[5 * g.width + 1501] = LogOdds::SYMMETRIC.max;
        let b = CellBox::known(&cells, &g, 0);
        let (w, h) = plot_size(3000, 10, 900);
        assert_eq!((w, h), (900, 3));
        let img = map_rgb(&cells, &g, b, w, h, &LogOdds::SYMMETRIC);
        let dark = img.chunks_exact(3).filter(|p| p[0] < 50).count();
        assert_eq!(dark, 1, "the one wall cell stays a dark pixel");
    }
}
