//! The beams a search uses ([`ScanPoint`]s thinned to at most [`MAX_SEARCH_BEAMS`], in
//! cells), the heading step their farthest one sets, and a search's inputs checked and
//! turned into its beams and candidate headings.

use super::{GlobalError, GlobalSearchConfig, MAX_HEADINGS, MAX_SEARCH_BEAMS};
use crate::grid::{GridView, MaxPoolLayers};
use crate::pf::correlation::ScanPoint;

/// Beams chosen for the search, robot frame.
#[derive(Clone)]
pub(super) struct Selected {
    /// Each beam's weight ([`ScanPoint::weight`]).
    pub(super) weights: [u32; MAX_SEARCH_BEAMS],
    /// Distance of each point from the robot origin, in cells.
    pub(super) rho_cells: [f32; MAX_SEARCH_BEAMS],
    /// Each point divided by the cell size (cells, robot frame).
    pub(super) scaled: [(f32, f32); MAX_SEARCH_BEAMS],
    pub(super) len: usize,
    pub(super) extent: f32,
    pub(super) total: u32,
}

/// The beams the search uses, for cells of `resolution` metres.
fn select(points: &[ScanPoint], config: &GlobalSearchConfig, resolution: f32) -> Selected {
    let mut s = Selected {
        weights: [0; MAX_SEARCH_BEAMS],
        rho_cells: [0.0; MAX_SEARCH_BEAMS],
        scaled: [(0.0, 0.0); MAX_SEARCH_BEAMS],
        len: 0,
        extent: 0.0,
        total: 0,
    };
    let usable = |p: &&ScanPoint| p.range.is_finite() && p.range <= config.max_range;
    let n = points.iter().filter(usable).count();
    let cap = usize::from(config.max_beams).min(MAX_SEARCH_BEAMS);
    if n == 0 || cap == 0 {
        return s;
    }
    let step = n.div_ceil(cap);
    for p in points.iter().filter(usable).step_by(step) {
        if let (Some(w), Some(rho), Some(scaled)) = (
            s.weights.get_mut(s.len),
            s.rho_cells.get_mut(s.len),
            s.scaled.get_mut(s.len),
        ) {
            *w = p.weight;
            *rho = libm::hypotf(p.x, p.y) / resolution;
            *scaled = (p.x / resolution, p.y / resolution);
            s.len += 1;
            s.extent = s.extent.max(p.range);
            s.total = s.total.saturating_add(p.weight);
        }
    }
    s
}

/// The heading step for cells of `resolution` metres and the farthest beam at `extent`
/// metres: `acos(1 − r² / (2 d²))`, the turn that moves that beam's end by one cell.
pub fn heading_step_for(resolution: f32, extent: f32) -> f32 {
    let d = extent.max(resolution);
    libm::acosf(1.0 - resolution * resolution / (2.0 * d * d))
}

/// Checks the inputs and prepares the beams: `(selection, step, headings)`.
pub(super) fn prepare(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
) -> Result<(Selected, f32, u32), GlobalError> {
    if !config.is_valid() {
        return Err(GlobalError::InvalidConfig);
    }
    if !layers.matches(map) {
        return Err(GlobalError::LayersMismatch);
    }
    let res = map.geometry().resolution;
    let sel = select(points, config, res);
    if sel.len == 0 || sel.total == 0 {
        return Err(GlobalError::EmptyScan);
    }
    let wanted = if config.heading_step > 0.0 {
        config.heading_step
    } else {
        heading_step_for(res, sel.extent)
    };
    let turn = 2.0 * core::f32::consts::PI;
    let n = libm::ceilf(turn / wanted.max(1e-6));
    let n = if n.is_finite() && n >= 1.0 {
        (n as u32).min(MAX_HEADINGS)
    } else {
        MAX_HEADINGS
    };
    Ok((sel, turn / n as f32, n))
}
