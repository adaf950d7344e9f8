//! The score accumulators of the sparse search ([`WindowSums`]): one loop over the set bits
//! of each window row ([`RowSums`]), the window packed into one word ([`PackedSums`]) or
//! two ([`WideSums`]), and the choice for the 9 × 9 window ([`NineByNineSums`]).

use super::MAX_SHIFTS;
use super::checked::add_checked;
use crate::grid::GridView;

/// Columns of a row of [`RowSums`]: a power of two above the widest window, so that a
/// bit index masked with `ROW - 1` needs no bounds check.
pub(super) const ROW: usize = 16;

/// The score accumulator of [`search_sparse`]: it takes each end point's window, as the
/// occupied-cell bits of its rows or cell by cell at the grid's edge, and adds the
/// point's weight to the shift of every occupied cell.
///
/// [`search_sparse`]: super::sparse::search_sparse
pub(super) trait WindowSums: Sized {
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
/// `R × R` (`R = 9` for the 9 × 9 window, so that its rows unroll; 15 for any other
/// size: one copy for all of them, a microcontroller's flash is scarce).
pub(super) struct RowSums<const R: usize>(pub(super) [[u32; ROW]; R]);

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
/// the Cortex-M4F fewer instructions than `RowSums<5>` for a 5 × 5 window: measured in
/// `docs/speed.md`.)
pub(super) struct PackedSums<const N: usize>([u32; 32]);

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

/// The accumulator of the 9 × 9 window (every preset's for SLAM). On a microcontroller one
/// loop over the set bits of each row ([`RowSums`]): the fewest instructions, and a branch
/// costs a cycle or three there. On a host CPU the exit of each such loop is a branch its
/// predictor often misses (a row's bit count follows the map, not a pattern), so
/// [`WideSums`] packs the window into two words and runs two loops whatever the rows hold;
/// a CPU with AVX-512 takes [`avx512`] instead, without any loop.
///
/// [`avx512`]: super::avx512
#[cfg(target_os = "none")]
pub(super) type NineByNineSums = RowSums<9>;
/// The accumulator of the 9 × 9 window on a host CPU (see the microcontroller's).
#[cfg(not(target_os = "none"))]
pub(super) type NineByNineSums = WideSums;

/// The sums of a 9 × 9 window, row-major as the scores are, for host CPUs: the window's
/// 81 bits are packed into a 128-bit mask held as two 64-bit words (row `r` at bits
/// `9r .. 9r + 9`), and one loop per word over its set bits adds the weight to the shift
/// of each occupied cell: two loop exits per window instead of nine. On the Intel log
/// with [`GridPfConfig::UNTUNED`](crate::pf::GridPfConfig::UNTUNED), fewer mispredicted
/// branches and less time than [`RowSums`] (measured in `docs/speed.md`). Same integer sums.
#[cfg(not(target_os = "none"))]
pub(super) struct WideSums([u32; 128]);

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
