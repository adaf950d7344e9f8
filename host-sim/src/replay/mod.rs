//! The replay loop: events → estimator → estimates. It never parses anything.

use crate::cli::ReplayArgs;
use anyhow::Result;

/// `host-sim replay`.
pub fn run_cli(args: &ReplayArgs, quiet: bool) -> Result<()> {
    let recording = crate::readers::read(&args.dataset, args.robot)?;
    if !quiet {
        println!("{}: {} events", recording.name, recording.events.len());
    }
    Ok(())
}
