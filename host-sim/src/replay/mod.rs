//! The replay loop: a [`Recording`]'s events → the landmark EKF-SLAM → estimates.
//!
//! It never parses anything: readers and the simulator hand it events. Each odometry
//! sample sets the velocity held until the next event; before every event the filter is
//! predicted up to its stamp. Sightings with (nearly) the same stamp form a batch for
//! JCBB. In the unknown-id modes the sighting's identity is hidden from the estimator and
//! kept aside only to score the association afterwards.

mod estimator;

pub use estimator::{
    AssociationCounts, MapLandmark, PoseSample, ReplayRun, dead_reckoning, replay,
};

use crate::cli::{AssociationMode, Precision, ReplayArgs};
use crate::config::Settings;
use crate::readers::Recording;
use anyhow::Result;
use std::path::Path;
use std::time::Instant;

/// `host-sim replay`.
pub fn run_cli(args: &ReplayArgs, quiet: bool) -> Result<()> {
    use crate::cli::FilterKind;
    use crate::readers::DatasetSpec;
    let lidar = matches!(args.dataset, DatasetSpec::Carmen(_) | DatasetSpec::Thor(_));
    if args.filter == Some(FilterKind::GridSlam) || (args.filter.is_none() && lidar) {
        return crate::grid_replay::replay_cli(args, quiet);
    }
    let started = Instant::now();
    let settings = Settings::load_for(
        args.dataset.family(),
        args.config.as_deref(),
        args.association,
    )?;
    let mut recording = crate::readers::read(&args.dataset, args.robot)?;
    let faults = args.faults.filter(|f| !f.is_none()).map(|rates| {
        let (events, counts) = crate::faults::inject(&recording.events, &rates, args.fault_seed);
        recording.events = events;
        crate::faults::FaultReport {
            rates,
            seed: args.fault_seed,
            injected: counts,
        }
    });
    let mode = settings.association.mode;
    run_and_report(
        &recording,
        &settings,
        mode,
        args.precision,
        &args.out,
        !args.no_plots,
        quiet,
        started,
        faults,
    )
}

/// Replays `recording`, scores it and writes `metrics.json`, the TUM trajectories and the
/// pictures into `out`. `started` is when the process began its work (for the wall time).
#[allow(clippy::too_many_arguments)]
pub fn run_and_report(
    recording: &Recording,
    settings: &Settings,
    mode: AssociationMode,
    precision: Precision,
    out: &Path,
    plots: bool,
    quiet: bool,
    started: Instant,
    faults: Option<crate::faults::FaultReport>,
) -> Result<()> {
    let progress = (!quiet).then(|| crate::output::progress_bar(recording.events.len() as u64));
    // The ground truth is written while the filter runs.
    let metrics = std::thread::scope(|s| -> Result<_> {
        let truth = s.spawn(|| crate::output::write_truth(out, recording));
        let run = replay(recording, settings, mode, precision, progress.as_ref())?;
        if let Some(p) = &progress {
            p.finish_and_clear();
        }
        let mut metrics = crate::metrics::evaluate(recording, &run);
        metrics.faults = faults;
        truth
            .join()
            .map_err(|_| anyhow::anyhow!("writer thread panicked"))??;
        crate::output::write_all(out, recording, &run, &mut metrics, plots, started)?;
        Ok(metrics)
    })?;
    if !quiet {
        println!("{}", crate::output::summary(&metrics, out));
    }
    Ok(())
}
