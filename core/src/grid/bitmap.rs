//! A fixed-size bitmap of occupied cells with its own geometry: a map that holds only
//! what the particle filter scores against, an eighth of the bytes of log-odds cells.

use super::scroll::{ScrollOrigin, shift_bit_row, shift_rows};
use super::{GridError, GridGeometry, GridView, OccupancyGrid, floor_i32, occupancy_bytes};

/// A `W × H` bitmap of occupied cells (bit `x % 8` of byte `y · ⌈W/8⌉ + x / 8` for cell
/// `(x, y)`, rows from the bottom edge) placed in the world by a [`GridGeometry`], which
/// can scroll over the world like [`OccupancyGrid::scroll`].
///
/// `BYTES` is [`occupancy_bytes`]`(W, H)` (any other value does not compile). A
/// 512 × 512 bitmap of 5 cm cells covers 25.6 m in 32 KB, where log-odds cells would
/// take 256 KB: the far part of grid SLAM's local map ([`crate::slam`]), whose near part
/// is an [`OccupancyGrid`] copied in with [`OccupancyBitmap::copy_grid`].
///
/// RAM: `BYTES` plus 44 bytes on a 32-bit target. Built with [`OccupancyBitmap::zeroed`]
/// (all zero bytes: a `static` in `.bss`) and placed with [`OccupancyBitmap::init`].
///
/// ```
/// use microslam::grid::{occupancy_bytes, OccupancyBitmap};
///
/// let mut far = Box::new(OccupancyBitmap::<64, 64, { occupancy_bytes(64, 64) }>::zeroed());
/// far.init(0.05, -1.6, -1.6, 20)?; // 3.2 m square around the origin
/// assert!(far.set_world(1.02, 0.52)); // cell (52, 42)
/// assert!(far.view().is_occupied(52, 42));
/// far.scroll(8, 0); // 0.4 m to the right
/// assert!(far.view().is_occupied(44, 42), "the same place in the world");
/// # Ok::<(), microslam::grid::GridError>(())
/// ```
#[derive(Clone, Debug)]
pub struct OccupancyBitmap<const W: usize, const H: usize, const BYTES: usize> {
    bits: [u8; BYTES],
    geometry: GridGeometry,
    scroll: ScrollOrigin,
    occupied_above: i8,
}

impl<const W: usize, const H: usize, const BYTES: usize> OccupancyBitmap<W, H, BYTES> {
    const BYTES_OK: () = assert!(
        BYTES == occupancy_bytes(W, H),
        "OccupancyBitmap<W, H, BYTES>: BYTES must be occupancy_bytes(W, H)"
    );
    const BYTES_PER_ROW: usize = W.div_ceil(8);

    /// A bitmap of zero bytes only, for a `static` in `.bss`: geometry `0 × 0` (every
    /// cell off the map) until [`OccupancyBitmap::init`].
    pub const fn zeroed() -> Self {
        let () = Self::BYTES_OK;
        Self {
            bits: [0; BYTES],
            geometry: GridGeometry::ZEROED,
            scroll: ScrollOrigin::new(0.0, 0.0),
            occupied_above: 0,
        }
    }

    /// Places the bitmap (`W × H` cells of `resolution` metres, lower-left corner at
    /// `(origin_x, origin_y)`) and clears it; `occupied_above` is the log-odds threshold
    /// of the grids whose occupancy it holds (reported by its views). Refused (nothing
    /// changed) when a number is not finite or the resolution is not positive.
    pub fn init(
        &mut self,
        resolution: f32,
        origin_x: f32,
        origin_y: f32,
        occupied_above: i8,
    ) -> Result<(), GridError> {
        if !(resolution.is_finite() && origin_x.is_finite() && origin_y.is_finite()) {
            return Err(GridError::NonFinite);
        }
        if resolution <= 0.0 {
            return Err(GridError::InvalidGeometry);
        }
        self.geometry = GridGeometry {
            width: W,
            height: H,
            resolution,
            origin_x,
            origin_y,
        };
        self.scroll = ScrollOrigin::new(origin_x, origin_y);
        self.occupied_above = occupied_above;
        self.clear();
        Ok(())
    }

    /// Clears every bit.
    pub fn clear(&mut self) {
        self.bits.fill(0);
    }

    /// Size, resolution and origin.
    #[inline]
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The bits, [`occupancy_bytes`]`(W, H)` bytes.
    #[inline]
    pub fn bits(&self) -> &[u8] {
        &self.bits
    }

    /// The bits to change in place (row `y`'s `⌈W / 8⌉` bytes from `y · ⌈W / 8⌉`, cell
    /// `x` in bit `x % 8` of byte `x / 8`).
    #[inline]
    pub(crate) fn bits_mut(&mut self) -> &mut [u8] {
        &mut self.bits
    }

    /// A read-only view for scoring scans (bits only, see
    /// [`GridView::from_occupancy_bits`]).
    pub fn view(&self) -> GridView<'_> {
        GridView::from_trusted(&[], self.geometry, self.occupied_above)
            .with_trusted_bits(&self.bits)
    }

    /// `true` when cell `(ix, iy)` is on the bitmap and set.
    pub fn is_set(&self, ix: i32, iy: i32) -> bool {
        self.index(ix, iy)
            .and_then(|(byte, bit)| self.bits.get(byte).map(|b| b >> bit & 1 == 1))
            .unwrap_or(false)
    }

    /// Sets cell `(ix, iy)`; `false` (nothing written) off the bitmap.
    pub fn set(&mut self, ix: i32, iy: i32) -> bool {
        match self
            .index(ix, iy)
            .and_then(|(byte, bit)| self.bits.get_mut(byte).map(|b| (b, bit)))
        {
            Some((b, bit)) => {
                *b |= 1 << bit;
                true
            }
            None => false,
        }
    }

    /// Sets the cell holding world point `(x, y)`; `false` (nothing written) off the
    /// bitmap or not finite.
    pub fn set_world(&mut self, x: f32, y: f32) -> bool {
        let (u, v) = self.geometry.world_to_grid(x, y);
        u.is_finite() && v.is_finite() && self.set(floor_i32(u), floor_i32(v))
    }

    /// Moves the bitmap by `(dx, dy)` cells over the world (see
    /// [`OccupancyGrid::scroll`]): bit `(x, y)` takes the bit that was at
    /// `(x + dx, y + dy)`, bits from off the bitmap are clear. In place, O(`BYTES`).
    pub fn scroll(&mut self, dx: i32, dy: i32) {
        if dx == 0 && dy == 0 || self.geometry.width == 0 {
            return;
        }
        self.scroll.scroll(dx, dy, &mut self.geometry);
        shift_rows(&mut self.bits, Self::BYTES_PER_ROW, dy as isize);
        if dx != 0 {
            for row in self.bits.chunks_exact_mut(Self::BYTES_PER_ROW) {
                shift_bit_row(row, W, dx as isize);
            }
        }
    }

    /// Overwrites the cells `grid` covers with its occupancy (cells above its threshold
    /// set, the others clear); the rest of the bitmap is unchanged. The grid must have
    /// this bitmap's resolution and lie on its cell lattice (its origin a whole number of
    /// cells away, within a thousandth of a cell), else [`GridError::SizeMismatch`] and
    /// nothing changes; the part of the grid off the bitmap is left out. With a grid
    /// column offset that is a multiple of 8 and a grid bitmap, whole bytes are copied.
    pub fn copy_grid<const GW: usize, const GH: usize, const GB: usize>(
        &mut self,
        grid: &OccupancyGrid<GW, GH, GB>,
    ) -> Result<(), GridError> {
        let g = grid.geometry();
        if g.width == 0 || self.geometry.width == 0 {
            return Ok(());
        }
        if g.resolution != self.geometry.resolution {
            return Err(GridError::SizeMismatch);
        }
        let (u, v) = self.geometry.world_to_grid(g.origin_x, g.origin_y);
        let (ox, oy) = (libm::roundf(u), libm::roundf(v));
        if !((u - ox).abs() < 1e-3 && (v - oy).abs() < 1e-3) {
            return Err(GridError::SizeMismatch);
        }
        let (ox, oy) = (ox as i32, oy as i32);
        let view = grid.view();
        let grid_bits = view.occupancy_bits();
        let grid_bytes_per_row = GW.div_ceil(8);
        for gy in 0..GH as i32 {
            let y = oy + gy;
            if !(0..H as i32).contains(&y) {
                continue;
            }
            let row_start = y as usize * Self::BYTES_PER_ROW;
            if let (Some(bits), true) = (grid_bits, ox % 8 == 0 && ox >= 0) {
                // Whole bytes: the grid's row over this one's, from byte ox / 8.
                let first = ox as usize / 8;
                let src = bits.get(gy as usize * grid_bytes_per_row..);
                let dst = self
                    .bits
                    .get_mut(row_start + first..row_start + Self::BYTES_PER_ROW);
                if let (Some(src), Some(dst)) = (src, dst) {
                    let n = grid_bytes_per_row.min(dst.len());
                    for (k, (d, s)) in dst.iter_mut().zip(src).take(n).enumerate() {
                        // Only bits inside both: a partial last byte of the grid keeps
                        // this bitmap's bits past it; bits past this bitmap's last
                        // column stay clear.
                        let inside = GW
                            .saturating_sub(8 * k)
                            .min(W.saturating_sub(8 * (first + k)))
                            .min(8);
                        let mask = u8::MAX.checked_shr(8 - inside as u32).unwrap_or(0);
                        *d = (*d & !mask) | (*s & mask);
                    }
                }
            } else {
                for gx in 0..GW as i32 {
                    let x = ox + gx;
                    if (0..W as i32).contains(&x)
                        && let Some(b) = self.bits.get_mut(row_start + x as usize / 8)
                    {
                        let bit = 1u8 << (x % 8);
                        if view.is_occupied(gx, gy) {
                            *b |= bit;
                        } else {
                            *b &= !bit;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// Byte index and bit of cell `(ix, iy)`, `None` off the bitmap.
    fn index(&self, ix: i32, iy: i32) -> Option<(usize, u32)> {
        self.geometry.contains(ix, iy).then(|| {
            (
                iy as usize * Self::BYTES_PER_ROW + ix as usize / 8,
                ix as u32 % 8,
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::LogOdds;

    type Far = OccupancyBitmap<37, 30, { occupancy_bytes(37, 30) }>;

    fn random_far(seed: u32) -> Far {
        let mut far = Far::zeroed();
        far.init(0.1, -2.0, -1.5, 20).unwrap();
        let mut state = seed;
        for y in 0..30 {
            for x in 0..37 {
                state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
                if state >> 16 & 3 == 0 {
                    far.set(x, y);
                }
            }
        }
        far
    }

    #[test]
    fn scroll_keeps_the_world_and_clears_what_comes_in() {
        let before = random_far(3);
        for (dx, dy) in [
            (8, 0),
            (-8, 3),
            (5, -2),
            (-13, 7),
            (36, 0),
            (0, -29),
            (41, 2),
        ] {
            let mut far = before.clone();
            far.scroll(dx, dy);
            for y in 0..30 {
                for x in 0..37 {
                    assert_eq!(
                        far.is_set(x, y),
                        before.is_set(x + dx, y + dy),
                        "({dx}, {dy}) at ({x}, {y})"
                    );
                }
            }
            // Nothing past the last column (37 cells: bits 5-7 of each row's last byte).
            for row in far.bits().chunks(5) {
                assert_eq!(row[4] >> 5, 0, "({dx}, {dy}): a padding bit is set");
            }
            far.scroll(-dx, -dy);
            assert_eq!(far.geometry(), before.geometry());
        }
    }

    #[test]
    fn copy_grid_overwrites_the_region_the_grid_covers() {
        const GB: usize = occupancy_bytes(13, 9);
        let model = LogOdds::SYMMETRIC;
        for (ox, oy) in [(8, 4), (3, 2), (32, 25), (-5, -3), (16, 0), (24, 21)] {
            let far0 = random_far(11);
            let mut grid = OccupancyGrid::<13, 9, GB>::new(
                0.1,
                -2.0 + 0.1 * ox as f32,
                -1.5 + 0.1 * oy as f32,
                model,
            );
            for y in 0..9 {
                for x in 0..13 {
                    grid.set_cell(x, y, if (x * 3 + y) % 4 == 0 { 60 } else { -30 });
                }
            }
            let mut far = far0.clone();
            far.copy_grid(&grid).unwrap();
            for y in 0..30 {
                for x in 0..37 {
                    let (gx, gy) = (x - ox, y - oy);
                    let want = if (0..13).contains(&gx) && (0..9).contains(&gy) {
                        (gx * 3 + gy) % 4 == 0
                    } else {
                        far0.is_set(x, y)
                    };
                    assert_eq!(far.is_set(x, y), want, "offset ({ox}, {oy}) at ({x}, {y})");
                }
            }
            // The same through the cell path (no grid bitmap).
            let mut plain = OccupancyGrid::<13, 9>::new(
                0.1,
                -2.0 + 0.1 * ox as f32,
                -1.5 + 0.1 * oy as f32,
                model,
            );
            for y in 0..9 {
                for x in 0..13 {
                    plain.set_cell(x, y, grid.cell(x, y).unwrap());
                }
            }
            let mut far2 = far0.clone();
            far2.copy_grid(&plain).unwrap();
            assert_eq!(far2.bits(), far.bits());
        }
        // Off the lattice or another resolution: refused, nothing changed.
        let far0 = random_far(5);
        let mut far = far0.clone();
        let off = OccupancyGrid::<13, 9, GB>::new(0.1, -1.95, -1.5, model);
        assert_eq!(far.copy_grid(&off), Err(GridError::SizeMismatch));
        let coarse = OccupancyGrid::<13, 9, GB>::new(0.2, -2.0, -1.5, model);
        assert_eq!(far.copy_grid(&coarse), Err(GridError::SizeMismatch));
        assert_eq!(far.bits(), far0.bits());
    }

    #[test]
    fn set_world_and_view_agree_with_the_geometry() {
        let mut far = Far::zeroed();
        assert!(!far.set(0, 0), "no geometry yet");
        far.init(0.1, -2.0, -1.5, 20).unwrap();
        assert!(far.set_world(0.05, 0.05));
        assert!(far.view().is_occupied(20, 15));
        assert!(!far.set_world(f32::NAN, 0.0));
        assert!(!far.set_world(2.0, 0.0), "the right edge is off the bitmap");
        assert_eq!(far.init(0.0, 0.0, 0.0, 20), Err(GridError::InvalidGeometry));
    }
}
