//! Hardware-in-the-loop under QEMU, through `host_sim::hil`: the firmware ELF on
//! `mps2-an386`, its UART0 on the child's stdin/stdout, semihosting (defmt) on a file so
//! it never mixes with the frames; plus the synthetic drive of the equality test.

use std::path::{Path, PathBuf};
use std::time::Duration;

use microslam::wire::{Command as WireCommand, Odometry, ToDevice};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The firmware ELF: `$FIRMWARE_ELF`, else the `firmware` profile build in the workspace's
/// target directory (`.ci/firmware.sh` builds it).
pub fn firmware_elf() -> PathBuf {
    std::env::var_os("FIRMWARE_ELF").map_or_else(
        || workspace_root().join("target/thumbv7em-none-eabihf/firmware/firmware-example"),
        PathBuf::from,
    )
}

pub use host_sim::hil::{LinkRun as QemuRun, encode_all, host_replies};

/// Runs `elf` under QEMU, writes `bytes` to its UART without waiting, and reads replies
/// until `expected` have arrived (or `timeout` passes: then fewer are returned).
pub fn run_in_qemu(elf: &Path, bytes: Vec<u8>, expected: usize, timeout: Duration) -> QemuRun {
    host_sim::hil::run_qemu(elf, bytes, expected, timeout).expect("qemu-system-arm runs")
}

/// A deterministic drive: a robot circling twice through a ring of 12 landmarks, velocity
/// odometry at 10 Hz with a slowly varying bias, range-bearing sightings (with
/// deterministic "noise") of the landmarks within 4 m and ±60°, a reset half-way (to
/// exercise re-initialisation in place) and a status request at the end.
pub fn synthetic_drive() -> Vec<ToDevice> {
    let landmarks: Vec<(f32, f32)> = (0..12)
        .map(|i| {
            let a = i as f32 * core::f32::consts::TAU / 12.0;
            let r = if i % 2 == 0 { 5.0 } else { 1.5 };
            (r * a.cos(), r * a.sin())
        })
        .collect();
    let (v, omega, dt) = (0.5f32, 0.5f32 / 3.0, 0.1f32);
    let (mut x, mut y, mut th) = (3.0f32, 0.0f32, core::f32::consts::FRAC_PI_2);
    let mut out = Vec::new();
    let mut seq = 0u32;
    let mut next = || {
        seq += 1;
        seq
    };
    let steps = 760;
    for k in 0..steps {
        let stamp_us = 1_000_000_000 + u64::from(k as u32) * 100_000;
        if k == steps / 2 {
            out.push(ToDevice::Command {
                seq: next(),
                command: WireCommand::Reset { x, y, theta: th },
            });
        }
        // Truth moves; odometry reports it with a bias.
        x += v * dt * (th + omega * dt / 2.0).cos();
        y += v * dt * (th + omega * dt / 2.0).sin();
        th += omega * dt;
        let kf = k as f32;
        out.push(ToDevice::Odometry {
            seq: next(),
            stamp_us,
            odometry: Odometry::Velocity {
                v: v * (1.0 + 0.03 * (0.07 * kf).sin()),
                omega: omega + 0.01 * (0.11 * kf).cos(),
                dt,
            },
        });
        for (id, &(lx, ly)) in landmarks.iter().enumerate() {
            let (dx, dy) = (lx - x, ly - y);
            let range = (dx * dx + dy * dy).sqrt();
            let mut bearing = dy.atan2(dx) - th;
            bearing = bearing.sin().atan2(bearing.cos());
            if range < 4.0 && bearing.abs() < 1.05 && (k + id) % 3 == 0 {
                let j = (k * 13 + id * 7) as f32;
                out.push(ToDevice::Landmark {
                    seq: next(),
                    stamp_us: stamp_us + 50_000,
                    id: 100 + id as u32,
                    range: range + 0.05 * (0.37 * j).sin(),
                    bearing: bearing + 0.02 * (0.53 * j).cos(),
                });
            }
        }
    }
    out.push(ToDevice::Command {
        seq: next(),
        command: WireCommand::ReportStatus,
    });
    out
}

/// `bytes` with line noise inserted every `every` frames: a run of junk (no delimiter
/// inside) and then a delimiter, as a glitching line produces.
pub fn with_line_noise(frames: &[u8], every: usize) -> (Vec<u8>, u32) {
    let mut out = Vec::with_capacity(frames.len() + frames.len() / 8);
    let mut count = 0;
    let mut injected = 0;
    for &b in frames {
        out.push(b);
        if b == 0 {
            count += 1;
            if count % every == 0 {
                out.extend_from_slice(&[0x42, 0x13, 0x37, 0xff, 0x01, 0x99, 0]);
                injected += 1;
            }
        }
    }
    (out, injected)
}
