//! The firmware: the EKF and a grid estimator in `static`s, the serial protocol of
//! `microslam::wire` on the board's UART, estimates streamed back for every event.
//!
//! Built without a map it carries the grid SLAM (its 64 KB grid in RAM); built with
//! `MICROSLAM_MAP=<map.yaml>` it carries the localizer on the map image in flash instead,
//! checked at boot: a bad image is reported to the host (`Refusal::BadMap`) when it asks
//! for the localizer, never a fault.
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use firmware_example::config::{EKF_CONFIG, EKF_LANDMARKS, Ekf, GRID_SETUP, ZEROED_EKF_CONFIG};
use firmware_example::{board, serve, stack};
use microslam::wire::Session;
use panic_probe as _;
use static_cell::ConstStaticCell;

/// The EKF, zero bytes at reset (`.bss`), handed out once as `&'static mut`: the 35 KB
/// covariance factor never passes through the stack.
static EKF: ConstStaticCell<Ekf> = ConstStaticCell::new(Ekf::new(ZEROED_EKF_CONFIG));

/// The session type of this firmware.
type FirmwareSession = Session<
    'static,
    { microslam::ekf::state_dim(EKF_LANDMARKS) },
    { microslam::ekf::factor_len(EKF_LANDMARKS) },
    EKF_LANDMARKS,
>;

#[entry]
fn main() -> ! {
    let (mut serial, mut led) = board::init();
    let mut session = grid::session(EKF.take());
    defmt::info!(
        "microslam firmware: EKF with {} landmarks, waiting for frames",
        EKF_LANDMARKS
    );
    serve(&mut session, &mut serial, &mut led, stack::peak_bytes)
}

/// The grid SLAM (firmware built without a map).
#[cfg(not(microslam_map))]
mod grid {
    use super::*;
    use firmware_example::config::{GRID_CONFIG, GRID_PARTICLES, Grid, GridEstimator};
    use microslam::geometry::Pose2;
    use static_cell::StaticCell;

    /// The 64 KB occupancy grid, zero bytes at reset (`.bss`); its geometry is set in place.
    static GRID: ConstStaticCell<Grid> = ConstStaticCell::new(Grid::zeroed());

    /// The grid estimator (particles, scan points; ~2.5 KB), borrowing [`GRID`].
    static GRID_SLAM: StaticCell<GridEstimator<'static>> = StaticCell::new();

    /// The session with the EKF and the grid SLAM; localizer requests are refused (no map).
    pub fn session(ekf: &'static mut Ekf) -> FirmwareSession {
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
        defmt::info!("grid estimator: {} particles", GRID_PARTICLES);
        Session::with_grid(ekf, EKF_CONFIG, GRID_SLAM.init(slam), GRID_SETUP)
    }
}

/// The localizer on the map in flash (firmware built with `MICROSLAM_MAP`).
#[cfg(microslam_map)]
mod grid {
    use super::*;
    use firmware_example::config::{
        LOCALIZER_CONFIG, LOCALIZER_PARTICLES, Localizer, MAP_IMAGE, MAP_ROW_BYTES, RELOCALIZATION,
    };
    use microslam::geometry::Pose2;
    use microslam::grid::{MapImage, MapImageError};
    use microslam::wire::{LocalizerEstimator, Refusal};
    use static_cell::StaticCell;

    /// The localizer (particles, scan points), borrowing the map image in flash.
    static LOCALIZER: StaticCell<Localizer<'static>> = StaticCell::new();

    /// The session with the EKF and the localizer, or with the reason the map was refused.
    pub fn session(ekf: &'static mut Ekf) -> FirmwareSession {
        let image = MapImage::parse(MAP_IMAGE);
        let checksum = image.as_ref().ok().map(|image| image.checksum());
        let localizer = match image {
            Ok(image) => {
                let g = image.geometry();
                defmt::info!(
                    "map: {} x {} cells of {} m, {} bytes, crc {:#010x}",
                    g.width,
                    g.height,
                    g.resolution,
                    image.len_bytes(),
                    image.checksum()
                );
                // The shift search compiled for this map's bitmap rows (build.rs).
                let Ok(localizer) =
                    Localizer::new(image.view(), LOCALIZER_CONFIG, Pose2::new(0.0, 0.0, 0.0))
                        .and_then(|l| l.with_bitmap_row_bytes::<MAP_ROW_BYTES>())
                else {
                    defmt::error!(
                        "localizer configuration invalid, or map rows not {}",
                        MAP_ROW_BYTES
                    );
                    board::halt(4)
                };
                // With the map's layers it can search the whole map (Relocalize, lost).
                match image.layers() {
                    None => Ok(LOCALIZER.init(localizer) as &mut dyn LocalizerEstimator),
                    Some(Ok(layers)) => match localizer.with_layers(layers, RELOCALIZATION) {
                        Ok(l) => Ok(LOCALIZER.init(l) as &mut dyn LocalizerEstimator),
                        Err(_) => Err(Refusal::BadMap {
                            code: MapImageError::BadLayers as u8,
                        }),
                    },
                    Some(Err(e)) => Err(Refusal::BadMap { code: e as u8 }),
                }
            }
            Err(e) => {
                defmt::error!("map image refused: {}", e);
                Err(Refusal::BadMap { code: e as u8 })
            }
        };
        defmt::info!("localizer: {} particles", LOCALIZER_PARTICLES);
        Session::new(ekf, EKF_CONFIG)
            .with_localizer(localizer, GRID_SETUP)
            .with_map_checksum(checksum)
    }
}

firmware_example::hard_fault_halts!();
