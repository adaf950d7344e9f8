//! Instruction counts per estimator step (and per packet of the board's own lidar), under
//! QEMU with `-icount shift=6`.
//!
//! With `-icount shift=6` QEMU's virtual clock advances 64 ns per executed instruction;
//! SysTick, clocked from the 25 MHz core clock of mps2-an386, ticks every 40 ns. So
//! `instructions = ticks · 40 / 64`, the same on every run. The ratio is checked at start
//! on a block of 1000 `nop`s, and the cost of an empty measurement is subtracted.
//!
//! Prints one line per figure on UART0 (`-serial stdio`) and exits through semihosting.
//! These are instructions, not cycles: a Cortex-M4F runs this FPU-heavy code at roughly
//! 1–1.5 cycles per instruction.
#![no_std]
#![no_main]

use core::fmt::Write;

use cortex_m_rt::entry;
use firmware_example::board::Serial;
use firmware_example::cost::Ticks;
use microslam::ekf::{EkfConfig, EkfSlam, UpdateOutcome, factor_len, state_dim};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use panic_probe as _;
use static_cell::ConstStaticCell;

type Ekf<const N: usize, const P: usize> = EkfSlam<f32, N, P>;
const ZEROED: EkfConfig<f32> = firmware_example::config::ZEROED_EKF_CONFIG;

static EKF16: ConstStaticCell<Ekf<{ state_dim(16) }, { factor_len(16) }>> =
    ConstStaticCell::new(Ekf::new(ZEROED));
static EKF32: ConstStaticCell<Ekf<{ state_dim(32) }, { factor_len(32) }>> =
    ConstStaticCell::new(Ekf::new(ZEROED));
static EKF64: ConstStaticCell<Ekf<{ state_dim(64) }, { factor_len(64) }>> =
    ConstStaticCell::new(Ekf::new(ZEROED));

/// Calls per figure: the reported value is the mean.
const REPEAT: u32 = 8;

/// Range and bearing of landmark `i` as the filter predicts it (so updates pass the gate),
/// slightly perturbed.
fn predicted<const N: usize, const P: usize>(
    slam: &Ekf<N, P>,
    i: usize,
    k: u32,
) -> Option<RangeBearing<f32>> {
    let p = slam.pose();
    let l = slam.landmark(i)?;
    let (dx, dy) = (l[0] - p.x, l[1] - p.y);
    let range = libm::sqrtf(dx * dx + dy * dy);
    let bearing = libm::atan2f(dy, dx) - p.theta;
    let wobble = (k % 3) as f32 * 0.01 - 0.01;
    Some(RangeBearing::new(range + wobble, bearing - wobble))
}

/// Maps `n` landmarks on a ring while driving, so the covariance is dense.
fn build_map<const N: usize, const P: usize>(
    slam: &mut Ekf<N, P>,
    n: usize,
) -> Result<(), microslam::EkfError> {
    slam.init(
        firmware_example::config::EKF_CONFIG,
        microslam::Pose2::new(0.0, 0.0, 0.0),
    )?;
    for i in 0..n {
        slam.predict_velocity(0.2, 0.05, 0.1)?;
        let bearing = ((i * 7) % 60) as f32 * 0.1 - 3.0; // spread over (−π, π)
        slam.add_landmark(&RangeBearing::new(2.0 + (i % 5) as f32 * 0.4, bearing))?;
    }
    Ok(())
}

fn measure<const N: usize, const P: usize>(
    out: &mut Serial,
    ticks: &mut Ticks,
    slam: &mut Ekf<N, P>,
    n: usize,
) -> core::fmt::Result {
    // The cost of the n-th landmark: a map of n − 1 landmarks, then one more, REPEAT times.
    let mut add = 0u32;
    for _ in 0..REPEAT {
        if build_map(slam, n - 1).is_err() {
            return writeln!(out, "error ekf n={n} map");
        }
        let mut outcome = None;
        add +=
            ticks.instructions(|| outcome = Some(slam.add_landmark(&RangeBearing::new(2.5, 0.7))));
        if !matches!(outcome, Some(Ok(_))) {
            return writeln!(out, "error ekf n={n} add");
        }
    }
    if build_map(slam, n).is_err() {
        return writeln!(out, "error ekf n={n} map");
    }
    // The first prediction after a new landmark starts a run of deferred predictions
    // (one pass over the robot's rows); the next ones are O(1).
    let first_predict = ticks.instructions(|| {
        let _ = slam.predict_velocity(0.2, 0.05, 0.1);
    });
    let mut predict = 0u32;
    for _ in 0..REPEAT {
        predict += ticks.instructions(|| {
            let _ = slam.predict_velocity(0.2, 0.05, 0.1);
        });
    }
    // Wheel odometry as increments (dx, dy, dθ) in the previous robot frame: the same
    // motion as above (0.2 m/s, 0.05 rad/s for 0.1 s), through `predict_increment`.
    let increment = Pose2::new(0.02, 0.000_05, 0.005);
    let mut predict_increment = 0u32;
    for _ in 0..REPEAT {
        predict_increment += ticks.instructions(|| {
            let _ = slam.predict_increment(&increment);
        });
    }
    // Each update follows a prediction, as on a robot, and applies it to the factor.
    let mut update = 0u32;
    for k in 0..REPEAT {
        let i = (k as usize * 5) % n;
        if slam.predict_velocity(0.2, 0.05, 0.1).is_err() {
            return writeln!(out, "error ekf n={n} predict");
        }
        let Some(z) = predicted(slam, i, k) else {
            return writeln!(out, "error ekf n={n} landmark");
        };
        let mut outcome = None;
        update += ticks.instructions(|| outcome = Some(slam.update(i, &z)));
        if !matches!(outcome, Some(Ok(UpdateOutcome::Accepted { .. }))) {
            return writeln!(out, "error ekf n={n} update not accepted");
        }
    }
    writeln!(
        out,
        "ekf n={} first_predict={} predict={} predict_increment={} update={} add_landmark={}",
        n,
        first_predict,
        predict / REPEAT,
        predict_increment / REPEAT,
        update / REPEAT,
        add / REPEAT
    )
}

/// The board's own LD06 reader (what `microslam-hal`'s `Ld06Uart` runs on each byte): a
/// revolution of a 2.4 m square room (360 points, 30 packets) and the first packet of the
/// next, byte by byte through `Ld06Decoder` and each packet into
/// `RevolutionBinner::<LIDAR_BINS>` with the board's `LIDAR_SETUP`; instructions per
/// packet, the mean and the most (the packet that finishes the revolution).
fn measure_ld06(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
    use firmware_example::config::{GRID_SETUP, LIDAR_BINS, LIDAR_SETUP};
    use microslam::sensors::ld06::{
        AngleDirection, Ld06Decoder, PACKET_BYTES, RevolutionBinner, revolution_packets,
    };
    use microslam::sensors::lidar::{LidarGeometry, LidarScan};
    const PACKETS: usize = 31;
    let mut ranges = [0f32; 360];
    for (i, r) in ranges.iter_mut().enumerate() {
        let a = (i as f32).to_radians();
        *r = 1.2 / libm::fabsf(libm::cosf(a)).max(libm::fabsf(libm::sinf(a)));
    }
    let geometry = LidarGeometry {
        first_angle: 0.0,
        angle_increment: 1f32.to_radians(),
        ..GRID_SETUP.lidar
    };
    let mut bytes = [[0u8; PACKET_BYTES]; PACKETS];
    let mut made = 0;
    for turn in 0..2 {
        let scan = LidarScan::new(&ranges, geometry);
        let sent = revolution_packets(&scan, AngleDirection::Clockwise, 3600, turn * 100, |p| {
            if let Some(slot) = bytes.get_mut(made) {
                *slot = p.encode();
                made += 1;
            }
        });
        if sent.is_err() {
            return writeln!(out, "error ld06 packets");
        }
    }
    let mut decoder = Ld06Decoder::new();
    let Some(mut binner) = RevolutionBinner::<LIDAR_BINS>::new(LIDAR_SETUP) else {
        return writeln!(out, "error ld06 setup");
    };
    let (mut total, mut most, mut finished) = (0u32, 0u32, 0u32);
    for packet in &bytes {
        let t = ticks.instructions(|| {
            for &b in packet {
                if let Some(p) = decoder.push(b) {
                    finished += u32::from(binner.push(&p));
                }
            }
        });
        total += t;
        most = most.max(t);
    }
    if made != PACKETS || finished != 1 || decoder.counters().packets != PACKETS as u32 {
        return writeln!(out, "error ld06 decode");
    }
    writeln!(
        out,
        "ld06 bins={} packet_mean={} packet_max={}",
        LIDAR_BINS,
        total / PACKETS as u32,
        most
    )
}

fn run(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
    firmware_example::cost::report_calibration(out, ticks)?;
    measure(out, ticks, EKF16.take(), 16)?;
    measure(out, ticks, EKF32.take(), 32)?;
    measure(out, ticks, EKF64.take(), 64)?;
    measure_ld06(out, ticks)?;
    firmware_example::cost::report_end(out)
}

#[entry]
fn main() -> ! {
    firmware_example::cost::run_and_halt(run)
}

firmware_example::hard_fault_halts!();
