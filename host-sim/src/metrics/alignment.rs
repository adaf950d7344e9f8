//! Rigid 2-D alignments of an estimated trajectory onto ground truth.

use microslam::geometry::{Pose2, wrap_near};

/// Least-squares rotation + translation (no scale) taking `estimated` points onto
/// `truth` points (Umeyama / Kabsch in 2-D), as the pose of the estimate's frame in the
/// truth frame. `None` for fewer than two pairs.
pub fn se2_least_squares<E: Planar, G: Planar>(estimated: &[E], truth: &[G]) -> Option<Pose2<f64>> {
    let n = estimated.len().min(truth.len());
    if n < 2 {
        return None;
    }
    fn mean<P: Planar>(pts: &[P], n: usize) -> [f64; 2] {
        let (sx, sy) = pts[..n].iter().fold((0.0, 0.0), |(x, y), p| {
            let [px, py] = p.xy();
            (x + px, y + py)
        });
        [sx / n as f64, sy / n as f64]
    }
    let (me, mt) = (mean(estimated, n), mean(truth, n));
    let (mut dot, mut cross) = (0.0, 0.0);
    for (e, t) in estimated[..n].iter().zip(&truth[..n]) {
        let ([ex, ey], [tx, ty]) = (e.xy(), t.xy());
        let (ex, ey) = (ex - me[0], ey - me[1]);
        let (tx, ty) = (tx - mt[0], ty - mt[1]);
        dot += ex * tx + ey * ty;
        cross += ex * ty - ey * tx;
    }
    let phi = cross.atan2(dot);
    let (s, c) = phi.sin_cos();
    Some(Pose2::new(
        mt[0] - (c * me[0] - s * me[1]),
        mt[1] - (s * me[0] + c * me[1]),
        phi,
    ))
}

/// Something with a position in the plane: a point `[x, y]` or a pose.
pub trait Planar {
    /// `[x, y]`.
    fn xy(&self) -> [f64; 2];
}

impl Planar for [f64; 2] {
    fn xy(&self) -> [f64; 2] {
        *self
    }
}

impl Planar for Pose2<f64> {
    fn xy(&self) -> [f64; 2] {
        [self.x, self.y]
    }
}

/// The transform that puts the estimate's first pose onto the truth's first pose:
/// `truth₀ ⊕ estimate₀⁻¹`. Comparing `T · estimate` with the truth is comparing both
/// paths in the frames of their own first poses.
pub fn first_pose(estimated0: &Pose2<f64>, truth0: &Pose2<f64>) -> Pose2<f64> {
    truth0.compose(&estimated0.inverse())
}

/// `T · pose` with the heading wrapped.
pub fn apply(t: &Pose2<f64>, pose: &Pose2<f64>) -> Pose2<f64> {
    Rigid::new(t).apply(pose)
}

/// A rigid transform with its sine and cosine computed once, for applying it to many
/// poses (the core's `compose` recomputes them and wraps with `atan2`).
#[derive(Clone, Copy, Debug)]
pub struct Rigid {
    x: f64,
    y: f64,
    theta: f64,
    sin: f64,
    cos: f64,
}

impl Rigid {
    /// The transform of pose `t`.
    pub fn new(t: &Pose2<f64>) -> Self {
        let (sin, cos) = t.theta.sin_cos();
        Self {
            x: t.x,
            y: t.y,
            theta: t.theta,
            sin,
            cos,
        }
    }

    /// `T · pose`, heading wrapped to (−π, π].
    pub fn apply(&self, p: &Pose2<f64>) -> Pose2<f64> {
        let [x, y] = self.point(p.x, p.y);
        Pose2::new(x, y, wrap_near(self.theta + p.theta))
    }

    /// `T · (x, y)`.
    pub fn point(&self, x: f64, y: f64) -> [f64; 2] {
        [
            self.x + self.cos * x - self.sin * y,
            self.y + self.sin * x + self.cos * y,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_known_rigid_motion() {
        let t = Pose2::new(1.5, -2.0, 0.7);
        let est: Vec<[f64; 2]> = (0..20)
            .map(|i| [f64::from(i).cos() * 3.0, f64::from(i) * 0.2])
            .collect();
        let truth: Vec<[f64; 2]> = est
            .iter()
            .map(|p| {
                let q = t.transform_point(&nalgebra::Vector2::new(p[0], p[1]));
                [q[0], q[1]]
            })
            .collect();
        let a = se2_least_squares(&est, &truth).unwrap();
        assert!((a.x - 1.5).abs() < 1e-12 && (a.y + 2.0).abs() < 1e-12);
        assert!((a.theta - 0.7).abs() < 1e-12);
        assert!(se2_least_squares(&est[..1], &truth[..1]).is_none());
        let f = first_pose(&Pose2::new(1.0, 0.0, 0.0), &Pose2::new(0.0, 1.0, 1.0));
        let p = apply(&f, &Pose2::new(1.0, 0.0, 0.0));
        assert!(p.x.abs() < 1e-12 && (p.y - 1.0).abs() < 1e-12 && (p.theta - 1.0).abs() < 1e-12);
    }
}
