//! The odometry between consecutive scans of a grid run, written once for both drive
//! loops (the one-map filters and the building-scale graph SLAM).
//!
//! The filter is predicted with the odometry pose increment between consecutive scans in
//! input order. An odometry pose that is not finite is refused and counted, and the next
//! good one predicts the whole motion. A step longer than the settings'
//! `max_odometry_step_m` is no robot's motion between two scans: it is taken as an
//! odometry reset (a restarted odometry node starts again at zero, a corrupt pose),
//! counted, and the filter is re-anchored on the new odometry frame without moving, so the
//! scan matching carries on where the robot is instead of jumping the estimate (and the
//! map) kilometres away.

use microslam::geometry::Pose2;

/// What to do with a scan's odometry pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OdometryStep {
    /// Predict the filter from the first pose to the second.
    Move(Pose2<f32>, Pose2<f32>),
    /// Nothing to predict: the first pose of the run, a refused one, or a reset.
    Hold,
}

/// The previous usable odometry pose and the counts of what was not used.
#[derive(Clone, Debug)]
pub struct ScanOdometry {
    previous: Option<Pose2<f32>>,
    max_step_m: f32,
    /// Poses refused: not finite.
    pub refused: usize,
    /// Steps longer than the limit: taken as odometry resets.
    pub resets: usize,
}

impl ScanOdometry {
    /// No pose yet; steps longer than `max_step_m` metres are resets.
    pub fn new(max_step_m: f32) -> Self {
        Self {
            previous: None,
            max_step_m,
            refused: 0,
            resets: 0,
        }
    }

    /// The step to the scan's odometry pose `odom`.
    pub fn step(&mut self, odom: Pose2<f32>) -> OdometryStep {
        if !odom.is_finite() {
            self.refused += 1;
            return OdometryStep::Hold;
        }
        let Some(from) = self.previous.replace(odom) else {
            return OdometryStep::Hold;
        };
        if (odom.x - from.x).hypot(odom.y - from.y) > self.max_step_m {
            self.resets += 1;
            return OdometryStep::Hold;
        }
        OdometryStep::Move(from, odom)
    }
}

/// The odometry path as the filter follows it, where grid SLAM's map is placed: the
/// finite poses of `poses` as they are until the first reset (a step longer than
/// `max_step_m`), and after one, carried into the frame that continues the path from
/// where it was (a reset does not move it).
pub fn chained(poses: impl IntoIterator<Item = Pose2<f32>>, max_step_m: f32) -> Vec<Pose2<f32>> {
    let mut odometry = ScanOdometry::new(max_step_m);
    // Odometry frame → the path's frame: none until the first reset (the poses as given).
    let mut anchor: Option<Pose2<f32>> = None;
    let mut last: Option<Pose2<f32>> = None;
    let mut path = Vec::new();
    for pose in poses {
        let step = odometry.step(pose);
        if !pose.is_finite() {
            continue;
        }
        let resets = step == OdometryStep::Hold && last.is_some();
        if let (true, Some(previous)) = (resets, last) {
            let here = anchor.map_or(previous, |a| a.compose(&previous));
            anchor = Some(here.compose(&pose.inverse()));
        }
        last = Some(pose);
        path.push(anchor.map_or(pose, |a| a.compose(&pose)));
    }
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refused_pose_is_bridged_and_a_jump_re_anchors_without_moving() {
        let p = |x: f32| Pose2::new(x, 0.0, 0.0);
        let mut o = ScanOdometry::new(10.0);
        assert_eq!(o.step(p(0.0)), OdometryStep::Hold);
        assert_eq!(o.step(p(0.5)), OdometryStep::Move(p(0.0), p(0.5)));
        assert_eq!(o.step(Pose2::new(f32::NAN, 0.0, 0.0)), OdometryStep::Hold);
        // The next good pose predicts the whole motion since the last good one.
        assert_eq!(o.step(p(1.0)), OdometryStep::Move(p(0.5), p(1.0)));
        // 5 km in one step: a reset; the next step is from the new frame.
        assert_eq!(o.step(p(5001.0)), OdometryStep::Hold);
        assert_eq!(o.step(p(5001.2)), OdometryStep::Move(p(5001.0), p(5001.2)));
        assert_eq!((o.refused, o.resets), (1, 1));
    }

    #[test]
    fn the_chained_path_leaves_out_the_jump() {
        let p = |x: f32| Pose2::new(x, 0.0, 0.0);
        let path = chained([p(1.0), p(1.5), p(5001.0), p(5001.25)], 10.0);
        let xs: Vec<f32> = path.iter().map(|q| q.x).collect();
        // One point a finite pose: the reset scan stays where the path was.
        assert_eq!(xs, [1.0, 1.5, 1.5, 1.75]);
    }
}
