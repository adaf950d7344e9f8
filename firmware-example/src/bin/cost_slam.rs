//! Instructions per scan of the building-scale grid SLAM (`microslam::profile::Slam`: the
//! board profile's sizes and settings) under QEMU `-icount shift=6` (see
//! `firmware_example::cost`), and its memory: the estimator's bytes and the stack's peak.
//!
//! The robot drives laps of a ring corridor (20 m × 14 m outside, 2 m wide, with boxes
//! along its walls, [`firmware_example::cost::RING`]) until the pose graph is full, so
//! that every scan's cost is measured, including those that close a loop (the matcher
//! over the old keyframes, the graph solved) with the graph at its largest. The odometry
//! turns 1 % too much, so that the loops have something to close. The keyframes go to a
//! NOR flash stand-in ([`firmware_example::flash::SramFlash`]) in QEMU's SRAM beyond the
//! board's 128 KB, through the same `NorFlashStorage` a board's flash uses. At the end the
//! run's map image is drawn into a second stand-in (`GraphSlam::write_map_image`, what
//! the firmware's `SaveMap` does) and its instructions reported (`slam_map …`).
//!
//! Prints `slam …` lines on UART0 and exits through semihosting.
#![no_std]
#![no_main]

use core::fmt::Write;

use cortex_m_rt::entry;
use firmware_example::board::Serial;
use firmware_example::config::{GRID_PARTICLES, SLAM_CONFIG, SLAM_LOOPS, SLAM_NODES, Slam};
use firmware_example::cost::{BEAMS, LIDAR, RING_WAYPOINTS, Ticks, ring_range};
use firmware_example::flash::SramFlash;
use microslam::geometry::Pose2;
use microslam::sensors::lidar::LidarScan;
use microslam::slam::ClosureWork;
use microslam::slam::keyframes::{KeyframeStore, NorFlashStorage};
use panic_probe as _;
use static_cell::ConstStaticCell;

/// The estimator, zero bytes at reset (`.bss`).
static SLAM: ConstStaticCell<Slam> = ConstStaticCell::new(Slam::zeroed());

/// Bytes of the keyframe store: twice the board profile's 128 KB (606 keyframes), so that
/// the drive fills the graph's 640 nodes and the probe measures a full graph's solves (a
/// board's store refuses keyframes past 606: its graph never grows that large).
const STORE_BYTES: u32 = 2 * firmware_example::config::SLAM_KEYFRAME_BYTES;

/// Bytes of the map image's flash region (the board profile's).
const MAP_BYTES: u32 = firmware_example::config::SLAM_MAP_BYTES;

/// The odometry's heading error, as a fraction of each turn.
const TURN_SCALE_ERROR: f32 = 0.01;

/// Scans at most (a bound on the drive; the graph fills long before).
const MAX_SCANS: u32 = 20_000;

fn scan_at(pose: &Pose2<f32>, ranges: &mut [f32; BEAMS]) {
    for (i, r) in ranges.iter_mut().enumerate() {
        *r = ring_range(pose.x, pose.y, pose.theta + LIDAR.beam_angle(i));
    }
}

/// Cost of each scan (prediction + observation) over a drive that fills the graph.
#[derive(Default)]
struct Costs {
    scans: u32,
    total: u64,
    max: u64,
    /// The most a scan that tried a loop closure cost, and the most one that added a
    /// loop edge (and so solved the graph) cost.
    max_attempt: u64,
    max_closure: u64,
    /// The most a keyframe's scan cost.
    max_keyframe: u64,
    /// The most a scan cost, by the loop closure work it did ([`ClosureWork`]: none, the
    /// old map drawn, a slice of the match, the graph solved).
    max_by_work: [u64; 4],
    /// The most any other scan cost.
    max_other: u64,
    /// Scans over 10 M instructions (100 ms at 100 MHz).
    over_10m: u32,
}

fn run(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
    firmware_example::cost::report_calibration(out, ticks)?;
    let slam = SLAM.take();
    let Some(flash) = SramFlash::take(STORE_BYTES) else {
        return writeln!(out, "error slam flash stand-in");
    };
    let Ok(storage) = NorFlashStorage::new(flash, 0, STORE_BYTES) else {
        return writeln!(out, "error slam storage");
    };
    let Ok(mut store) = KeyframeStore::create(storage, &LIDAR, 1, BEAMS) else {
        return writeln!(out, "error slam store");
    };
    let (x0, y0) = RING_WAYPOINTS[0];
    let start = Pose2::new(x0, y0, 0.0);
    if slam.init(SLAM_CONFIG, start).is_err() {
        return writeln!(out, "error slam init");
    }
    let mut ranges = [0.0f32; BEAMS];
    let mut costs = Costs::default();
    let (mut truth, mut odometry) = (start, start);
    let mut leg = 1;
    while costs.scans < MAX_SCANS && (slam.graph().len() < SLAM_NODES) {
        // 10 cm along the corridor, or a turn of at most 0.2 rad towards the next corner.
        let (wx, wy) = RING_WAYPOINTS[leg % RING_WAYPOINTS.len()];
        let (dx, dy) = (wx - truth.x, wy - truth.y);
        if libm::hypotf(dx, dy) < 0.05 {
            leg += 1;
            continue;
        }
        let turn =
            microslam::geometry::wrap_angle(libm::atan2f(dy, dx) - truth.theta).clamp(-0.2, 0.2);
        let d = if turn.abs() > 0.15 {
            0.0
        } else {
            libm::hypotf(dx, dy).min(0.1)
        };
        let next = truth.compose(&Pose2::new(d, 0.0, turn));
        let next_odometry = odometry.compose(&Pose2::new(d, 0.0, turn * (1.0 + TURN_SCALE_ERROR)));
        scan_at(&next, &mut ranges);
        let scan = LidarScan::new(&ranges, LIDAR);
        let mut result = None;
        let n = ticks.instructions_long(|| {
            result = Some(
                slam.predict_odometry(&odometry, &next_odometry)
                    .and_then(|()| slam.observe(&scan, &mut store)),
            )
        });
        let Some(Ok(step)) = result else {
            return writeln!(out, "error slam step {}", costs.scans);
        };
        costs.scans += 1;
        costs.total += n;
        costs.over_10m += u32::from(n > 10_000_000);
        costs.max = costs.max.max(n);
        let kind = match step.work {
            ClosureWork::None => 0,
            ClosureWork::OldMap => 1,
            ClosureWork::Match => 2,
            ClosureWork::Solve => 3,
        };
        if let Some(m) = costs.max_by_work.get_mut(kind) {
            *m = (*m).max(n);
        }
        if step.keyframe.is_some() {
            costs.max_keyframe = costs.max_keyframe.max(n);
        } else {
            costs.max_other = costs.max_other.max(n);
        }
        if let Some(closure) = step.closure {
            costs.max_attempt = costs.max_attempt.max(n);
            if closure.accepted {
                costs.max_closure = costs.max_closure.max(n);
            }
        }
        (truth, odometry) = (next, next_odometry);
    }
    let c = slam.counters();
    let est = slam.pose();
    writeln!(
        out,
        "slam p={} beams={} nodes={} loops={} scans={} keyframes={} attempts={} closures={} mean={} max={} max_attempt={} max_closure={} max_keyframe={} max_other={} max_plain={} max_old_map={} max_match={} max_solve={} over_10m={} error_mm={}",
        GRID_PARTICLES,
        BEAMS,
        SLAM_NODES,
        SLAM_LOOPS,
        costs.scans,
        c.keyframes,
        c.attempts,
        c.closures,
        costs.total / u64::from(costs.scans.max(1)),
        costs.max,
        costs.max_attempt,
        costs.max_closure,
        costs.max_keyframe,
        costs.max_other,
        costs.max_by_work[0],
        costs.max_by_work[1],
        costs.max_by_work[2],
        costs.max_by_work[3],
        costs.over_10m,
        (libm::hypotf(est.x - truth.x, est.y - truth.y) * 1000.0) as u32
    )?;
    writeln!(out, "slam_bytes={}", core::mem::size_of::<Slam>())?;
    // The end of the run: the whole map drawn into a map image in a second flash region
    // (what `SaveMap` does on the SLAM firmware), with its graph full.
    let Some(map_flash) = SramFlash::take_map(MAP_BYTES) else {
        return writeln!(out, "error slam map flash stand-in");
    };
    let Ok(mut map_storage) = NorFlashStorage::new(map_flash, 0, MAP_BYTES) else {
        return writeln!(out, "error slam map storage");
    };
    let free_below = SLAM_CONFIG.grid.log_odds.free_below;
    let mut written = None;
    let n = ticks.instructions_long(|| {
        written = Some(slam.write_map_image(&store, &mut map_storage, free_below));
    });
    let Some(Ok(summary)) = written else {
        return writeln!(out, "error slam map image");
    };
    writeln!(
        out,
        "slam_map cells={}x{} tiles={} keyframes={} scans_drawn={} bytes={} instructions={}",
        summary.geometry.width,
        summary.geometry.height,
        summary.tiles,
        summary.keyframes,
        summary.scans_drawn,
        summary.bytes,
        n
    )?;
    firmware_example::cost::report_end(out)
}

#[entry]
fn main() -> ! {
    firmware_example::cost::run_and_halt(run)
}

firmware_example::hard_fault_halts!();
firmware_example::systick_counts_wraps!();
