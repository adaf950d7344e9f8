//! The QEMU link: a firmware ELF run under `qemu-system-arm`, its UART0 on the child's
//! stdin/stdout, semihosting on a file, and with a lidar's bytes on UART1 through a socket.

use std::io::Write;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

#[cfg(doc)]
use super::handshake;
use super::phases::exchange_phases;
use super::{Expected, HANDSHAKE_TIMEOUT, LinkRun, Phase, reader_thread};

/// How long the STM32 firmware is given under `netduinoplus2` to enable its USART before
/// the host writes (QEMU's model of it drops bytes that arrive before).
const NETDUINO_BOOT: Duration = Duration::from_millis(500);

/// The QEMU board a firmware runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QemuMachine {
    /// `mps2-an386` (Cortex-M4): the firmware's `qemu` build, its link on UART0.
    Mps2An386,
    /// `netduinoplus2`, an STM32F405 (Cortex-M4F, the STM32F4 memory map and USARTs): the
    /// firmware's STM32 build (`stm32f411,stm32-in-qemu`), its link on USART2.
    NetduinoPlus2,
}

impl QemuMachine {
    /// QEMU's arguments for the board, its link on the child's stdin/stdout and, when
    /// `lidar` names a chardev, its lidar UART on that: mps2-an386's UART0 and UART1 are
    /// the first and second `-serial`; on the netduino, `-serial` goes to USART1, USART2,
    /// … in order, so the first is the lidar's (or null) and the second the link.
    fn args(self, lidar: Option<&str>) -> Vec<String> {
        let lidar = lidar.map(|id| format!("chardev:{id}"));
        let mut args: Vec<String> = match self {
            Self::Mps2An386 => ["-machine", "mps2-an386", "-cpu", "cortex-m4"]
                .map(String::from)
                .into(),
            Self::NetduinoPlus2 => ["-machine", "netduinoplus2"].map(String::from).into(),
        };
        let serials = match self {
            Self::Mps2An386 => [Some("stdio".to_string()), lidar],
            Self::NetduinoPlus2 => [
                Some(lidar.unwrap_or_else(|| "null".into())),
                Some("stdio".into()),
            ],
        };
        for serial in serials.into_iter().flatten() {
            args.push("-serial".into());
            args.push(serial);
        }
        args
    }

    /// How long the firmware is given to enable its UARTs before the host writes.
    fn boot_time(self) -> Duration {
        match self {
            Self::Mps2An386 => Duration::ZERO,
            // The STM32 USART model drops what arrives before the firmware has enabled it
            // (the mps2 UART does not).
            Self::NetduinoPlus2 => NETDUINO_BOOT,
        }
    }
}

/// Runs `elf` under QEMU (`mps2-an386`, UART0 on the child's stdin/stdout, semihosting
/// on a file next to the ELF), writes `bytes` and collects the `expected` replies (a
/// stream that opens with the [`handshake`] is refused when the firmware does not answer
/// it within [`HANDSHAKE_TIMEOUT`] or not as expected).
pub fn run_qemu(
    elf: &Path,
    bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> Result<LinkRun> {
    run_qemu_on(QemuMachine::Mps2An386, elf, bytes, expected, timeout)
}

/// [`run_qemu`] on the board `machine`.
pub fn run_qemu_on(
    machine: QemuMachine,
    elf: &Path,
    bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> Result<LinkRun> {
    run_qemu_phases(machine, elf, vec![Phase { bytes, expected }], timeout)
}

/// [`run_qemu_on`] for a run in parts ([`Phase`]), the device restarted between them
/// (QEMU keeps its RAM through the reset, where the firmware's flash stand-in is).
pub fn run_qemu_phases(
    machine: QemuMachine,
    elf: &Path,
    phases: Vec<Phase<'_>>,
    timeout: Duration,
) -> Result<LinkRun> {
    run_qemu_linked(machine, elf, phases, None, timeout)
}

/// [`run_qemu_on`] with `lidar` on the board's lidar UART (mps2-an386's UART1, the
/// netduino's USART1, where the firmware reads its own lidar): a socket QEMU serves,
/// written as fast as the device takes the bytes.
pub fn run_qemu_with_lidar(
    machine: QemuMachine,
    elf: &Path,
    bytes: Vec<u8>,
    lidar: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> Result<LinkRun> {
    let phases = vec![Phase { bytes, expected }];
    run_qemu_linked(machine, elf, phases, Some(lidar), timeout)
}

/// The second UART's socket: a path of its own for each run.
fn lidar_socket_path() -> std::path::PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static RUNS: AtomicUsize = AtomicUsize::new(0);
    let n = RUNS.fetch_add(1, Ordering::Relaxed);
    std::env::temp_dir().join(format!("microslam-lidar-{}-{n}.sock", std::process::id()))
}

/// Connects to QEMU's socket for the second UART (QEMU creates it as it starts) and
/// writes `bytes` into it on a thread of its own; the thread hands the connection back
/// once written (or when QEMU is gone).
fn feed_lidar(
    socket: &Path,
    bytes: Vec<u8>,
    boot: Duration,
) -> Result<thread::JoinHandle<Option<std::os::unix::net::UnixStream>>> {
    let started = Instant::now();
    let mut stream = loop {
        match std::os::unix::net::UnixStream::connect(socket) {
            Ok(s) => break s,
            Err(e) if started.elapsed() > HANDSHAKE_TIMEOUT => {
                return Err(e).with_context(|| {
                    format!("connecting to QEMU's lidar UART at {}", socket.display())
                });
            }
            Err(_) => thread::sleep(Duration::from_millis(20)),
        }
    };
    Ok(thread::spawn(move || {
        thread::sleep(boot);
        stream.write_all(&bytes).ok()?;
        Some(stream)
    }))
}

/// [`run_qemu_phases`], with a lidar's bytes on the second UART when given.
fn run_qemu_linked(
    machine: QemuMachine,
    elf: &Path,
    phases: Vec<Phase<'_>>,
    lidar: Option<Vec<u8>>,
    timeout: Duration,
) -> Result<LinkRun> {
    let semihosting_log = elf.with_extension("semihosting.log");
    let socket = lidar.as_ref().map(|_| lidar_socket_path());
    let mut qemu = Command::new("qemu-system-arm");
    if let Some(socket) = &socket {
        let _ = std::fs::remove_file(socket);
        qemu.arg("-chardev").arg(format!(
            "socket,id=lidar,path={},server=on,wait=off",
            socket.display()
        ));
    }
    qemu.args(machine.args(socket.as_ref().map(|_| "lidar")));
    let mut child: Child = qemu
        .args(["-display", "none", "-monitor", "none"])
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
    let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
        let _ = child.kill();
        let _ = child.wait();
        bail!("qemu-system-arm without piped stdio");
    };
    let rx = reader_thread(stdout);
    let feeder = match (socket.as_deref(), lidar) {
        (Some(socket), Some(bytes)) => match feed_lidar(socket, bytes, machine.boot_time()) {
            Ok(feeder) => Some(feeder),
            Err(e) => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(e);
            }
        },
        _ => None,
    };
    // Let the firmware enable its UARTs first.
    thread::sleep(machine.boot_time());
    let exchanged = exchange_phases(stdin, &rx, phases, timeout);
    let _ = child.kill();
    let _ = child.wait();
    if let Some(feeder) = feeder {
        drop(feeder.join());
    }
    if let Some(socket) = &socket {
        let _ = std::fs::remove_file(socket);
    }
    let (run, writer) = exchanged?;
    drop(writer.join());
    Ok(run)
}
