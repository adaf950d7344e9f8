//! The seed's observation model: map correlation of a scan's end points with the occupied
//! cells, optionally range-weighted, over a `(2k+1) × (2k+1)` window of cell shifts
//! (seed 2, eqs. 21 and 24).
//!
//! `corr(shift) = Σ_i w_i · 1[cell(end point i) + shift is occupied]`, with
//! `w_i = range_i^γ` (γ = 0: the plain count). Weights are fixed point
//! ([`WEIGHT_ONE`] = 1.0) and sums are integers, so every evaluation order gives the same
//! score — the fast search and the brute-force reference agree exactly, on every target.
//!
//! The fast search ([`search_window`]) converts each end point to its cell once per
//! particle (not once per shift), treats the shifts as index offsets into the `2k+1` rows
//! of `2k+1` bytes around it, and adds the beam's weight masked by the occupancy test to
//! all shifts of a row at once: no per-shift coordinate arithmetic, no bounds check per
//! cell, no branch on the map's content, so the compiler vectorises the row. Windows that
//! reach over the grid's edge take a checked path. Identical particles are scored once
//! (in [`ParticleFilter::update`](super::ParticleFilter::update)).
//!
//! Over a map with an occupied-cell bitmap ([`GridView::with_occupancy_bits`], or an
//! [`crate::grid::OccupancyGrid`] with a `BITMAP`) the search is sparse
//! ([`search_window_sparse`]): each window row is cut from the bitmap by one 4-byte read
//! and only its set bits add the beam's weight. Walls are thin, so most rows are empty
//! and the rest hold a few bits: on a Cortex-M4F a third of the byte-wise search's
//! instructions (on x86 the vectorised byte-wise search is the faster one).
//! [`search_window_brute_force`] is the plain triple loop, kept as the reference.

use crate::geometry::{Pose2, sin_cos_f32};
use crate::grid::{GridView, floor_i32};
use crate::sensors::lidar::{BeamDirections, LidarScan};

/// The fixed-point weight that stands for 1.0 (a beam of the unweighted count).
pub const WEIGHT_ONE: u32 = 256;
/// Largest weight of one beam (2²⁰ = range^γ of 4096): keeps sums of up to 4096 beams
/// inside a `u32`.
pub const MAX_WEIGHT: u32 = 1 << 20;
/// Largest half-width `k` of the shift window (15 × 15 shifts).
pub const MAX_SHIFT_WINDOW: u8 = 7;
/// Number of shifts of the largest window.
pub const MAX_SHIFTS: usize =
    (2 * MAX_SHIFT_WINDOW as usize + 1) * (2 * MAX_SHIFT_WINDOW as usize + 1);

/// A usable lidar end point in the robot frame with its correlation weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScanPoint {
    /// x in the robot frame, metres.
    pub x: f32,
    /// y in the robot frame, metres.
    pub y: f32,
    /// Fixed-point weight `range^γ` ([`WEIGHT_ONE`] = 1.0).
    pub weight: u32,
    /// Measured range, metres.
    pub range: f32,
}

/// Up to `B` end points of one scan, prepared once per scan for all particles.
///
/// RAM: 24 · B bytes + 40 (the end points and the beam directions of the lidar,
/// [`BeamDirections`], kept from scan to scan).
#[derive(Clone, Debug)]
pub struct ScanPoints<const B: usize> {
    points: [ScanPoint; B],
    len: usize,
    thinned: bool,
    directions: BeamDirections<B>,
}

impl<const B: usize> Default for ScanPoints<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const B: usize> ScanPoints<B> {
    /// No points.
    pub const fn new() -> Self {
        Self {
            points: [ScanPoint {
                x: 0.0,
                y: 0.0,
                weight: 0,
                range: 0.0,
            }; B],
            len: 0,
            thinned: false,
            directions: BeamDirections::new(),
        }
    }

    /// Replaces the content with the usable beams of `scan`, every `decimation`-th one,
    /// weighted by `range^range_weight_exponent`. When more than `B` beams would be used,
    /// the decimation is raised until they fit ([`ScanPoints::was_thinned`] tells).
    /// Returns the number of points.
    pub fn load(
        &mut self,
        scan: &LidarScan<'_>,
        decimation: usize,
        range_weight_exponent: f32,
    ) -> usize {
        let mut dec = decimation.max(1);
        if B > 0 && scan.ranges.len().div_ceil(dec) > B {
            dec = scan.ranges.len().div_ceil(B);
        }
        self.thinned = dec != decimation.max(1);
        self.len = 0;
        if B == 0 {
            return 0;
        }
        let gamma = if range_weight_exponent.is_finite() {
            range_weight_exponent
        } else {
            0.0
        };
        for (slot, beam) in self
            .points
            .iter_mut()
            .zip(scan.beams_cached(dec, &mut self.directions))
        {
            let w = if gamma == 0.0 {
                1.0
            } else {
                libm::powf(beam.range, gamma)
            };
            let fixed = libm::roundf(w * WEIGHT_ONE as f32);
            let weight = if fixed.is_nan() || fixed < 1.0 {
                1
            } else if fixed >= MAX_WEIGHT as f32 {
                MAX_WEIGHT
            } else {
                fixed as u32
            };
            *slot = ScanPoint {
                x: beam.robot_point.0,
                y: beam.robot_point.1,
                weight,
                range: beam.range,
            };
            self.len += 1;
        }
        self.len
    }

    /// The points loaded.
    pub fn as_slice(&self) -> &[ScanPoint] {
        self.points.get(..self.len).unwrap_or(&[])
    }

    /// The robot-frame end points `(x, y)` loaded, in beam order (what
    /// [`crate::grid::OccupancyGrid::integrate_points`] writes).
    pub fn robot_points(&self) -> impl Iterator<Item = (f32, f32)> + Clone + '_ {
        self.as_slice().iter().map(|p| (p.x, p.y))
    }

    /// `true` when the last [`ScanPoints::load`] had to raise the decimation to fit `B`.
    pub fn was_thinned(&self) -> bool {
        self.thinned
    }
}

/// The best shift of one particle's scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ShiftScore {
    /// Best shift along x, cells.
    pub dx: i32,
    /// Best shift along y, cells.
    pub dy: i32,
    /// Correlation at the best shift (fixed point, [`WEIGHT_ONE`] = 1.0).
    pub score: u32,
}

/// Continuous grid coordinates of a robot-frame point seen from `pose` (`sin`, `cos` of
/// its heading) — the one formula every search uses.
#[inline]
pub fn end_grid(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    sin: f32,
    cos: f32,
    p: &ScanPoint,
) -> (f32, f32) {
    let wx = pose.x + cos * p.x - sin * p.y;
    let wy = pose.y + sin * p.x + cos * p.y;
    map.geometry().world_to_grid(wx, wy)
}

/// The cell of a robot-frame point seen from `pose`: the floor of [`end_grid`].
#[inline]
pub fn end_cell(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    sin: f32,
    cos: f32,
    p: &ScanPoint,
) -> (i32, i32) {
    let (u, v) = end_grid(map, pose, sin, cos, p);
    (floor_i32(u), floor_i32(v))
}

/// Picks the best shift from the scores of a `(2k+1)²` window (row-major, `dy` outer):
/// the highest score; on a tie the unshifted particle if it is among the best, otherwise
/// the first in row-major order.
pub fn best_shift(scores: &[u32], half_width: u8) -> ShiftScore {
    let k = i32::from(half_width.min(MAX_SHIFT_WINDOW));
    let n = (2 * k + 1) as usize;
    let centre = n * n / 2;
    let mut best = (centre, scores.get(centre).copied().unwrap_or(0));
    for (i, s) in scores.iter().take(n * n).enumerate() {
        if *s > best.1 {
            best = (i, *s);
        }
    }
    ShiftScore {
        dx: (best.0 % n) as i32 - k,
        dy: (best.0 / n) as i32 - k,
        score: best.1,
    }
}

/// [`best_shift`] with a Gaussian prior on the shift: the shift that maximises
/// `score − penalty · (dx² + dy²)` (`penalty` in score units per cell², 0: plain
/// [`best_shift`]); the returned score is the correlation at that shift. Ties: the
/// unshifted particle, then the first in row-major order.
///
/// Without a prior, a shift that gains a single hit wins however far it moves the
/// particle; where the scan constrains a direction weakly (a corridor, the frontier of
/// the map where the end points ahead fall on unknown cells and shifting back puts them
/// on mapped ones) that biases every step the same way and the pose slides.
pub fn best_shift_with_prior(scores: &[u32], half_width: u8, penalty: f32) -> ShiftScore {
    if penalty.is_nan() || penalty <= 0.0 {
        return best_shift(scores, half_width);
    }
    let k = i32::from(half_width.min(MAX_SHIFT_WINDOW));
    let n = (2 * k + 1) as usize;
    let first = scores.get(n * n / 2).copied().unwrap_or(0);
    // (dx, dy, score, value), the unshifted particle first.
    let mut best = (0, 0, first, first as f32);
    let mut rows = scores.chunks_exact(n).take(n);
    for dy in -k..=k {
        let Some(row) = rows.next() else { break };
        for (dx, s) in (-k..=k).zip(row) {
            // The penalty only lowers a score: one no higher than the best value cannot win.
            if *s as f32 > best.3 {
                let v = *s as f32 - penalty * (dx * dx + dy * dy) as f32;
                if v > best.3 {
                    best = (dx, dy, *s, v);
                }
            }
        }
    }
    ShiftScore {
        dx: best.0,
        dy: best.1,
        score: best.2,
    }
}

/// Correlation of the scan seen from `pose` for every shift of the window of half-width
/// `half_width` (clamped to [`MAX_SHIFT_WINDOW`]); writes the `(2k+1)²` scores into
/// `scores` (row-major, `dy` outer) and returns the best. The fast search.
pub fn search_window(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    if map.occupancy_bits().is_some() {
        return search_window_sparse(map, pose, points, half_width, scores);
    }
    match hw {
        0 => search_fixed::<1>(map, pose, points, scores),
        1 => search_fixed::<3>(map, pose, points, scores),
        2 => search_fixed::<5>(map, pose, points, scores),
        3 => search_fixed::<7>(map, pose, points, scores),
        4 => search_fixed::<9>(map, pose, points, scores),
        5 => search_fixed::<11>(map, pose, points, scores),
        6 => search_fixed::<13>(map, pose, points, scores),
        _ => search_fixed::<15>(map, pose, points, scores),
    }
}

/// End points whose window rows are summed together in [`search_fixed`] (on a 32-bit
/// target, 128 bytes of stack for their cell indices and 128 for their weights).
const POINT_CHUNK: usize = 32;

/// [`search_window`] for a window of `N = 2k+1` cells: each window row is `N` bytes read
/// once, and every shift's score grows by the beam's weight masked by the occupancy
/// test — no branches on the map's content, so the compiler vectorises the row.
///
/// The end points are taken in chunks of [`POINT_CHUNK`]: their cells are computed first,
/// then each of the `N` accumulator rows is loaded once per chunk and kept in registers
/// while the chunk's points add into it (instead of loading and storing it once per point).
/// The sums are the same integers added in another order, so the scores are identical.
fn search_fixed<const N: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let k = (N / 2) as i32;
    let mut acc = [[0u32; N]; N];
    let (sin, cos) = sin_cos_f32(pose.theta);
    let g = map.geometry();
    let (w, h) = (g.width, g.height);
    let cells = map.cells();
    let t = map.occupied_above();
    let mut bases = [0usize; POINT_CHUNK];
    let mut weights = [0u32; POINT_CHUNK];
    for chunk in points.chunks(POINT_CHUNK) {
        // Pass 1: window origins of the points whose window lies inside the grid; the
        // others take the checked path now.
        let mut n = 0;
        for p in chunk {
            let (cx, cy) = end_cell(map, pose, sin, cos, p);
            let (x0, y0) = (cx.saturating_sub(k), cy.saturating_sub(k));
            let inside = x0 >= 0 && y0 >= 0 && (x0 as usize) + N <= w && (y0 as usize) + N <= h;
            if inside {
                if let (Some(b), Some(wt)) = (bases.get_mut(n), weights.get_mut(n)) {
                    *b = y0 as usize * w + x0 as usize;
                    *wt = p.weight;
                    n += 1;
                }
            } else {
                add_checked(map, x0, y0, N, p.weight, acc.as_flattened_mut());
            }
        }
        // Pass 2: row by row, all inside points of the chunk.
        let (chunk_bases, chunk_weights) = (
            bases.get(..n).unwrap_or(&[]),
            weights.get(..n).unwrap_or(&[]),
        );
        for (r, row_acc) in acc.iter_mut().enumerate() {
            let mut local = *row_acc;
            let offset = r * w;
            for (base, weight) in chunk_bases.iter().zip(chunk_weights) {
                let start = base + offset;
                let Some(Ok(row)) = cells.get(start..start + N).map(<&[i8; N]>::try_from) else {
                    continue;
                };
                for (s, c) in local.iter_mut().zip(row) {
                    *s = s.wrapping_add(weight & 0u32.wrapping_sub(u32::from(*c > t)));
                }
            }
            *row_acc = local;
        }
    }
    for (dst, src) in scores.iter_mut().zip(acc.as_flattened()) {
        *dst = *src;
    }
    best_shift(&scores[..N * N], (N / 2) as u8)
}

/// [`search_window`] with the sparse search only, so that a build that always has a
/// bitmap carries no byte-wise search: over a view without a bitmap every window takes
/// the checked per-cell path (same scores, slowly).
pub fn search_window_sparse(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    // The seed's 9 × 9 window (every preset's) gets its own constant-size copy; the
    // other sizes share one.
    if half_width.min(MAX_SHIFT_WINDOW) == 4 {
        search_sparse::<SeedWindow, 0>(map, map.occupancy_bits(), pose, points, 9, scores)
    } else {
        search_window_sparse_rows::<0>(map, pose, points, half_width, scores)
    }
}

/// [`search_window_sparse`] for a map whose occupied-cell bitmap has `S` bytes a row
/// (`⌈width / 8⌉`), known when the program is built: the 9 × 9 window's row offsets are
/// then constants — no bounds check per row, the offsets inside the load instructions:
/// on the Cortex-M4F about a sixth fewer instructions per grid step, on the host about a
/// tenth less time (see `docs/speed.md`). Same scores. Another window size, or a map of
/// another width, takes the general sparse path for any window size (correct, slower);
/// `S = 0` is that path alone. [`search_window_packed`] is the same for a 3 × 3 or 5 × 5
/// window.
///
/// A build uses only the copies it names: [`crate::pf::GridSlam`] takes this for its
/// grid of compile-time width, [`crate::pf::GridLocalizer::with_bitmap_row_bytes`] for a
/// map in flash.
pub fn search_window_sparse_rows<const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if let Some(best) = masked::search_rows::<S>(map, pose, points, half_width, scores) {
        return best;
    }
    search_rows::<SeedWindow, S>(map, pose, points, half_width, scores)
}

/// [`search_window_sparse_rows`] for a window of `N × N` cells with `N² ≤ 32` (`N` = 3 or
/// 5: a localizer's, [`GridPfConfig::for_localizer`](crate::pf::GridPfConfig::for_localizer))
/// and a map whose bitmap rows have `S` bytes, both known when the program is built: each
/// end point's window is packed into one 32-bit mask (`PackedSums`). Same scores;
/// another window size or row length takes the general sparse path.
pub fn search_window_packed<const N: usize, const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    search_rows::<PackedSums<N>, S>(map, pose, points, half_width, scores)
}

/// The search with accumulator `A` (for windows of `A::ROWS` rows) when the window is
/// `A::ROWS` wide and the map's bitmap rows `S` bytes long, else the general sparse path.
/// (Inlined on a host CPU, so that [`masked`] compiles it with the vector unit's
/// instructions; the microcontroller keeps one copy.)
#[cfg_attr(not(target_os = "none"), inline(always))]
fn search_rows<A: WindowSums, const S: usize>(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    let n = 2 * usize::from(hw) + 1;
    let bits = map.occupancy_bits();
    if n == A::ROWS && S > 0 && map.geometry().width.div_ceil(8) == S {
        search_sparse::<A, S>(map, bits, pose, points, n, scores)
    } else {
        search_sparse::<RowSums<{ 2 * MAX_SHIFT_WINDOW as usize + 1 }>, 0>(
            map, bits, pose, points, n, scores,
        )
    }
}

/// End points whose grid coordinates [`search_sparse`] computes in one pass before it
/// reads their windows: on a host CPU the pass runs several points per vector
/// instruction; a microcontroller has no vector unit, and a point at a time saves it the
/// stores and loads of the buffers.
const END_POINT_CHUNK: usize = if cfg!(target_os = "none") { 1 } else { 32 };

/// Columns of a row of [`RowSums`]: a power of two above the widest window, so that a
/// bit index masked with `ROW - 1` needs no bounds check.
const ROW: usize = 16;

/// The score accumulator of [`search_sparse`]: it takes each end point's window, as the
/// occupied-cell bits of its rows or cell by cell at the grid's edge, and adds the
/// point's weight to the shift of every occupied cell.
trait WindowSums: Sized {
    /// Rows of the window this accumulator is built for, at most.
    const ROWS: usize;
    /// Whether [`Self::add_rows`] takes each row with the bits beyond the window's `n`
    /// (bit `t`: column `x0 + t`, for every `t` up to 16) instead of exactly `n` bits.
    const WIDE_ROWS: bool = false;
    /// Zero sums.
    fn new() -> Self;
    /// Adds `weight` for the occupied cells of one `n × n` window; `rows(r)` is row `r`
    /// as `n` bits (bit `t`: column `x0 + t`), 0 from `r = n` on. Returns without adding
    /// when none is set.
    fn add_rows(&mut self, weight: u32, rows: impl Fn(usize) -> u32);
    /// Adds `weight` for the occupied cells of the `n × n` window at `(x0, y0)`, looked up
    /// one by one with bounds checks: a window at or over the grid's edge.
    fn add_checked(&mut self, map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32);
    /// Writes the `n × n` sums into `scores`, row-major.
    fn write(&self, n: usize, scores: &mut [u32; MAX_SHIFTS]);
}

/// `R` rows of [`ROW`] sums, one loop over the set bits of each row: any window up to
/// `R × R` (`R = 9` for the seed's window, so that its rows unroll; 15 for any other
/// size: one copy for all of them, a microcontroller's flash is scarce).
struct RowSums<const R: usize>([[u32; ROW]; R]);

impl<const R: usize> WindowSums for RowSums<R> {
    const ROWS: usize = R;

    fn new() -> Self {
        Self([[0; ROW]; R])
    }

    fn add_rows(&mut self, weight: u32, rows: impl Fn(usize) -> u32) {
        // All rows read before any is used: straight-line loads, and one test skips a
        // window without occupied cells.
        let masks: [u32; R] = core::array::from_fn(&rows);
        if masks.iter().fold(0, |any, m| any | m) == 0 {
            return;
        }
        for (row_acc, &mask) in self.0.iter_mut().zip(masks.iter()) {
            let mut m = mask;
            while m != 0 {
                let t = m.trailing_zeros() as usize & (ROW - 1);
                if let Some(s) = row_acc.get_mut(t) {
                    *s = s.wrapping_add(weight);
                }
                m &= m - 1;
            }
        }
    }

    fn add_checked(&mut self, map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32) {
        for (r, row_acc) in self.0.iter_mut().take(n).enumerate() {
            for (b, s) in row_acc.iter_mut().take(n).enumerate() {
                if map.is_occupied(x0.saturating_add(b as i32), y0.saturating_add(r as i32)) {
                    *s = s.wrapping_add(weight);
                }
            }
        }
    }

    fn write(&self, n: usize, scores: &mut [u32; MAX_SHIFTS]) {
        for (dst, row) in scores.chunks_exact_mut(n).zip(self.0.iter()) {
            for (d, s) in dst.iter_mut().zip(row.iter()) {
                *d = *s;
            }
        }
    }
}

/// The sums of an `N × N` window with `N² ≤ 32` (3 × 3, 5 × 5), row-major as the scores
/// are: the window's `N` rows of `N` bits are packed into one 32-bit mask (row `r` at
/// bits `r·N ..`), so that one loop over its set bits adds to the shift of each
/// occupied cell — no loop per row, and the sums are already in the scores' order. (On
/// the Cortex-M4F, localizer step at P = 64 on the Intel map, 5 × 5 window: 950 126
/// instructions against 981 507 with `RowSums<5>`.)
struct PackedSums<const N: usize>([u32; 32]);

impl<const N: usize> WindowSums for PackedSums<N> {
    const ROWS: usize = {
        assert!(N * N <= 32, "a packed window holds at most 32 cells");
        N
    };

    fn new() -> Self {
        Self([0; 32])
    }

    #[inline(always)]
    fn add_rows(&mut self, weight: u32, rows: impl Fn(usize) -> u32) {
        let mut m = 0u32;
        for r in 0..N {
            m |= rows(r) << (r * N);
        }
        while m != 0 {
            let t = m.trailing_zeros() as usize & 31;
            if let Some(s) = self.0.get_mut(t) {
                *s = s.wrapping_add(weight);
            }
            m &= m - 1;
        }
    }

    fn add_checked(&mut self, map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32) {
        add_checked(map, x0, y0, n.min(N), weight, &mut self.0);
    }

    fn write(&self, n: usize, scores: &mut [u32; MAX_SHIFTS]) {
        let cells = (n * n).min(N * N);
        if let (Some(dst), Some(src)) = (scores.get_mut(..cells), self.0.get(..cells)) {
            dst.copy_from_slice(src);
        }
    }
}

/// The accumulator of the seed's 9 × 9 window. On a microcontroller one loop over the set
/// bits of each row ([`RowSums`]): the fewest instructions, and a branch costs a cycle or
/// three there. On a host CPU the exit of each such loop is a branch its predictor often
/// misses (a row's bit count follows the map, not a pattern), so [`WideSums`] packs the
/// window into two words and runs two loops whatever the rows hold; a CPU with AVX-512
/// takes [`masked`] instead, without any loop.
#[cfg(target_os = "none")]
type SeedWindow = RowSums<9>;
/// The accumulator of the seed's 9 × 9 window on a host CPU (see the microcontroller's).
#[cfg(not(target_os = "none"))]
type SeedWindow = WideSums;

/// The sums of a 9 × 9 window, row-major as the scores are, for host CPUs: the window's
/// 81 bits are packed into a 128-bit mask held as two 64-bit words (row `r` at bits
/// `9r .. 9r + 9`), and one loop per word over its set bits adds the weight to the shift
/// of each occupied cell: two loop exits per window instead of nine. On the Intel log
/// with the seed's settings, a third fewer mispredicted branches (valgrind
/// `--branch-sim`) and about 5 % less time than [`RowSums`] (`docs/speed.md`). Same
/// integer sums.
#[cfg(not(target_os = "none"))]
struct WideSums([u32; 128]);

#[cfg(not(target_os = "none"))]
impl WideSums {
    /// Rows and columns of the window.
    const N: usize = 9;

    /// Adds `weight` at `base + t` for every set bit `t` of `m`.
    #[inline(always)]
    fn add_bits(&mut self, mut m: u64, base: usize, weight: u32) {
        while m != 0 {
            let t = (base + m.trailing_zeros() as usize) & 127;
            if let Some(s) = self.0.get_mut(t) {
                *s = s.wrapping_add(weight);
            }
            m &= m - 1;
        }
    }
}

#[cfg(not(target_os = "none"))]
impl WindowSums for WideSums {
    const ROWS: usize = Self::N;

    fn new() -> Self {
        Self([0; 128])
    }

    #[inline(always)]
    fn add_rows(&mut self, weight: u32, rows: impl Fn(usize) -> u32) {
        // The 9 × 9 window's rows packed row-major into 81 bits held as two words: row
        // `r` at bits `9r .. 9r + 9` of `lo` and, from bit 64 on, `hi`.
        const N: usize = WideSums::N;
        let (mut lo, mut hi) = (0u64, 0u64);
        for r in 0..N {
            let m = u64::from(rows(r));
            let at = r * N;
            if at < 64 {
                lo |= m << at;
                if at + N > 64 {
                    hi |= m >> (64 - at);
                }
            } else {
                hi |= m << (at - 64);
            }
        }
        if lo | hi == 0 {
            return;
        }
        self.add_bits(lo, 0, weight);
        self.add_bits(hi, 64, weight);
    }

    fn add_checked(&mut self, map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32) {
        add_checked(map, x0, y0, n.min(Self::N), weight, &mut self.0);
    }

    fn write(&self, n: usize, scores: &mut [u32; MAX_SHIFTS]) {
        let cells = (n * n).min(Self::N * Self::N);
        if let (Some(dst), Some(src)) = (scores.get_mut(..cells), self.0.get(..cells)) {
            dst.copy_from_slice(src);
        }
    }
}

/// The seed's 9 × 9 window on an x86-64 CPU with AVX-512: the sums stay in nine 16-lane
/// vector registers, one per window row, and an end point adds its weight to the shifts
/// of its window's occupied cells with one masked addition per row (the row's bits are
/// the mask) — no loop over the set bits, no branch that follows the map, and the rows
/// need not be cut to their 9 bits: lanes 9–15 collect what lies beyond the window and
/// are never read. Chosen when the program runs (`is_x86_feature_detected!`), so one
/// binary runs on any x86-64 CPU; the same integer sums as every other accumulator.
#[cfg(all(feature = "std", target_arch = "x86_64"))]
mod masked {
    use super::{
        GridView, MAX_SHIFTS, Pose2, ROW, RowSums, ScanPoint, ShiftScore, WindowSums,
        search_rows as search_rows_with,
    };
    use core::arch::x86_64::{
        __m512i, _mm512_mask_add_epi32, _mm512_set1_epi32, _mm512_setzero_si512,
    };

    /// Rows and columns of the window.
    const N: usize = 9;

    /// Sums of the 81 shifts: register `r` holds row `r`, lane `t` column `t` (the
    /// layout of [`RowSums<9>`], whose cell-by-cell and output code it borrows).
    struct MaskedSums([__m512i; N]);

    /// Adds `weight` to lane `t` of `acc[r]` for every set bit `t` of `rows[r]`.
    #[target_feature(enable = "avx512f,bmi2")]
    fn add_masked(acc: &mut [__m512i; N], rows: [u16; N], weight: u32) {
        let w = _mm512_set1_epi32(weight as i32);
        for (a, m) in acc.iter_mut().zip(rows) {
            *a = _mm512_mask_add_epi32(*a, m, *a, w);
        }
    }

    impl MaskedSums {
        /// The sums as [`RowSums<9>`].
        fn rows(&self) -> RowSums<N> {
            #[allow(unsafe_code)]
            // SAFETY: `[__m512i; 9]` and `[[u32; 16]; 9]` have the same size, and every
            // bit pattern is a valid value of both.
            RowSums(unsafe { core::mem::transmute::<[__m512i; N], [[u32; ROW]; N]>(self.0) })
        }
    }

    impl WindowSums for MaskedSums {
        const ROWS: usize = N;
        const WIDE_ROWS: bool = true;

        fn new() -> Self {
            #[allow(unsafe_code)]
            // SAFETY: a `MaskedSums` is only made inside `search_rows_avx512`, which runs
            // only on a CPU with AVX-512F and BMI2 (checked in `search_rows`).
            Self(unsafe { [_mm512_setzero_si512(); N] })
        }

        #[inline(always)]
        fn add_rows(&mut self, weight: u32, rows: impl Fn(usize) -> u32) {
            let masks: [u16; N] = core::array::from_fn(|r| rows(r) as u16);
            #[allow(unsafe_code)]
            // SAFETY: as in `new`: only on a CPU with AVX-512F and BMI2.
            unsafe {
                add_masked(&mut self.0, masks, weight);
            }
        }

        fn add_checked(&mut self, map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32) {
            let mut sums = self.rows();
            sums.add_checked(map, x0, y0, n, weight);
            #[allow(unsafe_code)]
            // SAFETY: as in `rows`.
            {
                self.0 = unsafe { core::mem::transmute::<[[u32; ROW]; N], [__m512i; N]>(sums.0) };
            }
        }

        fn write(&self, n: usize, scores: &mut [u32; MAX_SHIFTS]) {
            self.rows().write(n, scores);
        }
    }

    /// [`super::search_window_sparse_rows`] with [`MaskedSums`], or `None` when the CPU
    /// lacks AVX-512F or BMI2 (every CPU with AVX-512 has BMI2; the search uses its
    /// shifts).
    pub(super) fn search_rows<const S: usize>(
        map: &GridView<'_>,
        pose: &Pose2<f32>,
        points: &[ScanPoint],
        half_width: u8,
        scores: &mut [u32; MAX_SHIFTS],
    ) -> Option<ShiftScore> {
        if !(std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("bmi2")) {
            return None;
        }
        #[allow(unsafe_code)]
        // SAFETY: the CPU has AVX-512F and BMI2 (tested above).
        Some(unsafe { search_rows_avx512::<S>(map, pose, points, half_width, scores) })
    }

    /// The search compiled with AVX-512F and BMI2, so that [`add_masked`] inlines into its
    /// loop.
    #[target_feature(enable = "avx512f,bmi2")]
    fn search_rows_avx512<const S: usize>(
        map: &GridView<'_>,
        pose: &Pose2<f32>,
        points: &[ScanPoint],
        half_width: u8,
        scores: &mut [u32; MAX_SHIFTS],
    ) -> ShiftScore {
        search_rows_with::<MaskedSums, S>(map, pose, points, half_width, scores)
    }
}

/// [`search_window`] over a map with an occupied-cell bitmap: for each end point, each of
/// the `n = 2k+1` window rows is cut out of the bitmap as `n` bits (one 4-byte read and
/// two shifts) and only its set bits — the occupied cells — add the point's weight to
/// their shift in the accumulator `A` ([`RowSums`], or [`PackedSums`] for a window of at
/// most 5 × 5); a window without any occupied cell costs its `n` reads and one test.
/// Same integer sums as the other searches, in another order, so the scores are
/// identical.
///
/// The end cell's `floor` is taken as a truncation: the two agree whenever the window's
/// corner is at least one cell inside the grid (then the coordinate is ≥ 1), which is
/// the only case the bitmap path takes; windows at or over the grid's edge take the
/// checked path with the exact `floor`.
///
/// `S` is the bitmap's stride in bytes when the caller has checked it equals
/// `⌈width / 8⌉`, so that the compiler sees the row offsets; 0 reads it from the map.
#[cfg_attr(not(target_os = "none"), inline(always))]
fn search_sparse<A: WindowSums, const S: usize>(
    map: &GridView<'_>,
    bits: Option<&[u8]>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    n: usize,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let n = n.min(A::ROWS);
    let k = (n / 2) as i32;
    let mut acc = A::new();
    let (sin, cos) = sin_cos_f32(pose.theta);
    let g = map.geometry();
    let (w, h) = (g.width, g.height);
    let stride = if S == 0 { w.div_ceil(8) } else { S };
    // The bitmap path needs 1 ≤ x0 ≤ w − n and 1 ≤ y0 ≤ h − n: `(x0 − 1) as u32 <
    // x_limit` (an empty range when the grid is narrower than the window).
    let x_limit = w.saturating_sub(n) as u32;
    let y_limit = h.saturating_sub(n) as u32;
    // Bit `x0 % 8 + t` of a row read is column `x0 + t`: shifted up to the top `n` bits,
    // then down to bits `0..n`.
    let down = 32 - n as u32;
    let bits = bits.unwrap_or(&[]);
    // A window is read as `n` rows of 4 bytes one stride apart from the byte holding
    // column x0 (its bits are in those 4 bytes: x0 % 8 + n ≤ 22).
    let span = (n - 1) * stride + 4;
    let inside = |x0: i32, y0: i32| {
        (x0.wrapping_sub(1) as u32) < x_limit && (y0.wrapping_sub(1) as u32) < y_limit
    };
    // One end point: `(u, v)` in grid coordinates, `(x0, y0)` its window's corner.
    let mut add_point = |p: &ScanPoint, u: f32, v: f32, x0: i32, y0: i32| {
        let window = if inside(x0, y0) {
            let first = y0 as usize * stride + (x0 as usize >> 3);
            bits.get(first..first + span)
        } else {
            None
        };
        let Some(window) = window else {
            // At or over the grid's edge, or no bitmap: exact floor, cell by cell.
            let (x0, y0) = (
                floor_i32(u).saturating_sub(k),
                floor_i32(v).saturating_sub(k),
            );
            acc.add_checked(map, x0, y0, n, p.weight);
            return;
        };
        // Bit `first_bit` of a row read is column `x0`.
        let first_bit = x0 as u32 & 7;
        acc.add_rows(p.weight, |r| {
            let offset = r * stride;
            match window.get(offset..offset + 4) {
                Some(&[a, b, c, d]) if r < n => {
                    let word = u32::from_le_bytes([a, b, c, d]);
                    if A::WIDE_ROWS {
                        word >> first_bit
                    } else {
                        (word << (down - first_bit)) >> down
                    }
                }
                _ => 0,
            }
        });
    };
    let corner = |u: f32, v: f32| ((u as i32).saturating_sub(k), (v as i32).saturating_sub(k));
    if END_POINT_CHUNK == 1 {
        for p in points {
            let (u, v) = end_grid(map, pose, sin, cos, p);
            let (x0, y0) = corner(u, v);
            add_point(p, u, v, x0, y0);
        }
    } else {
        // Two passes per chunk: first the end points' coordinates and corners
        // (straight-line work that vector units do several points at a time), then the
        // windows. Neighbouring beams often end in the same cell (1° apart, up to
        // ~1.5 m away with 5 cm cells: 19 % of the Intel log's end points at 180 beams),
        // and then their windows are the same: a point whose successor in the chunk has
        // its corner, inside the grid, passes its weight on, and the window is read once
        // with the sum (wrapping additions commute: the same scores). On the M4F, one
        // point at a time, the test costs more than it saves at 90 beams (6 % merged).
        let mut grid = [(0f32, 0f32); END_POINT_CHUNK];
        let mut corners = [(0i32, 0i32); END_POINT_CHUNK];
        for chunk in points.chunks(END_POINT_CHUNK) {
            for (p, g) in chunk.iter().zip(grid.iter_mut()) {
                *g = end_grid(map, pose, sin, cos, p);
            }
            for (&(u, v), c) in grid.iter().zip(corners.iter_mut()) {
                *c = corner(u, v);
            }
            let mut carried = 0u32;
            for (i, ((p, &(u, v)), &(x0, y0))) in chunk
                .iter()
                .zip(grid.iter())
                .zip(corners.iter())
                .enumerate()
            {
                let weight = carried.wrapping_add(p.weight);
                let successor = corners.get(i + 1).filter(|_| i + 1 < chunk.len());
                if successor == Some(&(x0, y0)) && inside(x0, y0) {
                    carried = weight;
                } else {
                    carried = 0;
                    add_point(&ScanPoint { weight, ..*p }, u, v, x0, y0);
                }
            }
        }
    }
    acc.write(n, scores);
    best_shift(scores.get(..n * n).unwrap_or(&[]), k as u8)
}

/// Adds `weight` to every shift of the `n × n` window at `(x0, y0)` (scores row-major in
/// `acc`) whose cell is occupied, with a bounds check per cell: the path for windows that
/// reach over the grid's edge.
fn add_checked(map: &GridView<'_>, x0: i32, y0: i32, n: usize, weight: u32, acc: &mut [u32]) {
    for (r, row_acc) in acc.chunks_exact_mut(n).take(n).enumerate() {
        for (b, s) in row_acc.iter_mut().enumerate() {
            if map.is_occupied(x0.saturating_add(b as i32), y0.saturating_add(r as i32)) {
                *s = s.wrapping_add(weight);
            }
        }
    }
}

/// The brute-force reference of [`search_window`]: for every shift, for every point,
/// look the shifted end cell up. Same result, (2k+1)² lookups per point.
pub fn search_window_brute_force(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let hw = half_width.min(MAX_SHIFT_WINDOW);
    let k = i32::from(hw);
    let n = (2 * k + 1) as usize;
    let (sin, cos) = sin_cos_f32(pose.theta);
    for dy in -k..=k {
        for dx in -k..=k {
            let mut sum = 0u32;
            for p in points {
                let (cx, cy) = end_cell(map, pose, sin, cos, p);
                if map.is_occupied(cx.saturating_add(dx), cy.saturating_add(dy)) {
                    sum = sum.wrapping_add(p.weight);
                }
            }
            if let Some(s) = scores.get_mut((dy + k) as usize * n + (dx + k) as usize) {
                *s = sum;
            }
        }
    }
    best_shift(&scores[..n * n], hw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridGeometry;
    use crate::sensors::lidar::LidarGeometry;
    use rand::{Rng, SeedableRng};

    #[test]
    fn best_shift_tie_rules() {
        // 3 × 3 window: centre tied with a corner → centre wins.
        let s = [5, 0, 0, 0, 5, 0, 0, 0, 0];
        assert_eq!(
            best_shift(&s, 1),
            ShiftScore {
                dx: 0,
                dy: 0,
                score: 5
            }
        );
        // Two off-centre maxima → the first in row-major order.
        let s = [0, 0, 7, 0, 5, 0, 7, 0, 0];
        assert_eq!(
            best_shift(&s, 1),
            ShiftScore {
                dx: 1,
                dy: -1,
                score: 7
            }
        );
    }

    #[test]
    fn shift_prior_trades_score_for_distance() {
        // 3 × 3 window: centre 100, corner (+1, +1) 103. Without a prior the corner wins;
        // with 2 units per cell² it costs 4 and the centre wins; with 1 per cell² it costs
        // 2 and the corner still wins, reporting its own score.
        let s = [0, 0, 0, 0, 100, 0, 0, 0, 103];
        let corner = ShiftScore {
            dx: 1,
            dy: 1,
            score: 103,
        };
        let centre = ShiftScore {
            dx: 0,
            dy: 0,
            score: 100,
        };
        assert_eq!(best_shift_with_prior(&s, 1, 0.0), corner);
        assert_eq!(best_shift_with_prior(&s, 1, f32::NAN), corner);
        assert_eq!(best_shift_with_prior(&s, 1, 2.0), centre);
        assert_eq!(best_shift_with_prior(&s, 1, 1.0), corner);
        // A tie after the penalty keeps the unshifted particle.
        assert_eq!(best_shift_with_prior(&s, 1, 1.5), centre);
        // A far shift with a big gain wins over a near one with a small gain.
        let mut w = [0u32; 25];
        w[12] = 50; // centre of 5 × 5
        w[13] = 52; // (+1, 0): 52 − 1 = 51
        w[0] = 70; // (−2, −2): 70 − 8 = 62
        assert_eq!(
            best_shift_with_prior(&w, 2, 1.0),
            ShiftScore {
                dx: -2,
                dy: -2,
                score: 70
            }
        );
    }

    /// Asserts that `search` over `maps.0` (with a bitmap) gives the brute force's scores
    /// over `maps.1` and its best shift, for windows of half-width 1, 2, 4 and 7.
    fn assert_as_brute_force(
        search: crate::pf::filter::ShiftSearch,
        maps: (&GridView<'_>, &GridView<'_>),
        pose: &Pose2<f32>,
        points: &[ScanPoint],
        label: &str,
    ) {
        for k in [1u8, 2, 4, 7] {
            let n = (2 * k as usize + 1).pow(2);
            let (mut a, mut b) = ([0u32; MAX_SHIFTS], [0u32; MAX_SHIFTS]);
            let fast = search(maps.0, pose, points, k, &mut a);
            let slow = search_window_brute_force(maps.1, pose, points, k, &mut b);
            assert_eq!(a[..n], b[..n], "{label}, k {k}");
            assert_eq!(fast, slow, "{label}, k {k}");
        }
    }

    /// The occupied-cell bitmap of `cells` (threshold 20, as the tests' views).
    fn occupied_bits(cells: &[i8], g: &GridGeometry) -> Vec<u8> {
        let mut bits = vec![0u8; crate::grid::occupancy_bytes(g.width, g.height)];
        crate::grid::fill_occupancy_bits(cells, g.width, g.height, 20, &mut bits).unwrap();
        bits
    }

    fn random_map(seed: u64, w: usize, h: usize, density: f64) -> (Vec<i8>, GridGeometry) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let cells = (0..w * h)
            .map(|_| {
                if rng.random_bool(density) {
                    40
                } else {
                    rng.random_range(-30..20)
                }
            })
            .collect();
        (cells, GridGeometry::centred(w, h, 0.05))
    }

    #[test]
    fn fast_search_equals_brute_force() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        for trial in 0..60 {
            let (cells, g) = random_map(trial, 64 + trial as usize % 9, 48, 0.15);
            let view = GridView::new(&cells, g, 20).unwrap();
            let ranges: Vec<f32> = (0..90).map(|_| rng.random_range(0.05..2.5)).collect();
            let mut pts = ScanPoints::<90>::new();
            let geometry = LidarGeometry {
                first_angle: -3.0,
                angle_increment: 6.0 / 90.0,
                ..LidarGeometry::CARMEN_SICK_180
            };
            pts.load(
                &LidarScan::new(&ranges, geometry),
                1,
                [0.0, 2.0, 0.7][trial as usize % 3],
            );
            // Poses inside, near the border and off the grid.
            let pose = Pose2::new(
                rng.random_range(-2.5..2.5),
                rng.random_range(-1.8..1.8),
                rng.random_range(-4.0..4.0),
            );
            let k = (trial % 8) as u8;
            let (mut a, mut b) = ([0u32; MAX_SHIFTS], [0u32; MAX_SHIFTS]);
            let fast = search_window(&view, &pose, pts.as_slice(), k, &mut a);
            let slow = search_window_brute_force(&view, &pose, pts.as_slice(), k, &mut b);
            let n = (2 * k as usize + 1).pow(2);
            assert_eq!(a[..n], b[..n], "trial {trial}");
            assert_eq!(fast, slow, "trial {trial}");
            assert!(fast.score > 0 || trial % 8 == 0);
            // The same search over the occupied-cell bitmap (the sparse path).
            let bits = occupied_bits(&cells, &g);
            let with_bits = view.with_occupancy_bits(&bits).unwrap();
            let mut c = [0u32; MAX_SHIFTS];
            let sparse = search_window(&with_bits, &pose, pts.as_slice(), k, &mut c);
            assert_eq!(c[..n], b[..n], "sparse, trial {trial}");
            assert_eq!(sparse, slow, "sparse, trial {trial}");
            // The sparse-only search over a view without a bitmap: every window checked.
            let mut d = [0u32; MAX_SHIFTS];
            let checked = search_window_sparse(&view, &pose, pts.as_slice(), k, &mut d);
            assert_eq!(d[..n], b[..n], "checked, trial {trial}");
            assert_eq!(checked, slow, "checked, trial {trial}");
            if k == 4 {
                // The 9 × 9 window's two accumulators: the microcontroller's and the host's.
                let mut e = [0u32; MAX_SHIFTS];
                let rows = search_sparse::<RowSums<9>, 0>(
                    &view,
                    Some(&bits),
                    &pose,
                    pts.as_slice(),
                    9,
                    &mut e,
                );
                assert_eq!((&e[..n], rows), (&b[..n], slow), "row sums, trial {trial}");
                let mut f = [0u32; MAX_SHIFTS];
                let wide = search_sparse::<WideSums, 0>(
                    &view,
                    Some(&bits),
                    &pose,
                    pts.as_slice(),
                    9,
                    &mut f,
                );
                assert_eq!((&f[..n], wide), (&b[..n], slow), "wide sums, trial {trial}");
            }
        }
    }

    #[test]
    fn end_points_sharing_a_window_score_as_apart() {
        // 200 beams over 0.6 rad at 0.3–0.9 m: runs of consecutive end points in one cell
        // (read once by the sparse search, with their weights summed), runs across the
        // host's chunks of end points, and weights of every size.
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for trial in 0..20 {
            let (cells, g) = random_map(100 + trial, 80, 64, 0.2);
            let view = GridView::new(&cells, g, 20).unwrap();
            let bits = occupied_bits(&cells, &g);
            let with_bits = view.with_occupancy_bits(&bits).unwrap();
            let ranges: Vec<f32> = (0..200)
                .map(|i| 0.3 + 0.6 * (i / 25) as f32 / 8.0 + rng.random_range(0.0..0.01))
                .collect();
            let geometry = LidarGeometry {
                first_angle: -0.3,
                angle_increment: 0.6 / 200.0,
                ..LidarGeometry::CARMEN_SICK_180
            };
            let mut pts = ScanPoints::<200>::new();
            pts.load(
                &LidarScan::new(&ranges, geometry),
                1,
                [0.0, 2.0][trial as usize % 2],
            );
            let pose = Pose2::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-0.8..0.8),
                rng.random_range(-4.0..4.0),
            );
            let (sin, cos) = sin_cos_f32(pose.theta);
            let cells_of: Vec<_> = pts
                .as_slice()
                .iter()
                .map(|p| end_cell(&view, &pose, sin, cos, p))
                .collect();
            let shared = cells_of.windows(2).filter(|w| w[0] == w[1]).count();
            assert!(
                shared > 50,
                "trial {trial}: only {shared} neighbours share a cell"
            );
            let label = format!("trial {trial}");
            let search = search_window_sparse;
            assert_as_brute_force(search, (&with_bits, &view), &pose, pts.as_slice(), &label);
        }
    }

    #[test]
    fn searches_with_constant_row_offsets_score_as_the_brute_force() {
        // 256 and 1024 cells wide (32 and 128 bytes a bitmap row: the copies with constant
        // row offsets, 9 × 9, 3 × 3 and 5 × 5), next to 248 and 1016 (31 and 127: the
        // fallback).
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        for (trial, width) in [256usize, 1024, 248, 1016, 250].into_iter().enumerate() {
            let (cells, g) = random_map(200 + trial as u64, width, 40, 0.15);
            let view = GridView::new(&cells, g, 20).unwrap();
            let bits = occupied_bits(&cells, &g);
            let with_bits = view.with_occupancy_bits(&bits).unwrap();
            let ranges: Vec<f32> = (0..90).map(|_| rng.random_range(0.05..1.5)).collect();
            let mut pts = ScanPoints::<90>::new();
            pts.load(
                &LidarScan::new(&ranges, LidarGeometry::CARMEN_SICK_180),
                1,
                1.0,
            );
            for _ in 0..10 {
                // Inside, near the edges and over them.
                let half = (width as f32 * 0.05) / 2.0;
                let pose = Pose2::new(
                    rng.random_range(-half - 0.5..half + 0.5),
                    rng.random_range(-1.2..1.2),
                    rng.random_range(-4.0..4.0),
                );
                let label = format!("width {width}, pose {pose:?}");
                let maps = (&with_bits, &view);
                let pts = pts.as_slice();
                assert_as_brute_force(search_window_sparse_rows::<32>, maps, &pose, pts, &label);
                assert_as_brute_force(search_window_sparse_rows::<128>, maps, &pose, pts, &label);
                // The packed 3 × 3 and 5 × 5 copies (k = 1 and 2 run them, other windows
                // the fallback).
                assert_as_brute_force(search_window_packed::<3, 32>, maps, &pose, pts, &label);
                assert_as_brute_force(search_window_packed::<5, 32>, maps, &pose, pts, &label);
                assert_as_brute_force(search_window_packed::<5, 128>, maps, &pose, pts, &label);
            }
        }
    }

    #[test]
    fn planted_offset_is_found() {
        // Walls of a ~2 m × 1.5 m room; the scan is taken at the true pose and scored from a
        // pose off by (+3, −2) cells: the search must answer (−3, +2).
        let g = GridGeometry::centred(100, 100, 0.05);
        let mut cells = vec![0i8; 100 * 100];
        let truth = Pose2::new(0.12, -0.07, 0.3f32);
        let mut ranges = Vec::new();
        let geometry = LidarGeometry {
            first_angle: -3.1,
            angle_increment: 6.2 / 120.0,
            ..LidarGeometry::CARMEN_SICK_180
        };
        for i in 0..120 {
            // Ray cast against the axis-aligned room [-1, 1] × [-0.75, 0.75].
            let a = truth.theta + geometry.beam_angle(i);
            let (s, c) = a.sin_cos();
            // Walls kept off the cell borders (which fall on multiples of 5 cm).
            let tx = if c > 0.0 {
                (1.012 - truth.x) / c
            } else {
                (-1.012 - truth.x) / c
            };
            let ty = if s > 0.0 {
                (0.763 - truth.y) / s
            } else {
                (-0.763 - truth.y) / s
            };
            ranges.push(tx.min(ty));
        }
        for (i, r) in ranges.iter().enumerate() {
            let a = truth.theta + geometry.beam_angle(i);
            let (x, y) = (truth.x + r * a.cos(), truth.y + r * a.sin());
            if let Some((ix, iy)) = g.world_to_cell(x, y) {
                cells[iy * 100 + ix] = 50;
            }
        }
        let view = GridView::new(&cells, g, 20).unwrap();
        let mut pts = ScanPoints::<180>::new();
        pts.load(&LidarScan::new(&ranges, geometry), 1, 0.0);
        let off = Pose2::new(truth.x + 3.0 * 0.05, truth.y - 2.0 * 0.05, truth.theta);
        let mut s = [0u32; MAX_SHIFTS];
        let best = search_window(&view, &off, pts.as_slice(), 4, &mut s);
        assert_eq!((best.dx, best.dy), (-3, 2), "{best:?}");
        let at_truth = search_window(&view, &truth, pts.as_slice(), 4, &mut s);
        assert_eq!((at_truth.dx, at_truth.dy), (0, 0));
        assert!(best.score >= 100 * WEIGHT_ONE, "{best:?}");
    }

    #[test]
    fn weights_and_thinning() {
        let ranges = [1.0f32, 2.0, 0.01, 3.0, 1e5];
        let g = LidarGeometry::CARMEN_SICK_180;
        let mut pts = ScanPoints::<8>::new();
        assert_eq!(pts.load(&LidarScan::new(&ranges, g), 1, 2.0), 3);
        let w: Vec<u32> = pts.as_slice().iter().map(|p| p.weight).collect();
        assert_eq!(w, vec![256, 1024, 2304]);
        let mut few = ScanPoints::<2>::new();
        few.load(&LidarScan::new(&ranges, g), 1, 0.0);
        assert!(few.was_thinned());
        assert_eq!(few.as_slice().len(), 2); // beams 0 and 3 (decimation raised to 3)
        let mut none = ScanPoints::<0>::new();
        assert_eq!(none.load(&LidarScan::new(&ranges, g), 1, 0.0), 0);
    }
}
