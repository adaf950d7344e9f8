//! Max-pooled copies of a map for the global search ("precomputation grids", Olson 2009;
//! Cartographer's fast correlative scan matcher).
//!
//! Level `k` (1 ≤ k ≤ L) holds, for every cell `(x, y)`, whether **any** cell of the
//! `2^k × 2^k` window `[x, x + 2^k) × [y, y + 2^k)` (clipped to the grid) is occupied:
//! the max over the window of the 0/1 occupancy the correlation counts. A scan scored
//! against level `k` at a translation bounds from above its correlation at every one of
//! the `2^k × 2^k` translations starting there — the bound of the branch and bound in
//! [`crate::pf::global`]. Level 0 is the map itself.
//!
//! Each level also has a *free block* bitmap: bit `(bx, by)` of level `k` is set when the
//! aligned block `[bx·2^k, (bx+1)·2^k) × [by·2^k, (by+1)·2^k)` holds at least one free
//! cell (log-odds below the free threshold): the search drops blocks where the robot
//! cannot stand without scoring them.
//!
//! # Byte image
//!
//! One contiguous little-endian image, which can be built on the host and kept in flash
//! next to the map ([`MaxPoolLayers::from_bytes`] borrows it without copying), or built
//! at start-up into a RAM buffer ([`MaxPoolLayers::build`]):
//!
//! | offset | size | content |
//! |---|---|---|
//! | 0 | 4 | magic `b"MXPL"` |
//! | 4 | 1 | format version, [`MaxPoolLayers::VERSION`] |
//! | 5 | 1 | levels `L`, 1 ≤ L ≤ [`MAX_LEVELS`] |
//! | 6 | 1 | occupied threshold of the map (`i8`): a cell is occupied above it |
//! | 7 | 1 | free threshold (`i8`): a cell is free below it |
//! | 8 | 2 | width `W` in cells (`u16`) |
//! | 10 | 2 | height `H` in cells (`u16`) |
//! | 12 | 4 | zero |
//! | 16 | `L · ⌈W/8⌉ · H` | occupied levels 1..=L, each a bitmap of [`super::occupancy_bytes`]`(W, H)` bytes (bit `x % 8` of byte `y·⌈W/8⌉ + x/8`) |
//! | … | Σ free bytes | free levels 1..=L, level `k` a bitmap of `occupancy_bytes(⌈W/2^k⌉, ⌈H/2^k⌉)` bytes |
//!
//! Size ([`MaxPoolLayers::bytes_for`]): a 256 × 256 map takes 8192 bytes per occupied
//! level plus 2048, 512, 128, 32, 8, 4, … bytes for free levels 1, 2, 3, …: with L = 6,
//! 16 + 49 152 + 2 732 = 51 900 bytes.

use super::{GridView, occupancy_bytes};
use core::fmt;

/// Most levels an image may have (windows up to 256 × 256 cells).
pub const MAX_LEVELS: u8 = 8;
/// Bytes of the image header.
pub const HEADER_BYTES: usize = 16;
const MAGIC: [u8; 4] = *b"MXPL";

/// Why a layers image was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LayersError {
    /// Fewer bytes than the header, or than the header says the image holds.
    TooShort,
    /// More bytes than the header says the image holds.
    TooLong,
    /// The first four bytes are not `MXPL`.
    BadMagic,
    /// A format version this build does not read.
    UnsupportedVersion,
    /// Levels outside `1..=MAX_LEVELS`, or a zero width or height.
    BadHeader,
    /// The image was made for a map of another size or thresholds.
    MapMismatch,
    /// The output buffer of [`MaxPoolLayers::build`] has the wrong length.
    BufferSize,
    /// [`MaxPoolLayers::verify`] found a byte that differs from the map's.
    Corrupt,
}

impl fmt::Display for LayersError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::TooShort => "max-pool layers image is shorter than its header says",
            Self::TooLong => "max-pool layers image is longer than its header says",
            Self::BadMagic => "max-pool layers image does not start with MXPL",
            Self::UnsupportedVersion => "max-pool layers image has an unknown format version",
            Self::BadHeader => "max-pool layers header has a bad level count or size",
            Self::MapMismatch => "max-pool layers were made for another map",
            Self::BufferSize => "max-pool layers buffer has the wrong length",
            Self::Corrupt => "max-pool layers differ from the map",
        })
    }
}

impl core::error::Error for LayersError {}

/// A read-only view of the max-pooled levels of one map (see the module documentation
/// for the layout). `Copy`: it is two slices and a few numbers.
#[derive(Clone, Copy, Debug)]
pub struct MaxPoolLayers<'a> {
    bytes: &'a [u8],
    levels: u8,
    width: usize,
    height: usize,
    occupied_above: i8,
    free_below: i8,
}

/// Bytes of the free bitmap of level `k`.
const fn free_bytes(width: usize, height: usize, k: u8) -> usize {
    let s = 1usize << k;
    occupancy_bytes(width.div_ceil(s), height.div_ceil(s))
}

impl<'a> MaxPoolLayers<'a> {
    /// Format version written and read by this build.
    pub const VERSION: u8 = 1;

    /// Bytes of the image of a `width × height` map with `levels` levels (header
    /// included); `None` when `levels` is outside `1..=MAX_LEVELS` or the size overflows.
    pub const fn bytes_for(width: usize, height: usize, levels: u8) -> Option<usize> {
        if levels == 0 || levels > MAX_LEVELS || width == 0 || height == 0 {
            return None;
        }
        let mut total = HEADER_BYTES + occupancy_bytes(width, height) * levels as usize;
        let mut k = 1;
        while k <= levels {
            total += free_bytes(width, height, k);
            k += 1;
        }
        Some(total)
    }

    /// Bytes of one occupied level of a `width × height` map (256 × 256: 8192).
    pub const fn bytes_per_level(width: usize, height: usize) -> usize {
        occupancy_bytes(width, height)
    }

    /// Borrows an image (e.g. `&'static` bytes in flash) after checking its header and
    /// length. The content is not checked against any map here: see
    /// [`MaxPoolLayers::matches`] (cheap, header only) and [`MaxPoolLayers::verify`]
    /// (every byte).
    pub fn from_bytes(bytes: &'a [u8]) -> Result<Self, LayersError> {
        let header: &[u8; HEADER_BYTES] = bytes
            .first_chunk::<HEADER_BYTES>()
            .ok_or(LayersError::TooShort)?;
        let [
            m0,
            m1,
            m2,
            m3,
            version,
            levels,
            occ,
            free,
            w0,
            w1,
            h0,
            h1,
            ..,
        ] = *header;
        if [m0, m1, m2, m3] != MAGIC {
            return Err(LayersError::BadMagic);
        }
        if version != Self::VERSION {
            return Err(LayersError::UnsupportedVersion);
        }
        let width = usize::from(u16::from_le_bytes([w0, w1]));
        let height = usize::from(u16::from_le_bytes([h0, h1]));
        let want = Self::bytes_for(width, height, levels).ok_or(LayersError::BadHeader)?;
        if bytes.len() < want {
            return Err(LayersError::TooShort);
        }
        if bytes.len() > want {
            return Err(LayersError::TooLong);
        }
        Ok(Self {
            bytes,
            levels,
            width,
            height,
            occupied_above: occ as i8,
            free_below: free as i8,
        })
    }

    /// Computes the image of `map` with `levels` levels into `out` (exactly
    /// [`MaxPoolLayers::bytes_for`] bytes) and returns the view of it. A cell is free
    /// when its log-odds is below `free_below`. On the host the bytes are what goes into
    /// flash; on the device this builds them at start-up into RAM (≈ 0.1 s of a
    /// Cortex-M4F for 256 × 256 and L = 6: about 12 instructions per byte written).
    pub fn build(
        map: &GridView<'_>,
        free_below: i8,
        levels: u8,
        out: &'a mut [u8],
    ) -> Result<Self, LayersError> {
        let g = map.geometry();
        let (w, h) = (g.width, g.height);
        if w > usize::from(u16::MAX) || h > usize::from(u16::MAX) {
            return Err(LayersError::BadHeader);
        }
        let want = Self::bytes_for(w, h, levels).ok_or(LayersError::BadHeader)?;
        if out.len() != want {
            return Err(LayersError::BufferSize);
        }
        let (header, body) = out.split_at_mut(HEADER_BYTES);
        header.fill(0);
        if let Some(hd) = header.first_chunk_mut::<12>() {
            let [w0, w1] = (w as u16).to_le_bytes();
            let [h0, h1] = (h as u16).to_le_bytes();
            let [o] = map.occupied_above().to_le_bytes();
            let [f] = free_below.to_le_bytes();
            *hd = [
                MAGIC[0],
                MAGIC[1],
                MAGIC[2],
                MAGIC[3],
                Self::VERSION,
                levels,
                o,
                f,
                w0,
                w1,
                h0,
                h1,
            ];
        }
        let per = occupancy_bytes(w, h);
        let (occ, mut free) = body.split_at_mut(per * usize::from(levels));
        // Occupied levels: each from the one below (level 0: the map).
        let mut rest: &mut [u8] = occ;
        let mut below: Option<&[u8]> = None;
        for k in 1..=levels {
            let (this, tail) = rest.split_at_mut(per);
            for (i, byte) in this.iter_mut().enumerate() {
                *byte = pooled_byte(map, below, k, i / w.div_ceil(8), i % w.div_ceil(8));
            }
            below = Some(this);
            rest = tail;
        }
        // Free levels.
        let mut below: Option<&[u8]> = None;
        for k in 1..=levels {
            let (this, tail) = free.split_at_mut(free_bytes(w, h, k));
            fill_free_level(map, free_below, below, k, this);
            below = Some(this);
            free = tail;
        }
        // `out` is borrowed mutably above; the view re-borrows it read-only.
        Self::from_bytes(out)
    }

    /// Recomputes every byte from `map` and compares (a check at start-up of an image in
    /// flash: about as many instructions as [`MaxPoolLayers::build`], no RAM).
    pub fn verify(&self, map: &GridView<'_>) -> Result<(), LayersError> {
        if !self.matches(map) {
            return Err(LayersError::MapMismatch);
        }
        let (w, h) = (self.width, self.height);
        let per = occupancy_bytes(w, h);
        let stride = w.div_ceil(8);
        for k in 1..=self.levels {
            let below = if k == 1 {
                None
            } else {
                self.occupied_level(k - 1)
            };
            let this = self.occupied_level(k).ok_or(LayersError::Corrupt)?;
            for i in 0..per {
                let want = pooled_byte(map, below, k, i / stride, i % stride);
                if this.get(i) != Some(&want) {
                    return Err(LayersError::Corrupt);
                }
            }
        }
        for k in 1..=self.levels {
            let below = if k == 1 { None } else { self.free_level(k - 1) };
            let (bw, bh) = (w.div_ceil(1 << k), h.div_ceil(1 << k));
            for by in 0..bh {
                for bx in 0..bw {
                    let want = free_block(map, self.free_below, below, k, bx, by);
                    if self.any_free(k, bx, by) != want {
                        return Err(LayersError::Corrupt);
                    }
                }
            }
        }
        Ok(())
    }

    /// `true` when the image was made for a map of `map`'s size and occupied threshold.
    pub fn matches(&self, map: &GridView<'_>) -> bool {
        let g = map.geometry();
        g.width == self.width
            && g.height == self.height
            && map.occupied_above() == self.occupied_above
    }

    /// The image bytes (what [`MaxPoolLayers::from_bytes`] reads back).
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Number of levels `L`.
    pub fn levels(&self) -> u8 {
        self.levels
    }

    /// Map width, cells.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Map height, cells.
    pub fn height(&self) -> usize {
        self.height
    }

    /// The free threshold the free levels were made with.
    pub fn free_below(&self) -> i8 {
        self.free_below
    }

    /// The bitmap of occupied level `k` (1 ≤ k ≤ L).
    pub(crate) fn occupied_level(&self, k: u8) -> Option<&'a [u8]> {
        if k == 0 || k > self.levels {
            return None;
        }
        let per = occupancy_bytes(self.width, self.height);
        let start = HEADER_BYTES + per * usize::from(k - 1);
        self.bytes.get(start..start + per)
    }

    /// The bitmap of free level `k` (1 ≤ k ≤ L).
    fn free_level(&self, k: u8) -> Option<&'a [u8]> {
        if k == 0 || k > self.levels {
            return None;
        }
        let mut start =
            HEADER_BYTES + occupancy_bytes(self.width, self.height) * usize::from(self.levels);
        for j in 1..k {
            start += free_bytes(self.width, self.height, j);
        }
        self.bytes
            .get(start..start + free_bytes(self.width, self.height, k))
    }

    /// `true` when some cell of the window `[x, x + 2^k) × [y, y + 2^k)` is occupied
    /// (1 ≤ k ≤ L; any integer `x`, `y`: windows reaching over the grid's edge look at its
    /// part on the grid, or a larger one — still an upper bound). `false` for `k` = 0 or
    /// beyond `L` (use the map for level 0).
    #[inline]
    pub fn any_occupied(&self, k: u8, x: i32, y: i32) -> bool {
        let size = 1i32 << k.min(MAX_LEVELS);
        if x >= self.width as i32 || y >= self.height as i32 || x <= -size || y <= -size {
            return false;
        }
        let (x, y) = (x.max(0) as usize, y.max(0) as usize);
        let Some(level) = self.occupied_level(k) else {
            return false;
        };
        level
            .get(y * self.width.div_ceil(8) + x / 8)
            .is_some_and(|b| b >> (x % 8) & 1 == 1)
    }

    /// `true` when the aligned block `(bx, by)` of level `k` (cells
    /// `[bx·2^k, (bx+1)·2^k) × [by·2^k, (by+1)·2^k)`) holds a free cell (1 ≤ k ≤ L).
    #[inline]
    pub fn any_free(&self, k: u8, bx: usize, by: usize) -> bool {
        let Some(level) = self.free_level(k) else {
            return false;
        };
        let bw = self.width.div_ceil(1 << k);
        if bx >= bw {
            return false;
        }
        level
            .get(by * bw.div_ceil(8) + bx / 8)
            .is_some_and(|b| b >> (bx % 8) & 1 == 1)
    }
}

/// Byte `j` of row `y` of the occupancy bitmap at level 0 (from the view's bitmap when it
/// has one, otherwise from eight cells).
fn level0_byte(map: &GridView<'_>, y: usize, j: usize) -> u8 {
    let g = map.geometry();
    if y >= g.height {
        return 0;
    }
    if let Some(bits) = map.occupancy_bits() {
        return bits.get(y * g.width.div_ceil(8) + j).copied().unwrap_or(0);
    }
    let mut b = 0u8;
    for bit in 0..8 {
        let x = j * 8 + bit;
        if x < g.width && map.is_occupied(x as i32, y as i32) {
            b |= 1 << bit;
        }
    }
    b
}

/// Byte `j` of row `y` of occupied level `k − 1` (`below`: its bitmap; `None`: level 0).
fn source_byte(map: &GridView<'_>, below: Option<&[u8]>, y: usize, j: usize) -> u8 {
    let g = map.geometry();
    let stride = g.width.div_ceil(8);
    if y >= g.height || j >= stride {
        return 0;
    }
    match below {
        Some(b) => b.get(y * stride + j).copied().unwrap_or(0),
        None => level0_byte(map, y, j),
    }
}

/// Byte `j` of row `y` of the level-`k − 1` bitmap shifted left by `s` cells (bit `x` of
/// the result = cell `x + s` of the source), ORed with the unshifted byte.
fn pair_byte(map: &GridView<'_>, below: Option<&[u8]>, y: usize, j: usize, s: usize) -> u8 {
    let (q, r) = (s / 8, s % 8);
    let lo = source_byte(map, below, y, j + q);
    let shifted = if r == 0 {
        lo
    } else {
        (lo >> r) | (source_byte(map, below, y, j + q + 1) << (8 - r))
    };
    source_byte(map, below, y, j) | shifted
}

/// Byte `j` of row `y` of occupied level `k` from level `k − 1`: the OR of the four
/// level-`k−1` windows at `(x, y)`, `(x + s, y)`, `(x, y + s)`, `(x + s, y + s)`,
/// `s = 2^(k−1)`. Cells past the grid's edge count as not occupied (the padding bits of a
/// row are zero at every level).
fn pooled_byte(map: &GridView<'_>, below: Option<&[u8]>, k: u8, y: usize, j: usize) -> u8 {
    let s = 1usize << (k - 1);
    pair_byte(map, below, y, j, s) | pair_byte(map, below, y + s, j, s)
}

/// Bit `(bx, by)` of free level `k − 1` (`None`: the map's cells, free below
/// `free_below`).
fn free_bit(
    map: &GridView<'_>,
    free_below: i8,
    below: Option<&[u8]>,
    k: u8,
    bx: usize,
    by: usize,
) -> bool {
    let g = map.geometry();
    match below {
        None => map.is_free(bx as i32, by as i32, free_below),
        Some(b) => {
            let s = 1usize << (k - 1);
            let (bw, bh) = (g.width.div_ceil(s), g.height.div_ceil(s));
            bx < bw
                && by < bh
                && b.get(by * bw.div_ceil(8) + bx / 8)
                    .is_some_and(|v| v >> (bx % 8) & 1 == 1)
        }
    }
}

/// Bit `(bx, by)` of free level `k`: the OR of the four level-`k − 1` bits below it.
fn free_block(
    map: &GridView<'_>,
    free_below: i8,
    below: Option<&[u8]>,
    k: u8,
    bx: usize,
    by: usize,
) -> bool {
    (0..2).any(|dy| (0..2).any(|dx| free_bit(map, free_below, below, k, 2 * bx + dx, 2 * by + dy)))
}

/// Row `by` of free level `k` into `out` (its bytes).
fn free_row(
    map: &GridView<'_>,
    free_below: i8,
    below: Option<&[u8]>,
    k: u8,
    by: usize,
    out: &mut [u8],
) {
    let g = map.geometry();
    let bw = g.width.div_ceil(1 << k);
    out.fill(0);
    for bx in 0..bw {
        if free_block(map, free_below, below, k, bx, by)
            && let Some(byte) = out.get_mut(bx / 8)
        {
            *byte |= 1 << (bx % 8);
        }
    }
}

/// Free level `k` from level `k − 1` into `out`.
fn fill_free_level(
    map: &GridView<'_>,
    free_below: i8,
    below: Option<&[u8]>,
    k: u8,
    out: &mut [u8],
) {
    let g = map.geometry();
    let stride = g.width.div_ceil(1 << k).div_ceil(8).max(1);
    for (by, row) in out.chunks_mut(stride).enumerate() {
        free_row(map, free_below, below, k, by, row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridGeometry;
    use rand::{Rng, SeedableRng};

    fn random_map(seed: u64, w: usize, h: usize) -> Vec<i8> {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        (0..w * h)
            .map(|_| match rng.random_range(0..10) {
                0 => 50,
                1..=5 => -50,
                _ => 0,
            })
            .collect()
    }

    #[test]
    fn levels_are_window_maxima_and_free_blocks() {
        for (seed, (w, h)) in [(19usize, 13usize), (32, 32), (37, 9), (8, 40)]
            .into_iter()
            .enumerate()
        {
            let cells = random_map(seed as u64, w, h);
            let g = GridGeometry::centred(w, h, 0.05);
            let view = GridView::new(&cells, g, 20).unwrap();
            let levels = 4;
            let mut buf = vec![0u8; MaxPoolLayers::bytes_for(w, h, levels).unwrap()];
            let layers = MaxPoolLayers::build(&view, -20, levels, &mut buf).unwrap();
            for k in 1..=levels {
                let s = 1i32 << k;
                for y in -s - 2..h as i32 + 2 {
                    for x in -s - 2..w as i32 + 2 {
                        let want =
                            (x..x + s).any(|cx| (y..y + s).any(|cy| view.is_occupied(cx, cy)));
                        let got = layers.any_occupied(k, x, y);
                        if x >= 0 && y >= 0 {
                            assert_eq!(got, want, "k {k} ({x}, {y}) {w}×{h}");
                        } else {
                            // Windows over the lower edges: an upper bound.
                            assert!(got || !want, "k {k} ({x}, {y})");
                        }
                    }
                }
                for by in 0..h.div_ceil(s as usize) + 1 {
                    for bx in 0..w.div_ceil(s as usize) + 1 {
                        let want = (0..s).any(|dx| {
                            (0..s).any(|dy| {
                                view.log_odds(bx as i32 * s + dx, by as i32 * s + dy)
                                    .is_some_and(|v| v < -20)
                            })
                        });
                        assert_eq!(layers.any_free(k, bx, by), want, "free k {k} {bx} {by}");
                    }
                }
            }
            // Round trip through bytes, and the check against the map.
            let again = MaxPoolLayers::from_bytes(layers.as_bytes()).unwrap();
            assert_eq!(again.levels(), levels);
            assert_eq!(again.verify(&view), Ok(()));
            // The bitmap-backed view gives the same bytes.
            let mut bits = vec![0u8; occupancy_bytes(w, h)];
            crate::grid::fill_occupancy_bits(&cells, w, h, 20, &mut bits).unwrap();
            let with_bits = view.with_occupancy_bits(&bits).unwrap();
            let mut buf2 = vec![0u8; buf.len()];
            MaxPoolLayers::build(&with_bits, -20, levels, &mut buf2).unwrap();
            assert_eq!(buf, buf2);
        }
    }

    #[test]
    fn bad_images_are_refused() {
        let cells = random_map(3, 16, 16);
        let view = GridView::new(&cells, GridGeometry::centred(16, 16, 0.05), 20).unwrap();
        let n = MaxPoolLayers::bytes_for(16, 16, 3).unwrap();
        let mut buf = vec![0u8; n];
        MaxPoolLayers::build(&view, -20, 3, &mut buf).unwrap();
        assert_eq!(
            MaxPoolLayers::from_bytes(&buf[..10]).err(),
            Some(LayersError::TooShort)
        );
        assert_eq!(
            MaxPoolLayers::from_bytes(&buf[..n - 1]).err(),
            Some(LayersError::TooShort)
        );
        let mut long = buf.clone();
        long.push(0);
        assert_eq!(
            MaxPoolLayers::from_bytes(&long).err(),
            Some(LayersError::TooLong)
        );
        let mut bad = buf.clone();
        bad[0] = b'X';
        assert_eq!(
            MaxPoolLayers::from_bytes(&bad).err(),
            Some(LayersError::BadMagic)
        );
        let mut bad = buf.clone();
        bad[4] = 9;
        assert_eq!(
            MaxPoolLayers::from_bytes(&bad).err(),
            Some(LayersError::UnsupportedVersion)
        );
        let mut bad = buf.clone();
        bad[5] = 0;
        assert_eq!(
            MaxPoolLayers::from_bytes(&bad).err(),
            Some(LayersError::BadHeader)
        );
        let mut bad = buf.clone();
        bad[HEADER_BYTES + 5] ^= 0x10;
        let layers = MaxPoolLayers::from_bytes(&bad).unwrap();
        assert_eq!(layers.verify(&view), Err(LayersError::Corrupt));
        let mut bad = buf.clone();
        let last = bad.len() - 1;
        bad[last] ^= 0x01;
        let layers = MaxPoolLayers::from_bytes(&bad).unwrap();
        assert_eq!(layers.verify(&view), Err(LayersError::Corrupt));
        let other = GridView::new(&cells, GridGeometry::centred(16, 16, 0.05), 10).unwrap();
        let layers = MaxPoolLayers::from_bytes(&buf).unwrap();
        assert_eq!(layers.verify(&other), Err(LayersError::MapMismatch));
        assert_eq!(
            MaxPoolLayers::build(&view, -20, 3, &mut buf[..n - 1]).err(),
            Some(LayersError::BufferSize)
        );
        assert_eq!(
            MaxPoolLayers::build(&view, -20, 0, &mut buf).err(),
            Some(LayersError::BadHeader)
        );
    }

    #[test]
    fn sizes_for_a_256_map() {
        assert_eq!(MaxPoolLayers::bytes_per_level(256, 256), 8192);
        assert_eq!(MaxPoolLayers::bytes_for(256, 256, 6), Some(51_900));
        assert_eq!(MaxPoolLayers::bytes_for(256, 256, 9), None);
    }
}
