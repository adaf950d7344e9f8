//! One-to-one assignments (Hungarian method, via the `pathfinding` crate).

use pathfinding::kuhn_munkres::{kuhn_munkres, kuhn_munkres_min};
use pathfinding::matrix::Matrix;

/// Pairs rows with columns one-to-one minimising the total cost (`cost[r][c]`, finite,
/// non-negative); every row or every column is paired, whichever are fewer. Returns
/// `(row, column)` pairs.
pub fn min_cost(cost: &[Vec<f64>]) -> Vec<(usize, usize)> {
    solve(cost, |m| kuhn_munkres_min(m).1, 1e6)
}

/// Like [`min_cost`] but maximising the total of `gain`.
pub fn max_gain(gain: &[Vec<f64>]) -> Vec<(usize, usize)> {
    solve(gain, |m| kuhn_munkres(m).1, 1.0)
}

fn solve(
    w: &[Vec<f64>],
    run: impl Fn(&Matrix<i64>) -> Vec<usize>,
    scale: f64,
) -> Vec<(usize, usize)> {
    let rows = w.len();
    let cols = w.first().map_or(0, Vec::len);
    if rows == 0 || cols == 0 {
        return Vec::new();
    }
    // kuhn_munkres wants rows ≤ columns: transpose when needed.
    let transposed = rows > cols;
    let (r, c) = if transposed {
        (cols, rows)
    } else {
        (rows, cols)
    };
    let mut m = Matrix::new(r, c, 0i64);
    for i in 0..r {
        for j in 0..c {
            let v = if transposed { w[j][i] } else { w[i][j] };
            m[(i, j)] = (v * scale).round() as i64;
        }
    }
    run(&m)
        .into_iter()
        .enumerate()
        .map(|(i, j)| if transposed { (j, i) } else { (i, j) })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optimal_not_greedy() {
        // Greedy would take (0,0) at 1.0 and then (1,1) at 10.0; optimal is 2 + 2.
        let cost = vec![vec![1.0, 2.0], vec![2.0, 10.0]];
        let mut a = min_cost(&cost);
        a.sort();
        assert_eq!(a, vec![(0, 1), (1, 0)]);
        // Rectangular both ways.
        let wide = vec![vec![5.0, 1.0, 3.0]];
        assert_eq!(min_cost(&wide), vec![(0, 1)]);
        let tall = vec![vec![5.0], vec![1.0], vec![3.0]];
        assert_eq!(min_cost(&tall), vec![(1, 0)]);
        let gain = vec![vec![3.0, 1.0], vec![4.0, 0.0]];
        let mut g = max_gain(&gain);
        g.sort();
        assert_eq!(g, vec![(0, 1), (1, 0)]);
    }
}
