//! The host side of hardware in the loop (`host-sim hil`). A dataset is streamed as `microslam::wire` frames
//! to the firmware (`firmware-example`) — under QEMU or on a board's serial port — at full
//! speed, without waiting for replies; the firmware's estimates are collected and compared
//! with the host running the very code the firmware runs ([`Session`], f32, libm), fed the
//! same bytes. With libm on both sides they are equal bit for bit.
//!
//! The stream: a reset to the dataset's initial pose, the events through
//! [`EventsToWire`] (velocity odometry becomes motion steps up to each next event), and a
//! status request whose answer carries the firmware's counters and stack peak.

use std::io::{Read, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::profile;
use microslam::wire::{
    Command as WireCommand, EkfSettings, EventsToWire, FrameDecoder, MAX_FRAME_LEN, Session,
    ToDevice, ToHost, encode_frame,
};
use serde::Serialize;

use crate::domain::recording::Recording;

/// The messages for a recording: EKF settings when given, reset to its initial pose, its
/// events, a status request.
pub fn messages_for(recording: &Recording, settings: Option<EkfSettings>) -> Vec<ToDevice> {
    let start = recording.initial_pose.unwrap_or_default();
    let mut out: Vec<ToDevice> = settings
        .map(|s| ToDevice::Command {
            seq: 0,
            command: WireCommand::ConfigureEkf(s),
        })
        .into_iter()
        .collect();
    out.push(ToDevice::Command {
        seq: 0,
        command: WireCommand::Reset {
            x: start.x as f32,
            y: start.y as f32,
            theta: start.theta as f32,
        },
    });
    let mut to_wire = EventsToWire::new();
    for e in &recording.events {
        out.extend(to_wire.push(e));
    }
    out.push(ToDevice::Command {
        seq: to_wire.last_seq().wrapping_add(1),
        command: WireCommand::ReportStatus,
    });
    out
}

/// Frames of a message stream, back to back.
pub fn encode_all(messages: &[ToDevice]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for m in messages {
        // Every message type fits a frame (checked by the wire tests).
        if let Ok(frame) = encode_frame(m, &mut buf) {
            out.extend_from_slice(frame);
        }
    }
    out
}

/// Frames of a message stream with a fraction `rate` of them corrupted (one byte of the
/// frame, never its `0x00` delimiter, XORed with a non-zero value that keeps it non-zero;
/// commands are left intact),
/// from a generator seeded by `seed`. Returns the bytes and how many frames were
/// corrupted: the receiver must count exactly that many bad frames.
pub fn encode_all_corrupted(messages: &[ToDevice], rate: f64, seed: u64) -> (Vec<u8>, usize) {
    use rand_core::{RngCore, SeedableRng};
    use rand_distr::{Bernoulli, Distribution};
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
    let coin = Bernoulli::new(rate.clamp(0.0, 1.0))
        .unwrap_or_else(|_| Bernoulli::new(0.0).expect("0 is a probability"));
    let mut out = Vec::new();
    let mut corrupted = 0;
    let mut buf = [0u8; MAX_FRAME_LEN];
    for m in messages {
        let Ok(frame) = encode_frame(m, &mut buf) else {
            continue;
        };
        let start = out.len();
        out.extend_from_slice(frame);
        // Commands (the first reset, the final status request) are left intact.
        let body = frame.len().saturating_sub(1);
        if body > 0 && !matches!(m, ToDevice::Command { .. }) && coin.sample(&mut rng) {
            let at = start + (rng.next_u32() as usize) % body;
            let byte = out[at];
            let mask = loop {
                let m = (rng.next_u32() & 0xFF) as u8;
                if m != 0 && byte ^ m != 0 {
                    break m;
                }
            };
            out[at] = byte ^ mask;
            corrupted += 1;
        }
    }
    (out, corrupted)
}

/// The replies of the host reference: the firmware's [`Session`], with the firmware's EKF
/// and grid estimator (the sizes and settings of [`microslam::profile`]), fed the same bytes.
pub fn host_replies(bytes: &[u8]) -> Vec<ToHost> {
    let mut ekf = Box::new(profile::Ekf::new(profile::EKF_CONFIG));
    let config = profile::GRID_CONFIG;
    let mut grid = Box::new(profile::Grid::centred(config.resolution, config.log_odds));
    let Ok(mut slam) = profile::GridEstimator::new(&mut grid, config, Pose2::new(0.0, 0.0, 0.0))
    else {
        unreachable!("the firmware's grid configuration is valid")
    };
    let mut session = Session::<_, _, { profile::EKF_LANDMARKS }>::with_grid(
        &mut ekf,
        profile::EKF_CONFIG,
        &mut slam,
        profile::GRID_SETUP,
    );
    bytes.iter().filter_map(|&b| session.receive(b)).collect()
}

/// What came back over a link.
#[derive(Debug)]
pub struct LinkRun {
    /// Replies in arrival order.
    pub replies: Vec<ToHost>,
    /// Frames from the device that did not decode.
    pub bad_frames: u32,
    /// Wall time from start to the last expected reply.
    pub elapsed: Duration,
}

/// Writes `bytes` from one thread and decodes replies from `rx` until `expected` arrived
/// or `timeout` passed.
fn collect(
    rx: &mpsc::Receiver<Vec<u8>>,
    expected: usize,
    start: Instant,
    timeout: Duration,
) -> LinkRun {
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
    LinkRun {
        replies,
        bad_frames: decoder.counters().bad(),
        elapsed: start.elapsed(),
    }
}

fn reader_thread(mut source: impl Read + Send + 'static) -> mpsc::Receiver<Vec<u8>> {
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    thread::spawn(move || {
        let mut buf = [0u8; 4096];
        loop {
            match source.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    if tx.send(buf[..n].to_vec()).is_err() {
                        break;
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
    });
    rx
}

/// Runs `elf` under QEMU (`mps2-an386`, UART0 on the child's stdin/stdout, semihosting
/// on a file next to the ELF), writes `bytes` and collects `expected` replies.
pub fn run_qemu(elf: &Path, bytes: Vec<u8>, expected: usize, timeout: Duration) -> Result<LinkRun> {
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
        .context("starting qemu-system-arm (apt-get install qemu-system-arm)")?;
    let start = Instant::now();
    let (Some(mut stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
        bail!("qemu-system-arm without piped stdio");
    };
    let writer = thread::spawn(move || {
        let _ = stdin.write_all(&bytes);
        let _ = stdin.flush();
        // Kept open until the run ends: the firmware would not notice EOF anyway.
        stdin
    });
    let rx = reader_thread(stdout);
    let run = collect(&rx, expected, start, timeout);
    let _ = child.kill();
    let _ = child.wait();
    drop(writer.join());
    Ok(run)
}

/// Opens a board's serial port (8N1, `baud`), writes `bytes` and collects `expected`
/// replies.
pub fn run_serial(
    port: &str,
    baud: u32,
    bytes: Vec<u8>,
    expected: usize,
    timeout: Duration,
) -> Result<LinkRun> {
    let link = serialport::new(port, baud)
        .timeout(Duration::from_millis(200))
        .open()
        .with_context(|| format!("opening serial port {port}"))?;
    let reader = link.try_clone().context("cloning the serial port")?;
    let start = Instant::now();
    let mut writer_link = link;
    let writer = thread::spawn(move || {
        let _ = writer_link.write_all(&bytes);
        let _ = writer_link.flush();
        writer_link
    });
    let rx = reader_thread(reader);
    let run = collect(&rx, expected, start, timeout);
    drop(writer.join());
    Ok(run)
}

/// The comparison of the device's replies with the host's.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Comparison {
    /// Messages sent.
    pub messages: usize,
    /// Replies expected (one per message).
    pub expected: usize,
    /// Replies received.
    pub received: usize,
    /// Received frames that did not decode.
    pub bad_frames: u32,
    /// Replies equal to the host's bit for bit (the stack figure aside).
    pub identical: usize,
    /// Largest |device − host| over all estimates: x, y, θ (m, m, rad).
    pub max_pose_difference: [f64; 3],
    /// Largest |device − host| of the covariance entries `[xx, xy, xθ, yy, yθ, θθ]`.
    pub max_covariance_difference: [f64; 6],
    /// Wall time of the run, s.
    pub seconds: f64,
    /// The device's stack high-water mark from its final status, bytes.
    pub stack_peak_bytes: Option<u32>,
    /// Frames corrupted on purpose (`--corrupt-frames`).
    pub corrupted_frames: usize,
    /// Bad frames the device counted, from its final status.
    pub device_frames_bad: Option<u32>,
    /// ATE of the device's trajectory against the recording's ground truth after the SE(2)
    /// least-squares alignment (estimates inside the ground truth's time span), m.
    pub device_ate_se2_m: Option<f64>,
    /// How many device estimates that ATE is over.
    pub device_ate_poses: usize,
    /// The wire protocol version of the device's last status, when one decoded.
    pub device_protocol: Option<u16>,
}

/// Refuses a device that speaks another wire protocol version than this host, with what
/// to do about it (checked before the replies are compared: they cannot match then).
pub fn check_protocol(comparison: &Comparison) -> Result<()> {
    let host = microslam::wire::PROTOCOL_VERSION;
    match comparison.device_protocol {
        Some(device) if device != host => bail!(
            "the device speaks wire protocol {device}, this host {host}: build the firmware \
             from the same commit as host-sim"
        ),
        None if comparison.received == 0 && comparison.bad_frames > 0 => bail!(
            "none of the device's {} frames decoded: is its firmware built from the same \
             commit as host-sim (wire protocol {host})?",
            comparison.bad_frames
        ),
        _ => Ok(()),
    }
}

fn canonical(reply: &ToHost) -> Vec<u8> {
    let mut r = *reply;
    if let ToHost::Status {
        stack_peak_bytes, ..
    } = &mut r
    {
        *stack_peak_bytes = 0; // measured on the device only
    }
    let mut buf = [0u8; 256];
    postcard::to_slice(&r, &mut buf)
        .map(|b| b.to_vec())
        .unwrap_or_default()
}

/// Compares the device's replies with the host's, in order.
pub fn compare(messages: usize, device: &LinkRun, host: &[ToHost]) -> Comparison {
    let mut c = Comparison {
        messages,
        expected: host.len(),
        received: device.replies.len(),
        bad_frames: device.bad_frames,
        seconds: device.elapsed.as_secs_f64(),
        ..Comparison::default()
    };
    for (got, want) in device.replies.iter().zip(host) {
        c.identical += usize::from(canonical(got) == canonical(want));
        if let (ToHost::Estimate(a), ToHost::Estimate(b)) = (got, want) {
            for (m, (x, y)) in c
                .max_pose_difference
                .iter_mut()
                .zip(a.pose.iter().zip(b.pose))
            {
                *m = m.max(f64::from((x - y).abs()));
            }
            let pairs = a.covariance.iter().zip(b.covariance);
            for (m, (x, y)) in c.max_covariance_difference.iter_mut().zip(pairs) {
                *m = m.max(f64::from((x - y).abs()));
            }
        }
    }
    if let Some(ToHost::Status {
        protocol,
        stack_peak_bytes,
        status,
        ..
    }) = device.replies.last()
    {
        c.device_protocol = Some(*protocol);
        c.stack_peak_bytes = Some(*stack_peak_bytes);
        c.device_frames_bad = Some(status.frames_bad);
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_of_another_protocol_version_is_refused_with_both_versions() {
        let host = microslam::wire::PROTOCOL_VERSION;
        let ok = Comparison {
            received: 3,
            device_protocol: Some(host),
            ..Comparison::default()
        };
        assert!(check_protocol(&ok).is_ok());
        let other = Comparison {
            device_protocol: Some(host + 1),
            ..ok.clone()
        };
        let e = check_protocol(&other).unwrap_err().to_string();
        assert!(
            e.contains(&format!("protocol {}, this host {host}", host + 1)),
            "{e}"
        );
        let garbled = Comparison {
            received: 0,
            bad_frames: 7,
            device_protocol: None,
            ..Comparison::default()
        };
        let e = check_protocol(&garbled).unwrap_err().to_string();
        assert!(e.contains("none of the device's 7 frames decoded"), "{e}");
        // No reply at all is another error (the device did not answer), reported elsewhere.
        assert!(check_protocol(&Comparison::default()).is_ok());
    }
}
