//! The picture of a THOR dead-reckoning run.

use anyhow::Result;
use microslam::geometry::Pose2;
use plotters::prelude::*;
use std::path::Path;

/// Picture size, pixels.
const SIZE: u32 = 800;

/// The THOR dead-reckoning trajectory as an 800 × 800 PNG with a 1 m grid.
pub fn draw_trajectory(path: &Path, traj: &[(f64, Pose2<f64>)]) -> Result<()> {
    let mut rgb = vec![0u8; (SIZE * SIZE * 3) as usize];
    draw_on(BitMapBackend::with_buffer(&mut rgb, (SIZE, SIZE)), traj)?;
    super::write_png(path, SIZE, SIZE, &rgb)
}

/// Draws the 1 m grid, each line once, then the trajectory, on any plotters backend.
fn draw_on<DB: DrawingBackend>(backend: DB, traj: &[(f64, Pose2<f64>)]) -> Result<()> {
    let plot_error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (_, p) in traj {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    if traj.is_empty() {
        (x0, x1, y0, y1) = (0.0, 0.0, 0.0, 0.0);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1.0);
    let (x0, x1, y0, y1) = (x0 - pad, x1 + pad, y0 - pad, y1 + pad);
    let root = backend.into_drawing_area();
    root.fill(&WHITE).map_err(plot_error)?;
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(plot_error)?;
    // No axes: the plotters build here has no font backend (a 1 m grid instead).
    let grid_style = ShapeStyle::from(&RGBColor(220, 220, 220)).stroke_width(1);
    for gx in x0.ceil() as i64..=x1.floor() as i64 {
        let gx = gx as f64;
        chart
            .draw_series(LineSeries::new([(gx, y0), (gx, y1)], grid_style))
            .map_err(plot_error)?;
    }
    for gy in y0.ceil() as i64..=y1.floor() as i64 {
        let gy = gy as f64;
        chart
            .draw_series(LineSeries::new([(x0, gy), (x1, gy)], grid_style))
            .map_err(plot_error)?;
    }
    chart
        .draw_series(LineSeries::new(traj.iter().map(|(_, p)| (p.x, p.y)), &RED))
        .map_err(plot_error)?;
    root.present().map_err(plot_error)?;
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
