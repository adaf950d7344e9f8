//! The brute-force reference of the search: every heading, every free cell, every beam.

use super::beams::prepare;
use super::bound::{block_free, leaf_score};
use super::hypotheses::below_relative;
use super::search::pose_at;
#[cfg(doc)]
use super::search::search;
use super::tables::{Rotations, end_cells, heading_angle};
use super::{
    GlobalError, GlobalSearchConfig, Hypotheses, Hypothesis, MAX_SEARCH_BEAMS, NODE_WORK,
    SearchReport,
};
use crate::grid::{GridView, MaxPoolLayers};
use crate::pf::correlation::ScanPoint;

/// The brute-force reference of [`search`]: every heading, every free cell, every beam
/// (no bounds, no budget). Same candidates and scores; for tests on small maps.
pub fn search_brute_force<const N: usize>(
    map: &GridView<'_>,
    layers: &MaxPoolLayers<'_>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    out: &mut Hypotheses<N>,
) -> Result<SearchReport, GlobalError> {
    let (sel, step, headings) = prepare(map, layers, points, config)?;
    out.clear();
    let min_score = libm::ceilf(config.min_score_fraction * sel.total as f32) as u32;
    let g = *map.geometry();
    let mut cells = [(0i32, 0i32, 0u32); MAX_SEARCH_BEAMS];
    let mut nodes = 0u32;
    let rotations = Rotations::new(step);
    for j in 0..headings {
        let theta = heading_angle(j, step);
        end_cells(&sel, rotations.at(j), &mut cells);
        let cells = cells.get(..sel.len).unwrap_or(&[]);
        for y in 0..g.height as i32 {
            for x in 0..g.width as i32 {
                if !block_free(map, layers, 0, x, y) {
                    continue;
                }
                nodes = nodes.saturating_add(1);
                let s = leaf_score(map, cells, x, y);
                if s >= min_score.max(1) {
                    out.offer(
                        Hypothesis {
                            pose: pose_at(&g, x, y, theta),
                            score: s,
                        },
                        config.separation_m,
                        config.separation_rad,
                    );
                }
            }
        }
    }
    out.keep_above(below_relative(config, out.best()).max(min_score.saturating_sub(1)));
    Ok(SearchReport {
        beams: sel.len as u16,
        extent_m: sel.extent,
        heading_step: step,
        headings,
        heading_windows: 1,
        headings_searched: headings,
        nodes,
        // Every beam of every leaf.
        work: nodes.saturating_mul(sel.len as u32 + NODE_WORK),
        leaves: nodes,
        rotations: headings,
        nodes_per_level: [nodes, 0, 0, 0, 0, 0, 0, 0, 0],
        total_weight: sel.total,
        min_score,
        passes: 1,
        full_turn: false,
        complete: true,
    })
}
