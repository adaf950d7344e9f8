//! The firmware: the EKF and a grid estimator in `static`s, the serial protocol of
//! `microslam::wire` on the board's UART, estimates streamed back for every event.
//!
//! Built without a map it carries the grid SLAM (its 64 KB grid in RAM); built with
//! `MICROSLAM_MAP=<map.yaml>` it carries the localizer on the map image in flash instead,
//! checked at boot: a bad image is reported to the host (`Refusal::BadMap`) when it asks
//! for the localizer, never a fault. With the feature `building-slam` (QEMU) it carries
//! the building-scale grid SLAM with loop closure (`profile::Slam`, 112 KB) as its grid
//! estimator, its keyframes in the flash stand-in, beside a 4-landmark EKF.
#![no_std]
#![no_main]

#[cfg(all(feature = "building-slam", microslam_map))]
compile_error!("`building-slam` carries the grid SLAM: build it without MICROSLAM_MAP");
#[cfg(all(feature = "building-slam", not(feature = "qemu")))]
compile_error!(
    "`building-slam` keeps its keyframes in QEMU's flash stand-in: a board needs its flash \
     driver wired in first"
);

use cortex_m_rt::entry;
use firmware_example::config::{EKF_CONFIG, GRID_SETUP, ZEROED_EKF_CONFIG};
#[cfg(not(feature = "building-slam"))]
use firmware_example::config::{EKF_LANDMARKS, Ekf};
#[cfg(feature = "building-slam")]
use firmware_example::config::{SLAM_EKF_LANDMARKS as EKF_LANDMARKS, SlamEkf as Ekf};
use firmware_example::{board, serve, stack};
use microslam::device::Session;
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
#[cfg(not(any(microslam_map, feature = "building-slam")))]
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
    use microslam::device::LocalizerEstimator;
    use microslam::geometry::Pose2;
    use microslam::grid::{MapImage, MapImageError};
    use microslam::wire::Refusal;
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

/// The building-scale grid SLAM with loop closure (feature `building-slam`).
#[cfg(feature = "building-slam")]
mod grid {
    use super::*;
    use firmware_example::config::{
        SLAM_CONFIG, SLAM_KEYFRAME_BYTES, SLAM_MAP_BYTES, SLAM_NODES, Slam, SlamEstimator,
    };
    use firmware_example::flash::SramFlash;
    use microslam::geometry::Pose2;
    use microslam::slam::keyframes::NorFlashStorage;
    use static_cell::StaticCell;

    /// The estimator (maps, pose graph, workspace: 112 KB), all zero bytes (`.bss`: no
    /// initial image in flash), handed out once.
    static SLAM: ConstStaticCell<Slam> = ConstStaticCell::new(Slam::zeroed());

    /// Where its keyframes and its map image go: the flash stand-ins.
    type Storage = NorFlashStorage<SramFlash>;

    /// The SLAM with its keyframe storage, as the session's grid estimator.
    static ESTIMATOR: StaticCell<SlamEstimator<'static, Storage>> = StaticCell::new();

    /// The session with the small EKF and the building-scale SLAM; localizer requests
    /// are refused (no map).
    pub fn session(ekf: &'static mut Ekf) -> FirmwareSession {
        let Some(flash) = SramFlash::take(SLAM_KEYFRAME_BYTES) else {
            defmt::error!("flash stand-in taken");
            board::halt(4)
        };
        let Ok(storage) = Storage::new(flash, 0, SLAM_KEYFRAME_BYTES) else {
            defmt::error!("keyframe storage refused");
            board::halt(4)
        };
        let Some(map_flash) = SramFlash::take_map(SLAM_MAP_BYTES) else {
            defmt::error!("map flash stand-in taken");
            board::halt(4)
        };
        let Ok(map_storage) = Storage::new(map_flash, 0, SLAM_MAP_BYTES) else {
            defmt::error!("map storage refused");
            board::halt(4)
        };
        let Ok(slam) =
            SlamEstimator::new(SLAM.take(), storage, SLAM_CONFIG, Pose2::new(0.0, 0.0, 0.0))
        else {
            defmt::error!("building-scale SLAM configuration invalid");
            board::halt(4)
        };
        // `SaveMap` writes the run's map image here, `ReadMap` reads it back.
        let slam = slam.with_map_storage(map_storage);
        defmt::info!(
            "building-scale grid SLAM: {} keyframes, {} bytes of keyframe flash",
            SLAM_NODES,
            SLAM_KEYFRAME_BYTES
        );
        Session::with_grid(ekf, EKF_CONFIG, ESTIMATOR.init(slam), GRID_SETUP)
    }
}

firmware_example::hard_fault_halts!();
