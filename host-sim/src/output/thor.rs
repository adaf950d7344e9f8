//! The picture of a THOR dead-reckoning run.

use anyhow::Result;
use microslam::geometry::Pose2;
use std::path::Path;

/// The THOR dead-reckoning trajectory as an 800 × 800 PNG with a 1 m grid.
pub fn draw_trajectory(path: &Path, traj: &[(f64, Pose2<f64>)]) -> Result<()> {
    use plotters::prelude::*;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (_, p) in traj {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1.0);
    let mut rgb = vec![0u8; 800 * 800 * 3];
    let root = BitMapBackend::with_buffer(&mut rgb, (800, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .build_cartesian_2d(x0 - pad..x1 + pad, y0 - pad..y1 + pad)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // No axes: the plotters build here has no font backend (a 1 m grid instead).
    let grid_style = ShapeStyle::from(&RGBColor(220, 220, 220)).stroke_width(1);
    for gx in (x0 - pad).ceil() as i64..=(x1 + pad).floor() as i64 {
        let gx = gx as f64;
        chart
            .draw_series(LineSeries::new(
                [(gx, y0 - pad), (gx, y1 + pad)],
                grid_style,
            ))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        // No axes: the plotters build here has no font backend (a 1 m grid instead).
        let grid_style = ShapeStyle::from(&RGBColor(220, 220, 220)).stroke_width(1);
        for gx in (x0 - pad).ceil() as i64..=(x1 + pad).floor() as i64 {
            let gx = gx as f64;
            chart
                .draw_series(LineSeries::new(
                    [(gx, y0 - pad), (gx, y1 + pad)],
                    grid_style,
                ))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
        for gy in (y0 - pad).ceil() as i64..=(y1 + pad).floor() as i64 {
            let gy = gy as f64;
            chart
                .draw_series(LineSeries::new(
                    [(x0 - pad, gy), (x1 + pad, gy)],
                    grid_style,
                ))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
        chart
            .draw_series(LineSeries::new(traj.iter().map(|(_, p)| (p.x, p.y)), &RED))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    }
    chart
        .draw_series(LineSeries::new(traj.iter().map(|(_, p)| (p.x, p.y)), &RED))
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    drop(chart);
    drop(root);
    super::write_png(path, 800, 800, &rgb)
}
