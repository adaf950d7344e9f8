//! Instruction counting under QEMU `-icount shift=6` (the `cost` binaries).
//!
//! QEMU's virtual clock advances 64 ns per executed instruction; SysTick, clocked from
//! the 25 MHz core clock of mps2-an386, ticks every 40 ns: `instructions = ticks · 40 / 64`.

use core::fmt::Write;

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{SCB, SYST};

use crate::board::{self, Serial};

/// The body of a cost binary's `main`: sets up the board, runs `run` with the UART and an
/// instruction counter, and halts through semihosting with exit code 0 (all written), 1
/// (`run` failed to write) or 2 (the core peripherals were already taken).
pub fn run_and_halt(run: impl FnOnce(&mut Serial, &mut Ticks) -> core::fmt::Result) -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        board::halt(2)
    };
    let (mut out, _led) = board::init();
    // `board::init` masks every interrupt (PRIMASK) so that the serial link can sleep;
    // SysTick's exception must run to count the counter's wraps (`instructions_long`).
    out.spin_while_idle();
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

    /// Instructions executed by `f`, however many: SysTick's interrupt counts the
    /// counter's wraps ([`SYSTICK_WRAPS`]), so the binary must define the handler with
    /// [`systick_counts_wraps!`](crate::systick_counts_wraps). The counter is not reset
    /// (under QEMU, writing it signals a wrap of its own): the ticks are the difference of
    /// two readings of wraps and counter. The handler's own instructions (a few per 10 M)
    /// are counted too.
    pub fn instructions_long(&mut self, f: impl FnOnce()) -> u64 {
        self.syst.enable_interrupt();
        let t0 = Self::ticks_since_start();
        f();
        let t1 = Self::ticks_since_start();
        t1.saturating_sub(t0).saturating_sub(u64::from(self.empty)) * 40 / 64
    }

    /// Ticks counted by the wraps and the counter, read together with interrupts masked.
    fn ticks_since_start() -> u64 {
        cortex_m::interrupt::free(|_| {
            let current = SYST::get_current();
            let mut wraps = SYSTICK_WRAPS.load(Ordering::Relaxed);
            // A wrap not yet handled: counted when it came before `current` was read (the
            // counter then reads high, just reloaded), not when it came after (low).
            if SCB::is_pendst_pending() && current > Self::RELOAD / 2 {
                wraps += 1;
            }
            u64::from(wraps) * (u64::from(Self::RELOAD) + 1)
                + u64::from(Self::RELOAD - (current & Self::RELOAD))
        })
    }
}

/// SysTick wraps, counted by the handler [`systick_counts_wraps!`](crate::systick_counts_wraps)
/// defines (for [`Ticks::instructions_long`]).
pub static SYSTICK_WRAPS: AtomicU32 = AtomicU32::new(0);

/// Defines the binary's `SysTick` handler: it counts the counter's wraps in
/// [`SYSTICK_WRAPS`], for [`Ticks::instructions_long`].
#[macro_export]
macro_rules! systick_counts_wraps {
    () => {
        #[cortex_m_rt::exception]
        fn SysTick() {
            $crate::cost::SYSTICK_WRAPS.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
        }
    };
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

/// Boxes against the outer walls of [`RING`] (`[x, y, width, height]`, metres), at uneven
/// spacing so that no stretch of the corridor looks like the next.
const RING_BOXES: [[f32; 4]; 10] = [
    [-6.5, -6.6, 0.6, 0.4],
    [-1.2, -6.5, 0.9, 0.5],
    [4.3, -6.7, 0.5, 0.3],
    [9.5, -3.2, 0.5, 0.8],
    [9.6, 1.9, 0.4, 0.5],
    [5.1, 6.6, 0.7, 0.4],
    [-0.4, 6.5, 0.5, 0.5],
    [-7.3, 6.7, 1.0, 0.3],
    [-9.6, 2.5, 0.4, 0.9],
    [-9.5, -2.8, 0.5, 0.4],
];

/// Where the pillars along the inner block's long walls stand (`t` from −7 m, spaced
/// 1.3–2.1 m by where they are) and, with `short`, along its short walls (from −4 m,
/// 1.4–2.0 m): the spacing of the core's test world, so that no stretch looks like the
/// next. `out` gets the positions; the count is returned.
const fn pillar_positions(short: bool, out: &mut [f32; 16]) -> usize {
    let (mut t, end) = if short {
        (-4.0f32, 4.5)
    } else {
        (-7.0f32, 7.5)
    };
    let mut n = 0;
    while t < end && n < out.len() {
        out[n] = t;
        n += 1;
        t += if short {
            let k = (t * 3.0) as i32 % 4;
            1.4 + 0.2 * (if k < 0 { -k } else { k }) as f32
        } else {
            1.3 + 0.2 * ((t * 7.0) as i32 % 5) as f32
        };
    }
    n
}

const RING_PILLARS_LONG: usize = pillar_positions(false, &mut [0.0; 16]);
const RING_PILLARS_SHORT: usize = pillar_positions(true, &mut [0.0; 16]);
const RING_RECTS: usize = 2 + RING_BOXES.len() + 2 * RING_PILLARS_LONG + 2 * RING_PILLARS_SHORT;

/// The walls of the building-scale cost world (`[x1, y1, x2, y2]`, metres): a ring
/// corridor 2 m wide around a 16 m × 10 m block (outer walls 20 m × 14 m, centred on the
/// origin), larger than the SLAM's local map, with the boxes of [`RING_BOXES`] along its
/// outer walls and pillars of four sizes at uneven spacing along its inner ones (the
/// world of the core's graph SLAM tests, in a fixed array).
pub const RING: [[f32; 4]; 4 * RING_RECTS] = ring_walls();

/// The rectangles of [`RING`] (`[x0, y0, x1, y1]`).
const fn ring_rects() -> [[f32; 4]; RING_RECTS] {
    let mut r = [[0.0; 4]; RING_RECTS];
    r[0] = [-10.0, -7.0, 10.0, 7.0];
    r[1] = [-8.0, -5.0, 8.0, 5.0];
    let mut k = 0;
    while k < RING_BOXES.len() {
        let [x, y, sx, sy] = RING_BOXES[k];
        r[2 + k] = [x - sx / 2.0, y - sy / 2.0, x + sx / 2.0, y + sy / 2.0];
        k += 1;
    }
    let mut n = 2 + RING_BOXES.len();
    let mut at = [0.0f32; 16];
    let _ = pillar_positions(false, &mut at);
    let mut i = 0;
    while i < RING_PILLARS_LONG {
        let t = at[i];
        r[n] = pillar(t, -4.85, n);
        r[n + 1] = pillar(-t + 0.4, 4.85, n + 1);
        n += 2;
        i += 1;
    }
    let _ = pillar_positions(true, &mut at);
    let mut i = 0;
    while i < RING_PILLARS_SHORT {
        let t = at[i];
        r[n] = pillar(7.85, t, n);
        r[n + 1] = pillar(-7.85, -t + 0.3, n + 1);
        n += 2;
        i += 1;
    }
    r
}

/// A square pillar centred on `(x, y)`, half-width 0.1–0.25 m by `k`.
const fn pillar(x: f32, y: f32, k: usize) -> [f32; 4] {
    let h = 0.1 + 0.05 * (k % 4) as f32;
    [x - h, y - h, x + h, y + h]
}

const fn ring_walls() -> [[f32; 4]; 4 * RING_RECTS] {
    let rects = ring_rects();
    let mut w = [[0.0; 4]; 4 * RING_RECTS];
    let mut k = 0;
    while k < RING_RECTS {
        let [x0, y0, x1, y1] = rects[k];
        w[4 * k] = [x0, y0, x1, y0];
        w[4 * k + 1] = [x1, y0, x1, y1];
        w[4 * k + 2] = [x1, y1, x0, y1];
        w[4 * k + 3] = [x0, y1, x0, y0];
        k += 1;
    }
    w
}

/// The middle of [`RING`]'s corridor, corner by corner, anticlockwise from the south-west.
pub const RING_WAYPOINTS: [(f32, f32); 4] = [(-9.0, -6.0), (9.0, -6.0), (9.0, 6.0), (-9.0, 6.0)];

/// Range from `(x, y)` along `angle` to the nearest wall of [`RING`] (∞ when none).
pub fn ring_range(x: f32, y: f32, angle: f32) -> f32 {
    let direction = (libm::cosf(angle), libm::sinf(angle));
    microslam::geometry::ray_to_segments((x, y), direction, RING).unwrap_or(f32::INFINITY)
}
