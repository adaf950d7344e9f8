//! Benchmark relations and the relation metric of Kümmerle et al., "On measuring the
//! accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009.
//!
//! A relations file has lines `t1 t2 x y z roll pitch yaw`: the pose of the scan at `t2`
//! in the frame of the scan at `t1`. For each relation whose two stamps both match a
//! processed scan (nearest stamp within a tolerance, 1 ms by default), the error is the
//! difference between the estimated relative pose `⊖p(t1) ⊕ p(t2)` and the true one:
//! translational `|Δxy|` (m) and absolute rotational `|wrap(Δθ)|` (degrees). Reported as
//! mean and (population) standard deviation over the used relations.

use crate::drivers::grid::GridRun;
use microslam::geometry::{Pose2, wrap_angle};
use std::io::BufRead;
use std::path::{Path, PathBuf};

/// One relation: the pose of the scan at `t2` seen from the scan at `t1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Relation {
    /// First stamp, seconds.
    pub t1: f64,
    /// Second stamp, seconds.
    pub t2: f64,
    /// Relative pose `(x, y, yaw)`.
    pub pose: [f64; 3],
}

/// Reads a relations file (`#` lines and blank lines skipped). A line that cannot be read,
/// has fewer than 8 numbers or a number that is not finite is refused with its line number.
pub fn parse<R: BufRead>(
    reader: R,
) -> Result<Vec<Relation>, Box<dyn std::error::Error + Send + Sync>> {
    let mut out = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(|e| format!("relations line {}: {e}", i + 1))?;
        let t = line.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        let v: Vec<f64> = t
            .split_ascii_whitespace()
            .map(|s| s.parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("relations line {}: {e}", i + 1))?;
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return Err(format!("relations line {}: number {} is not finite", i + 1, k + 1).into());
        }
        if v.len() < 8 {
            return Err(format!(
                "relations line {}: expected 8 numbers, got {}",
                i + 1,
                v.len()
            )
            .into());
        }
        out.push(Relation {
            t1: v[0],
            t2: v[1],
            pose: [v[2], v[3], v[7]],
        });
    }
    Ok(out)
}

/// Reads a relations file.
pub fn read(path: &std::path::Path) -> anyhow::Result<Vec<Relation>> {
    let file = std::fs::File::open(path)
        .map_err(|e| anyhow::anyhow!("opening {}: {e}", path.display()))?;
    parse(std::io::BufReader::new(file)).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// The relation error summary (the keys of `metrics.json`'s `"relations"`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct RelationError {
    /// Relations whose both stamps matched a processed scan.
    pub used: usize,
    /// Mean translational error, metres.
    pub trans_mean_m: f64,
    /// Standard deviation of the translational error, metres.
    pub trans_std_m: f64,
    /// Mean absolute rotational error, degrees.
    pub rot_mean_deg: f64,
    /// Standard deviation of the rotational error, degrees.
    pub rot_std_deg: f64,
}

impl RelationError {
    /// `self` when every figure is finite; else an error naming the relations file
    /// `file` (of `relations` relations) and why the relation error cannot be computed:
    /// no relation matched two processed scans, or a figure that is not finite. A figure
    /// that cannot be computed is never written (`metrics.json` would hold `null`).
    pub fn computed(self, file: &Path, relations: usize) -> anyhow::Result<Self> {
        if self.used == 0 {
            anyhow::bail!(
                "{}: the relation error cannot be computed: none of its {relations} relations \
                 has both stamps within 1 ms of a processed scan (is it this log's relations file?)",
                file.display()
            );
        }
        for (name, value) in [
            ("trans_mean_m", self.trans_mean_m),
            ("trans_std_m", self.trans_std_m),
            ("rot_mean_deg", self.rot_mean_deg),
            ("rot_std_deg", self.rot_std_deg),
        ] {
            if !value.is_finite() {
                anyhow::bail!(
                    "{}: the relation error cannot be computed: its {name} over {} relations is {value}",
                    file.display(),
                    self.used
                );
            }
        }
        Ok(self)
    }
}

fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / v.len() as f64;
    (m, var.sqrt())
}

/// Index of the trajectory entry whose stamp is nearest to `t`, if within `tol`.
fn nearest(sorted: &[(f64, usize)], t: f64, tol: f64) -> Option<usize> {
    let i = sorted.partition_point(|(s, _)| *s < t);
    let mut best: Option<(f64, usize)> = None;
    for j in [i.wrapping_sub(1), i] {
        if let Some(&(s, idx)) = sorted.get(j) {
            let d = (s - t).abs();
            if d <= tol && best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, idx));
            }
        }
    }
    best.map(|b| b.1)
}

/// The relation error of a trajectory `(stamp, [x, y, θ])` (any order) against
/// `relations`, matching stamps within `tol` seconds.
pub fn evaluate(trajectory: &[(f64, [f64; 3])], relations: &[Relation], tol: f64) -> RelationError {
    let mut sorted: Vec<(f64, usize)> = trajectory
        .iter()
        .enumerate()
        .map(|(i, (t, _))| (*t, i))
        .collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut et, mut er) = (Vec::new(), Vec::new());
    for r in relations {
        let (Some(i), Some(j)) = (nearest(&sorted, r.t1, tol), nearest(&sorted, r.t2, tol)) else {
            continue;
        };
        let [a, b] =
            [trajectory[i].1, trajectory[j].1].map(|[x, y, theta]| Pose2::new(x, y, theta));
        let est = a.between(&b);
        et.push((est.x - r.pose[0]).hypot(est.y - r.pose[1]));
        er.push(wrap_angle(est.theta - r.pose[2]).abs().to_degrees());
    }
    let (tm, ts) = mean_std(&et);
    let (rm, rs) = mean_std(&er);
    RelationError {
        used: et.len(),
        trans_mean_m: tm,
        trans_std_m: ts,
        rot_mean_deg: rm,
        rot_std_deg: rs,
    }
}

/// The relation error of a run's trajectory (stamps matched within 1 ms).
pub fn relation_error(run: &GridRun, rels: &[Relation]) -> RelationError {
    let traj: Vec<(f64, [f64; 3])> = run
        .trajectory
        .iter()
        .map(|(t, p)| (*t, [f64::from(p.x), f64::from(p.y), f64::from(p.theta)]))
        .collect();
    evaluate(&traj, rels, 1e-3)
}

/// The relations file to use: the one given, else the single `*.relations` file next to
/// the log. `Err` says why there is none (no such file, or several to choose from).
pub fn find_relations(log_path: &Path, given: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(g) = given {
        return Ok(g.to_path_buf());
    }
    let dir = log_path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("cannot list {} for a relations file: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "relations"))
        .collect();
    found.sort();
    match found.len() {
        1 => Ok(found.swap_remove(0)),
        0 => Err(format!(
            "no *.relations file next to {}: the relation error is not computed (give one \
             with --relations FILE)",
            log_path.display()
        )),
        n => Err(format!(
            "{n} *.relations files next to {} ({}): give one with --relations FILE",
            log_path.display(),
            found
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_or_ambiguous_relations_file_is_explained() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let log = dir.path().join("run.clf");
        std::fs::write(&log, "").expect("write");
        let none = find_relations(&log, None).expect_err("no relations file");
        assert!(
            none.contains("no *.relations file") && none.contains("run.clf"),
            "{none}"
        );

        std::fs::write(dir.path().join("a.relations"), "").expect("write");
        assert_eq!(
            find_relations(&log, None),
            Ok(dir.path().join("a.relations"))
        );

        std::fs::write(dir.path().join("b.relations"), "").expect("write");
        let two = find_relations(&log, None).expect_err("two relations files");
        assert!(
            two.contains("2 *.relations files") && two.contains("b.relations"),
            "{two}"
        );

        let given = dir.path().join("given.txt");
        assert_eq!(find_relations(&log, Some(&given)), Ok(given));
    }

    #[test]
    fn metric_on_a_known_trajectory() {
        // Truth: (0,0,0) → (1,0,90°) → (1,1,90°). Estimate: the third pose 0.1 m off in x
        // and 2° off in heading.
        let d = std::f64::consts::FRAC_PI_2;
        let traj = vec![
            (10.0, [0.0, 0.0, 0.0]),
            (12.0, [1.1, 1.0, d + 2f64.to_radians()]),
            (11.0, [1.0, 0.0, d]),
        ];
        let rels = parse(
            "# t1 t2 x y z r p yaw\n10.0004 11.0 1 0 0 0 0 1.5707963267948966\n\
             11.0 12.0 1 0 0 0 0 0\n10.0 13.0 1 1 0 0 0 0\n"
                .as_bytes(),
        )
        .unwrap();
        let e = evaluate(&traj, &rels, 1e-3);
        assert_eq!(e.used, 2);
        // Relation 1 exact; relation 2: est in frame of pose 2 = (1, −0.1), yaw 2°.
        assert!((e.trans_mean_m - 0.05).abs() < 1e-9 && (e.trans_std_m - 0.05).abs() < 1e-9);
        assert!((e.rot_mean_deg - 1.0).abs() < 1e-9);
    }
}
