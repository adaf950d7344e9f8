//! Pictures of floor texture maps (`host-sim texture`): one or more square colour maps
//! side by side, each under axes in metres with a scale bar, a title, and a note that
//! explains the black cells.

use super::figure::{self, FONT};
use anyhow::{Result, anyhow};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// Smallest edge of one map's plotting area, pixels (maps are scaled up by a whole factor).
const PANEL_PX: u32 = 360;

/// Writes `panels` (each a title and a `n` × `n` RGB image, rows from the top, covering
/// `[-half_m, half_m]²`) side by side as one PNG under `title`, with `note` below.
pub fn draw_floor_maps(
    path: &Path,
    title: &str,
    panels: &[(&str, &[u8])],
    n: u32,
    half_m: f64,
    note: &str,
) -> Result<()> {
    figure::register_font()?;
    let n = n.max(1);
    let scale = PANEL_PX.div_ceil(n).max(1);
    let side = n * scale;
    let (margin, x_labels, y_labels, caption, head, foot_h) = (12, 48, 64, 28, 36, 40);
    let panel_w = side + y_labels + 2 * margin;
    let panel_h = side + x_labels + 2 * margin + caption;
    let k = u32::try_from(panels.len().max(1)).map_err(|_| anyhow!("too many panels"))?;
    let (w, h) = (panel_w * k, head + panel_h + foot_h);
    let mut buf = vec![0u8; (w as usize) * (h as usize) * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let e = figure::plot_error;
        root.fill(&WHITE).map_err(e)?;
        let centred = |size: u32| {
            TextStyle::from((FONT, size).into_font()).pos(Pos::new(HPos::Center, VPos::Top))
        };
        root.draw(&Text::new(
            title.to_string(),
            (w as i32 / 2, 8),
            centred(22),
        ))
        .map_err(e)?;
        root.draw(&Text::new(
            note.to_string(),
            (14, (head + panel_h + 12) as i32),
            (FONT, 15),
        ))
        .map_err(e)?;
        for (i, (name, rgb)) in panels.iter().enumerate() {
            let x0 = panel_w * i as u32;
            let column = root.clone().shrink((x0, head), (panel_w, panel_h));
            let mid = (margin + y_labels + side / 2) as i32;
            column
                .draw(&Text::new(name.to_string(), (mid, 4), centred(17)))
                .map_err(e)?;
            let mut chart = ChartBuilder::on(&column.margin(caption, 0, 0, 0))
                .margin(margin)
                .x_label_area_size(x_labels)
                .y_label_area_size(y_labels)
                .build_cartesian_2d(-half_m..half_m, -half_m..half_m)
                .map_err(e)?;
            chart
                .configure_mesh()
                .disable_mesh()
                .x_desc("x (m)")
                .y_desc("y (m)")
                .x_label_formatter(&figure::tick)
                .y_label_formatter(&figure::tick)
                .label_style((FONT, 14))
                .axis_desc_style((FONT, 15))
                .draw()
                .map_err(e)?;
            let (pw, ph) = chart.plotting_area().dim_in_pixel();
            let image = scaled(rgb, n, pw, ph);
            let element = BitMapElement::with_owned_buffer((-half_m, half_m), (pw, ph), image)
                .ok_or_else(|| anyhow!("floor map image of the wrong size"))?;
            chart.plotting_area().draw(&element).map_err(e)?;
            figure::scale_bar(&chart)?;
        }
        root.present().map_err(e)?;
    }
    super::write_png(path, w, h, &buf)
}

/// `rgb` (`n` × `n`) resampled to `w` × `h` by nearest neighbour.
fn scaled(rgb: &[u8], n: u32, w: u32, h: u32) -> Vec<u8> {
    let (n, w, h) = (n as usize, w.max(1) as usize, h.max(1) as usize);
    let mut out = Vec::with_capacity(w * h * 3);
    for v in 0..h {
        let r = (v * n / h).min(n - 1);
        for u in 0..w {
            let c = (u * n / w).min(n - 1);
            let i = 3 * (r * n + c);
            out.extend_from_slice(rgb.get(i..i + 3).unwrap_or(&[0, 0, 0]));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::figure::check::Rgb;

    #[test]
    fn floor_maps_stand_side_by_side_under_axes() {
        // Two 40 × 40 maps: red and green.
        let red: Vec<u8> = (0..40 * 40).flat_map(|_| [200, 0, 0]).collect();
        let green: Vec<u8> = (0..40 * 40).flat_map(|_| [0, 200, 0]).collect();
        let dir = tempfile::tempdir().expect("temporary folder");
        let path = dir.path().join("t.png");
        draw_floor_maps(
            &path,
            "Floor",
            &[("red", &red), ("green", &green)],
            40,
            2.0,
            "black: no point",
        )
        .expect("drawn");
        let img = Rgb::read(&path);
        let half = img.w / 2;
        let all = (0, img.h);
        // Each map fills a 360-pixel square (scaled 9×) in its own half.
        assert_eq!(
            (img.w, img.h),
            (2 * (360 + 64 + 24), 36 + 360 + 48 + 24 + 28 + 40)
        );
        assert!(img.count([200, 0, 0], (0, half), all) >= 350 * 350);
        assert!(img.count([0, 200, 0], (half, img.w), all) >= 350 * 350);
        assert_eq!(img.count([200, 0, 0], (half, img.w), all), 0);
        // Axis labels left of and below each map, the title and the note.
        assert!(
            img.dark((0, 70), (60, img.h - 120)) > 200,
            "y labels, left map"
        );
        assert!(
            img.dark((half, half + 70), (60, img.h - 120)) > 200,
            "y labels, right map"
        );
        assert!(
            img.dark((0, img.w), (img.h - 110, img.h - 40)) > 300,
            "x labels"
        );
        assert!(img.dark((0, img.w), (0, 30)) > 50, "title");
        assert!(img.dark((0, img.w), (img.h - 40, img.h)) > 50, "note");
    }
}
