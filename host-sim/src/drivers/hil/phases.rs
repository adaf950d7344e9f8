//! A run in parts over one link, the device restarted between them (`host-sim hil
//! --restart-after`): the parts ([`Phase`]), where a run is cut ([`restart_cut`]) and
//! which reply answers which message across the restart ([`replies_across_restart`]).

use std::io::Write;
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use microslam::wire::{ToDevice, ToHost};

use super::{Expected, LinkRun, exchange};

/// How long a device is given to reset and boot after it answered `Restart`, before the
/// next part of a run is sent ([`Phase`]).
const RESTART_BOOT: Duration = Duration::from_millis(500);

/// One part of a run over a link: the bytes, and the replies expected to them. A run of
/// several parts restarts the device between them (each part but the last ends with
/// `Command::Restart`); each part opens with the [`super::handshake`], which the device answers
/// once it has booted.
pub struct Phase<'h> {
    /// The bytes to send.
    pub bytes: Vec<u8>,
    /// The replies expected to them.
    pub expected: Expected<'h>,
}

impl<'h> Phase<'h> {
    /// The parts of a run as the host reference computed them (the bytes sent, the
    /// replies to them), each expecting those replies.
    pub fn of(parts: &'h [(Vec<u8>, Vec<ToHost>)]) -> Vec<Self> {
        parts
            .iter()
            .map(|(bytes, replies)| Phase {
                bytes: bytes.clone(),
                expected: Expected::host(replies),
            })
            .collect()
    }
}

/// Where a run of `messages` (one scan ending at each of `last_chunks`) is cut to restart
/// the device after `restart_after` scans: the index of the first message after them,
/// and the sequence number for the commands added (one past every message's).
pub fn restart_cut(
    messages: &[ToDevice],
    last_chunks: &[usize],
    restart_after: usize,
) -> Result<(usize, u32)> {
    let cut = match restart_after
        .checked_sub(1)
        .and_then(|k| last_chunks.get(k))
    {
        Some(&i) if restart_after < last_chunks.len() => i + 1,
        _ => bail!(
            "--restart-after {restart_after}: give a number of scans between 1 and {} (the \
             scans streamed less one)",
            last_chunks.len().saturating_sub(1)
        ),
    };
    let next_seq = messages
        .iter()
        .map(|m| m.seq().wrapping_add(1))
        .max()
        .unwrap_or(0);
    Ok((cut, next_seq))
}

/// The index, among the replies of a run restarted at message `cut` whose first part
/// had `before` replies, of the reply to each message of `last_chunks`: after the restart
/// the handshake's answer comes first, then one reply per message from `cut` on.
pub fn replies_across_restart(last_chunks: &[usize], cut: usize, before: usize) -> Vec<usize> {
    last_chunks
        .iter()
        .map(|&i| if i < cut { i } else { before + 1 + (i - cut) })
        .collect()
}

/// [`exchange`] for each of `phases` in turn on the same link: a part is sent once every
/// reply to the one before has arrived (the device has restarted by then). Stops after
/// the first part whose replies did not all arrive within `timeout` (counted from the
/// start). The replies of all parts, in order.
pub(super) fn exchange_phases<W: Write + Send + 'static>(
    mut link: W,
    rx: &mpsc::Receiver<Vec<u8>>,
    phases: Vec<Phase<'_>>,
    timeout: Duration,
) -> Result<(LinkRun, thread::JoinHandle<W>)> {
    let start = Instant::now();
    let mut total = LinkRun {
        replies: Vec::new(),
        bad_frames: 0,
        elapsed: Duration::ZERO,
    };
    let parts = phases.len();
    for (k, phase) in phases.into_iter().enumerate() {
        let left = timeout.saturating_sub(start.elapsed());
        let (run, writer) = exchange(link, rx, phase.bytes, phase.expected, left)
            .with_context(|| format!("part {} of {parts} of the run", k + 1))?;
        let complete = run.replies.len() >= phase.expected.replies;
        total.replies.extend(run.replies);
        total.bad_frames += run.bad_frames;
        total.elapsed = start.elapsed();
        if k + 1 == parts || !complete {
            return Ok((total, writer));
        }
        // Every reply arrived, so the device has read every byte: the writer is done.
        link = writer
            .join()
            .map_err(|_| anyhow::anyhow!("the thread writing to the device panicked"))?;
        // The device answers `Restart` before it resets: a byte sent at once could reach
        // its UART just before the reset clears it. Let it reset and boot first.
        thread::sleep(RESTART_BOOT);
    }
    bail!("a run of no parts")
}
