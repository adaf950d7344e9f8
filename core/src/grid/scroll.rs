//! Moving a fixed-size map over the world: rows, bytes and bits shifted in place, and the
//! origin kept as the one the map was given plus whole cells, so that scrolling never
//! accumulates rounding. Shared by [`super::OccupancyGrid`] and [`super::OccupancyBitmap`].

use super::GridGeometry;

/// The origin a map was given and the cells it has scrolled since.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct ScrollOrigin {
    anchor: [f32; 2],
    scrolled: [i32; 2],
}

impl ScrollOrigin {
    /// A map placed at `(origin_x, origin_y)`, not scrolled.
    pub(super) const fn new(origin_x: f32, origin_y: f32) -> Self {
        Self {
            anchor: [origin_x, origin_y],
            scrolled: [0, 0],
        }
    }

    /// Adds `(dx, dy)` cells and sets `geometry`'s origin to the anchor plus the cells
    /// scrolled, in `f64` (exact for any `i32` count of cells), rounded once to `f32`.
    pub(super) fn scroll(&mut self, dx: i32, dy: i32, geometry: &mut GridGeometry) {
        self.scrolled = [
            self.scrolled[0].saturating_add(dx),
            self.scrolled[1].saturating_add(dy),
        ];
        let res = f64::from(geometry.resolution);
        geometry.origin_x = (f64::from(self.anchor[0]) + f64::from(self.scrolled[0]) * res) as f32;
        geometry.origin_y = (f64::from(self.anchor[1]) + f64::from(self.scrolled[1]) * res) as f32;
    }
}

/// Moves the rows of a row-major array of `row_len`-element rows so that new row `y` is
/// old row `y + shift`; rows that come from outside are `T::default()`.
pub(super) fn shift_rows<T: Copy + Default>(items: &mut [T], row_len: usize, shift: isize) {
    let n = items.len();
    let by = shift.unsigned_abs().saturating_mul(row_len).min(n);
    if shift > 0 {
        items.copy_within(by.., 0);
        if let Some(tail) = items.get_mut(n - by..) {
            tail.fill(T::default());
        }
    } else if shift < 0 {
        items.copy_within(..n - by, by);
        if let Some(head) = items.get_mut(..by) {
            head.fill(T::default());
        }
    }
}

/// [`shift_rows`] within one row: new element `x` is old element `x + shift`.
pub(super) fn shift_row<T: Copy + Default>(row: &mut [T], shift: isize) {
    shift_rows(row, 1, shift);
}

/// Shifts the first `width` bits of a bitmap row (bit `x % 8` of byte `x / 8`) so that
/// new bit `x` is old bit `x + shift`; bits that come from outside are clear, and so are
/// the bits past `width` in the last byte.
pub(super) fn shift_bit_row(row: &mut [u8], width: usize, shift: isize) {
    let bytes = shift.unsigned_abs() / 8;
    let bits = (shift.unsigned_abs() % 8) as u32;
    let byte_shift = if shift < 0 {
        -(bytes as isize)
    } else {
        bytes as isize
    };
    shift_row(row, byte_shift);
    if bits > 0 {
        if shift > 0 {
            // New bit x = old bit x + bits: each byte takes the low bits of the next one.
            for i in 0..row.len() {
                let next = row.get(i + 1).copied().unwrap_or(0);
                if let Some(b) = row.get_mut(i) {
                    *b = (*b >> bits) | (next << (8 - bits));
                }
            }
        } else {
            for i in (0..row.len()).rev() {
                let previous = if i > 0 {
                    row.get(i - 1).copied().unwrap_or(0)
                } else {
                    0
                };
                if let Some(b) = row.get_mut(i) {
                    *b = (*b << bits) | (previous >> (8 - bits));
                }
            }
        }
    }
    let padding = (row.len() * 8).saturating_sub(width).min(8);
    if let Some(last) = row.last_mut() {
        *last &= u8::MAX.checked_shr(padding as u32).unwrap_or(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bit_row_shifts_like_its_bits() {
        // Every shift of a 21-bit row (3 bytes, 3 bits of padding) against bit-by-bit.
        let width = 21;
        let row = [0b1011_0110u8, 0b0101_1101, 0b0001_0111];
        let bit = |r: &[u8], x: isize| {
            (0..width as isize).contains(&x) && r[x as usize / 8] >> (x % 8) & 1 == 1
        };
        for shift in -24..=24isize {
            let mut got = row;
            shift_bit_row(&mut got, width, shift);
            for x in 0..24isize {
                let want = x < width as isize && bit(&row, x + shift);
                assert_eq!(
                    bit(&got, x)
                        || (x >= width as isize && got[x as usize / 8] >> (x % 8) & 1 == 1),
                    want,
                    "shift {shift}, bit {x}"
                );
            }
        }
    }

    #[test]
    fn rows_shift_and_fill() {
        let mut a = [1, 2, 3, 4, 5, 6];
        shift_rows(&mut a, 2, 1);
        assert_eq!(a, [3, 4, 5, 6, 0, 0]);
        shift_rows(&mut a, 2, -2);
        assert_eq!(a, [0, 0, 0, 0, 3, 4]);
        shift_rows(&mut a, 2, 5);
        assert_eq!(a, [0; 6]);
    }
}
