//! The built-in deterministic simulator.

use crate::cli::SimArgs;
use anyhow::Result;

/// `host-sim sim`.
pub fn run_cli(_args: &SimArgs, _quiet: bool) -> Result<()> {
    Ok(())
}
