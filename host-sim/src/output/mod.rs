//! Files written after a run: TUM trajectories, `metrics.json`, PNG pictures; the
//! progress bar and the one-line summary.

pub mod grid_map;
mod plots;
mod tum;

pub use plots::{draw_errors, draw_map};
pub use tum::{tum_line, write_tum};

use crate::metrics::Metrics;
use crate::readers::Recording;
use crate::replay::ReplayRun;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use microslam::geometry::Pose2;
use std::path::Path;
use std::time::Instant;

/// A progress bar over `len` events (drawn to stderr).
pub fn progress_bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{spinner} replay [{bar:40}] {pos}/{len} events ({eta})")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Writes `trajectory.tum`, `landmarks.csv`, `map.png` and
/// `errors.png` (when `plots`), then `metrics.json` with the wall time since `started`.
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
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let (a, b, c) = std::thread::scope(|s| {
        let tum = s.spawn(|| -> Result<()> {
            write_tum(
                &out.join("trajectory.tum"),
                run.trajectory.iter().map(|p| (p.stamp, p.pose)),
            )
        });
        let map = s.spawn(|| -> Result<()> {
            if plots {
                draw_map(&out.join("map.png"), recording, run, &alignment)?;
            }
            Ok(())
        });
        let errors =
            plots.then(|| draw_errors(&out.join("errors.png"), recording, run, &alignment));
        let join = |h: std::thread::ScopedJoinHandle<'_, Result<()>>| {
            h.join()
                .unwrap_or_else(|_| Err(anyhow::anyhow!("writer thread panicked")))
        };
        (join(tum), join(map), errors.unwrap_or(Ok(())))
    });
    a?;
    b?;
    c?;
    write_landmarks(&out.join("landmarks.csv"), run)?;
    metrics.wall_time_s = started.elapsed().as_secs_f64();
    let json = serde_json::to_string_pretty(metrics)?;
    let path = out.join("metrics.json");
    std::fs::write(&path, json + "\n").with_context(|| format!("cannot write {}", path.display()))
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
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `groundtruth.tum` (the recording's ground truth) into `out`, creating it.
pub fn write_truth(out: &Path, recording: &Recording) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    write_tum(
        &out.join("groundtruth.tum"),
        recording.ground_truth.iter().map(|p| (p.stamp, p.pose)),
    )
}

/// A short human-readable summary of the metrics.
pub fn summary(m: &Metrics, out: &Path) -> String {
    let f = |v: Option<f64>| v.map_or_else(|| "n/a".to_owned(), |v| format!("{v:.3}"));
    format!(
        "{} [{} {}]: ATE se2 {} m (first pose {}), landmarks se2 {} m, {} landmarks, purity {}, \
         NEES {}, NIS {}, dead reckoning {} m; filter {:.1} ms, wall {:.1} ms → {}",
        m.dataset,
        m.association,
        m.precision,
        f(m.ate_rmse_m.se2),
        f(m.ate_rmse_m.first_pose),
        f(m.landmark_rmse_m.se2),
        m.landmarks_created,
        f(m.association_purity),
        f(m.nees_pose_mean),
        f(m.nis_mean),
        f(m.dead_reckoning_ate_rmse_m.se2),
        m.filter_time_s * 1e3,
        m.wall_time_s * 1e3,
        out.display()
    )
}
