//! Instructions per grid particle-filter step under QEMU `-icount shift=6` (see
//! `firmware_example::cost`): grid SLAM at P = 16, 32, 64 particles, 90 beams, 9 × 9
//! shift window, a 256 × 256 grid of 5 cm cells, in a synthetic 6 m × 6 m room with a
//! pillar; then the localizer (no map writes, the firmware's `LOCALIZER_CONFIG`: a 3 × 3
//! window) at P = 32, 64, 128 on the map the SLAM runs built, read through its
//! occupied-cell bitmap alone (as a map image in flash is).
//!
//! Built with `MICROSLAM_MAP` (the map image in flash, `cfg(microslam_map)`), it times
//! the localizer on that map instead (`localizer_map` lines): the scans are ray-cast in
//! the map itself from the map frame's origin (the first pose of the run that built it)
//! along the same arc, so the end points meet the map's real walls (and once more at
//! P = 64 with grid SLAM's 9 × 9 window, for comparison). A room map built
//! from nine scans has thin walls and many windows without an occupied cell; a map of a
//! whole run has the walls a robot meets, and its step costs what a robot pays.
//!
//! Prints one line per P on UART0 and exits through semihosting.
#![no_std]
#![no_main]

use core::fmt::Write;

use cortex_m_rt::entry;
use firmware_example::board::Serial;
use firmware_example::config::LOCALIZER_CONFIG;
use firmware_example::cost::{BEAMS, LIDAR, Ticks, report_calibration};
use microslam::device::GridEstimator;
use microslam::geometry::Pose2;
use microslam::grid::GridView;
use microslam::pf::{GridLocalizer, GridPfConfig};
use microslam::sensors::lidar::LidarScan;
use panic_probe as _;

/// Grid SLAM's settings (the firmware's `GRID_CONFIG`).
const CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// Steps measured per P (after the first scan, which only builds the map).
const STEPS: u32 = 8;

/// What a [`drive`] line names: the filter, its particle count and its settings.
struct Label<'a> {
    what: &'a str,
    particles: usize,
    config: &'a GridPfConfig,
}

/// Drives `filter` from `start` for [`STEPS`] steps of an arc, with the scans `scan_at`
/// gives at each true pose, counting the instructions of each prediction and scan, and
/// prints one line named by `label` with their means.
fn drive<F: GridEstimator>(
    out: &mut Serial,
    ticks: &mut Ticks,
    label: Label<'_>,
    filter: &mut F,
    start: Pose2<f32>,
    scan_at: impl Fn(&Pose2<f32>, &mut [f32; BEAMS]),
) -> core::fmt::Result {
    let Label {
        what,
        particles,
        config,
    } = label;
    let mut truth = start;
    let mut ranges = [0.0f32; BEAMS];
    let (v, omega, dt) = (0.4f32, 0.3f32, 0.1f32);
    let (mut predict, mut observe, mut resamples) = (0u32, 0u32, 0u32);
    for _ in 0..STEPS {
        truth = Pose2::new(
            truth.x + v * dt * libm::cosf(truth.theta),
            truth.y + v * dt * libm::sinf(truth.theta),
            truth.theta + omega * dt,
        );
        let mut r = Ok(());
        predict += ticks.instructions(|| r = filter.predict_velocity(v, omega, dt));
        scan_at(&truth, &mut ranges);
        let scan = LidarScan::new(&ranges, LIDAR);
        let mut report = None;
        observe += ticks.instructions(|| report = Some(filter.observe(&scan)));
        match (r, report) {
            (Ok(()), Some(Ok(rep))) => resamples += u32::from(rep.resampled),
            _ => return writeln!(out, "error {what} p={particles} step"),
        }
    }
    let est = filter.pose();
    writeln!(
        out,
        "{} p={} beams={} window={} step={} predict={} observe={} resamples={} error_mm={}",
        what,
        particles,
        BEAMS,
        2 * config.filter.shift_window_cells + 1,
        (predict + observe) / STEPS,
        predict / STEPS,
        observe / STEPS,
        resamples,
        (libm::hypotf(est.x - truth.x, est.y - truth.y) * 1000.0) as u32
    )
}

/// The synthetic room: grid SLAM, then the localizer on the map it built.
#[cfg(not(microslam_map))]
mod room {
    use super::*;
    use firmware_example::cost::room_range;
    use microslam::grid::{OccupancyGrid, occupancy_bytes};
    use microslam::pf::GridSlam;
    use static_cell::ConstStaticCell;

    type Grid = OccupancyGrid<256, 256, { occupancy_bytes(256, 256) }>;

    static GRID: ConstStaticCell<Grid> = ConstStaticCell::new(Grid::zeroed());

    /// Where every drive starts (the filters are started there too).
    const START: Pose2<f32> = Pose2::new(-1.0, -1.0, 0.3);

    fn scan_at(pose: &Pose2<f32>, ranges: &mut [f32; BEAMS]) {
        for (i, r) in ranges.iter_mut().enumerate() {
            let a = pose.theta + LIDAR.beam_angle(i);
            *r = room_range(pose.x, pose.y, a);
        }
    }

    /// Grid SLAM's step: the map of the first scan at [`START`], then [`drive`].
    fn measure<const P: usize>(
        out: &mut Serial,
        ticks: &mut Ticks,
        grid: &mut Grid,
    ) -> core::fmt::Result {
        let Ok(mut slam) =
            GridSlam::<256, 256, P, BEAMS, { occupancy_bytes(256, 256) }>::new(grid, CONFIG, START)
        else {
            return writeln!(out, "error grid p={P} new");
        };
        let mut ranges = [0.0f32; BEAMS];
        scan_at(&START, &mut ranges);
        if slam.observe(&LidarScan::new(&ranges, LIDAR)).is_err() {
            return writeln!(out, "error grid p={P} first scan");
        }
        let label = Label {
            what: "grid",
            particles: P,
            config: &CONFIG,
        };
        drive(out, ticks, label, &mut slam, START, scan_at)
    }

    /// The localizer's step (prediction + scan) on `map`, started at the true pose, along the
    /// same drive as [`measure`].
    fn measure_localizer<const P: usize>(
        out: &mut Serial,
        ticks: &mut Ticks,
        map: GridView<'_>,
    ) -> core::fmt::Result {
        // The room's 256-cell rows: 32 bytes of bitmap (as a firmware with a map of this
        // size in flash compiles it).
        let Ok(mut loc) = GridLocalizer::<P, BEAMS>::new(map, LOCALIZER_CONFIG, START)
            .and_then(|l| l.with_bitmap_row_bytes::<{ occupancy_bytes(256, 1) }>())
        else {
            return writeln!(out, "error localizer p={P} new");
        };
        let label = Label {
            what: "localizer",
            particles: P,
            config: &LOCALIZER_CONFIG,
        };
        drive(out, ticks, label, &mut loc, START, scan_at)
    }

    pub fn run(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
        report_calibration(out, ticks)?;
        let grid = GRID.take();
        if grid
            .init_centred(CONFIG.resolution, CONFIG.log_odds)
            .is_err()
        {
            return writeln!(out, "error grid init");
        }
        measure::<16>(out, ticks, grid)?;
        measure::<32>(out, ticks, grid)?;
        measure::<64>(out, ticks, grid)?;
        // The map the last SLAM run built, as the bitmap alone (a map image's view).
        let view = grid.view();
        let Some(bits) = view.occupancy_bits() else {
            return writeln!(out, "error grid has no bitmap");
        };
        let Ok(map) = GridView::from_occupancy_bits(bits, *view.geometry(), view.occupied_above())
        else {
            return writeln!(out, "error localizer map");
        };
        measure_localizer::<32>(out, ticks, map)?;
        measure_localizer::<64>(out, ticks, map)?;
        measure_localizer::<128>(out, ticks, map)?;
        firmware_example::cost::report_end(out)
    }
}

/// The map image in flash (`MICROSLAM_MAP`).
#[cfg(microslam_map)]
mod flash_map {
    use super::*;
    use microslam::grid::MapImage;

    /// The localizer's step with `config` on the map image in flash, started at the map
    /// frame's origin, with scans ray-cast in the map (see the module documentation).
    fn measure_flash_map<const P: usize>(
        out: &mut Serial,
        ticks: &mut Ticks,
        map: GridView<'_>,
        config: &GridPfConfig,
    ) -> core::fmt::Result {
        let start = Pose2::new(0.0, 0.0, 0.0);
        let Ok(mut loc) = GridLocalizer::<P, BEAMS>::new(map, *config, start)
            .and_then(|l| l.with_bitmap_row_bytes::<{ firmware_example::config::MAP_ROW_BYTES }>())
        else {
            return writeln!(out, "error localizer_map p={P} new");
        };
        let cast = |pose: &Pose2<f32>, ranges: &mut [f32; BEAMS]| {
            for (i, r) in ranges.iter_mut().enumerate() {
                let a = pose.theta + LIDAR.beam_angle(i);
                *r = map
                    .ray_range(pose.x, pose.y, a, LIDAR.max_range)
                    .unwrap_or(f32::INFINITY);
            }
        };
        let label = Label {
            what: "localizer_map",
            particles: P,
            config,
        };
        drive(out, ticks, label, &mut loc, start, cast)
    }

    pub fn run(out: &mut Serial, ticks: &mut Ticks) -> core::fmt::Result {
        report_calibration(out, ticks)?;
        let Ok(image) = MapImage::parse(firmware_example::config::MAP_IMAGE) else {
            return writeln!(out, "error map image refused");
        };
        let map = image.view();
        let g = map.geometry();
        writeln!(out, "map cells={}x{}", g.width, g.height)?;
        measure_flash_map::<32>(out, ticks, map, &LOCALIZER_CONFIG)?;
        measure_flash_map::<64>(out, ticks, map, &LOCALIZER_CONFIG)?;
        measure_flash_map::<128>(out, ticks, map, &LOCALIZER_CONFIG)?;
        // For comparison: the same at P = 64 with grid SLAM's 9 × 9 window.
        measure_flash_map::<64>(out, ticks, map, &CONFIG)?;
        firmware_example::cost::report_end(out)
    }
}

#[cfg(not(microslam_map))]
use room::run;

#[cfg(microslam_map)]
use flash_map::run;

#[entry]
fn main() -> ! {
    firmware_example::cost::run_and_halt(run)
}

firmware_example::hard_fault_halts!();
