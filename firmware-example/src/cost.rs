//! Instruction counting under QEMU `-icount shift=6` (the `cost` binaries).
//!
//! QEMU's virtual clock advances 64 ns per executed instruction; SysTick, clocked from
//! the 25 MHz core clock of mps2-an386, ticks every 40 ns: `instructions = ticks · 40 / 64`.

use core::fmt::Write;

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;

use crate::board::{self, Serial};

/// The body of a cost binary's `main`: sets up the board, runs `run` with the UART and an
/// instruction counter, and halts through semihosting with exit code 0 (all written), 1
/// (`run` failed to write) or 2 (the core peripherals were already taken).
pub fn run_and_halt(run: impl FnOnce(&mut Serial, &mut Ticks) -> core::fmt::Result) -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        board::halt(2)
    };
    let (mut out, _led) = board::init();
    let mut ticks = Ticks::new(cp.SYST);
    let code = if run(&mut out, &mut ticks).is_ok() {
        0
    } else {
        1
    };
    let _ = embedded_io::Write::flush(&mut out);
    board::halt(code)
}

/// The first line of the grid and EKF cost binaries' output: the instructions QEMU counts
/// for 1000 `nop`s (`calibration nops=1000 instructions=…`; 1000 when the counter is right).
pub fn report_calibration(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
    writeln!(
        out,
        "calibration nops=1000 instructions={}",
        ticks.instructions(thousand_nops)
    )
}

/// The last lines of every cost binary's output: the stack's high-water mark
/// (`stack_peak_bytes=…`, read by `.ci/firmware.sh`) and `done`.
pub fn report_end(out: &mut Serial) -> core::fmt::Result {
    writeln!(out, "stack_peak_bytes={}", crate::stack::peak_bytes())?;
    writeln!(out, "done")
}

/// Counts SysTick ticks of a closure (the counter must not wrap: 2²⁴ ticks ≈ 10 M
/// instructions; a wrap is reported as `u32::MAX` ticks).
pub struct Ticks {
    syst: SYST,
    empty: u32,
}

impl Ticks {
    const RELOAD: u32 = 0x00FF_FFFF;

    /// Starts SysTick from the core clock and measures an empty closure.
    pub fn new(mut syst: SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(Self::RELOAD);
        syst.clear_current();
        syst.enable_counter();
        let mut t = Self { syst, empty: 0 };
        t.empty = t.raw(|| {});
        t
    }

    #[inline(never)]
    pub fn raw(&mut self, f: impl FnOnce()) -> u32 {
        self.syst.clear_current();
        let _ = self.syst.has_wrapped();
        let start = SYST::get_current();
        f();
        let end = SYST::get_current();
        if self.syst.has_wrapped() {
            return u32::MAX;
        }
        start.wrapping_sub(end) & Self::RELOAD
    }

    /// Instructions executed by `f` (ticks · 40 / 64, empty measurement subtracted).
    pub fn instructions(&mut self, f: impl FnOnce()) -> u32 {
        let t = self.raw(f).saturating_sub(self.empty);
        (u64::from(t) * 40 / 64) as u32
    }
}

/// A 1000-instruction block to check the tick/instruction ratio.
#[inline(never)]
pub fn thousand_nops() {
    // SAFETY: only `nop`s.
    unsafe { core::arch::asm!(".rept 1000", "nop", ".endr", options(nomem, nostack)) };
}

/// Beams of the cost measurements' lidar ([`LIDAR`]).
pub const BEAMS: usize = 90;

/// The cost measurements' lidar: [`BEAMS`] beams over 360°, 0.1 to 10 m, at the robot's
/// centre (the firmware's beam count).
pub const LIDAR: microslam::sensors::lidar::LidarGeometry =
    microslam::sensors::lidar::LidarGeometry {
        first_angle: -core::f32::consts::PI,
        angle_increment: 2.0 * core::f32::consts::PI / BEAMS as f32,
        min_range: 0.1,
        max_range: 10.0,
        no_return_range: 10.0,
        mount: microslam::geometry::Pose2::new(0.0, 0.0, 0.0),
    };

/// The walls of the cost measurements' world (`[x1, y1, x2, y2]`, metres): the room
/// `[-3, 3]²` and a pillar `[1, 1.6] × [-0.5, 0.5]`.
pub const ROOM: [[f32; 4]; 8] = [
    [-3.0, -3.0, 3.0, -3.0],
    [3.0, -3.0, 3.0, 3.0],
    [3.0, 3.0, -3.0, 3.0],
    [-3.0, 3.0, -3.0, -3.0],
    [1.0, -0.5, 1.6, -0.5],
    [1.6, -0.5, 1.6, 0.5],
    [1.6, 0.5, 1.0, 0.5],
    [1.0, 0.5, 1.0, -0.5],
];

/// Range from `(x, y)` along `angle` to the nearest wall of [`ROOM`] (∞ when none).
pub fn room_range(x: f32, y: f32, angle: f32) -> f32 {
    let direction = (libm::cosf(angle), libm::sinf(angle));
    microslam::geometry::ray_to_segments((x, y), direction, ROOM).unwrap_or(f32::INFINITY)
}
