//! What the command-line tests share: the `host-sim` binary and a run that must succeed.

use std::process::{Command, Output};

/// The `host-sim` binary cargo built for these tests.
pub fn host_sim() -> Command {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
}

/// Runs `command`, failing the test with its standard error when it does not succeed.
pub fn succeeds(command: &mut Command) -> Output {
    let out = command.output().expect("host-sim starts");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
