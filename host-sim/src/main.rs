//! `host-sim`: replay datasets and simulations through the microslam estimators.

use clap::Parser;

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    let cli = host_sim::cli::Cli::parse();
    match host_sim::cli::run(&cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("host-sim: error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
