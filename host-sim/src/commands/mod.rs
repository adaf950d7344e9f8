//! Layer 5: one module per subcommand. Each takes its options struct (filled by
//! [`crate::cli`]), wires readers, drivers, metrics and outputs together, and draws the
//! progress bars and prints the summaries.

pub mod detections;
pub mod export_landmarks;
pub mod global;
pub mod hil;
pub mod hil_localizer;
pub mod hil_slam;
pub mod ld06;
pub mod localize;
pub mod replay;
pub mod rosbag;
pub mod sim;
pub mod sweep;
pub mod texture;

use crate::drivers::grid::{GridObserver, GridRun};
use crate::metrics::Metrics;
use crate::metrics::relations::{self, RelationError, find_relations, relation_error};
use crate::output::mcap::McapFile;
use crate::output::mcap::scene::{GridRecording, RunRecorder, Throttle};
use indicatif::{ProgressBar, ProgressStyle};
use microslam::geometry::Pose2;
use microslam::grid::LogOdds;
use std::path::Path;

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

/// The relation error of a grid run on the log at `log`, with the relations file given or
/// found next to the log; when there is none, a note on stderr says why and `None`. A
/// relation error that cannot be computed (no relation matched) is an error
/// ([`RelationError::computed`]).
pub(crate) fn relation_error_for(
    log: &Path,
    given: Option<&Path>,
    run: &GridRun,
) -> anyhow::Result<Option<RelationError>> {
    match find_relations(log, given) {
        Ok(file) => {
            let relations = relations::read(&file)?;
            relation_error(run, &relations)
                .computed(&file, relations.len())
                .map(Some)
        }
        Err(why) => {
            eprintln!("note: {why}");
            Ok(None)
        }
    }
}

/// The `--mcap` file, created when one is asked for.
pub(crate) fn open_mcap(path: Option<&Path>) -> anyhow::Result<Option<McapFile>> {
    path.map(|p| McapFile::create(p, "")).transpose()
}

/// Finishes the `--mcap` file (summary and index) and says where it is.
pub(crate) fn close_mcap(file: Option<McapFile>, quiet: bool) -> anyhow::Result<()> {
    if let Some(f) = file {
        let n = f.messages;
        let path = f.finish()?;
        if !quiet {
            println!("  MCAP recording: {} ({n} messages)", path.display());
        }
    }
    Ok(())
}

/// A grid run (`run` given its observer), recorded into `file` under `prefix` when there
/// is one: `steps` scans, the true pose of each in `truth` (or none), the map recorded as
/// it grows (`growing`, SLAM) or once (localization).
pub(crate) fn recorded_grid_run(
    file: Option<&mut McapFile>,
    prefix: &str,
    steps: usize,
    log_odds: LogOdds,
    truth: &[Pose2<f64>],
    growing: bool,
    run: impl FnOnce(Option<&mut dyn GridObserver>) -> anyhow::Result<GridRun>,
) -> anyhow::Result<GridRun> {
    match file {
        None => run(None),
        Some(f) => {
            let mut rec = GridRecording {
                recorder: RunRecorder::new(f, prefix, steps, Throttle::default()),
                log_odds,
                truth,
                growing_map: growing,
            };
            run(Some(&mut rec))
        }
    }
}
