//! The 9 × 9 window on an x86-64 CPU with AVX-512: the sums stay in nine 16-lane
//! vector registers, one per window row, and an end point adds its weight to the shifts
//! of its window's occupied cells with one masked addition per row (the row's bits are
//! the mask) — no loop over the set bits, no branch that follows the map, and the rows
//! need not be cut to their 9 bits: lanes 9–15 collect what lies beyond the window and
//! are never read. Chosen when the program runs (`is_x86_feature_detected!`), so one
//! binary runs on any x86-64 CPU; the same integer sums as every other accumulator.

use super::sparse::search_rows as search_rows_with;
use super::sums::{ROW, RowSums, WindowSums};
use super::{MAX_SHIFTS, ScanPoint, ShiftScore};
use crate::geometry::Pose2;
use crate::grid::GridView;
use core::arch::x86_64::{__m512i, _mm512_mask_add_epi32, _mm512_set1_epi32, _mm512_setzero_si512};

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
