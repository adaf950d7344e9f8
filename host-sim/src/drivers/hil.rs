//! The host side of hardware in the loop (`host-sim hil`). A dataset is streamed as `microslam::wire` frames
//! to the firmware (`firmware-example`) — under QEMU or on a board's serial port — at full
//! speed, without waiting for replies; the firmware's estimates are collected and compared
//! with the host running the very code the firmware runs ([`Session`], f32, libm), fed the
//! same bytes. With libm on both sides they are equal bit for bit.
//!
//! The stream: a status request (the handshake, [`handshake`]: sent alone, and nothing
//! more is sent until the device answers it as the host does — the same wire protocol
//! version, the same map, a fresh start), a reset to the dataset's initial pose, the
//! events through [`EventsToWire`] (velocity odometry becomes motion steps up to each next
//! event), and a status request whose answer carries the firmware's counters and stack
//! peak.

use std::io::{Read, Write};
use std::path::Path;
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use microslam::device::Session;
use microslam::geometry::Pose2;
use microslam::profile;
use microslam::wire::{
    CarSettings, Command as WireCommand, EkfSettings, EventsToWire, FrameDecoder, MAX_FRAME_LEN,
    ToDevice, ToHost, encode_frame,
};
use serde::Serialize;

use crate::domain::recording::Recording;

mod phases;
use phases::exchange_phases;
mod qemu;
pub use phases::{Phase, replies_across_restart, restart_cut};
pub use qemu::{QemuMachine, run_qemu, run_qemu_on, run_qemu_phases, run_qemu_with_lidar};

/// How long the device has to answer the [`handshake`] (QEMU boots in well under a
/// second; a board that runs answers within milliseconds).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);

/// The status request that opens a stream: [`run_qemu`] and [`run_serial`] send it alone
/// and wait for its answer before the rest, so that a device that is not running, not
/// listening, or answering otherwise than the host reference (another wire protocol
/// version, another map, not a fresh start) is reported within [`HANDSHAKE_TIMEOUT`]
/// instead of after the whole recording.
pub fn handshake() -> ToDevice {
    ToDevice::Command {
        seq: 0,
        command: WireCommand::ReportStatus,
    }
}

/// What the host expects back over a link.
#[derive(Clone, Copy, Debug)]
pub struct Expected<'h> {
    /// Replies to wait for (one per message that decodes).
    pub replies: usize,
    /// The answer to the [`handshake`] the device must give (the host reference's), when
    /// known; without it only the protocol version is checked.
    pub handshake: Option<&'h ToHost>,
}

impl<'h> Expected<'h> {
    /// The replies of the host reference to the same bytes (the first answers the
    /// handshake when the stream opens with it).
    pub fn host(replies: &'h [ToHost]) -> Self {
        Self {
            replies: replies.len(),
            handshake: replies.first(),
        }
    }

    /// `replies` replies, the handshake's answer checked for the protocol version only.
    pub fn count(replies: usize) -> Self {
        Self {
            replies,
            handshake: None,
        }
    }
}

/// The messages for a recording: the [`handshake`], EKF settings when given, reset to its
/// initial pose, its events, a status request.
pub fn messages_for(recording: &Recording, settings: Option<EkfSettings>) -> Vec<ToDevice> {
    messages_with_car(recording, settings, None)
}

/// [`messages_for`] of a car's recording: `car` is configured first
/// ([`WireCommand::ConfigureCar`]), for its speed and steering odometry.
pub fn messages_with_car(
    recording: &Recording,
    settings: Option<EkfSettings>,
    car: Option<CarSettings>,
) -> Vec<ToDevice> {
    let start = recording.initial_pose.unwrap_or_default();
    let mut out = vec![handshake()];
    out.extend(car.map(|c| ToDevice::Command {
        seq: 0,
        command: WireCommand::ConfigureCar(c),
    }));
    out.extend(settings.map(|s| ToDevice::Command {
        seq: 0,
        command: WireCommand::ConfigureEkf(s),
    }));
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

/// Replies decoded from a link so far.
struct Collector {
    decoder: FrameDecoder<MAX_FRAME_LEN>,
    replies: Vec<ToHost>,
}

impl Collector {
    fn new(expected: usize) -> Self {
        Self {
            decoder: FrameDecoder::new(),
            replies: Vec::with_capacity(expected),
        }
    }

    /// Decodes what arrives on `rx` until `count` replies are in or `deadline` passed.
    /// Returns `false` when the link closed (the device stopped) before.
    fn until(&mut self, rx: &mpsc::Receiver<Vec<u8>>, count: usize, deadline: Instant) -> bool {
        while self.replies.len() < count {
            let left = deadline.saturating_duration_since(Instant::now());
            let chunk = match rx.recv_timeout(left) {
                Ok(chunk) => chunk,
                Err(mpsc::RecvTimeoutError::Timeout) => break,
                Err(mpsc::RecvTimeoutError::Disconnected) => return false,
            };
            let replies = &mut self.replies;
            self.decoder.feed::<ToHost>(&chunk, |r| {
                if let Ok(m) = r {
                    replies.push(m);
                }
            });
        }
        true
    }

    fn bad_frames(&self) -> u32 {
        self.decoder.counters().bad()
    }
}

/// The length of the frame `bytes` opens with when it is the [`handshake`].
fn handshake_len(bytes: &[u8]) -> Option<usize> {
    let end = bytes.iter().position(|&b| b == 0)? + 1;
    let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut first = None;
    decoder.feed::<ToDevice>(bytes.get(..end)?, |m| first = m.ok());
    (first == Some(handshake())).then_some(end)
}

/// Checks the device's answer to the [`handshake`]: there is one, it speaks this host's
/// wire protocol, and it equals the host's `answer` when given (the same map, a fresh
/// start). `waited`: how long the device had, or `None` when the link closed first.
fn check_handshake(
    replies: &[ToHost],
    bad_frames: u32,
    waited: Option<Duration>,
    answer: Option<&ToHost>,
) -> Result<()> {
    match replies.first() {
        None => {
            let garbled = if bad_frames > 0 {
                format!(
                    " ({bad_frames} frames from it did not decode: a firmware of another \
                     wire protocol version?)"
                )
            } else {
                String::new()
            };
            let when = match waited {
                Some(t) => format!("within {} s", t.as_secs_f64()),
                None => "before its link closed".to_string(),
            };
            bail!(
                "the device did not answer the opening status request {when}{garbled}: is \
                 the firmware running (under QEMU: the ELF; on a board: flashed, and the \
                 port and baud right)?"
            )
        }
        Some(ToHost::Status { protocol, .. }) if *protocol != microslam::wire::PROTOCOL_VERSION => {
            Err(other_protocol(*protocol))
        }
        Some(got) => match answer {
            Some(want) => check_answer(got, want),
            None => Ok(()),
        },
    }
}

/// The device's answer `got` to the [`handshake`] against the host's `want`: the map the
/// host runs on (when it runs on one), then everything else.
fn check_answer(got: &ToHost, want: &ToHost) -> Result<()> {
    let map_of = |r: &ToHost| match r {
        ToHost::Status { map_checksum, .. } => *map_checksum,
        _ => None,
    };
    match (map_of(got), map_of(want)) {
        (Some(device), Some(host)) if device != host => bail!(
            "the device carries the map with CRC-32 {device:#010x}, the host runs on the map \
             with CRC-32 {host:#010x}: give --map the map the firmware was built with, or \
             build it with MICROSLAM_MAP=<that map>"
        ),
        (None, Some(host)) => bail!(
            "the device carries no valid map, the host runs on the map with CRC-32 \
             {host:#010x}: build the firmware with MICROSLAM_MAP=<that map> (a map refused \
             at boot is in the firmware's log)"
        ),
        _ if canonical(got) != canonical(want) => bail!(
            "the device's answer to the opening status request is not the host's: device \
             {got:?}, host {want:?}: reset the device before the run (a board keeps its \
             state and counters until it is reset) and build its firmware from the same \
             commit as host-sim"
        ),
        _ => Ok(()),
    }
}

/// Writes `bytes` to `link` and decodes replies from `rx` until `expected` arrived or
/// `timeout` passed. A stream that opens with the [`handshake`] sends it alone first and
/// refuses a device that does not answer it (within [`HANDSHAKE_TIMEOUT`]) or answers
/// otherwise than `expected.handshake` ([`check_handshake`]), before anything else is
/// sent. The rest is written
/// from a thread, without waiting for replies; its handle returns the link, to be joined
/// once the device is stopped or has read everything.
fn exchange<W: Write + Send + 'static>(
    mut link: W,
    rx: &mpsc::Receiver<Vec<u8>>,
    mut bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> Result<(LinkRun, thread::JoinHandle<W>)> {
    let start = Instant::now();
    let mut collector = Collector::new(expected.replies);
    if let Some(n) = handshake_len(&bytes) {
        let rest = bytes.split_off(n);
        link.write_all(&bytes)
            .and_then(|()| link.flush())
            .context("writing the opening status request")?;
        let waited = timeout.min(HANDSHAKE_TIMEOUT);
        let open = collector.until(rx, 1, start + waited);
        check_handshake(
            &collector.replies,
            collector.bad_frames(),
            open.then_some(waited),
            expected.handshake,
        )?;
        bytes = rest;
    }
    let writer = thread::spawn(move || {
        let _ = link.write_all(&bytes);
        let _ = link.flush();
        // Kept open until the run ends: the firmware would not notice EOF anyway.
        link
    });
    collector.until(rx, expected.replies, start + timeout);
    let run = LinkRun {
        bad_frames: collector.bad_frames(),
        replies: collector.replies,
        elapsed: start.elapsed(),
    };
    Ok((run, writer))
}

/// Reads `source` on a thread of its own and passes what arrives on the channel it
/// returns. The thread ends, and drops `source` (closing a serial port), when the source
/// ends or fails, or when the receiver is dropped: a read that times out (a serial port
/// with nothing to say) sends an empty chunk, which fails once nobody listens.
fn reader_thread(mut source: impl Read + Send + 'static) -> mpsc::Receiver<Vec<u8>> {
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    thread::spawn(move || {
        let mut buf = [0u8; 4096];
        loop {
            let chunk = match source.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => buf[..n].to_vec(),
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => Vec::new(),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(_) => break,
            };
            if tx.send(chunk).is_err() {
                break;
            }
        }
    });
    rx
}

/// Where the device runs: a firmware ELF under QEMU, or a board on a serial port.
#[derive(Clone, Copy, Debug)]
pub enum Device<'a> {
    /// The firmware ELF, run by [`run_qemu`].
    Qemu(&'a Path),
    /// A board's serial port and its baud rate ([`run_serial`]).
    Serial {
        /// The port, e.g. `/dev/ttyACM0`.
        port: &'a str,
        /// Baud rate.
        baud: u32,
    },
}

impl<'a> Device<'a> {
    /// The device of `host-sim hil`'s options: exactly one of an ELF and a port.
    pub fn from_options(
        qemu: Option<&'a Path>,
        serial: Option<&'a str>,
        baud: u32,
    ) -> Result<Self> {
        match (qemu, serial) {
            (Some(elf), None) => Ok(Self::Qemu(elf)),
            (None, Some(port)) => Ok(Self::Serial { port, baud }),
            _ => bail!("give exactly one of --qemu <elf> and --serial <port>"),
        }
    }

    /// Streams `bytes` to the device and collects the `expected` replies ([`run_qemu`],
    /// [`run_serial`]).
    pub fn run(
        &self,
        bytes: Vec<u8>,
        expected: Expected<'_>,
        timeout: Duration,
    ) -> Result<LinkRun> {
        match *self {
            Self::Qemu(elf) => run_qemu(elf, bytes, expected, timeout),
            Self::Serial { port, baud } => run_serial(port, baud, bytes, expected, timeout),
        }
    }

    /// Streams a run in parts ([`Phase`]), the device restarting between them, and
    /// collects the replies of all.
    pub fn run_phases(&self, phases: Vec<Phase<'_>>, timeout: Duration) -> Result<LinkRun> {
        match *self {
            Self::Qemu(elf) => run_qemu_phases(QemuMachine::Mps2An386, elf, phases, timeout),
            Self::Serial { port, baud } => run_serial_phases(port, baud, phases, timeout),
        }
    }
}

/// Opens a board's serial port (8N1, `baud`), writes `bytes` and collects `expected`
/// replies (with the [`handshake`] first, as [`run_qemu`]).
pub fn run_serial(
    port: &str,
    baud: u32,
    bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> Result<LinkRun> {
    run_serial_phases(port, baud, vec![Phase { bytes, expected }], timeout)
}

/// [`run_serial`] for a run in parts ([`Phase`]): the board restarts between them (its
/// USB serial bridge stays open: an ST-LINK's virtual COM port is on the probe's chip).
pub fn run_serial_phases(
    port: &str,
    baud: u32,
    phases: Vec<Phase<'_>>,
    timeout: Duration,
) -> Result<LinkRun> {
    let link = serialport::new(port, baud)
        .timeout(Duration::from_millis(200))
        .open()
        .with_context(|| format!("opening serial port {port}"))?;
    let reader = link.try_clone().context("cloning the serial port")?;
    let rx = reader_thread(reader);
    let (run, writer) = exchange_phases(link, &rx, phases, timeout)?;
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
    /// Replies equal to the host's bit for bit (the stack figure aside, and the map
    /// checksum, which the handshake checks).
    pub identical: usize,
    /// Largest |device − host| over all estimates: x, y, θ (m, m, rad).
    pub max_pose_difference: [f64; 3],
    /// Largest |device − host| of the covariance entries `[xx, xy, xθ, yy, yθ, θθ]`.
    pub max_covariance_difference: [f64; 6],
    /// Wall time of the run, s.
    pub seconds: f64,
    /// The device's stack high-water mark from its final status, bytes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stack_peak_bytes: Option<u32>,
    /// Frames corrupted on purpose (`--corrupt-frames`).
    pub corrupted_frames: usize,
    /// Bad frames the device counted, from its final status.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_frames_bad: Option<u32>,
    /// ATE of the device's trajectory against the recording's ground truth after the SE(2)
    /// least-squares alignment (estimates inside the ground truth's time span), m.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_ate_se2_m: Option<f64>,
    /// How many device estimates that ATE is over.
    pub device_ate_poses: usize,
    /// The wire protocol version of the device's last status, when one decoded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_protocol: Option<u16>,
    /// The CRC-32 of the map image in the device's flash, from its last status (`None`:
    /// no valid map, or no status).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub device_map_checksum: Option<u32>,
    /// Index (in the messages sent, from 0) of the first reply that differs from the
    /// host's, when one does.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub first_difference: Option<usize>,
}

/// Refuses a device that speaks another wire protocol version than this host, with what
/// to do about it (checked before the replies are compared: they cannot match then).
pub fn check_protocol(comparison: &Comparison) -> Result<()> {
    let host = microslam::wire::PROTOCOL_VERSION;
    match comparison.device_protocol {
        Some(device) if device != host => Err(other_protocol(device)),
        None if comparison.received == 0 && comparison.bad_frames > 0 => bail!(
            "none of the device's {} frames decoded: is its firmware built from the same \
             commit as host-sim (wire protocol {host})?",
            comparison.bad_frames
        ),
        _ => Ok(()),
    }
}

/// Stops at the first command the device refused (`ToHost::Refused`), naming its sequence
/// number and the reason: a refused command (no map in flash, an EKF setting out of its
/// range, …) makes the rest of the run meaningless even where the host's reference,
/// refusing the same command, replies alike.
pub fn check_refusals(replies: &[ToHost]) -> Result<()> {
    match replies.iter().find_map(|r| match r {
        ToHost::Refused { seq, reason, .. } => Some((seq, reason)),
        _ => None,
    }) {
        Some((seq, reason)) => bail!("the device refused command {seq}: {reason}"),
        None => Ok(()),
    }
}

/// The error for a device that speaks wire protocol `device`, not this host's.
fn other_protocol(device: u16) -> anyhow::Error {
    anyhow::anyhow!(
        "the device speaks wire protocol {device}, this host {}: build the firmware from the \
         same commit as host-sim",
        microslam::wire::PROTOCOL_VERSION
    )
}

/// The bytes of a reply as compared: without what only the device knows (its stack peak)
/// and what the handshake checks on its own (the map checksum).
fn canonical(reply: &ToHost) -> Vec<u8> {
    let mut r = *reply;
    if let ToHost::Status {
        stack_peak_bytes,
        map_checksum,
        ..
    } = &mut r
    {
        *stack_peak_bytes = 0; // measured on the device only
        // Checked at the handshake against the host's map, when the host runs on one (the
        // EKF's reference has none, whatever the firmware carries).
        *map_checksum = None;
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
    for (i, (got, want)) in device.replies.iter().zip(host).enumerate() {
        let same = canonical(got) == canonical(want);
        c.identical += usize::from(same);
        if !same && c.first_difference.is_none() {
            c.first_difference = Some(i);
        }
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
        map_checksum,
        ..
    }) = device.replies.last()
    {
        c.device_protocol = Some(*protocol);
        c.device_map_checksum = *map_checksum;
        c.stack_peak_bytes = Some(*stack_peak_bytes);
        c.device_frames_bad = Some(status.frames_bad);
    }
    c
}

#[cfg(test)]
mod tests;
