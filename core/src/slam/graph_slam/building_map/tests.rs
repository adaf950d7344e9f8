//! The ring's whole map drawn tile by tile into a map image: what the localizer reads
//! after the run.

use super::super::tests::{Run, config, drive_ring};
use super::*;
use crate::geometry::Pose2;
use crate::grid::map_image::MapImage;
use crate::grid::{MaxPoolLayers, OccupancyGrid};
use crate::slam::GraphSlamConfig;
use crate::slam::keyframes::RamStorage;
use crate::testing::world::{distance_to_walls, ring_corridor};

type Image = RamStorage<{ 256 * 1024 }>;

/// The localizer's free threshold.
const FREE_BELOW: i8 = GraphSlamConfig::MICROCONTROLLER.grid.log_odds.free_below;

fn finished_ring() -> Run {
    drive_ring(config(), 1)
}

fn image_bytes(out: &Image, len: usize) -> Vec<u8> {
    let mut bytes = vec![0u8; len];
    out.read(0, &mut bytes).unwrap();
    bytes
}

#[test]
fn the_ring_map_is_an_image_the_localizer_reads() {
    let Run {
        mut slam,
        mut store,
        ..
    } = finished_ring();
    let mut out = Box::new(Image::new());
    let summary = slam
        .write_map_image(&*store, &mut *out, FREE_BELOW)
        .unwrap();
    let bytes = image_bytes(&out, summary.bytes);
    let image = MapImage::parse(&bytes).expect("a valid image");
    let g = *image.geometry();
    assert_eq!(g, summary.geometry);
    // The walls span 20 m × 14 m (the run's map a little more): whole tiles of 128
    // cells, 4 × 3 tiles of 6.4 m.
    assert_eq!((g.width, g.height, summary.tiles), (512, 384, 12));
    assert_eq!(summary.keyframes as usize, slam.graph().len());
    assert!(image.view().free_bits().is_some());
    // The occupied cells lie on the world's walls, within the run's own error (the ring
    // run is 0.5 m RMS off the truth: its map is bent, which the image keeps).
    let walls = ring_corridor();
    let view = image.view();
    let (mut occupied, mut on_wall) = (0usize, 0usize);
    for y in 0..g.height as i32 {
        for x in 0..g.width as i32 {
            if view.is_occupied(x, y) {
                occupied += 1;
                let (cx, cy) = g.cell_centre(x, y);
                let dd = distance_to_walls(&walls, cx, cy);
                if dd < 1.0 {
                    on_wall += 1;
                }
            }
        }
    }
    let share = on_wall as f64 / occupied as f64;
    println!("{occupied} occupied cells, {share:.3} within 1 m of a wall; {summary:?}");
    // Measured (seed 1, 151 keyframes): 3 542 occupied cells, all within 1 m of a wall.
    assert!((3_350..=3_750).contains(&occupied), "{occupied}");
    assert!(share > 0.98, "{share}");
    // The run is over: the estimator asks to be started again.
    let scan = [1.0f32; 180];
    assert_eq!(
        slam.observe(&LidarScan::new(&scan, store.lidar()), &mut *store),
        Err(SlamError::NotStarted)
    );
}

#[test]
fn tiles_match_one_grid() {
    let Run {
        mut slam, store, ..
    } = finished_ring();
    let mut out = Box::new(Image::new());
    let summary = slam
        .write_map_image(&*store, &mut *out, FREE_BELOW)
        .unwrap();
    let bytes = image_bytes(&out, summary.bytes);
    let image = MapImage::parse(&bytes).unwrap();
    let g = summary.geometry;
    // The same keyframes at the same poses into one grid of the whole extent.
    let c = slam.config().grid;
    let mut grid: Box<OccupancyGrid<512, 384, { occupancy_bytes(512, 384) }>> = Box::new(
        OccupancyGrid::new(c.resolution, g.origin_x, g.origin_y, c.log_odds),
    );
    let geometry = store.beam_geometry();
    let mut ranges = vec![0.0f32; store.beams()];
    for (k, pose) in slam.graph().poses().iter().enumerate() {
        store.read(k as u32, &mut ranges).unwrap();
        grid.integrate_points(pose, &geometry.mount, surface_points(&ranges, geometry))
            .unwrap();
    }
    let whole = grid.view();
    let (mut differ, mut free_differ) = (0usize, 0usize);
    for y in 0..g.height as i32 {
        for x in 0..g.width as i32 {
            differ += usize::from(whole.is_occupied(x, y) != image.view().is_occupied(x, y));
            free_differ += usize::from(
                whole.is_free(x, y, FREE_BELOW) != image.view().is_free(x, y, FREE_BELOW),
            );
        }
    }
    println!(
        "{differ} occupied and {free_differ} free cells differ of {}",
        g.width * g.height
    );
    // Measured (seed 1): 0 and 0 (the tiles' origins are whole multiples of 6.4 m at
    // 0.05 m, exact in f32 here; bounded for origins that are not).
    assert!(differ <= 10, "{differ}");
    assert!(free_differ <= 10, "{free_differ}");
    // The global search's layers made from the image's bitmaps alone equal those made
    // from the whole grid's cells wherever the bitmaps agree.
    if differ == 0 && free_differ == 0 {
        let len = MaxPoolLayers::bytes_for(g.width, g.height, 4).unwrap();
        let (mut a, mut b) = (vec![0u8; len], vec![0u8; len]);
        MaxPoolLayers::build(&image.view(), FREE_BELOW, 4, &mut a).unwrap();
        MaxPoolLayers::build(&whole, FREE_BELOW, 4, &mut b).unwrap();
        assert!(
            a == b,
            "layers from the image differ from those of the cells"
        );
    }
}

#[test]
fn a_storage_too_small_or_failing_leaves_no_image() {
    let Run {
        mut slam, store, ..
    } = finished_ring();
    // Too small: refused before anything is erased or drawn; the run goes on.
    let mut small = Box::new(RamStorage::<{ 16 * 1024 }>::new());
    small.write(0, &[1, 2, 3]).unwrap();
    assert_eq!(
        slam.write_map_image(&*store, &mut *small, FREE_BELOW),
        Err(SlamError::Store(StoreError::TooSmall))
    );
    let mut kept = [0u8; 3];
    small.read(0, &mut kept).unwrap();
    assert_eq!(kept, [1, 2, 3], "nothing erased");
    assert!(slam.filter().is_some(), "the run goes on");
    // Power lost after n writes, for n across the whole drawing (the header is the last
    // of them): never a valid image.
    let mut counting = Failing {
        inner: Box::new(Image::new()),
        writes_left: usize::MAX,
    };
    let summary = slam
        .clone()
        .write_map_image(&*store, &mut counting, FREE_BELOW)
        .unwrap();
    let writes = usize::MAX - counting.writes_left;
    assert!(MapImage::parse(&image_bytes(&counting.inner, summary.bytes)).is_ok());
    for n in [0, 1, 2, 3, writes / 2, writes - 1] {
        let mut failing = Failing {
            inner: Box::new(Image::new()),
            writes_left: n,
        };
        let result = slam
            .clone()
            .write_map_image(&*store, &mut failing, FREE_BELOW);
        assert_eq!(result, Err(SlamError::Store(StoreError::Storage)), "{n}");
        let bytes = image_bytes(&failing.inner, summary.bytes);
        assert!(
            MapImage::parse(&bytes).is_err(),
            "a valid image after {n} writes"
        );
    }
}

/// Storage whose writes fail after `writes_left` of them (power lost).
struct Failing {
    inner: Box<Image>,
    writes_left: usize,
}

impl KeyframeStorage for Failing {
    fn capacity(&self) -> usize {
        self.inner.capacity()
    }

    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        self.inner.read(offset, bytes)
    }

    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        if self.writes_left == 0 {
            return Err(StoreError::Storage);
        }
        self.writes_left -= 1;
        self.inner.write(offset, bytes)
    }

    fn erase_all(&mut self) -> Result<(), StoreError> {
        self.inner.erase_all()
    }
}

#[test]
fn beams_on_one_surface_are_joined_and_others_not() {
    let lidar = LidarGeometry {
        first_angle: 0.0,
        angle_increment: 0.1,
        min_range: 0.1,
        max_range: 20.0,
        no_return_range: 20.0,
        mount: Pose2::new(0.5, 0.0, 0.0),
    };
    let points: Vec<(f32, f32)> =
        surface_points(&[10.0, 10.2, 14.0, f32::NAN, 5.0], lidar).collect();
    // 10.0 and 10.2 differ by less than 0.1 + 0.05 · 10 m: joined by FILL_POINTS points;
    // 10.2 and 14.0 are two surfaces, NaN none, 5.0 has no right-hand neighbour.
    assert_eq!(points.len(), 4 + FILL_POINTS);
    let (x, y) = points[1];
    let t = 1.0 / (FILL_POINTS + 1) as f32;
    let (r, a) = (10.0 + t * 0.2, t * 0.1);
    assert!(
        (x - (0.5 + r * a.cos())).abs() < 1e-5 && (y - r * a.sin()).abs() < 1e-5,
        "{x} {y}"
    );
    assert_eq!(points[0], (10.5, 0.0));
    let last = points[points.len() - 1];
    assert!((last.0 - (0.5 + 5.0 * 0.4f32.cos())).abs() < 1e-5);
}
