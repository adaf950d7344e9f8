//! Scores of the grid filters in the simulator's lidar world: position and heading RMSE
//! against the true poses, with **no alignment** (both filters start at the true start
//! pose in the world frame, so the estimate's frame is the truth's), and the position
//! RMSE after the least-squares rotation and translation (ATE(se2), as `replay` scores
//! against a reference): a map turned as a whole about its start by an early heading error
//! counts fully in the first and not in the second.

use crate::drivers::grid::f32_pose;
use crate::inputs::sim::lidar_world::LidarRecording;
use microslam::geometry::Pose2;

/// Position RMSE of `trajectory` against the recording's truth (same length, no
/// alignment), metres.
pub fn ate_m(rec: &LidarRecording, trajectory: &[(f64, Pose2<f32>)]) -> f64 {
    let n = trajectory.len().min(rec.scans.len()).max(1);
    let sum: f64 = trajectory
        .iter()
        .zip(&rec.scans)
        .map(|((_, e), s)| {
            (f64::from(e.x) - s.truth.x).powi(2) + (f64::from(e.y) - s.truth.y).powi(2)
        })
        .sum();
    (sum / n as f64).sqrt()
}

/// Position RMSE of `trajectory` against the recording's truth after the least-squares
/// rotation and translation (ATE(se2)), metres; `None` for fewer than two poses.
pub fn ate_se2_m(rec: &LidarRecording, trajectory: &[(f64, Pose2<f32>)]) -> Option<f64> {
    let (est, truth): (Vec<Pose2<f64>>, Vec<Pose2<f64>>) = trajectory
        .iter()
        .zip(&rec.scans)
        .map(|((_, e), s)| (e.cast(), s.truth))
        .unzip();
    let t = super::alignment::se2_least_squares(&est, &truth)?;
    super::position_rmse(&t, &est, &truth)
}

/// Heading RMSE against the truth, degrees.
pub fn yaw_rmse_deg(rec: &LidarRecording, trajectory: &[(f64, Pose2<f32>)]) -> f64 {
    let n = trajectory.len().min(rec.scans.len()).max(1);
    let sum: f64 = trajectory
        .iter()
        .zip(&rec.scans)
        .map(|((_, e), s)| {
            microslam::geometry::wrap_angle(f64::from(e.theta) - s.truth.theta).powi(2)
        })
        .sum();
    (sum / n as f64).sqrt().to_degrees()
}

/// Dead-reckoning ATE (the odometry poses against the truth), metres.
pub fn odometry_ate_m(rec: &LidarRecording) -> f64 {
    let traj: Vec<(f64, Pose2<f32>)> = rec
        .scans
        .iter()
        .map(|s| (s.stamp, f32_pose(&s.odometry)))
        .collect();
    ate_m(rec, &traj)
}
