//! Hardware-in-the-loop under QEMU: the firmware ELF on `mps2-an386`, its UART0 on the
//! child's stdin/stdout, semihosting (defmt) on a file so it never mixes with the frames.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use microslam::ekf::{EkfConfig, EkfSlam, state_dim};
use microslam::wire::{
    Command as WireCommand, FrameDecoder, MAX_FRAME_LEN, Odometry, Session, ToDevice, ToHost,
    encode_frame,
};

/// Landmarks of the firmware's EKF (`firmware_example::config::EKF_LANDMARKS`).
pub const FIRMWARE_LANDMARKS: usize = 32;

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

/// Frames of a message stream, back to back.
pub fn encode_all(messages: &[ToDevice]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for m in messages {
        out.extend_from_slice(encode_frame(m, &mut buf).expect("every message fits a frame"));
    }
    out
}

/// The replies of the host reference: the firmware's `Session`, with the firmware's EKF
/// size and configuration, fed the same bytes.
pub fn host_replies(bytes: &[u8]) -> Vec<ToHost> {
    let mut ekf = Box::new(EkfSlam::<f32, { state_dim(FIRMWARE_LANDMARKS) }>::new(
        EkfConfig::DEFAULT_F32,
    ));
    let mut session = Session::<_, FIRMWARE_LANDMARKS>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    bytes.iter().filter_map(|&b| session.receive(b)).collect()
}

/// What a QEMU run returned.
pub struct QemuRun {
    /// Replies in arrival order.
    pub replies: Vec<ToHost>,
    /// Frames from the firmware that did not decode.
    pub bad_frames: u32,
    /// Wall time from spawn to the last expected reply.
    pub elapsed: Duration,
}

/// Runs `elf` under QEMU, writes `bytes` to its UART without waiting, and reads replies
/// until `expected` have arrived (or `timeout` passes: then fewer are returned).
pub fn run_in_qemu(elf: &Path, bytes: Vec<u8>, expected: usize, timeout: Duration) -> QemuRun {
    let semihosting_log = elf.with_extension("semihosting.log");
    let mut child: Child = Command::new("qemu-system-arm")
        .args(["-machine", "mps2-an386", "-cpu", "cortex-m4"])
        .args(["-display", "none", "-monitor", "none", "-serial", "stdio"])
        .arg("-chardev")
        .arg(format!("file,id=semi,path={}", semihosting_log.display()))
        .args([
            "-semihosting-config",
            "enable=on,target=native,chardev=semi",
        ])
        .arg("-kernel")
        .arg(elf)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("qemu-system-arm runs (apt-get install qemu-system-arm)");
    let start = Instant::now();
    let mut stdin = child.stdin.take().expect("piped stdin");
    let writer = thread::spawn(move || {
        // The device keeps up or QEMU's UART holds the line; either way no reply is awaited.
        let _ = stdin.write_all(&bytes);
        let _ = stdin.flush();
        // Keep the pipe open until the reader is done (EOF would not stop the firmware).
        stdin
    });
    let mut stdout = child.stdout.take().expect("piped stdout");
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    thread::spawn(move || {
        let mut buf = [0u8; 4096];
        while let Ok(n) = stdout.read(&mut buf) {
            if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                break;
            }
        }
    });
    let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut replies = Vec::with_capacity(expected);
    while replies.len() < expected {
        let left = timeout.saturating_sub(start.elapsed());
        let Ok(chunk) = rx.recv_timeout(left) else {
            break;
        };
        decoder.feed::<ToHost>(&chunk, |r| {
            if let Ok(m) = r {
                replies.push(m);
            }
        });
    }
    let elapsed = start.elapsed();
    let _ = child.kill();
    let _ = child.wait();
    drop(writer.join());
    QemuRun {
        replies,
        bad_frames: decoder.counters().bad(),
        elapsed,
    }
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
