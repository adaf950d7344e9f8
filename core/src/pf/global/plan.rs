//! What each pass of a search covers: the heading windows around the peaks of the
//! wall-direction correlation (or every heading), the rest of the turn outside them,
//! and the minimum scores the passes step down through.

use super::{GlobalSearchConfig, MAX_HEADING_PEAKS};
use crate::grid::GridView;
use crate::pf::correlation::ScanPoint;

/// Most heading windows: two headings per peak, each split in two at most where it
/// wraps around.
pub(super) const MAX_WINDOWS: usize = 4 * MAX_HEADING_PEAKS;
/// A scan whose line-like end points weigh less than this in all (about as many
/// points) searches every heading: its wall directions say too little.
const MIN_SCAN_LINES: f32 = 8.0;

/// The heading windows `(first, last)` (indices into the `headings` candidates of
/// `step`) the search visits, best peak first; their number. One window of every
/// heading when the prior is off or the scan shows too few lines.
pub(super) fn heading_windows(
    map: &GridView<'_>,
    walls: Option<&crate::pf::orientation::DirectionHistogram>,
    points: &[ScanPoint],
    config: &GlobalSearchConfig,
    step: f32,
    headings: u32,
    out: &mut [(u32, u32); MAX_WINDOWS],
) -> usize {
    use crate::pf::orientation::{BINS, DirectionHistogram, correlate, peaks};
    let last = headings.saturating_sub(1);
    let every = |out: &mut [(u32, u32); MAX_WINDOWS]| {
        if let Some(w) = out.first_mut() {
            *w = (0, last);
        }
        1
    };
    if config.heading_peaks == 0 {
        return every(out);
    }
    let scan = DirectionHistogram::of_scan(points);
    if scan.total.is_nan() || scan.total < MIN_SCAN_LINES {
        return every(out);
    }
    let computed;
    let walls = match walls {
        Some(w) => w,
        None => {
            computed = DirectionHistogram::of_map(map);
            &computed
        }
    };
    if walls.total.is_nan() || walls.total <= 0.0 {
        return every(out);
    }
    let c = correlate(&scan, walls);
    let bin = core::f32::consts::PI / BINS as f32;
    let separation = (libm::ceilf(2.0 * config.heading_window / bin) as usize).clamp(3, BINS / 4);
    let (found, n) = peaks::<MAX_HEADING_PEAKS>(&c, separation);
    let n = n.min(usize::from(config.heading_peaks));
    let count = headings as f32;
    let half = config.heading_window / step;
    if half.is_nan() || 2.0 * half + 1.0 >= count {
        return every(out);
    }
    let mut len = 0;
    let mut push = |lo: u32, hi: u32| {
        if let Some(slot) = out.get_mut(len) {
            *slot = (lo, hi);
            len += 1;
        }
    };
    for &(b, _) in found.iter().take(n) {
        for turn in [0.0, core::f32::consts::PI] {
            let centre = (b as f32 * bin + turn) / step;
            let lo = libm::floorf(centre - half) as i64;
            let hi = libm::ceilf(centre + half) as i64;
            let n = i64::from(headings);
            let clamp = |v: i64| v.clamp(0, n - 1) as u32;
            if lo < 0 {
                push(clamp(lo + n), last);
                push(0, clamp(hi));
            } else if hi >= n {
                push(clamp(lo), last);
                push(0, clamp(hi - n));
            } else {
                push(clamp(lo), clamp(hi));
            }
        }
    }
    if len == 0 {
        return every(out);
    }
    len
}

/// Writes into `out` the heading intervals outside the `n` windows `windows` (of
/// `headings` in all); returns how many.
pub(super) fn outside(
    windows: &[(u32, u32); MAX_WINDOWS],
    n: usize,
    headings: u32,
    out: &mut [(u32, u32); MAX_WINDOWS + 1],
) -> usize {
    let mut sorted = *windows;
    let sorted = sorted.get_mut(..n).unwrap_or(&mut []);
    // Insertion sort by start: a few windows (and no sort routine in the firmware's flash).
    for i in 1..sorted.len() {
        let mut j = i;
        while j > 0 && sorted.get(j - 1).map(|w| w.0) > sorted.get(j).map(|w| w.0) {
            sorted.swap(j - 1, j);
            j -= 1;
        }
    }
    let mut k = 0;
    let mut next = 0u32;
    for &(lo, hi) in sorted.iter() {
        if lo > next
            && let Some(slot) = out.get_mut(k)
        {
            *slot = (next, lo - 1);
            k += 1;
        }
        next = next.max(hi.saturating_add(1));
    }
    if next < headings
        && let Some(slot) = out.get_mut(k)
    {
        *slot = (next, headings - 1);
        k += 1;
    }
    k
}

/// Most minimum scores a search steps through (the last one is the configured minimum).
const MAX_PASS_FRACTIONS: usize = 64;

/// The first pass's minimum score (fraction of the total weight): never below the
/// configured minimum.
pub(super) fn first_fraction(c: &GlobalSearchConfig) -> f32 {
    c.first_pass_fraction.max(c.min_score_fraction)
}

/// How many minimum scores the passes step through: the first pass's, then one
/// [`GlobalSearchConfig::pass_step`] lower each, down to the minimum.
pub(super) fn pass_fractions(c: &GlobalSearchConfig) -> usize {
    let first = first_fraction(c);
    let mut n = 1;
    while n < MAX_PASS_FRACTIONS && first - n as f32 * c.pass_step > c.min_score_fraction + 1e-6 {
        n += 1;
    }
    // One more at the minimum itself, unless the first pass is already there.
    if first > c.min_score_fraction + 1e-6 {
        n += 1;
    }
    n.min(MAX_PASS_FRACTIONS)
}

/// The minimum score (fraction of the total weight) of the `i`-th of `n` steps.
pub(super) fn pass_fraction(c: &GlobalSearchConfig, i: usize, n: usize) -> f32 {
    let first = first_fraction(c);
    if i + 1 >= n {
        return c.min_score_fraction.min(first);
    }
    (first - i as f32 * c.pass_step).max(c.min_score_fraction)
}

/// The `p`-th pass of a search over `n` minimum scores: `(rest, i)`, the heading set
/// (`false`: the windows; `true`: every heading outside them) and the minimum score's
/// step. Without the full turn the windows alone, at each step in turn. With it, the
/// rest of the turn follows the windows one step behind: windows 0, windows 1, rest 0,
/// windows 2, rest 1, …, rest n − 1. A pass at a high minimum prunes hard even over
/// the whole turn, one at a low minimum prunes little even in the windows: the whole
/// turn at the first minimum costs about what the windows cost two steps lower, and a
/// robot whose wall directions the windows miss is found without them first being
/// searched down to the lowest minimum (`docs/global-localization.md`).
pub(super) fn pass_plan(p: usize, n: usize, full_turn: bool) -> Option<(bool, usize)> {
    if !full_turn {
        return (p < n).then_some((false, p));
    }
    let mut k = 0;
    for t in 0..=n {
        if t < n {
            if k == p {
                return Some((false, t));
            }
            k += 1;
        }
        if t >= 1 {
            if k == p {
                return Some((true, t - 1));
            }
            k += 1;
        }
    }
    None
}
