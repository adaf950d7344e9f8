//! Layer 4: files written after a run: TUM trajectories, `metrics.json`, `landmarks.csv`,
//! ROS `map_server` maps, PNG pictures, MCAP recordings and ROS 2 bags.

pub mod animation;
pub mod detections_bag;
pub mod figure;
pub mod floor_texture;
pub mod grid_map;
pub mod grid_picture;
pub mod landmark_log;
pub mod mcap;
mod plots;
pub mod report;
pub mod rosbag;
pub mod thor;
mod tum;

pub use plots::{draw_errors, draw_map, write_png};
pub use report::{drop_absent, write_report};
pub use tum::{tum_line, tum_text, write_tum};

use crate::domain::leave_outs::{LeaveOut, leave_out};
use crate::domain::recording::Recording;
use crate::drivers::ekf::ReplayRun;
use crate::metrics::Metrics;
use anyhow::{Context, Result};
use microslam::geometry::Pose2;
use std::path::Path;
use std::time::Instant;

/// Creates the folder `path` (and its parents) for a command's outputs; the error names
/// the folder.
pub fn create_folder(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path)
        .with_context(|| format!("creating the output folder {}", path.display()))
}

/// Creates the output file `path` as a new file: one already there is removed first, not
/// truncated. Truncating a file that holds data makes ext4 (`auto_da_alloc`) start its
/// write-back when the new one is closed: re-running a replay into the same folder took
/// ~4 ms longer that way (MRCLAM ds6 robot 1, medians of 15 runs on this machine's ext4).
/// The error names the file.
pub fn create_file(path: &Path) -> Result<std::fs::File> {
    remove_stale(path)?;
    std::fs::File::create(path).with_context(|| format!("cannot create {}", path.display()))
}

/// Removes the output file `path` an earlier run left in the folder, if there is one, so
/// that the folder holds this run's outputs only (a run with `--no-plots` leaves no
/// earlier run's picture behind). The error names the file.
pub fn remove_stale(path: &Path) -> Result<()> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(e).with_context(|| format!("cannot replace {}", path.display())),
    }
}

/// Writes `bytes` into the new output file `path` ([`create_file`]).
pub fn write_file(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    use std::io::Write;
    create_file(path)?
        .write_all(bytes.as_ref())
        .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `landmarks.csv`, `map.png` and `errors.png` (when `plots`; otherwise removes
/// those an earlier run left), then `metrics.json` with the wall time since `started`. (`trajectory.tum` and `groundtruth.tum` need no
/// metrics: [`write_trajectory`] and [`write_truth`] run while the filter runs.)
pub fn write_all(
    out: &Path,
    recording: &Recording,
    run: &ReplayRun,
    metrics: &mut Metrics,
    plots: bool,
    started: Instant,
) -> Result<()> {
    let alignment = metrics
        .se2_alignment
        .map_or(Pose2::IDENTITY, |[x, y, theta]| Pose2::new(x, y, theta));
    create_folder(out)?;
    if plots {
        let (map, errors) = std::thread::scope(|s| {
            let map = s.spawn(|| draw_map(&out.join("map.png"), recording, run, &alignment));
            let errors = draw_errors(&out.join("errors.png"), recording, run, &alignment);
            let map = join_writer(map);
            (map, errors)
        });
        map?;
        errors?;
    } else {
        remove_stale(&out.join("map.png"))?;
        remove_stale(&out.join("errors.png"))?;
    }
    write_landmarks(&out.join("landmarks.csv"), run)?;
    metrics.wall_time_s = started.elapsed().as_secs_f64();
    write_report(&out.join("metrics.json"), metrics)
}

/// The result of a scoped writer thread (a panic in it becomes an error).
pub fn join_writer<T>(writer: std::thread::ScopedJoinHandle<'_, Result<T>>) -> Result<T> {
    writer
        .join()
        .unwrap_or_else(|_| Err(anyhow::anyhow!("writer thread panicked")))
}

/// Writes `trajectory.tum` (the filter's estimate after each odometry sample) into `out`,
/// creating it, from poses as they come: `host-sim replay` hands them over while the
/// filter runs.
pub fn write_trajectory(
    out: &Path,
    poses: impl IntoIterator<Item = (f64, Pose2<f64>)>,
) -> Result<()> {
    create_folder(out)?;
    // A leave-out build (feature `leave-outs`): the poses are still paired with the
    // ground truth, not written.
    if leave_out(LeaveOut::TumFiles) {
        poses.into_iter().for_each(drop);
        return Ok(());
    }
    write_tum(&out.join("trajectory.tum"), poses)
}

/// `landmarks.csv`: the final map, one landmark a line: index, bound id (known-id mode,
/// else empty), x, y (m) and the covariance entries σxx, σxy, σyy (m²).
pub fn write_landmarks(path: &Path, run: &ReplayRun) -> Result<()> {
    use std::fmt::Write;
    let mut text = String::from("index,id,x,y,cov_xx,cov_xy,cov_yy\n");
    for (i, l) in run.landmarks.iter().enumerate() {
        let id = l.id.map(|id| id.to_string()).unwrap_or_default();
        let _ = writeln!(
            text,
            "{i},{id},{:.6},{:.6},{:.3e},{:.3e},{:.3e}",
            l.position[0],
            l.position[1],
            l.covariance[0][0],
            l.covariance[0][1],
            l.covariance[1][1]
        );
    }
    write_file(path, text)
}

/// Writes `groundtruth.tum` (the recording's ground truth) into `out`, creating it.
pub fn write_truth(out: &Path, recording: &Recording) -> Result<()> {
    create_folder(out)?;
    if leave_out(LeaveOut::TumFiles) {
        return Ok(());
    }
    write_tum(
        &out.join("groundtruth.tum"),
        recording.ground_truth.iter().map(|p| (p.stamp, p.pose)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_file_is_replaced_by_a_new_one_and_errors_name_it() {
        use std::os::unix::fs::MetadataExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("metrics.json");
        write_file(&path, "an older and longer run's text").unwrap();
        let old = path.metadata().unwrap().ino();
        let keep = std::fs::File::open(&path).unwrap(); // holds the old inode
        write_file(&path, "new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_ne!(
            path.metadata().unwrap().ino(),
            old,
            "a new file, not truncated"
        );
        drop(keep);
        let inside_a_file = path.join("x.tum");
        let e = format!("{:#}", create_file(&inside_a_file).unwrap_err());
        assert!(e.contains(&*inside_a_file.to_string_lossy()), "{e}");
    }

    #[test]
    fn an_output_folder_that_cannot_be_made_is_named_in_the_error() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a-file");
        std::fs::write(&file, b"not a folder").unwrap();
        let inside = file.join("out");
        let e = format!("{:#}", create_folder(&inside).unwrap_err());
        assert!(
            e.contains("creating the output folder") && e.contains(&*inside.to_string_lossy()),
            "{e}"
        );
        let fine = dir.path().join("a/b");
        create_folder(&fine).unwrap();
        assert!(fine.is_dir());
    }
}
