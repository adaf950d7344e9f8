//! Reference trajectories to score a run against (`--reference FILE`): a TUM file
//! (`t x y z qx qy qz qw`, `#` comments) or a corrected CARMEN log (the pose written with
//! each front-laser message, e.g. the GMapping-corrected `intel.gfs.log`).
//!
//! The format is told by the first line that is neither blank nor a comment: a number
//! starts a TUM line, a word (`FLASER`, `ODOM`, `PARAM`, …) a CARMEN message. Errors name
//! the file and the line.

use super::carmen;
use super::text::{self, ReadError};
use anyhow::{Context, Result, bail};
use microslam::geometry::{Pose2, wrap_angle};
use std::path::Path;

/// A reference pose with its stamp (seconds, after the offset) and its line in the file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferencePose {
    /// Stamp, seconds (the file's plus the offset given to [`read`]).
    pub stamp: f64,
    /// Planar pose (heading wrapped to (−π, π]).
    pub pose: Pose2<f64>,
    /// 1-based line of the file it came from (TUM) or its message index (CARMEN).
    pub line: usize,
}

/// The two formats [`read`] understands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReferenceFormat {
    /// `t x y z qx qy qz qw`.
    Tum,
    /// A CARMEN log: the pose of each front-laser message.
    Carmen,
}

/// Tells the format of `text` from its first line that is not blank or a comment.
pub fn detect(text: &str) -> Option<ReferenceFormat> {
    let first = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))?;
    let token = first.split_whitespace().next()?;
    Some(if token.parse::<f64>().is_ok() {
        ReferenceFormat::Tum
    } else {
        ReferenceFormat::Carmen
    })
}

/// Reads the reference trajectory in `path`, adding `offset_s` seconds to every stamp
/// (the Intel log's `intel.gfs.log` has log-relative stamps: 976052857.337 s puts them
/// on the clock of `intel-raw-part.clf`). The poses come back in file order.
pub fn read(path: &Path, offset_s: f64) -> Result<Vec<ReferencePose>> {
    if !offset_s.is_finite() {
        bail!("reference time offset must be finite, got {offset_s}");
    }
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let gz = path.extension().is_some_and(|e| e == "gz");
    if gz {
        return read_carmen(path, offset_s);
    }
    let text =
        String::from_utf8(bytes).with_context(|| format!("{}: not UTF-8 text", path.display()))?;
    let poses = match detect(&text) {
        None => bail!("{}: no poses (empty reference trajectory)", path.display()),
        Some(ReferenceFormat::Tum) => parse_tum(path, &text, offset_s)?,
        Some(ReferenceFormat::Carmen) => read_carmen(path, offset_s)?,
    };
    if poses.is_empty() {
        bail!("{}: no poses (empty reference trajectory)", path.display());
    }
    Ok(poses)
}

/// Parses TUM text (`path` only names the file in errors).
pub fn parse_tum(path: &Path, text: &str, offset_s: f64) -> Result<Vec<ReferencePose>, ReadError> {
    let rows = text::parse_table::<8>(path, text)?;
    rows.iter()
        .map(|r| {
            let [t, x, y, _z, qx, qy, qz, qw] = r.values;
            let norm = (qx * qx + qy * qy + qz * qz + qw * qw).sqrt();
            if norm.is_nan() || norm <= 1e-9 {
                return Err(text::invalid(path, r.line, "quaternion has zero length"));
            }
            let (qx, qy, qz, qw) = (qx / norm, qy / norm, qz / norm, qw / norm);
            let yaw = (2.0 * (qw * qz + qx * qy)).atan2(1.0 - 2.0 * (qy * qy + qz * qz));
            Ok(ReferencePose {
                stamp: t + offset_s,
                pose: Pose2::new(x, y, wrap_angle(yaw)),
                line: r.line,
            })
        })
        .collect()
}

fn read_carmen(path: &Path, offset_s: f64) -> Result<Vec<ReferencePose>> {
    let log = carmen::read(path)?;
    let poses: Vec<ReferencePose> = log
        .lasers()
        .filter(|l| !l.rear)
        .enumerate()
        .map(|(i, l)| ReferencePose {
            stamp: l.stamp + offset_s,
            pose: Pose2::new(l.pose[0], l.pose[1], wrap_angle(l.pose[2])),
            line: i + 1,
        })
        .collect();
    if poses.is_empty() {
        bail!(
            "{}: CARMEN log without front-laser messages: no reference poses",
            path.display()
        );
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tum_lines_give_planar_poses_and_bad_lines_name_the_line() {
        let p = Path::new("ref.tum");
        let half = 0.3f64;
        let text = format!(
            "# t x y z qx qy qz qw\n1.5 1 2 0 0 0 {} {}\n\n2.5 -1 0.5 0 0 0 0 1\n",
            half.sin(),
            half.cos()
        );
        assert_eq!(detect(&text), Some(ReferenceFormat::Tum));
        let poses = parse_tum(p, &text, 10.0).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].line, 2);
        assert_eq!(poses[0].stamp, 11.5);
        assert!((poses[0].pose.theta - 0.6).abs() < 1e-12, "{:?}", poses[0]);
        assert_eq!(
            (poses[1].pose.x, poses[1].pose.y, poses[1].line),
            (-1.0, 0.5, 4)
        );
        let e = parse_tum(p, "1 2 3 4 5 6 7\n", 0.0).unwrap_err();
        assert_eq!(e.to_string(), "ref.tum:1: truncated line: 7 of 8 fields");
        let e = parse_tum(p, "# c\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 0\n", 0.0).unwrap_err();
        assert!(e.to_string().starts_with("ref.tum:3: "), "{e}");
        assert!(e.to_string().contains("quaternion"), "{e}");
    }

    #[test]
    fn carmen_logs_give_the_laser_poses_and_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("corrected.log");
        let beams = vec!["1.0"; 180].join(" ");
        std::fs::write(
            &path,
            format!(
                "# header\nODOM 0 0 0 0 0 0 0.1 h 0.1\nFLASER 180 {beams} 1 2 0.5 9 9 9 0.2 h 0.2\n\
                 FLASER 180 {beams} 3 4 -0.5 9 9 9 0.4 h 0.4\n"
            ),
        )
        .unwrap();
        let poses = read(&path, 100.0).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[1].pose, Pose2::new(3.0, 4.0, -0.5));
        assert!((poses[0].stamp - 100.2).abs() < 1e-9);
        std::fs::write(&path, format!("FLASER 180 {beams} 1 2\n")).unwrap();
        let e = format!("{:#}", read(&path, 0.0).unwrap_err());
        assert!(e.contains("corrected.log") && e.contains("line 1"), "{e}");
        std::fs::write(&path, "# nothing\n").unwrap();
        let e = format!("{:#}", read(&path, 0.0).unwrap_err());
        assert!(e.contains("corrected.log") && e.contains("no poses"), "{e}");
        assert!(read(&path, f64::NAN).is_err());
    }
}
