//! Global consistency of a run: ATE against a reference trajectory (a corrected log or a
//! TUM file, [`crate::inputs::readers::reference`]) whose poses are matched to the run's by stamp.
//!
//! The relation metric ([`super::relations`]) scores relative poses a few metres apart
//! and so rewards local accuracy; a map bent over the whole building scores well there.
//! ATE against a globally corrected trajectory sees the bend. Both alignments of
//! [`super::Aligned`] are reported: `first_pose` (both paths in the frames of their first
//! matched poses) and `se2` (least-squares rotation + translation of the positions).
//!
//! Matching: every reference pose is paired with the run pose of the nearest stamp when
//! the two are at most half a scan period apart ([`matching_tolerance_s`]: half the
//! median interval between the run's stamps), so every reference pose that has a scan
//! within half a period is scored; a run pose is used at most once, so stamps that repeat
//! or go backwards in the run (the Intel log's do) cannot count a pose twice. The figures
//! always travel with how many reference poses they cover ([`ReferenceAte::matched`],
//! and [`ReferenceAte::in_span`], the reference poses inside the run's time span).

use super::{Aligned, position_rmse, transforms, yaw_rmse_deg};
use crate::drivers::grid::GridRun;
use crate::inputs::readers::reference::{self, ReferencePose};
use anyhow::{Result, bail};
use microslam::geometry::Pose2;
use serde::Serialize;
use std::path::Path;

/// How far apart (seconds) a reference pose and a run pose may be to be paired: half the
/// median interval between the run's distinct stamps (half a scan period), so that a
/// reference pose is paired with the scan it was taken at, never with a neighbour. `None`
/// with fewer than two distinct finite stamps.
pub fn matching_tolerance_s(run: &[(f64, Pose2<f64>)]) -> Option<f64> {
    let mut stamps: Vec<f64> = run
        .iter()
        .map(|(t, _)| *t)
        .filter(|t| t.is_finite())
        .collect();
    stamps.sort_by(f64::total_cmp);
    let mut gaps: Vec<f64> = stamps
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|g| *g > 0.0)
        .collect();
    if gaps.is_empty() {
        return None;
    }
    gaps.sort_by(f64::total_cmp);
    Some(0.5 * gaps[gaps.len() / 2])
}

/// ATE and heading RMSE against a reference trajectory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ReferenceAte {
    /// Reference poses in the file.
    pub reference_poses: usize,
    /// Reference poses whose stamps lie inside the run's time span (first to last scan,
    /// widened by the tolerance): those a run could be scored on.
    pub in_span: usize,
    /// Reference poses matched to a run pose (the ATE is over these).
    pub matched: usize,
    /// The pairing tolerance, seconds ([`matching_tolerance_s`]).
    pub tolerance_s: f64,
    /// Position RMSE, metres.
    pub ate_m: Aligned,
    /// Heading RMSE, degrees.
    pub yaw_deg: Aligned,
}

/// Pairs of `(run pose, reference pose)` matched by stamp, in the reference's order.
pub fn match_by_stamp(
    run: &[(f64, Pose2<f64>)],
    reference: &[ReferencePose],
    tolerance_s: f64,
) -> Vec<(Pose2<f64>, Pose2<f64>)> {
    let mut order: Vec<usize> = (0..run.len()).collect();
    order.sort_by(|a, b| run[*a].0.total_cmp(&run[*b].0).then(a.cmp(b)));
    let stamps: Vec<f64> = order.iter().map(|i| run[*i].0).collect();
    let mut used = vec![false; run.len()];
    let mut pairs = Vec::new();
    for r in reference {
        let k = stamps.partition_point(|s| *s < r.stamp - tolerance_s);
        // The nearest unused run pose inside the tolerance.
        let best = (k..stamps.len())
            .take_while(|j| stamps[*j] <= r.stamp + tolerance_s)
            .filter(|j| !used[order[*j]])
            .min_by(|a, b| {
                (stamps[*a] - r.stamp)
                    .abs()
                    .total_cmp(&(stamps[*b] - r.stamp).abs())
            });
        if let Some(j) = best {
            used[order[j]] = true;
            pairs.push((run[order[j]].1, r.pose));
        }
    }
    pairs
}

/// ATE of `run` (stamp, pose in file order) against `reference`.
pub fn evaluate(
    run: &[(f64, Pose2<f64>)],
    reference: &[ReferencePose],
    tolerance_s: f64,
) -> ReferenceAte {
    let pairs = match_by_stamp(run, reference, tolerance_s);
    let (lo, hi) = run
        .iter()
        .map(|(t, _)| *t)
        .filter(|t| t.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
    let in_span = reference
        .iter()
        .filter(|r| r.stamp >= lo - tolerance_s && r.stamp <= hi + tolerance_s)
        .count();
    let (est, gt): (Vec<Pose2<f64>>, Vec<Pose2<f64>>) = pairs.into_iter().unzip();
    let (fp, se2) = transforms(&est, &gt);
    let figure = |f: &dyn Fn(&Pose2<f64>) -> Option<f64>| Aligned {
        first_pose: fp.as_ref().and_then(f),
        se2: se2.as_ref().and_then(f),
    };
    ReferenceAte {
        reference_poses: reference.len(),
        in_span,
        matched: est.len(),
        tolerance_s,
        ate_m: figure(&|t| position_rmse(t, &est, &gt)),
        yaw_deg: figure(&|t| yaw_rmse_deg(t, &est, &gt)),
    }
}

/// ATE of a grid run's trajectory against the reference trajectory in `path` (TUM or a
/// corrected CARMEN log, stamps + `offset_s`), matched by stamp within half a scan
/// period ([`matching_tolerance_s`]). A reference that matches no scan is an error, and so
/// is a figure that cannot be computed (the SE(2) alignment with one matched pose) or is
/// not finite: no figure is written as `null`.
pub fn grid_run_ate(run: &GridRun, path: &Path, offset_s: f64) -> Result<ReferenceAte> {
    let traj: Vec<(f64, Pose2<f64>)> = run
        .trajectory
        .iter()
        .map(|(t, p)| {
            (
                *t,
                Pose2::new(f64::from(p.x), f64::from(p.y), f64::from(p.theta)),
            )
        })
        .collect();
    trajectory_ate(&traj, path, offset_s)
}

/// [`grid_run_ate`] of any trajectory (stamp, pose; e.g. a device's estimates).
pub fn trajectory_ate(
    traj: &[(f64, Pose2<f64>)],
    path: &Path,
    offset_s: f64,
) -> Result<ReferenceAte> {
    let poses = reference::read(path, offset_s)?;
    let Some(tolerance_s) = matching_tolerance_s(traj) else {
        bail!(
            "{}: the run has fewer than two distinct scan stamps: no scan period to match the reference by",
            path.display()
        );
    };
    let ate = evaluate(traj, &poses, tolerance_s);
    if ate.matched == 0 {
        bail!(
            "{}: no reference pose matches a scan's stamp within half a scan period ({:.4} s; is --reference-offset right?)",
            path.display(),
            tolerance_s
        );
    }
    for (name, value) in [
        ("ate_m.first_pose", ate.ate_m.first_pose),
        ("ate_m.se2", ate.ate_m.se2),
        ("yaw_deg.first_pose", ate.yaw_deg.first_pose),
        ("yaw_deg.se2", ate.yaw_deg.se2),
    ] {
        match value {
            Some(v) if v.is_finite() => {}
            Some(v) => bail!(
                "{}: the ATE against the reference cannot be computed: its {name} over {} matched poses is {v}",
                path.display(),
                ate.matched
            ),
            None => bail!(
                "{}: the ATE against the reference cannot be computed: its {name} needs at least 2 matched poses, {} matched",
                path.display(),
                ate.matched
            ),
        }
    }
    Ok(ate)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference(poses: &[(f64, Pose2<f64>)]) -> Vec<ReferencePose> {
        poses
            .iter()
            .enumerate()
            .map(|(i, (t, p))| ReferencePose {
                stamp: *t,
                pose: *p,
                line: i + 1,
            })
            .collect()
    }

    /// The pairing tolerance of the hand-made runs below (their scans are 0.25 s and 1 s
    /// apart; their stamps differ from the reference by at most 0.4 ms).
    const TOLERANCE_S: f64 = 5e-3;

    #[test]
    fn the_tolerance_is_half_the_median_scan_period() {
        // Scans every 0.2 s, one repeated stamp, one going backwards, one NaN, one gap.
        let mut run: Vec<(f64, Pose2<f64>)> = (0..50)
            .map(|i| (10.0 + 0.2 * f64::from(i), Pose2::IDENTITY))
            .collect();
        run.push((12.0, Pose2::IDENTITY));
        run.push((f64::NAN, Pose2::IDENTITY));
        run.push((40.0, Pose2::IDENTITY));
        let t = matching_tolerance_s(&run).expect("a period");
        assert!((t - 0.1).abs() < 1e-9, "{t}");
        assert_eq!(matching_tolerance_s(&[(1.0, Pose2::IDENTITY); 3]), None);
        // A reference pose 0.09 s from a scan is matched, one 0.11 s from every scan is not.
        let reference = [
            ReferencePose {
                stamp: 10.49,
                pose: Pose2::IDENTITY,
                line: 1,
            },
            ReferencePose {
                stamp: 20.0,
                pose: Pose2::IDENTITY,
                line: 2,
            },
            ReferencePose {
                stamp: 99.0,
                pose: Pose2::IDENTITY,
                line: 3,
            },
        ];
        let r = evaluate(&run, &reference, t);
        assert_eq!((r.reference_poses, r.in_span, r.matched), (3, 2, 1));
    }

    #[test]
    fn a_rigidly_moved_copy_has_zero_se2_error_and_matching_is_by_stamp() {
        // The reference: a bent path; the run: the same path moved rigidly, with scans the
        // reference does not have, one stamp repeated and stamps out of order.
        let truth: Vec<(f64, Pose2<f64>)> = (0..40)
            .map(|i| {
                let s = f64::from(i) * 0.25;
                (100.0 + s, Pose2::new(s, 0.3 * s * s, 0.6 * s))
            })
            .collect();
        let t = Pose2::new(2.0, -1.0, 0.9);
        let mut run: Vec<(f64, Pose2<f64>)> = truth
            .iter()
            .map(|(s, p)| (s + 0.0004, t.compose(p)))
            .collect();
        run.insert(5, (100.6, Pose2::new(50.0, 50.0, 0.0))); // no reference at 100.6
        run.swap(10, 11); // out of order
        run.insert(20, run[19]); // a repeated scan
        let r = evaluate(&run, &reference(&truth), TOLERANCE_S);
        assert_eq!((r.reference_poses, r.matched), (40, 40));
        assert!(r.ate_m.se2.unwrap() < 1e-9, "{r:?}");
        assert!(r.ate_m.first_pose.unwrap() < 1e-9, "{r:?}");
        assert!(r.yaw_deg.se2.unwrap() < 1e-6, "{r:?}");
        // Past the tolerance nothing matches.
        let late: Vec<_> = run.iter().map(|(s, p)| (s + 0.01, *p)).collect();
        let r = evaluate(&late, &reference(&truth), TOLERANCE_S);
        assert_eq!(r.matched, 0);
        assert_eq!(r.ate_m, Aligned::default());
    }

    #[test]
    fn a_known_offset_gives_its_rmse() {
        // Every position visited twice along a line: the run 0.1 m left of the truth the
        // first time, 0.1 m right the second. The least-squares fit cannot remove an
        // alternating error (RMSE 0.1); the first-pose alignment shifts everything by the
        // first pose's 0.1 m, leaving errors 0 and 0.2 in turn (RMSE √0.02).
        let truth: Vec<(f64, Pose2<f64>)> = (0..20)
            .map(|i| (f64::from(i), Pose2::new(f64::from(i / 2), 0.0, 0.0)))
            .collect();
        let run: Vec<(f64, Pose2<f64>)> = truth
            .iter()
            .enumerate()
            .map(|(i, (s, p))| {
                let dy = if i % 2 == 0 { 0.1 } else { -0.1 };
                (*s, Pose2::new(p.x, dy, 0.0))
            })
            .collect();
        let r = evaluate(&run, &reference(&truth), TOLERANCE_S);
        assert!((r.ate_m.se2.unwrap() - 0.1).abs() < 1e-9, "{r:?}");
        assert!(
            (r.ate_m.first_pose.unwrap() - 0.02f64.sqrt()).abs() < 1e-9,
            "{r:?}"
        );
    }
}
