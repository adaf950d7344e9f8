//! The firmware: the EKF and the grid estimator in `static`s, the serial protocol of `microslam::wire` on the
//! board's UART, estimates streamed back for every event.
#![no_std]
#![no_main]

use cortex_m_rt::{ExceptionFrame, entry, exception};
use firmware_example::config::{
    EKF_CONFIG, EKF_LANDMARKS, Ekf, GRID_CONFIG, GRID_PARTICLES, GRID_SETUP, Grid, GridEstimator,
    ZEROED_EKF_CONFIG,
};
use firmware_example::{board, serve, stack};
use microslam::geometry::Pose2;
use microslam::wire::Session;
use panic_probe as _;
use static_cell::{ConstStaticCell, StaticCell};

/// The EKF, zero bytes at reset (`.bss`), handed out once as `&'static mut`: the 18 KB
/// covariance never passes through the stack.
static EKF: ConstStaticCell<Ekf> = ConstStaticCell::new(Ekf::new(ZEROED_EKF_CONFIG));

/// The 64 KB occupancy grid, zero bytes at reset (`.bss`); its geometry is set in place.
static GRID: ConstStaticCell<Grid> = ConstStaticCell::new(Grid::zeroed());

/// The grid estimator (particles, scan points; ~2.5 KB), borrowing [`GRID`].
static GRID_SLAM: StaticCell<GridEstimator> = StaticCell::new();

#[entry]
fn main() -> ! {
    let (mut serial, mut led) = board::init();
    let ekf = EKF.take();
    let grid = GRID.take();
    if grid
        .init_centred(GRID_CONFIG.resolution, GRID_CONFIG.log_odds)
        .is_err()
    {
        defmt::error!("grid configuration invalid");
        board::halt(4)
    }
    let Ok(slam) = GridEstimator::new(grid, GRID_CONFIG, Pose2::new(0.0, 0.0, 0.0)) else {
        defmt::error!("grid estimator configuration invalid");
        board::halt(4)
    };
    let slam = GRID_SLAM.init(slam);
    let mut session = Session::<_, _, EKF_LANDMARKS>::with_grid(ekf, EKF_CONFIG, slam, GRID_SETUP);
    defmt::info!("grid estimator: {} particles", GRID_PARTICLES);
    defmt::info!(
        "microslam firmware: EKF with {} landmarks, waiting for frames",
        EKF_LANDMARKS
    );
    serve(&mut session, &mut serial, &mut led, stack::peak_bytes)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!("HardFault at pc = {:#010x}", frame.pc());
    board::halt(3)
}
