//! Scores of a replay against ground truth, written to `metrics.json`.
//!
//! - **ATE** (m) and **yaw** RMSE (deg) over the estimates whose stamps lie inside the
//!   ground truth's span (ground truth interpolated at the estimate stamps), after two
//!   alignments: `first_pose` (both paths in the frames of their own first poses) and
//!   `se2` (least-squares rotation + translation, no scale, of the estimated positions
//!   onto the true ones).
//! - **Landmark RMSE** (m): estimated landmarks carried by the same transform; known ids
//!   matched by id, unknown ones by a one-to-one assignment minimising total distance.
//! - **Association purity** (the textbook cluster purity): each estimated landmark is
//!   credited with the sightings of its majority true landmark; purity is their share of
//!   all sightings the filter used (updates and creations). Mixed landmarks lower it,
//!   duplicates do not: `association_one_to_one_purity` also penalises duplicates by
//!   pairing estimated and true landmarks one-to-one (maximising shared sightings) and
//!   counting only the sightings that went to the partner of their true landmark.
//! - **NEES** of the pose against ground truth (filter frame = world frame: the filter
//!   starts at the true initial pose), mean over the evaluated estimates whose position
//!   standard deviation is at least [`NEES_MIN_POSITION_STD`] in every direction; **NIS**
//!   mean of the accepted updates.

mod alignment;
mod assignment;
pub mod global;
pub mod grid;
pub mod inputs;
pub mod reference;
pub mod relations;

pub use alignment::{Rigid, apply, first_pose, se2_least_squares};
pub use assignment::{max_gain, min_cost};

use crate::domain::recording::{Recording, TruePose, TruthCursor};
use crate::drivers::ekf::{PoseSample, ReplayRun};
use microslam::geometry::{Pose2, wrap_near};
use nalgebra::{Matrix3, Vector2, Vector3};
use serde::Serialize;

/// Estimates whose position standard deviation is below this (m) in some direction (the
/// smallest eigenvalue of the position block is below its square) are left out of the
/// NEES: ground-truth noise (millimetres for Vicon) would dominate it. After the first
/// steps from the known start the position covariance is long and thin (along the
/// motion only), so a bound on its trace alone lets a millimetre of cross-track truth
/// noise count as a NEES of 10⁹.
pub const NEES_MIN_POSITION_STD: f64 = 0.01;

/// A run reports itself lost when the supervision's lost flag was up for at least this
/// share of its pose estimates ([`Metrics::lost_share`]).
pub const LOST_RUN_SHARE: f64 = 0.1;

/// Position error (m) beyond which a pose estimate counts as lost when the lost flag is
/// scored against the ground truth.
pub const LOST_ERROR_M: f64 = 1.0;

/// The smallest eigenvalue of the position block `[[a, b], [b, d]]` of a pose covariance.
fn smallest_position_variance(p: &[[f64; 3]; 3]) -> f64 {
    let (a, b, d) = (p[0][0], p[0][1], p[1][1]);
    let half_gap = ((a - d) / 2.0).hypot(b);
    (a + d) / 2.0 - half_gap
}

/// A figure under both alignments (left out of the JSON where it cannot be computed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Aligned {
    /// Both paths in the frames of their own first poses.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_pose: Option<f64>,
    /// Least-squares rotation + translation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub se2: Option<f64>,
}

impl Aligned {
    /// Neither alignment gave a figure (the whole entry is left out of the JSON).
    pub fn is_empty(&self) -> bool {
        self.first_pose.is_none() && self.se2.is_none()
    }
}

/// One landmark's error after the `se2` alignment.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LandmarkError {
    /// The true landmark's id (its subject number in MRCLAM).
    pub id: u32,
    /// Distance between its estimate and its true position, metres.
    pub error_m: f64,
}

/// The contents of `metrics.json`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Metrics {
    /// Dataset name.
    pub dataset: String,
    /// Odometry steps replayed.
    pub steps: usize,
    /// Landmark sightings offered to the estimator.
    pub sightings: usize,
    /// Absolute trajectory error, RMSE of positions, metres.
    #[serde(skip_serializing_if = "Aligned::is_empty")]
    pub ate_rmse_m: Aligned,
    /// RMSE of headings, degrees.
    #[serde(skip_serializing_if = "Aligned::is_empty")]
    pub yaw_rmse_deg: Aligned,
    /// RMSE of landmark positions, metres.
    #[serde(skip_serializing_if = "Aligned::is_empty")]
    pub landmark_rmse_m: Aligned,
    /// Landmarks in the final map.
    pub landmarks_created: usize,
    /// Cluster purity of the association (see the module docs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub association_purity: Option<f64>,
    /// Mean NEES of the pose (3 dof).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nees_pose_mean: Option<f64>,
    /// Mean NIS of accepted updates (2 dof).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nis_mean: Option<f64>,
    /// Wall time of the whole command (reading, replay, scoring, writing), seconds.
    pub wall_time_s: f64,
    /// Time of the replay loop (prediction, association and update of every event,
    /// recording the pose estimates; no reading, scoring or writing), seconds.
    pub filter_time_s: f64,
    // ---- extras ----
    /// Association mode.
    pub association: String,
    /// Filter scalar.
    pub precision: String,
    /// One-to-one purity: duplicates count as errors too (see the module docs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub association_one_to_one_purity: Option<f64>,
    /// True landmarks in the dataset.
    pub landmarks_true: usize,
    /// Estimates scored against ground truth.
    pub evaluated_poses: usize,
    /// ATE of odometry alone (dead reckoning), same alignments.
    #[serde(skip_serializing_if = "Aligned::is_empty")]
    pub dead_reckoning_ate_rmse_m: Aligned,
    /// Fraction of evaluated estimates whose NEES is below the 95 % χ²(3) quantile.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nees_pose_within_95: Option<f64>,
    /// What the association did.
    pub counts: crate::drivers::ekf::AssociationCounts,
    /// Sightings dropped by the reader (other robots, unknown barcodes).
    pub reader_dropped_sightings: usize,
    /// What the run read, used and lost of each input stream, with the reasons.
    pub inputs: inputs::EkfInputs,
    /// Self-calibration the filter estimated (odometry scale, range bias).
    pub calibration: crate::drivers::ekf::Calibration,
    /// Faults injected into the event stream (`replay --faults`), if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub faults: Option<crate::inputs::faults::FaultReport>,
    /// The SE(2) alignment of the estimate onto ground truth: x, y (m), θ (rad).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub se2_alignment: Option<[f64; 3]>,
    /// What the `se2` landmark error was aligned on: `trajectory` (the robot's ground
    /// truth) or `landmarks` (no robot ground truth: the estimated landmarks, matched by
    /// id — with hidden ids by the true landmark most of each one's sightings were of —
    /// least-squares aligned onto the true ones).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmark_alignment: Option<String>,
    /// Each landmark's error under the alignment of `landmark_rmse_m.se2`, by true id:
    /// which landmarks make up the RMSE.
    pub landmark_errors_m: Vec<LandmarkError>,
    /// Share of the pose estimates with the supervision's lost flag up.
    pub lost_share: f64,
    /// The run reports itself lost: `lost_share` ≥ [`LOST_RUN_SHARE`].
    pub lost_reported: bool,
    /// With ground truth: whether the report agrees with the ATE(se2), lost being an ATE
    /// above [`LOST_ERROR_M`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost_report_agrees: Option<bool>,
    /// With ground truth: share of the evaluated estimates whose lost flag agrees with
    /// their own position error (after the `se2` alignment) being above
    /// [`LOST_ERROR_M`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lost_flag_agreement: Option<f64>,
}

/// Scores a replay against the recording's ground truth.
pub fn evaluate(recording: &Recording, run: &ReplayRun) -> Metrics {
    let mut pairs = PosePairs::new(recording, run.trajectory.len());
    pairs.extend(&run.trajectory);
    evaluate_paired(recording, run, pairs)
}

/// [`evaluate`] with the pose samples already paired with the ground truth (`pairs` of
/// every sample of `run.trajectory`, in order): a replay pairs them while the filter runs.
pub fn evaluate_paired(recording: &Recording, run: &ReplayRun, pairs: PosePairs<'_>) -> Metrics {
    let truth = &recording.ground_truth;
    // Dead reckoning is scored on another core meanwhile.
    std::thread::scope(|s| {
        let dead_reckoning = s.spawn(|| dead_reckoning_ate(truth, &run.dead_reckoning));
        let mut m = evaluate_filter(recording, run, pairs);
        m.dead_reckoning_ate_rmse_m = dead_reckoning
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        m
    })
}

/// ATE of the dead reckoning `(stamp, pose)` against `truth`, under both alignments.
fn dead_reckoning_ate(truth: &[TruePose], dead_reckoning: &[(f64, Pose2<f64>)]) -> Aligned {
    let mut dr_est = Vec::with_capacity(dead_reckoning.len());
    let mut dr_gt = Vec::with_capacity(dead_reckoning.len());
    let mut cursor = TruthCursor::new(truth);
    for (t, p) in dead_reckoning {
        if let Some(g) = cursor.at(*t) {
            dr_est.push(*p);
            dr_gt.push(g);
        }
    }
    let dr = transforms(&dr_est, &dr_gt);
    Aligned {
        first_pose: dr.0.and_then(|t| position_rmse(&t, &dr_est, &dr_gt)),
        se2: dr.1.and_then(|t| position_rmse(&t, &dr_est, &dr_gt)),
    }
}

/// Each pose estimate paired with the ground truth at its stamp (estimates outside the
/// ground truth's span are left out), and the NEES of those it can say something about.
/// Filled sample by sample, in stamp order.
pub struct PosePairs<'a> {
    cursor: TruthCursor<'a>,
    /// The NEES is scored only when the filter starts at the true pose.
    nees_scored: bool,
    est: Vec<Pose2<f64>>,
    gt: Vec<Pose2<f64>>,
    nees: Vec<f64>,
    /// The lost flag of each paired estimate.
    lost: Vec<bool>,
}

impl<'a> PosePairs<'a> {
    /// No pairs yet, room for `capacity` (sized up front: growing these by doubling
    /// copied and faulted in megabytes).
    pub fn new(recording: &'a Recording, capacity: usize) -> Self {
        Self {
            cursor: TruthCursor::new(&recording.ground_truth),
            nees_scored: recording.initial_pose.is_some(),
            est: Vec::with_capacity(capacity),
            gt: Vec::with_capacity(capacity),
            nees: Vec::with_capacity(capacity),
            lost: Vec::with_capacity(capacity),
        }
    }

    /// Pairs the next samples of the trajectory.
    pub fn extend(&mut self, samples: &[PoseSample]) {
        for s in samples {
            let Some(g) = self.cursor.at(s.stamp) else {
                continue;
            };
            self.est.push(s.pose);
            self.gt.push(g);
            self.lost.push(s.lost);
            // The filter starts at the true pose with zero covariance; while it claims
            // less than NEES_MIN_POSITION_STD of position uncertainty in some direction,
            // the ground truth's own noise dominates the error there and the NEES says
            // nothing about the filter.
            if self.nees_scored
                && smallest_position_variance(&s.covariance) >= NEES_MIN_POSITION_STD.powi(2)
                && let Some(v) = pose_nees(&s.pose, &g, &s.covariance)
            {
                self.nees.push(v);
            }
        }
    }
}

/// [`evaluate_paired`] but the dead reckoning's figures.
fn evaluate_filter(recording: &Recording, run: &ReplayRun, pairs: PosePairs<'_>) -> Metrics {
    let PosePairs {
        est,
        gt,
        nees,
        lost,
        ..
    } = pairs;
    let transforms = transforms(&est, &gt);
    let se2_alignment = transforms.1.map(|t| [t.x, t.y, t.theta]);
    let mut m = Metrics {
        dataset: recording.name.clone(),
        steps: run.steps,
        sightings: run.sightings,
        landmarks_created: run.landmarks.len(),
        landmarks_true: recording.landmarks.len(),
        evaluated_poses: est.len(),
        association: format!("{:?}", run.mode).to_lowercase(),
        precision: format!("{:?}", run.precision).to_lowercase(),
        filter_time_s: run.filter_time.as_secs_f64(),
        counts: run.counts,
        calibration: run.calibration,
        reader_dropped_sightings: recording.dropped_sightings,
        inputs: inputs::EkfInputs::of(recording, run),
        faults: None,
        se2_alignment,
        ..Metrics::default()
    };
    let by_alignment = |f: &dyn Fn(&Pose2<f64>) -> Option<f64>| Aligned {
        first_pose: transforms.0.as_ref().and_then(f),
        se2: transforms.1.as_ref().and_then(f),
    };
    m.ate_rmse_m = by_alignment(&|t| position_rmse(t, &est, &gt));
    m.yaw_rmse_deg = by_alignment(&|t| yaw_rmse_deg(t, &est, &gt));
    m.landmark_rmse_m = by_alignment(&|t| landmark_rmse(t, recording, run));
    m.landmark_alignment = transforms.1.map(|_| "trajectory".to_owned());
    if transforms.1.is_none()
        && let Some(t) = landmark_only_alignment(recording, run)
    {
        // No robot ground truth (MRCLAM dataset 1): align the maps themselves.
        m.landmark_errors_m = landmark_errors(&t, recording, run);
        m.landmark_rmse_m.se2 = rms(&m.landmark_errors_m);
        m.landmark_alignment = Some("landmarks".to_owned());
    } else if let Some(t) = &transforms.1 {
        m.landmark_errors_m = landmark_errors(t, recording, run);
    }
    m.nees_pose_mean = mean(&nees);
    let bound = microslam::gate::chi_square_quantile(0.95, 3);
    m.nees_pose_within_95 = (!nees.is_empty())
        .then(|| nees.iter().filter(|v| **v <= bound).count() as f64 / nees.len() as f64);
    m.nis_mean = mean(&run.nis);
    let raised = run.trajectory.iter().filter(|s| s.lost).count();
    m.lost_share = raised as f64 / run.trajectory.len().max(1) as f64;
    m.lost_reported = m.lost_share >= LOST_RUN_SHARE;
    m.lost_report_agrees = m
        .ate_rmse_m
        .se2
        .map(|ate| (ate > LOST_ERROR_M) == m.lost_reported);
    m.lost_flag_agreement = transforms.1.as_ref().and_then(|t| {
        let r = Rigid::new(t);
        let agree = est.iter().zip(&gt).zip(&lost).filter(|((e, g), l)| {
            let [x, y] = r.point(e.x, e.y);
            ((x - g.x).hypot(y - g.y) > LOST_ERROR_M) == **l
        });
        (!est.is_empty()).then(|| agree.count() as f64 / est.len() as f64)
    });
    (m.association_one_to_one_purity, m.association_purity) = purity(recording, run);
    m
}

/// First-pose and SE(2) least-squares transforms of the estimate onto the truth.
pub fn transforms(
    est: &[Pose2<f64>],
    gt: &[Pose2<f64>],
) -> (Option<Pose2<f64>>, Option<Pose2<f64>>) {
    let fp = est.first().zip(gt.first()).map(|(e, g)| first_pose(e, g));
    (fp, se2_least_squares(est, gt))
}

fn mean(v: &[f64]) -> Option<f64> {
    mean_of(v.iter().copied(), v.len())
}

/// The mean of `n` values given one by one (no vector of them: the long runs' per-pose
/// figures would each fault in a megabyte).
fn mean_of(values: impl Iterator<Item = f64>, n: usize) -> Option<f64> {
    (n > 0).then(|| values.sum::<f64>() / n as f64)
}

/// Position RMSE of `t · est` against `gt`.
pub fn position_rmse(t: &Pose2<f64>, est: &[Pose2<f64>], gt: &[Pose2<f64>]) -> Option<f64> {
    let r = Rigid::new(t);
    let sq = est.iter().zip(gt).map(|(e, g)| {
        let [x, y] = r.point(e.x, e.y);
        (x - g.x).powi(2) + (y - g.y).powi(2)
    });
    mean_of(sq, est.len().min(gt.len())).map(f64::sqrt)
}

pub(crate) fn yaw_rmse_deg(t: &Pose2<f64>, est: &[Pose2<f64>], gt: &[Pose2<f64>]) -> Option<f64> {
    let r = Rigid::new(t);
    let sq = est
        .iter()
        .zip(gt)
        .map(|(e, g)| wrap_near(r.apply(e).theta - g.theta).powi(2));
    mean_of(sq, est.len().min(gt.len())).map(|v| v.sqrt().to_degrees())
}

/// NEES of a pose estimate with covariance `p` against the truth; `None` when `p` is not
/// invertible (e.g. at the known start).
pub fn pose_nees(est: &Pose2<f64>, truth: &Pose2<f64>, p: &[[f64; 3]; 3]) -> Option<f64> {
    let p = Matrix3::from_fn(|r, c| p[r][c]);
    let e = Vector3::new(
        truth.x - est.x,
        truth.y - est.y,
        wrap_near(truth.theta - est.theta),
    );
    // eᵀ P⁻¹ e = |L⁻¹ e|² for P = L Lᵀ: one triangular solve, no inverse (this runs once
    // per pose sample, 61 785 times on MRCLAM ds6 robot 1).
    let v = p.cholesky()?.l().solve_lower_triangular(&e)?.norm_squared();
    v.is_finite().then_some(v)
}

/// Pairs of (estimated landmark index, true landmark index) used for the landmark error.
pub fn landmark_pairs(
    t: &Pose2<f64>,
    recording: &Recording,
    run: &ReplayRun,
) -> Vec<(usize, usize)> {
    let truth = &recording.landmarks;
    if run.landmarks.iter().all(|l| l.id.is_some()) && !run.landmarks.is_empty() {
        return run
            .landmarks
            .iter()
            .enumerate()
            .filter_map(|(i, l)| {
                let id = l.id?;
                truth.iter().position(|t| t.id == id).map(|j| (i, j))
            })
            .collect();
    }
    let cost: Vec<Vec<f64>> = run
        .landmarks
        .iter()
        .map(|l| {
            let p = t.transform_point(&Vector2::new(l.position[0], l.position[1]));
            truth
                .iter()
                .map(|g| (p[0] - g.position[0]).hypot(p[1] - g.position[1]))
                .collect()
        })
        .collect();
    min_cost(&cost)
}

/// SE(2) least-squares alignment of the estimated landmarks onto the true ones, matched
/// by id — with hidden ids, by the true landmark most of a landmark's sightings were of
/// (for scoring only, as the purity) — `None` with fewer than two matches.
fn landmark_only_alignment(recording: &Recording, run: &ReplayRun) -> Option<Pose2<f64>> {
    let mut est = Vec::new();
    let mut truth = Vec::new();
    for l in &run.landmarks {
        let majority = || {
            l.true_ids
                .iter()
                .max_by_key(|&(id, n)| (*n, std::cmp::Reverse(*id)))
                .map(|(id, _)| *id)
        };
        let Some(id) = l.id.or_else(majority) else {
            continue;
        };
        if let Some(g) = recording.landmarks.iter().find(|g| g.id == id) {
            est.push(l.position);
            truth.push(g.position);
        }
    }
    se2_least_squares(&est, &truth)
}

/// The error of each estimated landmark paired with a true one ([`landmark_pairs`])
/// after the alignment `t`, sorted by id.
fn landmark_errors(t: &Pose2<f64>, recording: &Recording, run: &ReplayRun) -> Vec<LandmarkError> {
    let mut errors: Vec<LandmarkError> = landmark_pairs(t, recording, run)
        .into_iter()
        .filter_map(|(i, j)| {
            let l = run.landmarks.get(i)?;
            let g = recording.landmarks.get(j)?;
            let p = t.transform_point(&Vector2::new(l.position[0], l.position[1]));
            Some(LandmarkError {
                id: g.id,
                error_m: (p[0] - g.position[0]).hypot(p[1] - g.position[1]),
            })
        })
        .collect();
    errors.sort_by_key(|e| e.id);
    errors
}

fn landmark_rmse(t: &Pose2<f64>, recording: &Recording, run: &ReplayRun) -> Option<f64> {
    rms(&landmark_errors(t, recording, run))
}

/// Root mean square of the errors; `None` without one.
fn rms(errors: &[LandmarkError]) -> Option<f64> {
    let sq: Vec<f64> = errors.iter().map(|e| e.error_m * e.error_m).collect();
    mean(&sq).map(f64::sqrt)
}

/// (one-to-one purity, cluster purity) of the association; `None` without sightings.
fn purity(recording: &Recording, run: &ReplayRun) -> (Option<f64>, Option<f64>) {
    let mut ids: Vec<u32> = recording.landmarks.iter().map(|l| l.id).collect();
    for l in &run.landmarks {
        for id in l.true_ids.keys() {
            if !ids.contains(id) {
                ids.push(*id);
            }
        }
    }
    let total: usize = run.landmarks.iter().flat_map(|l| l.true_ids.values()).sum();
    if total == 0 {
        return (None, None);
    }
    let gain: Vec<Vec<f64>> = run
        .landmarks
        .iter()
        .map(|l| {
            ids.iter()
                .map(|id| *l.true_ids.get(id).unwrap_or(&0) as f64)
                .collect()
        })
        .collect();
    let matched: f64 = max_gain(&gain).into_iter().map(|(i, j)| gain[i][j]).sum();
    let cluster: usize = run
        .landmarks
        .iter()
        .map(|l| l.true_ids.values().copied().max().unwrap_or(0))
        .sum();
    (
        Some(matched / total as f64),
        Some(cluster as f64 / total as f64),
    )
}

#[cfg(test)]
mod tests {
    use crate::domain::config::Settings;
    use crate::domain::{AssociationMode, Precision};
    use crate::metrics::{PosePairs, evaluate, evaluate_paired, smallest_position_variance};

    #[test]
    fn poses_paired_chunk_by_chunk_score_as_when_paired_at_once() {
        let settings = Settings::load_for("sim", None, None).unwrap();
        let recording = crate::inputs::sim::simulate(&settings, 3).unwrap();
        let run = crate::drivers::ekf::replay(
            &recording,
            &settings,
            AssociationMode::Known,
            Precision::F64,
            None,
        )
        .unwrap();
        let whole = evaluate(&recording, &run);
        assert!(whole.evaluated_poses > 1000, "{}", whole.evaluated_poses);
        assert!(whole.nees_pose_mean.is_some() && whole.ate_rmse_m.se2.is_some());
        for chunk in [1, 7, 4096] {
            let mut pairs = PosePairs::new(&recording, 0);
            for samples in run.trajectory.chunks(chunk) {
                pairs.extend(samples);
            }
            assert_eq!(
                evaluate_paired(&recording, &run, pairs),
                whole,
                "chunks of {chunk}"
            );
        }
        // Pairing only a part scores something else: the comparison can fail.
        let mut part = PosePairs::new(&recording, 0);
        part.extend(&run.trajectory[..run.trajectory.len() / 2]);
        assert_ne!(evaluate_paired(&recording, &run, part), whole);
    }

    #[test]
    fn smallest_position_variance_of_a_thin_rotated_covariance() {
        // σ 0.1 m along a direction at 30°, σ 1 mm across it: the eigenvalues are 1e-2
        // and 1e-6 whatever the rotation, while the trace is 1.0001e-2.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let (l1, l2) = (1e-2, 1e-6);
        let p = [
            [l1 * c * c + l2 * s * s, (l1 - l2) * c * s, 0.0],
            [(l1 - l2) * c * s, l1 * s * s + l2 * c * c, 0.0],
            [0.0, 0.0, 1e-4],
        ];
        assert!((smallest_position_variance(&p) - 1e-6).abs() < 1e-12);
        let round = [[4e-4, 0.0, 0.0], [0.0, 9e-4, 0.0], [0.0, 0.0, 1.0]];
        assert!((smallest_position_variance(&round) - 4e-4).abs() < 1e-15);
    }
}
