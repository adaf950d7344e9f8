//! The whole map of a finished run, for the localizer: [`GraphSlam::write_map_image`].
//!
//! A board cannot hold a building's log-odds (the Intel lab at 5 cm: 667 × 716 cells,
//! 466 KB); it holds the local map's `NEAR × NEAR` near window. So the map is drawn tile
//! by tile. The building's extent is the box of the keyframes' graph poses and their
//! scans' end points, rounded out to whole tiles; for each `NEAR × NEAR` tile the near window is
//! cleared and placed over it, every keyframe whose scan can reach the tile is written
//! at its final graph pose (free rays, then end points: the one map update of this crate,
//! [`crate::grid::OccupancyGrid::integrate_scan`]), and the tile's occupied and free bits
//! are written to their place in a map image ([`crate::grid::map_image`]: the localizer's
//! format, with a [`SECTION_FREE`] bitmap so that the global search's layers can be made
//! from it). Each keyframe is read back from the store once per tile it reaches.
//!
//! The image is written into a [`KeyframeStorage`] (a flash region), erased first; its
//! header goes last, once every other byte is written and checksummed, so that a write
//! cut short (power lost) leaves no image that [`crate::grid::MapImage::parse`] accepts.
//!
//! A tile's cells are the log-odds a single grid covering the whole building would hold
//! but for rounding: the tile's origin is the building's plus whole tiles, in `f32`, so a
//! ray end within a few ULPs of a cell boundary may fall into the neighbouring cell (the
//! test `tiles_match_one_grid` bounds how many cells differ).

use super::{GraphSlam, SlamError};
use crate::grid::map_image::{
    ImageChecksum, MAP_IMAGE_HEADER_LEN, SECTION_FREE, SECTION_OCCUPIED, encode_header,
    section_header,
};
use crate::grid::{GridGeometry, floor_i32, occupancy_bytes};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore, StoreError};

/// Widest and tallest map [`GraphSlam::write_map_image`] draws, cells (the global search's
/// layers store sizes as `u16`): 3.2 km at 5 cm.
pub const MAX_MAP_CELLS: usize = u16::MAX as usize;

/// What [`GraphSlam::write_map_image`] wrote.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MapImageSummary {
    /// The map's size, resolution and origin (whole tiles).
    pub geometry: GridGeometry,
    /// Length of the image, bytes (from offset 0 of the storage).
    pub bytes: usize,
    /// Keyframes drawn (those with a node in the graph).
    pub keyframes: u32,
    /// Tiles drawn.
    pub tiles: u32,
    /// Keyframe scans written, summed over the tiles (each keyframe once per tile it
    /// reaches): the work done.
    pub scans_drawn: u32,
}

/// Where the image's parts lie, bytes from the storage's start.
struct Layout {
    /// Bytes of a bitmap row.
    stride: usize,
    /// Start of the occupied bitmap's body.
    occupied: usize,
    /// Start of the free bitmap's body.
    free: usize,
    /// Length of the whole image.
    total: usize,
}

impl Layout {
    /// The sections' part of the header: their count and length.
    fn payload(&self) -> u32 {
        u32::try_from(self.total - MAP_IMAGE_HEADER_LEN).unwrap_or(u32::MAX)
    }
}

/// The building's extent: the box of `points` (the poses and the scans' end points),
/// rounded out to whole `tile × tile` tiles of `resolution` metres with a cell to spare,
/// the origin on a whole cell.
fn extent(
    lo: [f32; 2],
    hi: [f32; 2],
    resolution: f32,
    tile: usize,
) -> Result<GridGeometry, SlamError> {
    if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
        return Err(SlamError::NoKeyframes);
    }
    let cells = |a: f32, b: f32| -> Option<(i32, usize)> {
        let first = floor_i32(a / resolution) - 1;
        let last = floor_i32(b / resolution) + 1;
        let span = usize::try_from(i64::from(last) - i64::from(first) + 1).ok()?;
        let span = span.div_ceil(tile).checked_mul(tile)?;
        (span <= MAX_MAP_CELLS).then_some((first, span))
    };
    let ((x0, width), (y0, height)) = match (cells(lo[0], hi[0]), cells(lo[1], hi[1])) {
        (Some(x), Some(y)) => (x, y),
        _ => return Err(SlamError::MapTooLarge),
    };
    Ok(GridGeometry {
        width,
        height,
        resolution,
        origin_x: x0 as f32 * resolution,
        origin_y: y0 as f32 * resolution,
    })
}

/// Points a stored scan is drawn from between two neighbouring beams that hit one
/// surface, per gap: a keyframe keeps every `decimation`-th beam, which leaves a wall
/// seen at 10 m as dots 0.35 m apart (2° apart); the points in between, at ranges
/// interpolated along the angle, draw it whole, as the lidar's own beams would have.
pub const FILL_POINTS: usize = 3;
/// Two neighbouring readings are one surface when they differ by at most this, metres…
const SURFACE_GAP: f32 = 0.1;
/// … plus this fraction of the shorter.
const SURFACE_GAP_PER_M: f32 = 0.05;

/// The robot-frame points a keyframe's `ranges` (of `geometry`) are drawn from: every
/// valid reading's end point and, between two neighbours on one surface,
/// [`FILL_POINTS`] more (see there).
fn surface_points(
    ranges: &[f32],
    geometry: LidarGeometry,
) -> impl Iterator<Item = (f32, f32)> + Clone + '_ {
    let (ms, mc) = libm::sincosf(geometry.mount.theta);
    let to_robot = move |range: f32, angle: f32| {
        let (s, c) = libm::sincosf(angle);
        let (x, y) = (range * c, range * s);
        (
            geometry.mount.x + mc * x - ms * y,
            geometry.mount.y + ms * x + mc * y,
        )
    };
    let valid = move |r: f32| geometry.classify(r) == crate::sensors::lidar::BeamStatus::Valid;
    ranges.iter().enumerate().flat_map(move |(i, &r)| {
        let next = ranges.get(i + 1).copied().unwrap_or(f32::NAN);
        let joined = valid(r)
            && valid(next)
            && (r - next).abs() <= SURFACE_GAP + SURFACE_GAP_PER_M * r.min(next);
        let angle = geometry.beam_angle(i);
        let own = valid(r).then(|| to_robot(r, angle));
        let fill = (1..=FILL_POINTS).filter(move |_| joined).map(move |k| {
            let t = k as f32 / (FILL_POINTS + 1) as f32;
            to_robot(r + t * (next - r), angle + t * geometry.angle_increment)
        });
        own.into_iter().chain(fill)
    })
}

/// The image's layout for `geometry`: header, occupied section, free section.
fn layout(geometry: GridGeometry) -> Layout {
    let bitmap = occupancy_bytes(geometry.width, geometry.height);
    // Widths are whole tiles, tiles whole bytes of 8 cells: no section needs padding
    // when the bitmap is a multiple of 4 bytes, and the padding is written otherwise.
    let padded = bitmap.next_multiple_of(4);
    let occupied = MAP_IMAGE_HEADER_LEN + 8;
    let free = occupied + padded + 8;
    Layout {
        stride: geometry.width.div_ceil(8),
        occupied,
        free,
        total: free + padded,
    }
}

impl<
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>
{
    /// The keyframes with a graph node, how far their scans reach, and the map's extent:
    /// the box of their poses and of their scans' end points at those poses (a pass over
    /// the store).
    fn map_extent<S: KeyframeStorage>(
        &self,
        store: &KeyframeStore<S>,
    ) -> Result<(usize, f32, GridGeometry), SlamError> {
        if !self.started {
            return Err(SlamError::NotStarted);
        }
        let n = self.graph.len().min(store.len() as usize);
        let poses = self.graph.poses().get(..n).unwrap_or(&[]);
        let lidar = store.lidar();
        let mount = lidar.mount;
        // How far from a keyframe's pose its scan can write: the longest reading kept,
        // from the sensor's place on the robot, and a cell's rounding either way.
        let reach =
            lidar.max_range + libm::hypotf(mount.x, mount.y) + 2.0 * self.config.grid.resolution;
        let geometry = store.beam_geometry();
        let beams = store.beams().min(B);
        let mut ranges = [0.0f32; B];
        let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
        for (k, pose) in poses.iter().enumerate() {
            if !pose.is_finite() {
                return Err(SlamError::Filter(crate::pf::PfError::NonFiniteInput));
            }
            let ranges = ranges.get_mut(..beams).unwrap_or(&mut []);
            store.read(u32::try_from(k).unwrap_or(u32::MAX), ranges)?;
            let (sin, cos) = libm::sincosf(pose.theta);
            let scan = LidarScan::new(ranges, geometry);
            let ends = scan.beams(1).map(|b| {
                let (x, y) = b.robot_point;
                (pose.x + cos * x - sin * y, pose.y + sin * x + cos * y)
            });
            for (x, y) in ends.chain(core::iter::once((pose.x, pose.y))) {
                lo = [lo[0].min(x), lo[1].min(y)];
                hi = [hi[0].max(x), hi[1].max(y)];
            }
        }
        let geometry = extent(lo, hi, self.config.grid.resolution, NEAR)?;
        Ok((n, reach, geometry))
    }

    /// The size and length in bytes of the image [`GraphSlam::write_map_image`] would
    /// write now (to choose or check the flash region before the run is ended).
    pub fn map_image_size<S: KeyframeStorage>(
        &self,
        store: &KeyframeStore<S>,
    ) -> Result<(GridGeometry, usize), SlamError> {
        let (_, _, geometry) = self.map_extent(store)?;
        Ok((geometry, layout(geometry).total))
    }

    /// Ends the run and writes its whole map, every keyframe of `store` at its final
    /// graph pose, into `out` as a map image (see the module): what the localizer reads
    /// ([`crate::grid::MapImage::parse`] over the bytes in flash) after a reset. `out` is
    /// erased first and must hold the image ([`StoreError::TooSmall`] otherwise, before
    /// anything is erased) and take writes at offsets that are multiples of 8
    /// ([`StoreError::Misaligned`] for a larger flash word). Cells are free below
    /// `free_below` (the localizer's [`crate::grid::LogOdds::free_below`]).
    ///
    /// The local map is drawn over, so the run cannot go on: after this (whatever it
    /// returns, once [`GraphSlam::init`] has been called) the estimator refuses scans with
    /// [`SlamError::NotStarted`] until it is started again. A keyframe that cannot be read
    /// back stops the drawing with [`SlamError::Store`] and leaves no valid image.
    pub fn write_map_image<S: KeyframeStorage, O: KeyframeStorage>(
        &mut self,
        store: &KeyframeStore<S>,
        out: &mut O,
        free_below: i8,
    ) -> Result<MapImageSummary, SlamError> {
        let (n, reach, geometry) = self.map_extent(store)?;
        let poses = self.graph.poses().get(..n).unwrap_or(&[]);
        let layout = layout(geometry);
        if layout.total > out.capacity() {
            return Err(SlamError::Store(StoreError::TooSmall));
        }
        if out.write_size() > 8 {
            return Err(SlamError::Store(StoreError::Misaligned));
        }
        let log_odds = self.config.grid.log_odds;
        let mut header = encode_header(
            &geometry,
            log_odds.occupied_above,
            free_below,
            2,
            layout.payload(),
        )
        .map_err(|_| SlamError::MapTooLarge)?;
        // From here on the local map is drawn over.
        self.started = false;
        out.erase_all()?;
        let bitmap = occupancy_bytes(geometry.width, geometry.height);
        let bitmap_u32 = u32::try_from(bitmap).map_err(|_| SlamError::MapTooLarge)?;
        out.write(
            layout.occupied - 8,
            &section_header(SECTION_OCCUPIED, bitmap_u32),
        )?;
        out.write(layout.free - 8, &section_header(SECTION_FREE, bitmap_u32))?;
        let padding = bitmap.next_multiple_of(4) - bitmap;
        if padding > 0 {
            let zeros = [0u8; 4];
            let pad = zeros.get(..padding).unwrap_or(&[]);
            out.write(layout.occupied + bitmap, pad)?;
            out.write(layout.free + bitmap, pad)?;
        }
        let scan_geometry = store.beam_geometry();
        let beams = store.beams().min(B);
        let tile_m = NEAR as f32 * geometry.resolution;
        let (tiles_x, tiles_y) = (geometry.width / NEAR, geometry.height / NEAR);
        let mut summary = MapImageSummary {
            geometry,
            bytes: layout.total,
            keyframes: u32::try_from(n).unwrap_or(u32::MAX),
            tiles: 0,
            scans_drawn: 0,
        };
        for ty in 0..tiles_y {
            for tx in 0..tiles_x {
                let (ox, oy) = (
                    geometry.origin_x + tx as f32 * tile_m,
                    geometry.origin_y + ty as f32 * tile_m,
                );
                let grid = self.map.near_mut();
                grid.reset();
                grid.set_origin(ox, oy)?;
                for (k, pose) in poses.iter().enumerate() {
                    // The scan reaches the tile only from within `reach` of its square.
                    let dx = (ox - pose.x).max(pose.x - (ox + tile_m)).max(0.0);
                    let dy = (oy - pose.y).max(pose.y - (oy + tile_m)).max(0.0);
                    if dx * dx + dy * dy > reach * reach {
                        continue;
                    }
                    let ranges = self.ranges.get_mut(..beams).unwrap_or(&mut []);
                    store.read(u32::try_from(k).unwrap_or(u32::MAX), ranges)?;
                    let ranges = self.ranges.get(..beams).unwrap_or(&[]);
                    let points = surface_points(ranges, scan_geometry);
                    self.map
                        .near_mut()
                        .integrate_points(pose, &scan_geometry.mount, points)?;
                    summary.scans_drawn = summary.scans_drawn.saturating_add(1);
                }
                self.write_tile(out, &layout, tx, ty, free_below)?;
                summary.tiles += 1;
            }
        }
        // The checksum over the sections in order, read back from the storage.
        let mut crc = ImageChecksum::new(&header);
        let mut chunk = [0u8; 64];
        let mut at = MAP_IMAGE_HEADER_LEN;
        while at < layout.total {
            let len = (layout.total - at).min(chunk.len());
            let part = chunk.get_mut(..len).unwrap_or(&mut []);
            out.read(at, part)?;
            crc.update(part);
            at += len;
        }
        crc.finish(&mut header);
        out.write(0, &header)?;
        Ok(summary)
    }

    /// Writes the near window's occupied and free bits as tile `(tx, ty)` of the image.
    fn write_tile<O: KeyframeStorage>(
        &self,
        out: &mut O,
        layout: &Layout,
        tx: usize,
        ty: usize,
        free_below: i8,
    ) -> Result<(), SlamError> {
        let grid = self.map.near();
        let row_bytes = NEAR / 8;
        let bits = grid.occupancy_bits();
        let cells = grid.cells();
        const PIECE: usize = 64;
        let mut free = [0u8; PIECE];
        for row in 0..NEAR {
            let y = ty * NEAR + row;
            let at = y * layout.stride + tx * row_bytes;
            let occupied = bits
                .get(row * row_bytes..(row + 1) * row_bytes)
                .ok_or(SlamError::MapTooLarge)?;
            out.write(layout.occupied + at, occupied)?;
            let row_cells = cells
                .get(row * NEAR..(row + 1) * NEAR)
                .ok_or(SlamError::MapTooLarge)?;
            // The free bits in pieces of 64 bytes (512 cells): no buffer of NEAR's size.
            for (piece, cells) in row_cells.chunks(PIECE * 8).enumerate() {
                let bytes = cells.len().div_ceil(8);
                let buf = free.get_mut(..bytes).unwrap_or(&mut []);
                buf.fill(0);
                for (i, &c) in cells.iter().enumerate() {
                    if c < free_below
                        && let Some(b) = buf.get_mut(i / 8)
                    {
                        *b |= 1 << (i % 8);
                    }
                }
                out.write(layout.free + at + piece * PIECE, buf)?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
