//! Integer line rasterisation (Bresenham): the cells a lidar beam crosses.

/// The cells of the digital line from `(x0, y0)` to `(x1, y1)`, both ends included, in
/// order from the start. Every step moves to one of the 8 neighbours; the line is
/// symmetric in the sense that it never leaves the band of width one cell around the
/// exact segment. Arithmetic is in `i64`, so no coordinates of `i32` overflow.
#[derive(Clone, Copy, Debug)]
pub struct Bresenham {
    x: i64,
    y: i64,
    x1: i64,
    y1: i64,
    dx: i64,
    dy: i64,
    sx: i64,
    sy: i64,
    err: i64,
    done: bool,
}

impl Bresenham {
    /// The line from `(x0, y0)` to `(x1, y1)`.
    pub fn new(x0: i32, y0: i32, x1: i32, y1: i32) -> Self {
        let (x0, y0, x1, y1) = (i64::from(x0), i64::from(y0), i64::from(x1), i64::from(y1));
        let dx = (x1 - x0).abs();
        let dy = -(y1 - y0).abs();
        Self {
            x: x0,
            y: y0,
            x1,
            y1,
            dx,
            dy,
            sx: if x0 < x1 { 1 } else { -1 },
            sy: if y0 < y1 { 1 } else { -1 },
            err: dx + dy,
            done: false,
        }
    }

    /// Number of cells the line has in total (Chebyshev length + 1).
    pub fn cell_count(x0: i32, y0: i32, x1: i32, y1: i32) -> u64 {
        let dx = (i64::from(x1) - i64::from(x0)).unsigned_abs();
        let dy = (i64::from(y1) - i64::from(y0)).unsigned_abs();
        dx.max(dy) + 1
    }
}

/// Longest line, in cells, that [`walk_to_end`] draws (its `i32` error term stays far from
/// overflow below this).
pub(crate) const MAX_WALK_CELLS: u64 = 1 << 28;

/// Calls `visit` for each cell of the line from `(x0, y0)` to `(x1, y1)` except the last
/// one, in order: the cells [`Bresenham`] yields before `(x1, y1)`, in `i32` arithmetic
/// (on a 32-bit microcontroller several times fewer instructions than the iterator's
/// `i64`). Lines longer than [`MAX_WALK_CELLS`] are not drawn and `false` is returned.
pub(crate) fn walk_to_end(
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
    mut visit: impl FnMut(i32, i32),
) -> bool {
    if Bresenham::cell_count(x0, y0, x1, y1) > MAX_WALK_CELLS {
        return false;
    }
    // |x1 − x0|, |y1 − y0| < 2²⁸: none of the sums below overflows.
    let dx = x1.wrapping_sub(x0).wrapping_abs();
    let dy = y1.wrapping_sub(y0).wrapping_abs().wrapping_neg();
    let sx = if x0 < x1 { 1 } else { -1 };
    let sy = if y0 < y1 { 1 } else { -1 };
    let (mut x, mut y, mut err) = (x0, y0, dx.wrapping_add(dy));
    while x != x1 || y != y1 {
        visit(x, y);
        let e2 = err.wrapping_mul(2);
        if e2 >= dy {
            err = err.wrapping_add(dy);
            x = x.wrapping_add(sx);
        }
        if e2 <= dx {
            err = err.wrapping_add(dx);
            y = y.wrapping_add(sy);
        }
    }
    true
}

impl Iterator for Bresenham {
    type Item = (i32, i32);

    fn next(&mut self) -> Option<(i32, i32)> {
        if self.done {
            return None;
        }
        // Coordinates stay between the two i32 ends, so the narrowing is lossless.
        let out = (self.x as i32, self.y as i32);
        if self.x == self.x1 && self.y == self.y1 {
            self.done = true;
        } else {
            let e2 = 2 * self.err;
            if e2 >= self.dy {
                self.err += self.dy;
                self.x += self.sx;
            }
            if e2 <= self.dx {
                self.err += self.dx;
                self.y += self.sy;
            }
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(x0: i32, y0: i32, x1: i32, y1: i32) -> Vec<(i32, i32)> {
        Bresenham::new(x0, y0, x1, y1).collect()
    }

    #[test]
    fn walk_visits_the_iterators_cells_but_the_last() {
        let mut seed = 12345u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 16) as i32 % 200 - 100
        };
        for _ in 0..3000 {
            let (x0, y0, x1, y1) = (next(), next(), next(), next());
            let mut want = line(x0, y0, x1, y1);
            want.pop();
            let mut got = Vec::new();
            assert!(walk_to_end(x0, y0, x1, y1, |x, y| got.push((x, y))));
            assert_eq!(got, want, "({x0}, {y0}) → ({x1}, {y1})");
        }
        let mut none = 0;
        assert!(!walk_to_end(0, 0, i32::MAX, 5, |_, _| none += 1));
        assert!(!walk_to_end(i32::MIN, 0, i32::MAX, 0, |_, _| none += 1));
        assert_eq!(none, 0);
    }

    #[test]
    fn known_lines() {
        assert_eq!(line(0, 0, 0, 0), vec![(0, 0)]);
        assert_eq!(line(0, 0, 3, 0), vec![(0, 0), (1, 0), (2, 0), (3, 0)]);
        assert_eq!(line(2, 2, -1, -1), vec![(2, 2), (1, 1), (0, 0), (-1, -1)]);
        // The classic octant-one example (0,0)→(5,2).
        assert_eq!(
            line(0, 0, 5, 2),
            vec![(0, 0), (1, 0), (2, 1), (3, 1), (4, 2), (5, 2)]
        );
        assert_eq!(
            line(0, 0, 1, 4),
            vec![(0, 0), (0, 1), (1, 2), (1, 3), (1, 4)]
        );
    }

    #[test]
    fn lines_are_8_connected_and_close_to_the_segment() {
        for (x1, y1) in [(7, 3), (-5, 9), (12, -12), (-3, -8), (0, -6), (11, 1)] {
            let cells = line(0, 0, x1, y1);
            assert_eq!(cells.len() as u64, Bresenham::cell_count(0, 0, x1, y1));
            assert_eq!(*cells.last().unwrap(), (x1, y1));
            for w in cells.windows(2) {
                let (a, b) = (w[0], w[1]);
                assert!((a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1 && a != b);
            }
            let len = f64::from(x1 * x1 + y1 * y1).sqrt();
            for (x, y) in cells {
                // Distance from the cell centre to the exact line through the ends.
                let d = f64::from(x * y1 - y * x1).abs() / len;
                assert!(
                    d <= 0.75,
                    "({x},{y}) is {d} cells off the line to ({x1},{y1})"
                );
            }
        }
    }

    #[test]
    fn extreme_coordinates_do_not_overflow() {
        let mut it = Bresenham::new(i32::MAX, i32::MIN, i32::MAX - 2, i32::MIN + 1);
        assert_eq!(it.next(), Some((i32::MAX, i32::MIN)));
        assert_eq!(it.last(), Some((i32::MAX - 2, i32::MIN + 1)));
    }
}
