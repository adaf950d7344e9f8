//! The picture of a THOR dead-reckoning run.

use super::figure::{self, ESTIMATE, ESTIMATE_WIDTH, MapLayout, Mark};
use anyhow::Result;
use microslam::geometry::Pose2;
use plotters::prelude::*;
use std::path::Path;

/// Size of the (square) plotting area, pixels.
const PLOT_PX: u32 = 720;

/// The THOR dead-reckoning trajectory as a PNG: axes in metres, a legend, a scale bar,
/// start and end markers; `title` above it.
pub fn draw_trajectory(path: &Path, traj: &[(f64, Pose2<f64>)], title: &str) -> Result<()> {
    figure::register_font()?;
    let (w, h) = MapLayout::MAP.image_size(PLOT_PX, PLOT_PX);
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    draw_on(BitMapBackend::with_buffer(&mut rgb, (w, h)), traj, title)?;
    super::write_png(path, w, h, &rgb)
}

/// Draws the picture on any plotters backend.
fn draw_on<DB: DrawingBackend>(backend: DB, traj: &[(f64, Pose2<f64>)], title: &str) -> Result<()> {
    let e = figure::plot_error;
    let points: Vec<(f64, f64)> = traj.iter().map(|(_, p)| (p.x, p.y)).collect();
    let [x0, x1, y0, y1] = figure::bounds(&points).unwrap_or([-1.0, 1.0, -1.0, 1.0]);
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1.0);
    let layout = MapLayout::MAP;
    let (pw, ph) = layout.plot_size(backend.get_size().0, backend.get_size().1);
    let (x, y) = figure::equal_aspect((x0 - pad, x1 + pad), (y0 - pad, y1 + pad), pw, ph);
    let root = backend.into_drawing_area();
    root.fill(&WHITE).map_err(e)?;
    let (mut chart, side) = figure::map_chart(&root, &layout, title, x, y)?;
    figure::grid_lines(&mut chart)?;
    figure::path(&chart, &points, ESTIMATE, ESTIMATE_WIDTH)?;
    figure::start_end(&chart, &points)?;
    figure::scale_bar(&chart)?;
    let top = i32::try_from(layout.title + layout.margin).unwrap_or(0);
    figure::legend(
        &side,
        (6, top),
        &[
            (
                Mark::Line(ESTIMATE, ESTIMATE_WIDTH),
                "dead reckoning (encoders + IMU)",
            ),
            (Mark::Start, "start"),
            (Mark::End, "end"),
        ],
    )?;
    root.present().map_err(e)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::figure::check::Rgb;
    use crate::output::figure::{END, START};

    #[test]
    fn the_dead_reckoning_picture_is_labelled() {
        // 0 … 9 m in x, 0 … 4 m in y.
        let traj: Vec<(f64, Pose2<f64>)> = (0..=90)
            .map(|i| {
                let t = f64::from(i) / 10.0;
                (t, Pose2::new(t, 4.0 * t / 9.0, 0.0))
            })
            .collect();
        let dir = tempfile::tempdir().expect("temporary folder");
        let path = dir.path().join("trajectory.png");
        draw_trajectory(&path, &traj, "THOR run 20").expect("drawn");
        let img = Rgb::read(&path);
        let layout = MapLayout::MAP;
        assert_eq!((img.w, img.h), layout.image_size(PLOT_PX, PLOT_PX));
        let (px0, py0) = (
            layout.margin + layout.y_labels,
            layout.margin + layout.title,
        );
        let (px1, py1) = (px0 + PLOT_PX, py0 + PLOT_PX);
        let colour = |c: RGBColor| [c.0, c.1, c.2];
        // The 9 m diagonal spans most of the 720-pixel plot, 2 pixels wide.
        assert!(img.count(colour(ESTIMATE), (px0, px1), (py0, py1)) > 1000);
        assert!(img.count(colour(START), (px0, px1), (py0, py1)) > 50);
        assert!(img.count(colour(END), (px0, px1), (py0, py1)) > 50);
        assert!(img.dark((px0, px1), (0, py0)) > 150, "title");
        assert!(
            img.dark((px0, px1), (py1 + 8, img.h)) > 120,
            "x axis labels"
        );
        assert!(img.dark((0, px0 - 8), (py0, py1)) > 120, "y axis labels");
        assert!(
            img.dark((img.w - layout.legend, img.w), (0, img.h)) > 400,
            "legend"
        );
    }
}
