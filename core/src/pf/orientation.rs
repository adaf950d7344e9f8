//! Which headings are worth a global search: the scan's wall directions against the
//! map's (the angle-histogram method of Weiss, Wetzler and von Puttkamer 1994).
//!
//! Both the scan and the map are reduced to a histogram of local line directions, modulo
//! π, in bins of one degree: for each end point (each occupied cell of the map) the
//! principal axis of its neighbours (end points within [`NEIGHBOUR_M`] and a few beams
//! apart; occupied cells of its 5 × 5 neighbourhood) gives a direction,
//! `½ · atan2(2 Sxy, Sxx − Syy)`, weighted by how line-like the neighbours are
//! (`√((Sxx − Syy)² + 4 Sxy²) / (Sxx + Syy)`, 1 on a line, 0 on a blob). Turning the
//! robot by `θ` turns every scan direction by `θ`, so the circular correlation
//! `C(s) = Σ_b H_scan(b) · H_map(b + s)` peaks at the robot's heading modulo π (and, in
//! rectilinear buildings, modulo π / 2). The peaks of `C`, each taken as `s` and `s + π`,
//! are the heading windows the search visits.
//!
//! No allocation: three arrays of [`BINS`] numbers on the stack.

use super::correlation::ScanPoint;
use crate::grid::GridView;

/// Bins of the histograms over [0, π): one degree each.
pub const BINS: usize = 180;
/// Scan neighbours are end points closer than this to the point, metres.
pub const NEIGHBOUR_M: f32 = 0.25;
/// Scan neighbours are at most this many points before or after the point.
const NEIGHBOUR_POINTS: usize = 4;
/// A direction counts when its line-likeness is at least this (0..1).
const MIN_LINEARITY: f32 = 0.6;

/// A histogram of line directions modulo π, [`BINS`] bins.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionHistogram {
    bins: [f32; BINS],
    /// Sum of the weights put in.
    pub total: f32,
}

impl Default for DirectionHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl DirectionHistogram {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            bins: [0.0; BINS],
            total: 0.0,
        }
    }

    /// The bins.
    pub fn bins(&self) -> &[f32; BINS] {
        &self.bins
    }

    /// Adds the principal direction of the second moments `(sxx, syy, sxy)` (about the
    /// centre) when line-like enough.
    fn add_moments(&mut self, sxx: f32, syy: f32, sxy: f32) {
        let trace = sxx + syy;
        if trace.is_nan() || trace <= 0.0 {
            return;
        }
        let d = sxx - syy;
        let linearity = libm::sqrtf(d * d + 4.0 * sxy * sxy) / trace;
        if linearity.is_nan() || linearity < MIN_LINEARITY {
            return;
        }
        let phi = 0.5 * libm::atan2f(2.0 * sxy, d); // (−π/2, π/2]
        let pi = core::f32::consts::PI;
        let u = (phi + pi) * (BINS as f32 / pi);
        if !u.is_finite() {
            return;
        }
        let b = (u as usize) % BINS;
        if let Some(bin) = self.bins.get_mut(b) {
            *bin += linearity;
            self.total += linearity;
        }
    }

    /// The directions of the scan's end points (robot frame, in beam order).
    pub fn of_scan(points: &[ScanPoint]) -> Self {
        let mut h = Self::new();
        let r2 = NEIGHBOUR_M * NEIGHBOUR_M;
        for (i, p) in points.iter().enumerate() {
            let (px, py) = (p.x, p.y);
            let lo = i.saturating_sub(NEIGHBOUR_POINTS);
            let hi = (i + NEIGHBOUR_POINTS + 1).min(points.len());
            let near = || {
                points
                    .get(lo..hi)
                    .unwrap_or(&[])
                    .iter()
                    .map(|q| (q.x, q.y))
                    .filter(move |(x, y)| (x - px) * (x - px) + (y - py) * (y - py) < r2)
            };
            let (mut n, mut mx, mut my) = (0.0f32, 0.0f32, 0.0f32);
            for (x, y) in near() {
                n += 1.0;
                mx += x;
                my += y;
            }
            if n < 3.0 {
                continue;
            }
            let (mx, my) = (mx / n, my / n);
            let (mut sxx, mut syy, mut sxy) = (0.0f32, 0.0f32, 0.0f32);
            for (x, y) in near() {
                let (dx, dy) = (x - mx, y - my);
                sxx += dx * dx;
                syy += dy * dy;
                sxy += dx * dy;
            }
            h.add_moments(sxx, syy, sxy);
        }
        h
    }

    /// The directions of the map's walls: every occupied cell with its occupied 5 × 5
    /// neighbourhood. One pass over the map (≈ 10 instructions a cell) plus 25 look-ups
    /// per occupied cell.
    pub fn of_map(map: &GridView<'_>) -> Self {
        let mut h = Self::new();
        let g = map.geometry();
        let (w, ht) = (g.width as i32, g.height as i32);
        for y in 0..ht {
            for x in 0..w {
                if !map.is_occupied(x, y) {
                    continue;
                }
                let (mut n, mut mx, mut my) = (0i32, 0i32, 0i32);
                let (mut sxx, mut syy, mut sxy) = (0i32, 0i32, 0i32);
                for dy in -2i32..=2 {
                    for dx in -2i32..=2 {
                        if map.is_occupied(x + dx, y + dy) {
                            n += 1;
                            mx += dx;
                            my += dy;
                            sxx += dx * dx;
                            syy += dy * dy;
                            sxy += dx * dy;
                        }
                    }
                }
                if n < 3 {
                    continue;
                }
                let nf = n as f32;
                let (cx, cy) = (mx as f32 / nf, my as f32 / nf);
                h.add_moments(
                    sxx as f32 - nf * cx * cx,
                    syy as f32 - nf * cy * cy,
                    sxy as f32 - nf * cx * cy,
                );
            }
        }
        h
    }

    /// The bins smoothed with the circular kernel `[1, 2, 1] / 4`.
    fn smoothed(&self) -> [f32; BINS] {
        let mut out = [0.0f32; BINS];
        for (i, o) in out.iter_mut().enumerate() {
            let at = |j: usize| self.bins.get(j % BINS).copied().unwrap_or(0.0);
            *o = 0.25 * at(i + BINS - 1) + 0.5 * at(i) + 0.25 * at(i + 1);
        }
        out
    }
}

/// The circular correlation `C(s) = Σ_b scan(b) · map(b + s)`, `s` in degrees over
/// [0, 180): `C(s)` is high when turning the scan by `s` aligns its directions with the
/// map's. Both histograms are smoothed first.
pub fn correlate(scan: &DirectionHistogram, map: &DirectionHistogram) -> [f32; BINS] {
    let (a, mut b) = (scan.smoothed(), map.smoothed());
    // The map's directions compressed (square root): a building's main directions
    // dominate its histogram, and a scan taken where the walls run otherwise must still
    // find them.
    for v in b.iter_mut() {
        *v = libm::sqrtf(*v);
    }
    let mut c = [0.0f32; BINS];
    for (s, cs) in c.iter_mut().enumerate() {
        let mut acc = 0.0f32;
        for (i, ai) in a.iter().enumerate() {
            acc += ai * b.get((i + s) % BINS).copied().unwrap_or(0.0);
        }
        *cs = acc;
    }
    c
}

/// The `n` highest local maxima of the circular `c`, at least `separation` bins apart,
/// best first, as `(bin, value)`; fewer when `c` has fewer.
pub fn peaks<const N: usize>(c: &[f32; BINS], separation: usize) -> ([(usize, f32); N], usize) {
    let mut out = [(0usize, 0.0f32); N];
    let mut len = 0;
    for _ in 0..N {
        let mut best: Option<(usize, f32)> = None;
        for (i, &v) in c.iter().enumerate() {
            let prev = c.get((i + BINS - 1) % BINS).copied().unwrap_or(0.0);
            let next = c.get((i + 1) % BINS).copied().unwrap_or(0.0);
            if !(v > 0.0 && v >= prev && v >= next) {
                continue;
            }
            let taken = out.get(..len).unwrap_or(&[]).iter().any(|&(j, _)| {
                let d = i.abs_diff(j);
                d.min(BINS - d) < separation
            });
            if !taken && best.is_none_or(|(_, b)| v > b) {
                best = Some((i, v));
            }
        }
        let Some(b) = best else { break };
        if let Some(slot) = out.get_mut(len) {
            *slot = b;
            len += 1;
        }
    }
    (out, len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridGeometry;

    /// A rectilinear room's map and a scan of its walls turned by `turn`: the
    /// correlation peaks at `turn` modulo 90°.
    #[test]
    fn correlation_peaks_at_the_turn() {
        let (w, h) = (80usize, 60usize);
        let mut cells = vec![-60i8; w * h];
        for x in 0..w {
            cells[5 * w + x] = 60;
            cells[50 * w + x] = 60;
        }
        for y in 0..h {
            cells[y * w + 10] = 60;
            cells[y * w + 70] = 60;
        }
        let view = GridView::new(&cells, GridGeometry::centred(w, h, 0.05), 20).unwrap();
        let map = DirectionHistogram::of_map(&view);
        assert!(map.total > 100.0);
        for turn_deg in [0.0f32, 17.0, 33.0, 71.0] {
            // Walls at x = ±1.5, y = ±1.0 (metres) seen from the centre, turned by `turn`.
            let t = -turn_deg.to_radians();
            let pts: Vec<ScanPoint> = (0..360)
                .map(|i| {
                    let a = (i as f32).to_radians();
                    let (c, s) = (a.cos(), a.sin());
                    let r = (1.5 / c.abs().max(1e-6)).min(1.0 / s.abs().max(1e-6));
                    let (x, y) = (r * c, r * s);
                    ScanPoint {
                        x: t.cos() * x - t.sin() * y,
                        y: t.sin() * x + t.cos() * y,
                        weight: 1,
                        range: r,
                    }
                })
                .collect();
            let scan = DirectionHistogram::of_scan(&pts);
            let c = correlate(&scan, &map);
            let (p, n) = peaks::<2>(&c, 10);
            assert_eq!(n, 2);
            let d = |a: usize, b: f32| {
                let d = (a as f32 - b).rem_euclid(90.0);
                d.min(90.0 - d)
            };
            assert!(d(p[0].0, turn_deg) <= 1.0, "{turn_deg}: {p:?}");
            assert!(d(p[1].0, turn_deg) <= 1.0, "{turn_deg}: {p:?}");
        }
    }
}
