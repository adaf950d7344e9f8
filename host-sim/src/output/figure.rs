//! What every picture shares: the embedded font, the colours, axes in metres, the legend,
//! the scale bar and the start and end markers.
//!
//! The font is DejaVu Sans from the `dejavu` crate, compiled into the binary and handed to
//! plotters' `ab_glyph` renderer: the pictures need no system font library and render the
//! same on every machine. Colours are from the Okabe–Ito palette (told apart with every
//! common colour-vision deficiency); the ground truth is drawn wide and first, the estimate
//! narrow and on top, so both stay visible where they overlap.

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::sync::OnceLock;

/// The font family every label is drawn with (registered by [`register_font`]).
pub const FONT: &str = "sans-serif";
/// Ground truth: blue, drawn wide under the estimate.
pub const TRUTH: RGBColor = RGBColor(0, 114, 178);
/// The estimate: vermillion, drawn narrow on top of the truth.
pub const ESTIMATE: RGBColor = RGBColor(213, 94, 0);
/// The start marker (a circle).
pub const START: RGBColor = RGBColor(0, 158, 115);
/// The end marker (a square).
pub const END: RGBColor = RGBColor(240, 228, 66);
/// Covariance ellipses of estimated landmarks.
pub const ELLIPSE: RGBColor = RGBColor(204, 121, 167);
/// Light grid lines at the axis ticks.
pub const GRID_LINE: RGBColor = RGBColor(225, 225, 225);
/// Width of the truth path, pixels.
pub const TRUTH_WIDTH: u32 = 5;
/// Width of the estimated path, pixels.
pub const ESTIMATE_WIDTH: u32 = 2;

/// A chart whose axes are both in metres or seconds.
pub type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Registers DejaVu Sans as plotters' `sans-serif` (once per process).
pub fn register_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded DejaVu Sans font does not parse"))
    }
}

/// An error of a plotters call as an `anyhow` error.
pub fn plot_error<E: std::fmt::Debug>(e: E) -> anyhow::Error {
    anyhow!("plot: {e:?}")
}

/// The largest of 1, 2, 5 × 10ⁿ that is at most `limit` (and positive).
pub fn nice_length(limit: f64) -> f64 {
    if !(limit.is_finite() && limit > 0.0) {
        return 1.0;
    }
    let decade = 10f64.powf(limit.log10().floor());
    [5.0, 2.0, 1.0]
        .into_iter()
        .map(|m| m * decade)
        .find(|l| *l <= limit)
        .unwrap_or(decade)
}

/// `x` and `y` ranges grown (about their centres) so that one metre spans as many pixels
/// across as up on a `width` × `height` plotting area.
pub fn equal_aspect(
    x: (f64, f64),
    y: (f64, f64),
    width: u32,
    height: u32,
) -> ((f64, f64), (f64, f64)) {
    let (w, h) = (f64::from(width.max(1)), f64::from(height.max(1)));
    let per_px = ((x.1 - x.0) / w).max((y.1 - y.0) / h);
    let grow = |(a, b): (f64, f64), px: f64| {
        let c = 0.5 * (a + b);
        (c - 0.5 * per_px * px, c + 0.5 * per_px * px)
    };
    (grow(x, w), grow(y, h))
}

/// The bounding box `(x0, x1, y0, y1)` of the finite points, or `None`.
pub fn bounds<'a>(points: impl IntoIterator<Item = &'a (f64, f64)>) -> Option<[f64; 4]> {
    let mut b: Option<[f64; 4]> = None;
    for &(x, y) in points {
        if x.is_finite() && y.is_finite() {
            let r = b.get_or_insert([x, x, y, y]);
            *r = [r[0].min(x), r[1].max(x), r[2].min(y), r[3].max(y)];
        }
    }
    b
}

/// Layout of a map picture: outer margin, label areas, the legend column.
pub struct MapLayout {
    /// Margin around the chart, pixels.
    pub margin: u32,
    /// Height of the x axis labels and description, pixels.
    pub x_labels: u32,
    /// Width of the y axis labels and description, pixels.
    pub y_labels: u32,
    /// Height of the title, pixels.
    pub title: u32,
    /// Width of the legend column right of the chart, pixels.
    pub legend: u32,
}

impl MapLayout {
    /// The layout of every map picture.
    pub const MAP: Self = Self {
        margin: 14,
        x_labels: 52,
        y_labels: 70,
        title: 34,
        legend: 250,
    };

    /// The image size for a plotting area of `w` × `h` pixels.
    pub fn image_size(&self, w: u32, h: u32) -> (u32, u32) {
        (
            w + self.y_labels + 2 * self.margin + self.legend,
            h + self.x_labels + 2 * self.margin + self.title,
        )
    }

    /// The plotting area of an image of `w` × `h` pixels.
    pub fn plot_size(&self, w: u32, h: u32) -> (u32, u32) {
        (
            w.saturating_sub(self.y_labels + 2 * self.margin + self.legend),
            h.saturating_sub(self.x_labels + 2 * self.margin + self.title),
        )
    }
}

/// Draws the title, splits off the legend column and builds a chart over `x` × `y` (in
/// metres) with axes "x (m)" and "y (m)"; returns the chart and the legend column.
pub fn map_chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    layout: &MapLayout,
    title: &str,
    x: (f64, f64),
    y: (f64, f64),
) -> Result<(Chart<'a, DB>, DrawingArea<DB, Shift>)> {
    let (w, _) = root.dim_in_pixel();
    let (left, legend) = root.split_horizontally(w.saturating_sub(layout.legend));
    let mut chart = ChartBuilder::on(&left)
        .margin(layout.margin)
        .caption(title, (FONT, 22))
        .x_label_area_size(layout.x_labels)
        .y_label_area_size(layout.y_labels)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(plot_error)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("x (m)")
        .y_desc("y (m)")
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .x_labels(8)
        .y_labels(8)
        .draw()
        .map_err(plot_error)?;
    Ok((chart, legend))
}

/// Draws `points` (chart coordinates) as a line `width` pixels wide: a round brush
/// stamped at every pixel of every segment. (Plotters' wide strokes join segments with
/// mitres that spike where a noisy path turns back, and its one-pixel lines leave gaps on
/// segments a pixel or two long; the brush does neither.)
pub fn path<DB: DrawingBackend>(
    chart: &Chart<'_, DB>,
    points: &[(f64, f64)],
    colour: RGBColor,
    width: u32,
) -> Result<()> {
    let plot = chart.plotting_area();
    let base = plot.get_base_pixel();
    let (w, h) = plot.dim_in_pixel();
    let area = plot.strip_coord_spec();
    let r = f64::from(width.max(1)) / 2.0;
    let reach = r.ceil() as i32;
    let brush: Vec<(i32, i32)> = (-reach..=reach)
        .flat_map(|dy| (-reach..=reach).map(move |dx| (dx, dy)))
        .filter(|(dx, dy)| {
            // Centre of the brush between pixels for even widths.
            let c = if width.is_multiple_of(2) { 0.5 } else { 0.0 };
            let (x, y) = (f64::from(*dx) - c, f64::from(*dy) - c);
            x * x + y * y <= r * r
        })
        .collect();
    let mut last: Option<(i32, i32)> = None;
    let stamp = |q: (i32, i32)| -> Result<()> {
        for (dx, dy) in &brush {
            let (x, y) = (q.0 + dx, q.1 + dy);
            if x >= 0 && y >= 0 && (x as u32) < w && (y as u32) < h {
                area.draw_pixel((x, y), &colour).map_err(plot_error)?;
            }
        }
        Ok(())
    };
    for p in points.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
        let q = plot.map_coordinate(p);
        let q = (q.0 - base.0, q.1 - base.1);
        match last {
            Some(l) if l == q => continue,
            Some(l) => {
                let n = (q.0 - l.0).abs().max((q.1 - l.1).abs());
                for k in 1..=n {
                    let t = f64::from(k) / f64::from(n);
                    stamp((
                        l.0 + (t * f64::from(q.0 - l.0)).round() as i32,
                        l.1 + (t * f64::from(q.1 - l.1)).round() as i32,
                    ))?;
                }
            }
            None => stamp(q)?,
        }
        last = Some(q);
    }
    Ok(())
}

/// Tick labels without trailing zeros: `2`, `0.5`, `-1.25`.
pub fn tick(v: &f64) -> String {
    let r = (v * 1000.0).round() / 1000.0;
    if r == 0.0 {
        "0".to_string()
    } else {
        format!("{r}")
    }
}

/// Light grid lines at the ticks of a chart (drawn under the paths).
pub fn grid_lines<DB: DrawingBackend>(chart: &mut Chart<'_, DB>) -> Result<()> {
    chart
        .configure_mesh()
        .bold_line_style(GRID_LINE)
        .light_line_style(TRANSPARENT)
        .x_labels(8)
        .y_labels(8)
        .x_label_formatter(&|_| String::new())
        .y_label_formatter(&|_| String::new())
        .axis_style(TRANSPARENT)
        .draw()
        .map_err(plot_error)
}

/// A legend entry's symbol.
#[derive(Clone, Copy, Debug)]
pub enum Mark {
    /// A line of this colour and width.
    Line(RGBColor, u32),
    /// A filled dot.
    Dot(RGBColor),
    /// A cross.
    Cross(RGBColor),
    /// An ellipse outline.
    Ellipse(RGBColor),
    /// The start marker.
    Start,
    /// The end marker.
    End,
    /// A filled square with a grey border (a map cell colour).
    Swatch(RGBColor),
}

/// Draws `entries` as a legend box with its top-left corner at `at` on `area`.
pub fn legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    at: (i32, i32),
    entries: &[(Mark, &str)],
) -> Result<()> {
    let font = (FONT, 16).into_font();
    let row = 26;
    let text_w = entries
        .iter()
        .map(|(_, t)| font.box_size(t).map_or(0, |b| b.0 as i32))
        .max()
        .unwrap_or(0);
    let (x, y) = at;
    let (w, h) = (text_w + 56, row * entries.len() as i32 + 10);
    area.draw(&Rectangle::new([(x, y), (x + w, y + h)], WHITE.filled()))
        .map_err(plot_error)?;
    area.draw(&Rectangle::new(
        [(x, y), (x + w, y + h)],
        RGBColor(150, 150, 150),
    ))
    .map_err(plot_error)?;
    for (i, (mark, text)) in entries.iter().enumerate() {
        let cy = y + 5 + row * i as i32 + row / 2;
        let cx = x + 24;
        draw_mark(area, *mark, (cx, cy))?;
        area.draw(&Text::new(
            *text,
            (x + 46, cy),
            TextStyle::from(font.clone()).pos(Pos::new(HPos::Left, VPos::Center)),
        ))
        .map_err(plot_error)?;
    }
    Ok(())
}

/// Draws a legend symbol centred on `c` (pixels).
fn draw_mark<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    mark: Mark,
    c: (i32, i32),
) -> Result<()> {
    let (x, y) = c;
    match mark {
        Mark::Line(colour, width) => area.draw(&PathElement::new(
            vec![(x - 16, y), (x + 16, y)],
            colour.stroke_width(width),
        )),
        Mark::Dot(colour) => area.draw(&Circle::new(c, 4, colour.filled())),
        Mark::Cross(colour) => area.draw(&Cross::new(c, 6, colour.stroke_width(2))),
        Mark::Ellipse(colour) => area.draw(&Circle::new(c, 8, colour.stroke_width(2))),
        Mark::Start => return start_marker(area, c),
        Mark::End => return end_marker(area, c),
        Mark::Swatch(colour) => {
            area.draw(&Rectangle::new(
                [(x - 9, y - 9), (x + 9, y + 9)],
                colour.filled(),
            ))
            .map_err(plot_error)?;
            area.draw(&Rectangle::new(
                [(x - 9, y - 9), (x + 9, y + 9)],
                RGBColor(120, 120, 120),
            ))
        }
    }
    .map_err(plot_error)
}

/// The start marker (a green circle with a black rim) centred on `c`, pixels.
pub fn start_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    c: (i32, i32),
) -> Result<()> {
    area.draw(&Circle::new(c, 8, START.filled()))
        .map_err(plot_error)?;
    area.draw(&Circle::new(c, 8, BLACK.stroke_width(2)))
        .map_err(plot_error)
}

/// The end marker (a yellow square with a black rim) centred on `c`, pixels.
pub fn end_marker<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, c: (i32, i32)) -> Result<()> {
    let (x, y) = c;
    let corners = [(x - 7, y - 7), (x + 7, y + 7)];
    area.draw(&Rectangle::new(corners, END.filled()))
        .map_err(plot_error)?;
    area.draw(&Rectangle::new(corners, BLACK.stroke_width(2)))
        .map_err(plot_error)
}

/// Start and end markers at the first and last point of `path` (metres).
pub fn start_end<DB: DrawingBackend>(chart: &Chart<'_, DB>, path: &[(f64, f64)]) -> Result<()> {
    let area = chart.plotting_area().strip_coord_spec();
    if let (Some(first), Some(last)) = (path.first(), path.last()) {
        let (b0, b1) = (
            chart.plotting_area().map_coordinate(first),
            chart.plotting_area().map_coordinate(last),
        );
        let base = chart.plotting_area().get_base_pixel();
        let local = |p: (i32, i32)| (p.0 - base.0, p.1 - base.1);
        start_marker(&area, local(b0))?;
        end_marker(&area, local(b1))?;
    }
    Ok(())
}

/// A scale bar of a round length (about a fifth of the width) at the lower left of the
/// plotting area, on a white plate, labelled with its length in metres.
pub fn scale_bar<DB: DrawingBackend>(chart: &Chart<'_, DB>) -> Result<()> {
    let plot = chart.plotting_area();
    let (xr, _) = (plot.get_x_range(), plot.get_y_range());
    let (w, h) = plot.dim_in_pixel();
    let m_per_px = (xr.end - xr.start) / f64::from(w.max(1));
    let length = nice_length(0.2 * (xr.end - xr.start));
    let px = (length / m_per_px).round() as i32;
    let area = plot.strip_coord_spec();
    let (x, y) = (16, h as i32 - 16);
    let label = if length >= 1.0 {
        format!("{length:.0} m")
    } else {
        format!("{length} m")
    };
    area.draw(&Rectangle::new(
        [(x - 8, y - 34), (x + px + 8, y + 8)],
        WHITE.mix(0.85).filled(),
    ))
    .map_err(plot_error)?;
    area.draw(&Rectangle::new([(x, y - 6), (x + px, y)], BLACK.filled()))
        .map_err(plot_error)?;
    area.draw(&Text::new(
        label,
        (x + px / 2, y - 9),
        TextStyle::from((FONT, 15).into_font()).pos(Pos::new(HPos::Center, VPos::Bottom)),
    ))
    .map_err(plot_error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nice_lengths_are_one_two_five() {
        for (limit, want) in [(0.3, 0.2), (1.0, 1.0), (4.9, 2.0), (7.0, 5.0), (43.0, 20.0)] {
            assert!((nice_length(limit) - want).abs() < 1e-12, "{limit}");
        }
    }

    #[test]
    fn equal_aspect_gives_square_pixels() {
        let ((x0, x1), (y0, y1)) = equal_aspect((0.0, 10.0), (0.0, 2.0), 400, 200);
        assert!(((x1 - x0) / 400.0 - (y1 - y0) / 200.0).abs() < 1e-12);
        assert_eq!((x0, x1), (0.0, 10.0), "the wider range is kept");
        assert!((0.5 * (y0 + y1) - 1.0).abs() < 1e-12, "centred");
    }
}

/// Reading pictures back in tests.
#[cfg(test)]
pub mod check {
    /// A decoded 8-bit RGB PNG: width, height, pixels.
    pub struct Rgb {
        /// Columns.
        pub w: u32,
        /// Rows.
        pub h: u32,
        /// `w · h · 3` bytes, rows top to bottom.
        pub px: Vec<u8>,
    }

    impl Rgb {
        /// Reads an RGB PNG.
        pub fn read(path: &std::path::Path) -> Self {
            let decoder = png::Decoder::new(std::io::BufReader::new(
                std::fs::File::open(path).expect("the picture exists"),
            ));
            let mut reader = decoder.read_info().expect("a PNG");
            let mut px = vec![0; reader.output_buffer_size()];
            let info = reader.next_frame(&mut px).expect("one frame");
            assert_eq!(info.color_type, png::ColorType::Rgb);
            px.truncate(info.buffer_size());
            Self {
                w: info.width,
                h: info.height,
                px,
            }
        }

        /// Pixels of exactly `colour` in the rectangle `x0 .. x1` × `y0 .. y1`.
        pub fn count(&self, colour: [u8; 3], (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
            self.matching(|p| p == colour, (x0, x1), (y0, y1))
        }

        /// Dark pixels (every channel below 100: text, axes) in a rectangle.
        pub fn dark(&self, (x0, x1): (u32, u32), (y0, y1): (u32, u32)) -> usize {
            self.matching(|p| p.iter().all(|c| *c < 100), (x0, x1), (y0, y1))
        }

        fn matching(
            &self,
            f: impl Fn([u8; 3]) -> bool,
            (x0, x1): (u32, u32),
            (y0, y1): (u32, u32),
        ) -> usize {
            let mut n = 0;
            for y in y0..y1.min(self.h) {
                for x in x0..x1.min(self.w) {
                    let i = 3 * (y * self.w + x) as usize;
                    if f([self.px[i], self.px[i + 1], self.px[i + 2]]) {
                        n += 1;
                    }
                }
            }
            n
        }

        /// The whole picture as a rectangle.
        pub fn all(&self) -> ((u32, u32), (u32, u32)) {
            ((0, self.w), (0, self.h))
        }
    }
}
