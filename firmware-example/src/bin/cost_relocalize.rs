//! Instructions per global relocalization under QEMU `-icount shift=6` (see
//! `firmware_example::cost`): a localizer with no pose (P = 64, 90 beams,
//! `RelocalizationConfig::DEFAULT`) on a 256 × 256 map of 5 cm cells — the 6 m × 6 m room
//! with a pillar of `cost_grid` — takes one scan, which runs the global search over the
//! whole map (branch and bound over 6 max-pooled levels) and seeds the particles. The
//! localizer reads the map as the localizer firmware does: its occupied-cell bitmap and
//! the layers (a map image, `GridView::from_occupancy_bits`), no log-odds cells; both are
//! built at start-up into RAM from the cells in flash. A separate binary from `cost_grid`:
//! its 52 KB of layers and `cost_grid`'s 72 KB grid do not fit 128 KB of RAM together.
//!
//! Then the worst cases of the work budget: the same scan searched with every minimum
//! score at 0, so nothing is pruned by score and the budget stops the search, with the
//! default 30 beams and with 45.
//!
//! SysTick wraps every 2²⁴ ticks (≈ 10 M instructions): its exception counts the wraps.
//! Prints one line on UART0 and exits through semihosting.
#![no_std]
#![no_main]

use core::fmt::Write;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::SYST;
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use firmware_example::board::{self, Serial};
use firmware_example::cost::{BEAMS, LIDAR, room_range};
use microslam::geometry::Pose2;
use microslam::grid::{
    GridGeometry, GridView, MaxPoolLayers, fill_occupancy_bits, occupancy_bytes,
};
use microslam::pf::global::GlobalSearchConfig;
use microslam::pf::{GridLocalizer, GridPfConfig, RelocalizationConfig};
use microslam::sensors::lidar::LidarScan;
use panic_probe as _;
use static_cell::ConstStaticCell;

const PARTICLES: usize = 64;
const CELLS: usize = 256;
const RESOLUTION: f32 = 0.05;
const LEVELS: u8 = 6;
const CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;
const LAYER_BYTES: usize = match MaxPoolLayers::bytes_for(CELLS, CELLS, LEVELS) {
    Some(n) => n,
    None => 0,
};

/// Log-odds of the cell whose centre is `(x, y)`: walls of the room `[-3, 3]²` and the
/// pillar `[1, 1.6] × [-0.5, 0.5]` (one cell thick) occupied, their inside free, the rest
/// unknown.
const fn room_cell(x: f32, y: f32) -> i8 {
    let h = RESOLUTION;
    let (ax, ay) = (if x < 0.0 { -x } else { x }, if y < 0.0 { -y } else { y });
    let room = if ax > ay { ax } else { ay };
    let in_pillar = x >= 1.0 && x <= 1.6 && y >= -0.5 && y <= 0.5;
    let pillar_inner = x >= 1.0 + h && x <= 1.6 - h && y >= -0.5 + h && y <= 0.5 - h;
    let wall = room >= 3.0 - h / 2.0 && room <= 3.0 + h;
    if wall || (in_pillar && !pillar_inner) {
        100
    } else if room < 3.0 && !in_pillar {
        -100
    } else {
        0
    }
}

const fn room_map() -> [i8; CELLS * CELLS] {
    let mut cells = [0i8; CELLS * CELLS];
    let origin = -(CELLS as f32) * RESOLUTION * 0.5;
    let mut i = 0;
    while i < CELLS * CELLS {
        let x = origin + ((i % CELLS) as f32 + 0.5) * RESOLUTION;
        let y = origin + ((i / CELLS) as f32 + 0.5) * RESOLUTION;
        cells[i] = room_cell(x, y);
        i += 1;
    }
    cells
}

/// The map, in flash.
static MAP: [i8; CELLS * CELLS] = room_map();

/// The max-pooled layers, built at start-up.
static LAYERS: ConstStaticCell<[u8; LAYER_BYTES]> = ConstStaticCell::new([0; LAYER_BYTES]);

/// The occupied-cell bitmap, built at start-up (8 KB).
static BITS: ConstStaticCell<[u8; occupancy_bytes(CELLS, CELLS)]> =
    ConstStaticCell::new([0; occupancy_bytes(CELLS, CELLS)]);

static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// Instructions of `f` (ticks · 40 / 64 as in `firmware_example::cost`, wraps counted).
fn instructions(f: impl FnOnce()) -> u64 {
    const RELOAD: u32 = 0x00FF_FFFF;
    WRAPS.store(0, Ordering::Relaxed);
    // SAFETY: reading SysTick's current value register has no side effect.
    let start = SYST::get_current();
    f();
    let end = SYST::get_current();
    let wraps = u64::from(WRAPS.load(Ordering::Relaxed));
    let ticks = wraps * (u64::from(RELOAD) + 1) + u64::from(start) - u64::from(end);
    ticks * 40 / 64
}

fn run(out: &mut Serial) -> core::fmt::Result {
    // The wrap counting checked on a known count: 30 000 × 1000 nops (3 wraps).
    let nops = instructions(|| {
        for _ in 0..30_000 {
            firmware_example::cost::thousand_nops();
        }
    });
    writeln!(out, "calibration nops=30000000 instructions={nops}")?;
    let geometry = GridGeometry::centred(CELLS, CELLS, RESOLUTION);
    let Ok(map) = GridView::new(&MAP, geometry, CONFIG.log_odds.occupied_above) else {
        return writeln!(out, "error map");
    };
    let buffer = LAYERS.take();
    let mut layers = None;
    let build = instructions(|| {
        layers = MaxPoolLayers::build(&map, CONFIG.log_odds.free_below, LEVELS, buffer).ok();
    });
    let Some(layers) = layers else {
        return writeln!(out, "error layers");
    };
    // The map image the localizer firmware holds: the bitmap and the layers, no cells.
    let bits = BITS.take();
    let occupied_above = CONFIG.log_odds.occupied_above;
    if fill_occupancy_bits(&MAP, CELLS, CELLS, occupied_above, bits).is_err() {
        return writeln!(out, "error bitmap");
    }
    let bits: &'static [u8] = bits;
    let Ok(image) = GridView::from_occupancy_bits(bits, geometry, occupied_above) else {
        return writeln!(out, "error bitmap view");
    };
    let truth = Pose2::new(-1.3, 1.1, 2.0);
    let mut ranges = [0.0f32; BEAMS];
    for (i, r) in ranges.iter_mut().enumerate() {
        let a = truth.theta + LIDAR.beam_angle(i);
        *r = room_range(truth.x, truth.y, a);
    }
    // As the localizer firmware: the shift search compiled for the map's bitmap rows.
    let Ok(Ok(mut loc)) = GridLocalizer::<PARTICLES, BEAMS>::without_pose(
        image,
        CONFIG,
        layers,
        RelocalizationConfig::DEFAULT,
    )
    .map(|l| l.with_bitmap_row_bytes::<{ occupancy_bytes(CELLS, 1) }>()) else {
        return writeln!(out, "error localizer");
    };
    let scan = LidarScan::new(&ranges, LIDAR);
    let mut report = None;
    let relocalize = instructions(|| report = Some(loc.observe(&scan)));
    let Some(Ok(step)) = report else {
        return writeln!(out, "error relocalization step");
    };
    let status = loc.status();
    let search = status.last_search;
    let err = libm::hypotf(step.pose.x - truth.x, step.pose.y - truth.y);
    writeln!(
        out,
        "relocalize cells={} levels={} particles={} beams={} instructions={} layers_build={} nodes={} work={} headings={} complete={} relocalizations={} error_mm={} view=bitmap",
        CELLS,
        LEVELS,
        PARTICLES,
        BEAMS,
        relocalize,
        build,
        search.map_or(0, |s| s.nodes),
        search.map_or(0, |s| s.work),
        search.map_or(0, |s| s.headings),
        search.is_some_and(|s| s.complete),
        status.relocalizations,
        (err * 1000.0) as u32
    )?;
    // The worst cases the work budget allows: the same scan with nothing pruned by score
    // (every minimum score 0), so the search runs until the budget stops it; on one scan
    // (`search_scans` 1), which then also starts the search, seeds the particles and
    // filters: more than any scan of a search spanning scans spends. Every node looks at
    // all its beams: with the default 30, and with 45, the most a unit of work was
    // measured to cost (1 to 45 beams, docs/global-localization.md).
    for (name, max_beams) in [
        (
            "relocalize_budget",
            RelocalizationConfig::DEFAULT.search.max_beams,
        ),
        ("relocalize_budget_b45", 45),
    ] {
        let exhaustive = RelocalizationConfig {
            search: GlobalSearchConfig {
                min_score_fraction: 0.0,
                first_pass_fraction: 0.0,
                relative_score: 0.0,
                max_beams,
                ..RelocalizationConfig::DEFAULT.search
            },
            search_scans: 1,
            ..RelocalizationConfig::DEFAULT
        };
        let Ok(Ok(mut loc)) =
            GridLocalizer::<PARTICLES, BEAMS>::without_pose(image, CONFIG, layers, exhaustive)
                .map(|l| l.with_bitmap_row_bytes::<{ occupancy_bytes(CELLS, 1) }>())
        else {
            return writeln!(out, "error localizer");
        };
        let mut report = None;
        let worst = instructions(|| report = Some(loc.observe(&scan)));
        if !matches!(report, Some(Ok(_))) {
            return writeln!(out, "error exhaustive relocalization step");
        }
        let search = loc.status().last_search;
        writeln!(
            out,
            "{} cells={} beams={} nodes={} work={} budget={} complete={} instructions={} view=bitmap",
            name,
            CELLS,
            search.map_or(0, |s| s.beams),
            search.map_or(0, |s| s.nodes),
            search.map_or(0, |s| s.work),
            exhaustive.search.work_budget,
            search.is_some_and(|s| s.complete),
            worst,
        )?;
    }
    firmware_example::cost::report_end(out)
}

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        board::halt(2)
    };
    let (mut out, _led) = board::init();
    let mut syst = cp.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    // SAFETY: the only interrupt handler is SysTick's counter increment.
    unsafe { cortex_m::interrupt::enable() };
    let code = if run(&mut out).is_ok() { 0 } else { 1 };
    let _ = embedded_io::Write::flush(&mut out);
    board::halt(code)
}

firmware_example::hard_fault_halts!();
