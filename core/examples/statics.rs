//! Every estimator in a `static`, as a firmware holds them: built at compile time or in
//! place, handed out once as `&'static mut`, never passed by value through the stack.
//!
//! - `EkfSlam::new` is a `const fn`: the whole filter (18 KB at 32 landmarks) is the
//!   static's initial value. With `EkfConfig::DEFAULT_F32` that value has non-zero bytes,
//!   so it goes to `.data` (its image costs flash); built from an all-zero `EkfConfig`
//!   instead, it goes to `.bss` and `EkfSlam::init` sets the real settings in place
//!   (`firmware-example/src/config.rs`, `ZEROED_EKF_CONFIG`).
//! - `OccupancyGrid::zeroed()` is all zero bytes (`.bss`, no flash), and `init_centred`
//!   sets its geometry in place: the 64 KB grid never moves.
//! - `GridSlam` and `GridLocalizer` borrow their map and are small (`28·P + 24·B` bytes
//!   plus ~100): `StaticCell::init_with` builds each once at start-up.
//!
//! `static_cell` hands each static out exactly once (a second `take` panics), so no
//! `static mut` and no `unsafe` are needed. The same code runs on a Cortex-M.
//!
//! Run: `cargo run -p microslam --example statics`

#[path = "support/room.rs"]
mod room;

use microslam::association::{KnownIds, observe_known};
use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::grid::{GridGeometry, GridView, OccupancyGrid};
use microslam::pf::{GridLocalizer, GridPfConfig, GridSlam};
use microslam::sensors::lidar::LidarScan;
use microslam::sensors::range_bearing::RangeBearing;
use static_cell::{ConstStaticCell, StaticCell};

const LANDMARKS: usize = 32;
type Ekf = EkfSlam<f32, { state_dim(LANDMARKS) }, { factor_len(LANDMARKS) }>;
type Grid = OccupancyGrid<256, 256>;
const P: usize = 32;
const GRID_CONFIG: GridPfConfig = GridPfConfig::MICROCONTROLLER;

/// The landmark EKF, built at compile time.
static EKF: ConstStaticCell<Ekf> = ConstStaticCell::new(Ekf::new(EkfConfig::DEFAULT_F32));
/// Its id table (marker id → landmark slot).
static IDS: ConstStaticCell<KnownIds<LANDMARKS>> = ConstStaticCell::new(KnownIds::new());
/// The 64 KB grid, zero bytes until `init_centred`.
static GRID: ConstStaticCell<Grid> = ConstStaticCell::new(Grid::zeroed());
/// Grid SLAM, borrowing [`GRID`] for ever.
static GRID_SLAM: StaticCell<GridSlam<'static, 256, 256, P, { room::BEAMS }>> = StaticCell::new();
/// A map in flash, and the localizer on it.
static MAP: [i8; room::MAP_SIZE * room::MAP_SIZE] = room::map(GRID_CONFIG.log_odds.max);
static LOCALIZER: StaticCell<GridLocalizer<'static, P, { room::BEAMS }>> = StaticCell::new();

fn main() {
    if let Err(e) = run() {
        eprintln!("statics: {e}");
        std::process::exit(1);
    }
}

/// What start-up and one step of each estimator produced: the EKF's landmark count and
/// the two grid filters' poses.
fn run() -> Result<(usize, [f32; 2], [f32; 2]), String> {
    // The landmark EKF: take it once, then step it through the reference.
    let ekf: &'static mut Ekf = EKF.take();
    let ids = IDS.take();
    ekf.predict_velocity(0.2, 0.0, 0.1)
        .map_err(|e| e.to_string())?;
    observe_known(ekf, ids, 42, &RangeBearing::new(2.0, 0.3)).map_err(|e| e.to_string())?;

    // Grid SLAM: the grid gets its geometry in place, the filter is built once.
    let grid: &'static mut Grid = GRID.take();
    grid.init_centred(GRID_CONFIG.resolution, GRID_CONFIG.log_odds)
        .map_err(|e| e.to_string())?;
    let slam = GridSlam::new(grid, GRID_CONFIG, room::START).map_err(|e| e.to_string())?;
    let slam = GRID_SLAM.init_with(|| slam);
    let ranges = room::scan(&room::START);
    let first = slam
        .observe(&LidarScan::new(&ranges, room::LIDAR))
        .map_err(|e| e.to_string())?;

    // The localizer on the map in flash (a `&'static` view: nothing copied).
    let geometry = GridGeometry::centred(room::MAP_SIZE, room::MAP_SIZE, room::MAP_RESOLUTION);
    let map = GridView::new(&MAP, geometry, GRID_CONFIG.log_odds.occupied_above)
        .map_err(|e| e.to_string())?;
    let localizer = GridLocalizer::new(map, GRID_CONFIG, room::START).map_err(|e| e.to_string())?;
    let localizer = LOCALIZER.init_with(|| localizer);
    let located = localizer
        .observe(&LidarScan::new(&ranges, room::LIDAR))
        .map_err(|e| e.to_string())?;

    println!(
        "EKF: {} B in a static, {} landmark(s); grid: {} B in a static, SLAM: {} B, \
         localizer: {} B; first scan: SLAM at ({:.2}, {:.2}), localizer at ({:.2}, {:.2})",
        size_of::<Ekf>(),
        ekf.landmark_count(),
        size_of::<Grid>(),
        size_of::<GridSlam<'static, 256, 256, P, { room::BEAMS }>>(),
        size_of::<GridLocalizer<'static, P, { room::BEAMS }>>(),
        first.pose.x,
        first.pose.y,
        located.pose.x,
        located.pose.y,
    );
    Ok((
        ekf.landmark_count(),
        [first.pose.x, first.pose.y],
        [located.pose.x, located.pose.y],
    ))
}

#[cfg(test)]
mod tests {
    #[test]
    fn every_static_is_handed_out_and_steps() {
        let (landmarks, slam, localizer) = super::run().expect("start-up succeeds");
        assert_eq!(landmarks, 1);
        // The first scan builds the map at the start pose; the localizer's first scan
        // scores the particles, all at the true start, against the exact map.
        let start = [super::room::START.x, super::room::START.y];
        assert_eq!(slam, start);
        assert!((localizer[0] - start[0]).hypot(localizer[1] - start[1]) <= 0.05);
    }
}
