//! A borrowed, read-only occupancy map: what scans are scored against.

use super::{GridError, GridGeometry};

/// Read-only log-odds cells (row-major, row 0 at the grid's bottom edge) with their
/// geometry and occupied threshold. Borrows from an [`super::OccupancyGrid`] or from any
/// `&[i8]`, e.g. a `&'static [i8]` map kept in flash for localization.
///
/// A view may also carry the bitmap of the occupied cells
/// ([`GridView::with_occupancy_bits`]; an [`super::OccupancyGrid`] with a bitmap hands
/// out its own): the shift search then visits only the occupied cells of each window.
#[derive(Clone, Copy, Debug)]
pub struct GridView<'a> {
    cells: &'a [i8],
    geometry: GridGeometry,
    occupied_above: i8,
    bits: Option<&'a [u8]>,
    /// Free cells of a bitmap-only view (a map image's free section), for the layers.
    free: Option<&'a [u8]>,
}

/// Widest window [`GridView::occupied_row_mask`] answers in one call, cells.
pub const MAX_MASK_WIDTH: u32 = 16;

impl<'a> GridView<'a> {
    /// A view of `cells` (`geometry.width × geometry.height` values, row-major); a cell is
    /// occupied when its value is above `occupied_above`.
    pub fn new(
        cells: &'a [i8],
        geometry: GridGeometry,
        occupied_above: i8,
    ) -> Result<Self, GridError> {
        if !geometry.is_valid() {
            return Err(GridError::InvalidGeometry);
        }
        if geometry.width.checked_mul(geometry.height) != Some(cells.len()) {
            return Err(GridError::SizeMismatch);
        }
        Ok(Self {
            cells,
            geometry,
            occupied_above,
            bits: None,
            free: None,
        })
    }

    /// The same view with the bitmap of its occupied cells: [`super::occupancy_bytes`]
    /// bytes, bit `x % 8` of byte `y · ⌈width/8⌉ + x / 8` set when cell `(x, y)` is
    /// above the threshold — as [`fill_occupancy_bits`] computes it (e.g. once at
    /// start-up for a map in flash). A bitmap of another length is refused with
    /// [`GridError::SizeMismatch`]; one that disagrees with the cells is not detected
    /// and makes the scores follow the bitmap.
    pub fn with_occupancy_bits(self, bits: &'a [u8]) -> Result<Self, GridError> {
        if bits.len() != super::occupancy_bytes(self.geometry.width, self.geometry.height) {
            return Err(GridError::SizeMismatch);
        }
        Ok(Self {
            bits: Some(bits),
            ..self
        })
    }

    /// A view made of the occupied-cell bitmap alone (no log-odds cells): what a map in
    /// flash carries (`MapImage`, feature `map-image`), an eighth of the bytes of the cells. Cell
    /// `(x, y)` is occupied when bit `x % 8` of byte `y · ⌈width/8⌉ + x / 8` is set;
    /// [`GridView::log_odds`] answers `None` and [`GridView::cells`] is empty. Scores
    /// against it equal the scores against the cells the bitmap was computed from. A
    /// bitmap of another length is refused with [`GridError::SizeMismatch`].
    /// `occupied_above` is the threshold the bitmap was made with (kept for
    /// [`GridView::occupied_above`], not applied).
    pub fn from_occupancy_bits(
        bits: &'a [u8],
        geometry: GridGeometry,
        occupied_above: i8,
    ) -> Result<Self, GridError> {
        if !geometry.is_valid() {
            return Err(GridError::InvalidGeometry);
        }
        if geometry.width.checked_mul(geometry.height).is_none()
            || bits.len() != super::occupancy_bytes(geometry.width, geometry.height)
        {
            return Err(GridError::SizeMismatch);
        }
        Ok(Self {
            cells: &[],
            geometry,
            occupied_above,
            bits: Some(bits),
            free: None,
        })
    }

    /// [`GridView::with_occupancy_bits`] for a bitmap kept by the grid itself.
    pub(crate) fn with_trusted_bits(self, bits: &'a [u8]) -> Self {
        Self {
            bits: Some(bits),
            ..self
        }
    }

    /// The occupied-cell bitmap, when the view has one.
    #[inline]
    pub fn occupancy_bits(&self) -> Option<&'a [u8]> {
        self.bits
    }

    /// A bitmap-only view ([`GridView::from_occupancy_bits`]) with the bitmap of its free
    /// cells (the same layout; bit set where the cell's log-odds was below the free
    /// threshold the bitmap was made with), so that [`super::MaxPoolLayers::build`] can
    /// make the global search's layers from the bitmaps alone (a map image with a free
    /// section). Refused with [`GridError::SizeMismatch`] for a bitmap of another length
    /// and on a view with cells (whose free cells are their log-odds).
    pub fn with_free_bits(self, free: &'a [u8]) -> Result<Self, GridError> {
        if !self.cells.is_empty()
            || free.len() != super::occupancy_bytes(self.geometry.width, self.geometry.height)
        {
            return Err(GridError::SizeMismatch);
        }
        Ok(Self {
            free: Some(free),
            ..self
        })
    }

    /// The free-cell bitmap of a bitmap-only view, when it has one.
    #[inline]
    pub fn free_bits(&self) -> Option<&'a [u8]> {
        self.free
    }

    /// `true` when `(ix, iy)` is on the grid and known free: its log-odds below
    /// `free_below` on a view with cells, its bit set on a view with a free bitmap (made
    /// with its own threshold; `free_below` is then not read), never otherwise.
    #[inline]
    pub fn is_free(&self, ix: i32, iy: i32, free_below: i8) -> bool {
        if !self.geometry.contains(ix, iy) {
            return false;
        }
        if !self.cells.is_empty() {
            return self.log_odds(ix, iy).is_some_and(|v| v < free_below);
        }
        let (x, y) = (ix as usize, iy as usize);
        self.free
            .and_then(|b| b.get(y * self.geometry.width.div_ceil(8) + x / 8))
            .is_some_and(|b| b & (1 << (x % 8)) != 0)
    }

    /// A view over cells whose length is known to be `width × height` (for
    /// [`super::OccupancyGrid::view`]); an invalid geometry only makes every point off-grid.
    pub(crate) fn from_trusted(
        cells: &'a [i8],
        geometry: GridGeometry,
        occupied_above: i8,
    ) -> Self {
        Self {
            cells,
            geometry,
            occupied_above,
            bits: None,
            free: None,
        }
    }

    /// Size, resolution and origin.
    #[inline]
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The occupied threshold.
    #[inline]
    pub fn occupied_above(&self) -> i8 {
        self.occupied_above
    }

    /// All cells, row-major (empty on a view made with
    /// [`GridView::from_occupancy_bits`]).
    #[inline]
    pub fn cells(&self) -> &'a [i8] {
        self.cells
    }

    /// Log-odds of cell `(ix, iy)`, `None` off the grid (and everywhere on a view made
    /// with [`GridView::from_occupancy_bits`]).
    #[inline]
    pub fn log_odds(&self, ix: i32, iy: i32) -> Option<i8> {
        if !self.geometry.contains(ix, iy) {
            return None;
        }
        self.cells
            .get(iy as usize * self.geometry.width + ix as usize)
            .copied()
    }

    /// `true` when `(ix, iy)` is on the grid and occupied.
    #[inline]
    pub fn is_occupied(&self, ix: i32, iy: i32) -> bool {
        if self.cells.is_empty() {
            return self.occupancy_bit(ix, iy);
        }
        self.log_odds(ix, iy)
            .is_some_and(|v| v > self.occupied_above)
    }

    /// Range from `(x, y)` (metres, world frame) along `angle` (radians) to the first
    /// occupied cell, sampled every quarter cell (at `k · resolution / 4`, `k ≥ 1`): what a
    /// lidar at that pose would measure on this map (for simulating scans on a map, e.g.
    /// to test or time a localizer on it). `None` when no occupied cell is met within
    /// `max_range` (the last sample may lie up to a quarter cell beyond it), for a
    /// non-finite input or an invalid geometry. Only the part of the ray over the grid is
    /// sampled, so the work is bounded by the grid's size whatever `max_range` is.
    pub fn ray_range(&self, x: f32, y: f32, angle: f32, max_range: f32) -> Option<f32> {
        let g = &self.geometry;
        let finite = x.is_finite() && y.is_finite() && angle.is_finite() && max_range.is_finite();
        if !(finite && g.is_valid()) {
            return None;
        }
        let (sin, cos) = libm::sincosf(angle);
        // The ray's stretch over the grid's rectangle (slab test), within 0 ..= max_range.
        let (w, h) = (
            g.width as f32 * g.resolution,
            g.height as f32 * g.resolution,
        );
        let (mut enter, mut exit) = (0.0f32, max_range);
        for (start, dir, low, size) in [(x, cos, g.origin_x, w), (y, sin, g.origin_y, h)] {
            if dir == 0.0 {
                if start < low || start > low + size {
                    return None;
                }
                continue;
            }
            let (a, b) = ((low - start) / dir, (low + size - start) / dir);
            enter = enter.max(a.min(b));
            exit = exit.min(a.max(b));
        }
        let step = 0.25 * g.resolution;
        if !(enter.is_finite() && exit.is_finite()) || enter > exit + step {
            return None;
        }
        // Samples k · step for k ≥ 1 from the one at or before the entry to one past the
        // exit; k is an integer, so the march cannot stall where r + step rounds to r.
        let first = libm::floorf(enter / step).max(1.0) as u32;
        let last = libm::ceilf(exit / step) as u32;
        (first..=last).find_map(|k| {
            let r = k as f32 * step;
            let (u, v) = g.world_to_grid(x + r * cos, y + r * sin);
            self.is_occupied(super::floor_i32(u), super::floor_i32(v))
                .then_some(r)
        })
    }

    /// The bitmap's bit of cell `(ix, iy)`; `false` off the grid or without a bitmap.
    #[inline]
    fn occupancy_bit(&self, ix: i32, iy: i32) -> bool {
        if !self.geometry.contains(ix, iy) {
            return false;
        }
        let (x, y) = (ix as usize, iy as usize);
        let byte = y * self.geometry.width.div_ceil(8) + x / 8;
        self.bits
            .and_then(|b| b.get(byte))
            .is_some_and(|b| b & (1 << (x % 8)) != 0)
    }

    /// Occupancy of the `n ≤ 16` cells `(x0 + k, y)`, `k < n`, as bits (bit `k` set when
    /// occupied; cells off the grid are not occupied). The scoring hot loop: one 16-byte
    /// compare when the window lies inside the row.
    #[inline]
    pub fn occupied_row_mask(&self, x0: i32, y: i32, n: u32) -> u32 {
        let n = n.min(MAX_MASK_WIDTH);
        let w = self.geometry.width;
        if y < 0 || y as usize >= self.geometry.height {
            return 0;
        }
        let row = y as usize * w;
        if x0 >= 0 && (x0 as usize) + 16 <= w {
            let start = row + x0 as usize;
            if let Some(chunk) = self.cells.get(start..start + 16)
                && let Ok(bytes) = <&[i8; 16]>::try_from(chunk)
            {
                return bool_bytes_to_mask(bytes, self.occupied_above) & ((1u32 << n) - 1);
            }
        }
        let mut mask = 0u32;
        for k in 0..n {
            if self.is_occupied(x0.saturating_add(k as i32), y) {
                mask |= 1 << k;
            }
        }
        mask
    }
}

/// Writes the occupied-cell bitmap of `width × height` `cells` (row-major) into `bits`
/// ([`super::occupancy_bytes`] bytes, see [`GridView::with_occupancy_bits`]): bit set
/// when the cell is above `occupied_above`. Refused with [`GridError::SizeMismatch`]
/// (nothing written) when a length does not fit.
pub fn fill_occupancy_bits(
    cells: &[i8],
    width: usize,
    height: usize,
    occupied_above: i8,
    bits: &mut [u8],
) -> Result<(), GridError> {
    let bytes_per_row = width.div_ceil(8);
    if width.checked_mul(height) != Some(cells.len())
        || bits.len() != super::occupancy_bytes(width, height)
    {
        return Err(GridError::SizeMismatch);
    }
    if bytes_per_row == 0 {
        return Ok(());
    }
    for (row, row_bits) in cells.chunks(width).zip(bits.chunks_mut(bytes_per_row)) {
        for (byte, chunk) in row_bits.iter_mut().zip(row.chunks(8)) {
            *byte = chunk
                .iter()
                .enumerate()
                .fold(0, |b, (k, c)| b | (u8::from(*c > occupied_above) << k));
        }
    }
    Ok(())
}

/// Bit `k` set when `bytes[k] > t`: one vector compare into 0/1 bytes, then each group of
/// eight 0/1 bytes gathered into 8 bits by one multiplication (every partial product
/// lands on its own bit, so nothing carries).
#[inline]
fn bool_bytes_to_mask(bytes: &[i8; 16], t: i8) -> u32 {
    const GATHER: u64 = 0x0102_0408_1020_4080;
    let mut flags = [0u8; 16];
    for (f, b) in flags.iter_mut().zip(bytes) {
        *f = u8::from(*b > t);
    }
    let (groups, _) = flags.as_chunks::<8>();
    let mut mask = 0u32;
    for (g, group) in groups.iter().enumerate() {
        let bits = u64::from_le_bytes(*group).wrapping_mul(GATHER) >> 56;
        mask |= (bits as u32) << (8 * g);
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_match_cell_queries_everywhere() {
        let g = GridGeometry::centred(23, 7, 0.1);
        let cells: Vec<i8> = (0..23 * 7)
            .map(|i| ((i * 37 + 11) % 61) as i8 - 30)
            .collect();
        let view = GridView::new(&cells, g, 5).unwrap();
        for y in -2..9 {
            for x0 in -20..26 {
                for n in [1u32, 5, 9, 16] {
                    let mut want = 0u32;
                    for k in 0..n {
                        if view.is_occupied(x0 + k as i32, y) {
                            want |= 1 << k;
                        }
                    }
                    assert_eq!(view.occupied_row_mask(x0, y, n), want, "{x0} {y} {n}");
                }
            }
        }
        assert!(!view.is_occupied(-1, 0) && view.log_odds(23, 0).is_none());
    }

    #[test]
    fn a_bitmap_alone_answers_like_the_cells() {
        let g = GridGeometry::centred(21, 6, 0.1);
        let cells: Vec<i8> = (0..21 * 6)
            .map(|i| ((i * 29 + 3) % 53) as i8 - 26)
            .collect();
        let mut bits = vec![0u8; super::super::occupancy_bytes(21, 6)];
        fill_occupancy_bits(&cells, 21, 6, 4, &mut bits).unwrap();
        let full = GridView::new(&cells, g, 4).unwrap();
        let only = GridView::from_occupancy_bits(&bits, g, 4).unwrap();
        assert!(only.cells().is_empty() && only.log_odds(0, 0).is_none());
        for y in -2..8 {
            for x in -3..24 {
                assert_eq!(only.is_occupied(x, y), full.is_occupied(x, y), "{x} {y}");
                assert_eq!(
                    only.occupied_row_mask(x, y, 9),
                    full.occupied_row_mask(x, y, 9)
                );
            }
        }
        assert_eq!(
            GridView::from_occupancy_bits(&bits[1..], g, 4).err(),
            Some(GridError::SizeMismatch)
        );
    }

    #[test]
    fn a_ray_stops_at_the_first_occupied_cell() {
        // 20 × 20 cells of 0.1 m centred on the origin: a wall in column 15 (x = 0.5 to
        // 0.6 m) and one cell in row 2 (y = -0.8 to -0.7 m) of column 10 (x = 0 to 0.1).
        let g = GridGeometry::centred(20, 20, 0.1);
        let mut cells = vec![-10i8; 400];
        for y in 0..20 {
            cells[y * 20 + 15] = 50;
        }
        cells[2 * 20 + 10] = 50;
        let view = GridView::new(&cells, g, 0).unwrap();
        // East: the wall's near face at 0.5 m, met within a quarter cell past it.
        let r = view.ray_range(0.0, 0.05, 0.0, 5.0).unwrap();
        assert!((0.5..=0.525).contains(&r), "{r}");
        // South from (0.05, 0): the single cell's top face at 0.7 m.
        let r = view.ray_range(0.05, 0.0, -core::f32::consts::FRAC_PI_2, 5.0);
        assert!(r.is_some_and(|r| (0.7..=0.725).contains(&r)), "{r:?}");
        // West: nothing before the grid's edge, nor beyond (off the grid is free).
        assert_eq!(view.ray_range(0.0, 0.05, core::f32::consts::PI, 5.0), None);
        // Short of the wall, and non-finite inputs.
        assert_eq!(view.ray_range(0.0, 0.05, 0.0, 0.45), None);
        assert_eq!(view.ray_range(f32::NAN, 0.0, 0.0, 5.0), None);
        assert_eq!(view.ray_range(0.0, 0.0, 0.0, f32::INFINITY), None);
        // From far outside, towards the grid: the wall is met; away from it: nothing.
        let r = view.ray_range(-1.0e3, 0.05, 0.0, 2.0e3).unwrap();
        assert!((1000.5..=1000.6).contains(&r), "{r}");
        assert_eq!(
            view.ray_range(-1.0e3, 0.05, core::f32::consts::PI, 2.0e3),
            None
        );
        // A range far beyond f32's quarter-cell resolution ends (the ray leaves the grid).
        assert_eq!(
            view.ray_range(0.0, 0.05, core::f32::consts::PI, 1.0e30),
            None
        );
        // Along a row outside the grid, and inside it along an axis with a zero component.
        assert_eq!(view.ray_range(0.0, 5.0, 0.0, 10.0), None);
        assert!(
            view.ray_range(0.55, -0.95, core::f32::consts::FRAC_PI_2, 5.0)
                .is_some()
        );
    }

    #[test]
    fn wrong_sizes_are_refused() {
        let cells = [0i8; 12];
        let g = GridGeometry::centred(4, 4, 0.1);
        assert_eq!(
            GridView::new(&cells, g, 0).err(),
            Some(GridError::SizeMismatch)
        );
        let bad = GridGeometry {
            resolution: 0.0,
            ..GridGeometry::centred(4, 3, 0.1)
        };
        assert_eq!(
            GridView::new(&cells, bad, 0).err(),
            Some(GridError::InvalidGeometry)
        );
    }
}
