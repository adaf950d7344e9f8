//! Hardware-in-the-loop under QEMU, through `host_sim::drivers::hil`: the firmware ELF on
//! `mps2-an386`, its UART0 on the child's stdin/stdout, semihosting (defmt) on a file so
//! it never mixes with the frames; plus the synthetic drive of the equality test.

use std::path::{Path, PathBuf};
use std::time::Duration;

use microslam::geometry::ray_to_segments;
use microslam::wire::{
    Command as WireCommand, EstimatorKind, Odometry, SCAN_CHUNK_BEAMS, ScanChunk, ToDevice,
};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// The firmware ELF: `$FIRMWARE_ELF`, else `firmware-elf/qemu.elf` in the target directory
/// (`$CARGO_TARGET_DIR`, default `<workspace>/target`), where `.ci/firmware.sh` puts the
/// QEMU firmware. (Not cargo's own `firmware` profile output: the localizer firmware is
/// built there too, and whichever was built last would be taken.)
pub fn firmware_elf() -> PathBuf {
    firmware_elf_from(
        std::env::var_os("FIRMWARE_ELF"),
        std::env::var_os("CARGO_TARGET_DIR"),
    )
}

/// [`firmware_elf`] given the values of `$FIRMWARE_ELF` and `$CARGO_TARGET_DIR` (a
/// relative target directory is relative to the workspace root, as for cargo run there).
pub fn firmware_elf_from(
    firmware_elf: Option<std::ffi::OsString>,
    target_dir: Option<std::ffi::OsString>,
) -> PathBuf {
    if let Some(elf) = firmware_elf.filter(|v| !v.is_empty()) {
        return PathBuf::from(elf);
    }
    let target = target_dir
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("target"), PathBuf::from);
    workspace_root().join(target).join("firmware-elf/qemu.elf")
}

pub use host_sim::drivers::hil::{Expected, LinkRun as QemuRun, encode_all, host_replies};

/// Runs `elf` under QEMU, writes `bytes` to its UART without waiting (after the
/// handshake's answer, when the stream opens with it), and reads replies until the
/// `expected` ones have arrived (or `timeout` passes: then fewer are returned).
pub fn run_in_qemu(
    elf: &Path,
    bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> QemuRun {
    host_sim::drivers::hil::run_qemu(elf, bytes, expected, timeout).expect("qemu-system-arm runs")
}

/// [`run_in_qemu`] on another QEMU board.
pub fn run_in_qemu_on(
    machine: host_sim::drivers::hil::QemuMachine,
    elf: &Path,
    bytes: Vec<u8>,
    expected: Expected<'_>,
    timeout: Duration,
) -> QemuRun {
    host_sim::drivers::hil::run_qemu_on(machine, elf, bytes, expected, timeout)
        .expect("qemu-system-arm runs")
}

/// The STM32 build of the firmware for QEMU's `netduinoplus2` (`--no-default-features
/// --features stm32f411,stm32-in-qemu`): `$STM32_QEMU_ELF`, else
/// `target/firmware-elf/stm32-qemu.elf` (where `.ci/firmware.sh` puts it).
pub fn stm32_qemu_elf() -> PathBuf {
    path_from_env("STM32_QEMU_ELF", "target/firmware-elf/stm32-qemu.elf")
}

/// The STM32 build of the localizer firmware for QEMU's `netduinoplus2`, reading its own
/// lidar on USART1 (`--features stm32f411,stm32-in-qemu,own-lidar`, `MICROSLAM_MAP` the
/// map of [`localizer_map`]): `$STM32_LOCALIZER_QEMU_ELF`, else
/// `target/firmware-elf/localizer-stm32-qemu.elf` (where `.ci/firmware.sh` puts it).
pub fn stm32_localizer_qemu_elf() -> PathBuf {
    path_from_env(
        "STM32_LOCALIZER_QEMU_ELF",
        "target/firmware-elf/localizer-stm32-qemu.elf",
    )
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
    let mut out = Messages::default();
    let steps = 760;
    for k in 0..steps {
        let stamp_us = 1_000_000_000 + u64::from(k as u32) * 100_000;
        if k == steps / 2 {
            out.command(WireCommand::Reset { x, y, theta: th });
        }
        // Truth moves; odometry reports it with a bias.
        x += v * dt * (th + omega * dt / 2.0).cos();
        y += v * dt * (th + omega * dt / 2.0).sin();
        th += omega * dt;
        let kf = k as f32;
        out.odometry(
            stamp_us,
            Odometry::Velocity {
                v: v * (1.0 + 0.03 * (0.07 * kf).sin()),
                omega: omega + 0.01 * (0.11 * kf).cos(),
                dt,
            },
        );
        for (id, &(lx, ly)) in landmarks.iter().enumerate() {
            let (dx, dy) = (lx - x, ly - y);
            let range = (dx * dx + dy * dy).sqrt();
            let mut bearing = dy.atan2(dx) - th;
            bearing = bearing.sin().atan2(bearing.cos());
            if range < 4.0 && bearing.abs() < 1.05 && (k + id) % 3 == 0 {
                let j = (k * 13 + id * 7) as f32;
                out.0.push(ToDevice::Landmark {
                    seq: out.seq(),
                    stamp_us: stamp_us + 50_000,
                    id: 100 + id as u32,
                    range: range + 0.05 * (0.37 * j).sin(),
                    bearing: bearing + 0.02 * (0.53 * j).cos(),
                });
            }
        }
    }
    out.finish()
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

/// Walls of the grid drive's room (segments, metres): an 8 m × 6 m box with a pillar and
/// a wall stub, so that scans constrain both position and heading.
const ROOM: [((f32, f32), (f32, f32)); 9] = [
    ((-4.0, -3.0), (4.0, -3.0)),
    ((4.0, -3.0), (4.0, 3.0)),
    ((4.0, 3.0), (-4.0, 3.0)),
    ((-4.0, 3.0), (-4.0, -3.0)),
    ((-0.4, -0.4), (0.4, -0.4)),
    ((0.4, -0.4), (0.4, 0.4)),
    ((0.4, 0.4), (-0.4, 0.4)),
    ((-0.4, 0.4), (-0.4, -0.4)),
    ((2.5, 3.0), (2.5, 1.8)),
];

/// Range from `(x, y)` along angle `a` to the nearest wall of [`ROOM`], metres.
fn cast(x: f32, y: f32, a: f32) -> Option<f32> {
    let walls = ROOM.iter().map(|&((x1, y1), (x2, y2))| [x1, y1, x2, y2]);
    ray_to_segments((x, y), (a.cos(), a.sin()), walls)
}

/// Beams of the grid drive's lidar: 90 over the full circle.
pub const GRID_DRIVE_BEAMS: usize = 90;

/// A deterministic lidar drive for the grid estimator: select the grid, reset to the
/// start pose, then a robot circling a pillar in a walled room with biased
/// velocity odometry at 10 Hz (a few steps as pose increments and encoder ticks, to
/// exercise every odometry form) and a 90-beam scan every 5th step, ray-cast in the room
/// with deterministic noise and sent in chunks of [`SCAN_CHUNK_BEAMS`]; a status request
/// at the end. Returns the messages and the number of scans.
pub fn synthetic_lidar_drive(steps: usize) -> (Vec<ToDevice>, usize) {
    let (v, omega, dt) = (0.3f32, 0.2f32, 0.1f32);
    let (mut x, mut y, mut th) = (1.5f32, 0.0f32, core::f32::consts::FRAC_PI_2);
    let mut out = Messages::grid_from(x, y, th);
    let mut scans = 0;
    let increment = core::f32::consts::TAU / GRID_DRIVE_BEAMS as f32;
    for k in 0..steps {
        let stamp_us = 2_000_000_000 + u64::from(k as u32) * 100_000;
        if k % 5 == 0 {
            let ranges: Vec<u16> = (0..GRID_DRIVE_BEAMS)
                .map(|i| {
                    let a = -core::f32::consts::PI + increment * i as f32;
                    let noise = 0.01 * (0.91 * (k * 7 + i) as f32).sin();
                    match cast(x, y, th + a) {
                        Some(r) if r < 29.0 => ((r + noise) * 1000.0).round() as u16,
                        _ => 0,
                    }
                })
                .collect();
            out.scan(
                stamp_us,
                scans as u16,
                &ranges,
                -core::f32::consts::PI,
                increment,
            );
            scans += 1;
        }
        x += v * dt * (th + omega * dt / 2.0).cos();
        y += v * dt * (th + omega * dt / 2.0).sin();
        th += omega * dt;
        let kf = k as f32;
        let odometry = match k % 10 {
            3 => Odometry::Increment {
                dx: v * dt * 1.02,
                dy: 0.0,
                dtheta: omega * dt,
            },
            7 => {
                // Arc of v·dt with turn ω·dt on a 0.3937 m track, 0.0022 m per tick.
                let (d, t) = (v * dt, omega * dt);
                let right = ((d + t * 0.3937 / 2.0) / 0.0022).round() as i32;
                let left = ((d - t * 0.3937 / 2.0) / 0.0022).round() as i32;
                Odometry::EncoderTicks {
                    front_left: left,
                    front_right: right,
                    rear_left: left,
                    rear_right: right,
                    dt,
                }
            }
            _ => Odometry::Velocity {
                v: v * (1.0 + 0.03 * (0.07 * kf).sin()),
                omega: omega + 0.01 * (0.11 * kf).cos(),
                dt,
            },
        };
        out.odometry(stamp_us + 50_000, odometry);
    }
    (out.finish(), scans)
}

/// The simulator's office world with `laps` laps, its lidar moved to the robot's centre
/// (the wire carries no mount pose), recorded with noise seed `seed`.
pub fn office_recording(
    laps: u32,
    seed: u64,
) -> host_sim::inputs::sim::lidar_world::LidarRecording {
    use host_sim::inputs::sim::lidar_world::{LidarWorld, simulate};
    let mut world = LidarWorld::office();
    world.lidar.mount = [0.0; 3];
    world.laps = laps;
    simulate(&world, seed).expect("the office world simulates")
}

/// The simulator's lidar world (`host_sim::inputs::sim::lidar_world`, seed `seed`) as wire frames
/// for the grid estimator: select the grid, reset to the start pose, then for every sweep
/// the odometry increment since the previous sweep (in the previous odometry frame) and the
/// sweep in chunks (readings at or beyond the maximum range as 0 mm: no return); a status
/// request at the end. The lidar is moved to the robot's centre (the wire carries no mount
/// pose) and `laps` set. Returns the messages and the sweeps' true poses.
pub fn lidar_world_messages(laps: u32, seed: u64) -> (Vec<ToDevice>, Vec<[f64; 3]>) {
    let rec = office_recording(laps, seed);
    let start = rec.world.start_pose();
    let mut out = Messages::grid_from(start.x as f32, start.y as f32, start.theta as f32);
    let truth = out.sweeps(&rec, &rec.scans);
    (out.finish(), truth)
}

/// A relocalization in the office world for the localizer firmware: select the
/// localizer, reset it at the map's origin (a pose the robot is not at), ask it to
/// `Relocalize`, then the sweeps `sweeps` of `rec` as [`lidar_world_messages`] sends them
/// (no odometry before the first) and a status request. Returns the messages and the
/// sweeps' true poses.
pub fn office_relocalization_messages(
    rec: &host_sim::inputs::sim::lidar_world::LidarRecording,
    sweeps: std::ops::Range<usize>,
) -> (Vec<ToDevice>, Vec<[f64; 3]>) {
    let mut out = Messages::default();
    out.command(WireCommand::SelectEstimator(EstimatorKind::Localizer));
    out.command(WireCommand::Reset {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    });
    out.command(WireCommand::Relocalize);
    let truth = out.sweeps(rec, rec.scans.get(sweeps).unwrap_or(&[]));
    (out.finish(), truth)
}

/// `$var` when it is set, else `default` under the workspace root.
fn path_from_env(var: &str, default: &str) -> PathBuf {
    std::env::var_os(var).map_or_else(|| workspace_root().join(default), PathBuf::from)
}

/// The localizer firmware ELF (built with `MICROSLAM_MAP`): `$LOCALIZER_ELF`, else
/// `target/firmware-elf/localizer.elf` (where `.ci/firmware.sh` puts it).
pub fn localizer_elf() -> PathBuf {
    path_from_env("LOCALIZER_ELF", "target/firmware-elf/localizer.elf")
}

/// The building-scale SLAM firmware (built with `--features building-slam`):
/// `$CAR_ELF`, else `target/firmware-elf/car.elf` (where `.ci/firmware.sh` puts it): the
/// firmware with the car model (feature `car`).
pub fn car_elf() -> PathBuf {
    path_from_env("CAR_ELF", "target/firmware-elf/car.elf")
}

/// `$SLAM_ELF`, else `target/firmware-elf/slam.elf` (where `.ci/firmware.sh` puts it).
pub fn slam_elf() -> PathBuf {
    path_from_env("SLAM_ELF", "target/firmware-elf/slam.elf")
}

/// The map the localizer firmware was built with: `$LOCALIZER_MAP`, else
/// `target/firmware-elf/intel-map/map.yaml` (the map of the host grid-SLAM run on the
/// Intel log that `.ci/firmware.sh` makes).
pub fn localizer_map() -> PathBuf {
    path_from_env("LOCALIZER_MAP", "target/firmware-elf/intel-map/map.yaml")
}

/// The localizer firmware built with the office map (`MICROSLAM_MAP` = the map of a
/// `host-sim sim` grid-SLAM run of the simulator's office): `$OFFICE_LOCALIZER_ELF`, else
/// `target/firmware-elf/localizer-office.elf` (where `.ci/firmware.sh` puts it).
pub fn office_localizer_elf() -> PathBuf {
    path_from_env(
        "OFFICE_LOCALIZER_ELF",
        "target/firmware-elf/localizer-office.elf",
    )
}

/// The map [`office_localizer_elf`] was built with: `$OFFICE_LOCALIZER_MAP`, else
/// `target/firmware-elf/office-sim/grid/slam/map.yaml` (the `host-sim sim` run that
/// `.ci/firmware.sh` makes).
pub fn office_localizer_map() -> PathBuf {
    path_from_env(
        "OFFICE_LOCALIZER_MAP",
        "target/firmware-elf/office-sim/grid/slam/map.yaml",
    )
}

/// The localizer firmware built with the board's own map of the Intel lab
/// (`MICROSLAM_MAP` = the `map.bin` the building-scale SLAM writes at the end of a
/// `host-sim replay --particles 32 --loop-closure` run, the image the board writes into
/// its flash): `$BOARD_MAP_LOCALIZER_ELF`, else
/// `target/firmware-elf/localizer-board-map.elf` (where `.ci/firmware.sh` puts it).
pub fn board_map_localizer_elf() -> PathBuf {
    path_from_env(
        "BOARD_MAP_LOCALIZER_ELF",
        "target/firmware-elf/localizer-board-map.elf",
    )
}

/// The map [`board_map_localizer_elf`] was built with: `$BOARD_MAP_LOCALIZER_MAP`, else
/// `target/firmware-elf/intel-board-map/map.bin`.
pub fn board_map_localizer_map() -> PathBuf {
    path_from_env(
        "BOARD_MAP_LOCALIZER_MAP",
        "target/firmware-elf/intel-board-map/map.bin",
    )
}

/// A copy of `elf` at `out` with one byte of the embedded map image `image` flipped
/// (after the header: the CRC-32 no longer matches). `None` when the image is not found
/// in the ELF verbatim.
pub fn elf_with_corrupt_map(elf: &Path, image: &[u8], out: &Path) -> Option<()> {
    let mut bytes = std::fs::read(elf).ok()?;
    let at = bytes.windows(image.len()).position(|w| w == image)?;
    bytes[at + image.len() / 2] ^= 0x5a;
    std::fs::write(out, bytes).ok()
}

/// The messages of a drive as they are written, numbered from 1 in order.
#[derive(Default)]
struct Messages(Vec<ToDevice>);

impl Messages {
    /// Select the grid estimator and reset it to `(x, y, theta)`.
    fn grid_from(x: f32, y: f32, theta: f32) -> Self {
        let mut m = Self::default();
        m.command(WireCommand::SelectEstimator(EstimatorKind::Grid));
        m.command(WireCommand::Reset { x, y, theta });
        m
    }

    /// The next message's sequence number.
    fn seq(&self) -> u32 {
        self.0.len() as u32 + 1
    }

    fn command(&mut self, command: WireCommand) {
        self.0.push(ToDevice::Command {
            seq: self.seq(),
            command,
        });
    }

    fn odometry(&mut self, stamp_us: u64, odometry: Odometry) {
        self.0.push(ToDevice::Odometry {
            seq: self.seq(),
            stamp_us,
            odometry,
        });
    }

    /// Scan `scan_id` in chunks of [`SCAN_CHUNK_BEAMS`] (0 mm: no return).
    fn scan(
        &mut self,
        stamp_us: u64,
        scan_id: u16,
        ranges: &[u16],
        angle_min: f32,
        angle_increment: f32,
    ) {
        for (c, chunk) in ranges.chunks(SCAN_CHUNK_BEAMS).enumerate() {
            self.0.push(ToDevice::Scan(ScanChunk {
                seq: self.seq(),
                stamp_us,
                scan_id,
                beam_offset: (c * SCAN_CHUNK_BEAMS) as u16,
                beam_total: ranges.len() as u16,
                angle_min,
                angle_increment,
                ranges_mm: heapless::Vec::from_slice(chunk).unwrap_or_default(),
            }));
        }
    }

    /// `scans` of `rec`, each after the odometry increment since the previous one (in the
    /// previous odometry frame; none before the first) and in chunks (readings at or
    /// beyond the maximum range as 0 mm: no return). Returns their true poses.
    fn sweeps(
        &mut self,
        rec: &host_sim::inputs::sim::lidar_world::LidarRecording,
        scans: &[host_sim::inputs::sim::lidar_world::SimScan],
    ) -> Vec<[f64; 3]> {
        let max_mm = rec.world.lidar.max_range_m * 1000.0;
        let mut last = None;
        let mut truth = Vec::with_capacity(scans.len());
        for (k, scan) in scans.iter().enumerate() {
            let stamp_us = (scan.stamp * 1e6) as u64;
            if let Some(prev) = last.replace(scan.odometry) {
                let (c, s) = (prev.theta.cos(), prev.theta.sin());
                let (dx, dy) = (scan.odometry.x - prev.x, scan.odometry.y - prev.y);
                let dth = scan.odometry.theta - prev.theta;
                self.odometry(
                    stamp_us,
                    Odometry::Increment {
                        dx: (c * dx + s * dy) as f32,
                        dy: (-s * dx + c * dy) as f32,
                        dtheta: dth.sin().atan2(dth.cos()) as f32,
                    },
                );
            }
            let ranges: Vec<u16> = scan
                .ranges
                .iter()
                .map(|&r| {
                    let mm = f64::from(r) * 1000.0;
                    if mm >= max_mm || mm <= 0.0 {
                        0
                    } else {
                        mm.round() as u16
                    }
                })
                .collect();
            self.scan(
                stamp_us,
                k as u16,
                &ranges,
                rec.lidar.first_angle,
                rec.lidar.angle_increment,
            );
            truth.push([scan.truth.x, scan.truth.y, scan.truth.theta]);
        }
        truth
    }

    /// A status request at the end; the messages.
    fn finish(mut self) -> Vec<ToDevice> {
        self.command(WireCommand::ReportStatus);
        self.0
    }
}
