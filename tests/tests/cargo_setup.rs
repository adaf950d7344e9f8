//! How the workspace builds for a new user: `cargo run` inside `firmware-example/` picks
//! the firmware, and every path to a build output honours `$CARGO_TARGET_DIR`.

use std::ffi::OsString;
use std::path::Path;
use std::process::Command;

use microslam_replay_tests::firmware::{firmware_elf_from, workspace_root};

/// `cargo metadata` of the workspace (no dependencies), parsed.
fn metadata() -> serde_json::Value {
    let out = Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--no-deps",
            "--format-version",
            "1",
            "--offline",
        ])
        .current_dir(workspace_root())
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "cargo metadata: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("cargo metadata prints JSON")
}

#[test]
fn cargo_run_in_firmware_example_picks_the_firmware() {
    let metadata = metadata();
    let packages = metadata["packages"].as_array().expect("a package list");
    let firmware = packages
        .iter()
        .find(|p| p["name"] == "firmware-example")
        .expect("firmware-example is a workspace member");
    let bins: Vec<&str> = firmware["targets"]
        .as_array()
        .expect("targets")
        .iter()
        .filter(|t| {
            t["kind"]
                .as_array()
                .is_some_and(|k| k.iter().any(|k| k == "bin"))
        })
        .filter_map(|t| t["name"].as_str())
        .collect();
    assert!(bins.len() > 1, "several binaries: {bins:?}");
    assert_eq!(
        firmware["default_run"].as_str(),
        Some("firmware-example"),
        "`cargo run` must not have to choose among {bins:?}"
    );
}

#[test]
fn the_firmware_elf_is_found_in_cargo_target_dir() {
    let root = workspace_root();
    let built = "firmware-elf/qemu.elf";
    assert_eq!(
        firmware_elf_from(None, None),
        root.join("target").join(built)
    );
    assert_eq!(
        firmware_elf_from(None, Some(OsString::from("/tmp/elsewhere"))),
        Path::new("/tmp/elsewhere").join(built)
    );
    assert_eq!(
        firmware_elf_from(None, Some(OsString::from("build"))),
        root.join("build").join(built),
        "a relative target directory is relative to the workspace"
    );
    assert_eq!(
        firmware_elf_from(
            Some(OsString::from("/x/fw.elf")),
            Some(OsString::from("/y"))
        ),
        Path::new("/x/fw.elf"),
        "$FIRMWARE_ELF wins"
    );
}

/// `.ci/firmware.sh` copies the ELFs out of cargo's target directory and writes its
/// measurements next to them: every such path goes through `$CARGO_TARGET_DIR`.
#[test]
fn the_firmware_script_honours_cargo_target_dir() {
    let script = std::fs::read_to_string(workspace_root().join(".ci/firmware.sh"))
        .expect(".ci/firmware.sh is readable");
    let hard_coded: Vec<(usize, &str)> = script
        .lines()
        .enumerate()
        .filter(|(_, line)| !line.trim_start().starts_with('#'))
        .filter(|(_, line)| {
            line.match_indices("target/").any(|(i, _)| {
                // `target/` as a path start, not as the end of another word.
                line[..i]
                    .chars()
                    .last()
                    .is_none_or(|c| !c.is_alphanumeric() && c != '_' && c != '-')
            })
        })
        .map(|(i, line)| (i + 1, line))
        .collect();
    assert!(
        hard_coded.is_empty(),
        "paths into target/ that ignore $CARGO_TARGET_DIR: {hard_coded:?}"
    );
    assert!(script.contains("${CARGO_TARGET_DIR:-target}"));
}
