//! The firmware: the EKF and a grid estimator in `static`s, the serial protocol of
//! `microslam::wire` on the board's UART, estimates streamed back for every event.
//!
//! Built without a map it carries the grid SLAM (its 64 KB grid in RAM); built with
//! `MICROSLAM_MAP=<map.yaml>` it carries the localizer on the map image in flash instead,
//! checked at boot: a bad image is reported to the host (`Refusal::BadMap`) when it asks
//! for the localizer, never a fault. With the feature `building-slam` it carries the
//! building-scale grid SLAM with loop closure (`profile::Slam`, 112 KB) as its grid
//! estimator, beside a 4-landmark EKF, its keyframes, map image and saved pose in the
//! board's flash (`board::keyframe_flash`, …: QEMU's stand-in, or the STM32F411's own
//! sectors).
#![no_std]
#![no_main]

#[cfg(all(feature = "building-slam", microslam_map))]
compile_error!("`building-slam` carries the grid SLAM: build it without MICROSLAM_MAP");
#[cfg(all(feature = "building-slam", feature = "stm32-in-qemu"))]
compile_error!(
    "`building-slam` writes the STM32's flash, which QEMU's netduinoplus2 does not model: \
     build it for the board, or for mps2-an386 (feature `qemu`)"
);

use cortex_m_rt::entry;
use firmware_example::config::{EKF_CONFIG, GRID_SETUP, ZEROED_EKF_CONFIG};
#[cfg(not(feature = "building-slam"))]
use firmware_example::config::{EKF_LANDMARKS, Ekf};
#[cfg(feature = "building-slam")]
use firmware_example::config::{SLAM_EKF_LANDMARKS as EKF_LANDMARKS, SlamEkf as Ekf};
use firmware_example::{board, serve, stack};
use microslam::device::Session;
use microslam::wire::ToHost;
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
    let (mut session, after_reply) = grid::session(EKF.take());
    defmt::info!(
        "microslam firmware: EKF with {} landmarks, waiting for frames",
        EKF_LANDMARKS
    );
    serve(
        &mut session,
        &mut serial,
        &mut led,
        stack::peak_bytes,
        after_reply,
    )
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
    /// Nothing is kept in flash.
    pub fn session(ekf: &'static mut Ekf) -> (FirmwareSession, impl FnMut(&ToHost, bool)) {
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
        (
            Session::with_grid(ekf, EKF_CONFIG, GRID_SLAM.init(slam), GRID_SETUP),
            |_: &ToHost, _: bool| {},
        )
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

    /// The session with the EKF and the localizer, or with the reason the map was refused;
    /// under QEMU the robot's pose is kept in flash, and a pose saved in this map before a
    /// reset starts the session on the localizer there.
    pub fn session(ekf: &'static mut Ekf) -> (FirmwareSession, impl FnMut(&ToHost, bool)) {
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
        let session = Session::new(ekf, EKF_CONFIG)
            .with_localizer(localizer, GRID_SETUP)
            .with_map_checksum(checksum);
        kept_pose::resume(own_lidar::wire(session), checksum)
    }

    /// An LD06 lidar's packets arrive on the board's lidar UART (UART1 under QEMU, USART1
    /// on the STM32): `NextRevolution` reads it.
    #[cfg(feature = "own-lidar")]
    mod own_lidar {
        use super::*;
        use firmware_example::config::{LIDAR_BINS, LIDAR_SETUP};
        use microslam_hal::lidar::Ld06Uart;

        /// The reader (its two revolutions of beams, 2.9 KB), zeroed at reset.
        static LIDAR: StaticCell<Ld06Uart<board::LidarUart, LIDAR_BINS>> = StaticCell::new();

        pub fn wire(session: FirmwareSession) -> FirmwareSession {
            let Some(lidar) = Ld06Uart::new(board::lidar_uart(), LIDAR_SETUP) else {
                defmt::error!("lidar setup invalid");
                board::halt(4)
            };
            session.with_lidar(LIDAR.init(lidar))
        }
    }

    /// Without the feature `own-lidar`, `NextRevolution` is refused.
    #[cfg(not(feature = "own-lidar"))]
    mod own_lidar {
        use super::*;

        pub fn wire(session: FirmwareSession) -> FirmwareSession {
            session
        }
    }

    /// Under QEMU the robot's pose is kept in the flash stand-in: a pose saved in this map
    /// before a reset starts the session on the localizer there.
    #[cfg(feature = "qemu")]
    mod kept_pose {
        use super::*;
        use firmware_example::kept_pose::{KeptPose, after_reply, store};

        pub fn resume(
            session: FirmwareSession,
            checksum: Option<u32>,
        ) -> (FirmwareSession, impl FnMut(&ToHost, bool)) {
            let store = store();
            let saved = checksum
                .zip(store.as_ref())
                .and_then(|(crc, s)| s.latest_in(crc));
            let session = match saved {
                Some(pose) => {
                    defmt::info!(
                        "saved pose ({}, {}, {}): localizing from it",
                        pose.x,
                        pose.y,
                        pose.theta
                    );
                    session.localizing_from(pose)
                }
                None => session,
            };
            let kept = store.map(|store| KeptPose::new(store, checksum));
            (session, after_reply(kept))
        }
    }

    /// On the STM32F411 the localizer's map leaves no flash sector free for a pose store
    /// (the building-slam build keeps one in sectors 1 and 2): no pose is kept.
    #[cfg(not(feature = "qemu"))]
    mod kept_pose {
        use super::*;

        pub fn resume(
            session: FirmwareSession,
            _checksum: Option<u32>,
        ) -> (FirmwareSession, impl FnMut(&ToHost, bool)) {
            (session, |_: &ToHost, _: bool| {})
        }
    }
}

/// The building-scale grid SLAM with loop closure (feature `building-slam`), and the
/// localizer on the map it saved once the board is reset.
#[cfg(feature = "building-slam")]
mod grid {
    use super::*;
    use core::mem::ManuallyDrop;
    use firmware_example::board::{KEYFRAME_BYTES, MAP_BYTES, SlamFlash};
    use firmware_example::config::{
        LOCALIZER_CONFIG, Localizer, SLAM_CONFIG, SLAM_NODES, Slam, SlamEstimator,
    };
    use firmware_example::kept_pose::{KeptPose, after_reply, store};
    use microslam::device::LocalizerEstimator;
    use microslam::geometry::Pose2;
    use microslam::grid::MapImage;
    use microslam::pf::PfError;
    use microslam::slam::keyframes::NorFlashStorage;
    use static_cell::StaticCell;

    /// The RAM of the grid estimator: the SLAM (maps, pose graph, workspace: 112 KB)
    /// while the board maps, or the localizer on the map the SLAM saved (a few KB) after
    /// a reset that found one. Never both: the same bytes serve either.
    union GridMemory {
        slam: ManuallyDrop<Slam>,
        localizer: ManuallyDrop<Result<Localizer<'static>, PfError>>,
    }

    /// The grid estimator's RAM, all zero bytes at reset (`.bss`: no initial image in
    /// flash), handed out once.
    static MEMORY: ConstStaticCell<GridMemory> = ConstStaticCell::new(GridMemory {
        slam: ManuallyDrop::new(Slam::zeroed()),
    });

    /// Where its keyframes and its map image go: the board's flash.
    type Storage = NorFlashStorage<SlamFlash>;

    /// The SLAM with its keyframe storage, as the session's grid estimator.
    static ESTIMATOR: StaticCell<SlamEstimator<'static, Storage>> = StaticCell::new();

    /// The session, and what keeps the robot's pose in flash after each reply.
    ///
    /// At boot the map region is read: when it holds a valid map image and the pose store
    /// a pose in it (the SLAM saved both at `SaveMap`), the board localizes in that map
    /// from that pose (the session starts on the localizer, and the pose is kept every
    /// half metre, `PoseKeeping`); otherwise it maps with the building-scale SLAM, and a
    /// `SaveMap` keeps the map and the pose for the next boot.
    pub fn session(ekf: &'static mut Ekf) -> (FirmwareSession, impl FnMut(&ToHost, bool)) {
        let memory = MEMORY.take();
        let store = store();
        let Some(map_flash) = board::map_flash() else {
            defmt::error!("map flash taken");
            board::halt(4)
        };
        let saved = match (MapImage::parse_at_start(map_flash.bytes()), &store) {
            (Ok(image), Some(store)) => store.latest_in(image.checksum()),
            (Err(e), _) => {
                defmt::info!("no saved map ({}): mapping", e);
                None
            }
            _ => None,
        };
        let session = match saved {
            Some(pose) => localize(ekf, memory, map_flash.into_bytes(), pose),
            None => map(ekf, memory, map_flash),
        };
        let kept = store.map(|store| KeptPose::new(store, session.1));
        (session.0, after_reply(kept))
    }

    /// The localizer on the map image at the start of `region` (the map flash) from
    /// `pose`, in `memory`; the map's checksum. Not inlined, nor is [`map`]: the 10 KB
    /// localizer passes through this function's stack frame on its way into `memory`,
    /// and a frame holding both paths would not fit beside the SLAM's 112 KB.
    #[inline(never)]
    fn localize(
        ekf: &'static mut Ekf,
        memory: &'static mut GridMemory,
        region: &'static [u8],
        pose: Pose2<f32>,
    ) -> (FirmwareSession, Option<u32>) {
        // The bytes read at boot, not written since.
        let Ok(image) = MapImage::parse_at_start(region) else {
            defmt::error!("saved map changed during boot");
            board::halt(4)
        };
        let g = image.geometry();
        defmt::info!(
            "saved map: {} x {} cells, crc {:#010x}; localizing from ({}, {}, {})",
            g.width,
            g.height,
            image.checksum(),
            pose.x,
            pose.y,
            pose.theta
        );
        let localizer = place_localizer(memory, &image, pose);
        let checksum = image.checksum();
        let session = Session::new(ekf, EKF_CONFIG)
            .with_localizer(Ok(localizer as &mut dyn LocalizerEstimator), GRID_SETUP)
            .with_map_checksum(Some(checksum))
            .localizing_from(pose);
        (session, Some(checksum))
    }

    /// The localizer on `image` from `pose`, made in `memory`. In a function of its own,
    /// so that its frame is gone before the session is made.
    #[inline(never)]
    fn place_localizer(
        memory: &'static mut GridMemory,
        image: &MapImage<'static>,
        pose: Pose2<f32>,
    ) -> &'static mut Localizer<'static> {
        // Made where it stays: `new`'s result is written straight into the union (the
        // return slot is the static's address), not built on the stack and copied.
        let slot = (&raw mut memory.localizer).cast::<Result<Localizer<'static>, PfError>>();
        // SAFETY: `slot` points into the union, valid for a write of its `localizer`
        // field's type and aligned for it; the SLAM was never started, so nothing of it
        // is lost; `memory` is the one `&'static mut` to the union (ConstStaticCell::take).
        #[allow(unsafe_code)]
        unsafe {
            slot.write(Localizer::new(image.view(), LOCALIZER_CONFIG, pose));
        }
        // SAFETY: the field was written just above and is the only one used from here on.
        #[allow(unsafe_code)]
        let made = unsafe { &mut *memory.localizer };
        match made {
            Ok(localizer) => localizer,
            Err(_) => {
                defmt::error!("localizer configuration invalid");
                board::halt(4)
            }
        }
    }

    /// The building-scale SLAM in `memory`, with the small EKF, its map image to be
    /// written into `map_flash`; localizer requests are refused (no map yet).
    #[inline(never)]
    fn map(
        ekf: &'static mut Ekf,
        memory: &'static mut GridMemory,
        map_flash: SlamFlash,
    ) -> (FirmwareSession, Option<u32>) {
        // SAFETY: the union was made with its `slam` field (all zero bytes, what
        // `Slam::zeroed` is), and it is the only field used from here on; `memory` is
        // the one `&'static mut` to the union (ConstStaticCell::take).
        #[allow(unsafe_code)]
        let slam: &'static mut Slam = unsafe { &mut memory.slam };
        let Some(flash) = board::keyframe_flash() else {
            defmt::error!("keyframe flash taken");
            board::halt(4)
        };
        let Ok(storage) = Storage::new(flash, 0, KEYFRAME_BYTES) else {
            defmt::error!("keyframe storage refused");
            board::halt(4)
        };
        let Ok(map_storage) = Storage::new(map_flash, 0, MAP_BYTES) else {
            defmt::error!("map storage refused");
            board::halt(4)
        };
        let Ok(slam) = SlamEstimator::new(slam, storage, SLAM_CONFIG, Pose2::new(0.0, 0.0, 0.0))
        else {
            defmt::error!("building-scale SLAM configuration invalid");
            board::halt(4)
        };
        // `SaveMap` writes the run's map image here, `ReadMap` reads it back.
        let slam = slam.with_map_storage(map_storage);
        defmt::info!(
            "building-scale grid SLAM: {} keyframes, {} bytes of keyframe flash",
            SLAM_NODES,
            KEYFRAME_BYTES
        );
        (
            Session::with_grid(ekf, EKF_CONFIG, ESTIMATOR.init(slam), GRID_SETUP),
            None,
        )
    }
}

firmware_example::hard_fault_halts!();
