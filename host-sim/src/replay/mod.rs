//! The replay loop: events → estimator → estimates. It never parses anything.

use crate::cli::ReplayArgs;
use anyhow::Result;

/// `host-sim replay`.
pub fn run_cli(args: &ReplayArgs, quiet: bool) -> Result<()> {
    use crate::cli::FilterKind;
    use crate::readers::DatasetSpec;
    let lidar = matches!(args.dataset, DatasetSpec::Carmen(_) | DatasetSpec::Thor(_));
    if args.filter == Some(FilterKind::GridSlam) || (args.filter.is_none() && lidar) {
        return crate::grid_replay::replay_cli(args, quiet);
    }
    let recording = crate::readers::read(&args.dataset, args.robot)?;
    if !quiet {
        println!("{}: {} events", recording.name, recording.events.len());
    }
    Ok(())
}
