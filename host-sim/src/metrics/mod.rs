//! Scores of an estimate against ground truth.

pub mod relations;

use crate::readers::TruePose;
use microslam::geometry::{Pose2, wrap_angle};

/// Ground truth linearly interpolated at `stamp` (heading along the shorter arc), or
/// `None` outside its time span.
pub fn interpolate_pose(truth: &[TruePose], stamp: f64) -> Option<Pose2<f64>> {
    let first = truth.first()?;
    let last = truth.last()?;
    if !(stamp >= first.stamp && stamp <= last.stamp) {
        return None;
    }
    let i = truth.partition_point(|p| p.stamp <= stamp);
    if i == 0 {
        return Some(first.pose);
    }
    let a = truth.get(i - 1)?;
    let Some(b) = truth.get(i) else {
        return Some(a.pose);
    };
    let span = b.stamp - a.stamp;
    let s = if span > 0.0 {
        (stamp - a.stamp) / span
    } else {
        0.0
    };
    Some(Pose2::new(
        a.pose.x + s * (b.pose.x - a.pose.x),
        a.pose.y + s * (b.pose.y - a.pose.y),
        wrap_angle(a.pose.theta + s * wrap_angle(b.pose.theta - a.pose.theta)),
    ))
}
