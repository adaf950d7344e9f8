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
    use plotters_backend::{
        BackendColor, BackendCoord, BackendStyle, DrawingBackend, DrawingErrorKind,
    };
    use std::cell::Cell;

    /// Counts what is drawn, draws nothing.
    struct Counting<'a> {
        paths: &'a Cell<usize>,
        presents: &'a Cell<usize>,
    }

    impl DrawingBackend for Counting<'_> {
        type ErrorType = std::io::Error;
        fn get_size(&self) -> (u32, u32) {
            (SIZE, SIZE)
        }
        fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<std::io::Error>> {
            Ok(())
        }
        fn present(&mut self) -> Result<(), DrawingErrorKind<std::io::Error>> {
            self.presents.set(self.presents.get() + 1);
            Ok(())
        }
        fn draw_pixel(
            &mut self,
            _: BackendCoord,
            _: BackendColor,
        ) -> Result<(), DrawingErrorKind<std::io::Error>> {
            Ok(())
        }
        fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
            &mut self,
            _: I,
            _: &S,
        ) -> Result<(), DrawingErrorKind<std::io::Error>> {
            self.paths.set(self.paths.get() + 1);
            Ok(())
        }
    }

    #[test]
    fn every_grid_line_and_the_trajectory_are_drawn_once() {
        // 0 … 9 m in x, 0 … 4 m in y: padded by 0.45 m, grid lines at x = 0 … 9
        // (10) and y = 0 … 4 (5), and one trajectory.
        let traj: Vec<(f64, Pose2<f64>)> = (0..=90)
            .map(|i| {
                let t = f64::from(i) / 10.0;
                (t, Pose2::new(t, 4.0 * t / 9.0, 0.0))
            })
            .collect();
        let (paths, presents) = (Cell::new(0), Cell::new(0));
        let backend = Counting {
            paths: &paths,
            presents: &presents,
        };
        draw_on(backend, &traj).expect("drawing succeeds");
        assert_eq!(paths.get(), 10 + 5 + 1);
        assert!(presents.get() >= 1);
    }
}
