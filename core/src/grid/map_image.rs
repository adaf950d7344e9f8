//! A map as one binary image for flash: geometry, the occupied-cell bitmap and optional
//! layers, with a format version and a CRC-32 (feature `map-image`).
//!
//! The image is read in place ([`MapImage::parse`] over a `&'static [u8]` embedded in
//! the firmware with `include_bytes!`): nothing is copied, every length, the version and
//! the checksum are checked first, and a bad image is a [`MapImageError`], never a panic.
//! With feature `std`, [`encode_map_image`] writes one from log-odds cells (the host's
//! exporter and the firmware's build script share it).
//!
//! # Layout (version 1, little-endian)
//!
//! | offset | bytes | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `MSMP` |
//! | 4 | 2 | format version (1) |
//! | 6 | 2 | header length (40) |
//! | 8 | 4 | width, cells |
//! | 12 | 4 | height, cells |
//! | 16 | 4 | resolution, m (`f32`) |
//! | 20 | 4 | origin x, m (`f32`): world x of the left edge of column 0 |
//! | 24 | 4 | origin y, m (`f32`): world y of the bottom edge of row 0 |
//! | 28 | 1 | occupied threshold (`i8`): the bitmap marks cells with log-odds above it |
//! | 29 | 1 | free threshold (`i8`) of the layers made from the same cells |
//! | 30 | 2 | number of sections |
//! | 32 | 4 | length of the sections, bytes (the image is `40 +` this long) |
//! | 36 | 4 | CRC-32 (ISO-HDLC, as zlib's) of bytes 0–35 followed by bytes 40–end |
//! | 40 | … | sections |
//!
//! A section is a tag (`u32`), a length `n` (`u32`) and `n` bytes, padded with zeros to a
//! multiple of 4. [`SECTION_OCCUPIED`] (the bitmap of [`super::occupancy_bytes`] bytes
//! the particle filter scores against) is required; [`SECTION_MAX_POOL_LAYERS`] (the
//! precomputed layers of the global search, in their own byte image) and [`SECTION_FREE`]
//! (the free-cell bitmap, from which those layers can be made) are optional; a
//! reader skips tags it does not know, so later layers can be added without a new
//! version. The log-odds cells themselves are not stored: scans are scored against the
//! occupied bits only, and a 669 × 717 map (the Intel lab at 5 cm) takes 60 KB as a
//! bitmap instead of 480 KB as cells.

use super::{GridGeometry, GridView, MaxPoolLayers, occupancy_bytes};
use core::fmt;

/// The first four bytes of every image.
pub const MAP_IMAGE_MAGIC: [u8; 4] = *b"MSMP";
/// The format version this code writes and reads.
pub const MAP_IMAGE_VERSION: u16 = 1;
/// Length of the header, bytes.
pub const MAP_IMAGE_HEADER_LEN: usize = 40;
/// Section tag of the occupied-cell bitmap (required).
pub const SECTION_OCCUPIED: u32 = 1;
/// Section tag of the max-pooled layers of the global search (optional): a
/// [`MaxPoolLayers`] byte image made from the same cells.
pub const SECTION_MAX_POOL_LAYERS: u32 = 2;
/// Section tag of the free-cell bitmap (optional): the bitmap layout of
/// [`SECTION_OCCUPIED`], a bit set where the cell's log-odds was below the image's free
/// threshold. With it the global search's layers can be made from the image alone
/// ([`MapImage::view`] carries it; [`MaxPoolLayers::build`]), as a map drawn on the device
/// (`microslam::slam::GraphSlam::write_map_image`) needs.
pub const SECTION_FREE: u32 = 3;

/// Levels of the max-pooled layers [`encode_map_image_with_layers`] writes by default: 5
/// (blocks up to 32 × 32 cells). Each level costs a bitmap of the map's size: the Intel
/// lab's 669 × 717 map takes 60 KB for the occupied bits and 321 KB for 5 levels, which
/// with the firmware's code fits the STM32F411's 512 KB of flash (6 levels would not).
pub const DEFAULT_LAYER_LEVELS: u8 = 5;

use crate::checksum::CRC32;
const CRC_AT: usize = 36;

/// Why a map image was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MapImageError {
    /// No image at all (a firmware built without a map).
    Missing,
    /// Shorter than the header, or than the header says.
    Truncated,
    /// Longer than the header says.
    TrailingBytes,
    /// The first four bytes are not [`MAP_IMAGE_MAGIC`].
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion,
    /// The header length is not [`MAP_IMAGE_HEADER_LEN`].
    BadHeader,
    /// The CRC-32 does not match the bytes.
    ChecksumMismatch,
    /// Zero size, a resolution that is not positive and finite, or an origin not finite.
    InvalidGeometry,
    /// A section runs past the end of the image.
    BadSection,
    /// No occupied-cell bitmap.
    MissingOccupancy,
    /// A bitmap is not [`super::occupancy_bytes`] long.
    BitmapSizeMismatch,
    /// The max-pooled layers section is not a layers image of this map.
    BadLayers,
}

impl fmt::Display for MapImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Missing => "no map image",
            Self::Truncated => "map image is truncated",
            Self::TrailingBytes => "map image is longer than its header says",
            Self::BadMagic => "not a microslam map image (magic is not MSMP)",
            Self::UnsupportedVersion => "map image format version is not supported",
            Self::BadHeader => "map image header length is wrong",
            Self::ChecksumMismatch => "map image checksum does not match",
            Self::InvalidGeometry => "map image geometry is invalid",
            Self::BadSection => "map image section runs past the end",
            Self::MissingOccupancy => "map image has no occupied-cell bitmap",
            Self::BitmapSizeMismatch => "map image bitmap length differs from the geometry",
            Self::BadLayers => "map image layers do not belong to its map",
        })
    }
}

impl core::error::Error for MapImageError {}

/// A checked map image borrowed from its bytes (e.g. `&'static` in flash).
#[derive(Clone, Copy, Debug)]
pub struct MapImage<'a> {
    bytes: &'a [u8],
    view: GridView<'a>,
    free_below: i8,
    checksum: u32,
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    b.get(at..at + 2)?.try_into().ok().map(u16::from_le_bytes)
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    b.get(at..at + 4)?.try_into().ok().map(u32::from_le_bytes)
}

fn f32_at(b: &[u8], at: usize) -> Option<f32> {
    u32_at(b, at).map(f32::from_bits)
}

/// The header of an image of `geometry` with `sections` sections of `payload` bytes in
/// all, its CRC-32 field zero ([`ImageChecksum`] computes it as the sections are
/// written). Refused with [`MapImageError::InvalidGeometry`] for a geometry an image
/// cannot hold.
pub fn encode_header(
    geometry: &GridGeometry,
    occupied_above: i8,
    free_below: i8,
    sections: u16,
    payload: u32,
) -> Result<[u8; MAP_IMAGE_HEADER_LEN], MapImageError> {
    let (w, h) = (geometry.width, geometry.height);
    let (Ok(w), Ok(h)) = (u32::try_from(w), u32::try_from(h)) else {
        return Err(MapImageError::InvalidGeometry);
    };
    if !geometry.is_valid() {
        return Err(MapImageError::InvalidGeometry);
    }
    let mut out = [0u8; MAP_IMAGE_HEADER_LEN];
    let fields: [(usize, &[u8]); 12] = [
        (0, &MAP_IMAGE_MAGIC),
        (4, &MAP_IMAGE_VERSION.to_le_bytes()),
        (6, &(MAP_IMAGE_HEADER_LEN as u16).to_le_bytes()),
        (8, &w.to_le_bytes()),
        (12, &h.to_le_bytes()),
        (16, &geometry.resolution.to_le_bytes()),
        (20, &geometry.origin_x.to_le_bytes()),
        (24, &geometry.origin_y.to_le_bytes()),
        (28, &occupied_above.to_le_bytes()),
        (29, &free_below.to_le_bytes()),
        (30, &sections.to_le_bytes()),
        (32, &payload.to_le_bytes()),
    ];
    for (at, bytes) in fields {
        if let Some(slot) = out.get_mut(at..at + bytes.len()) {
            slot.copy_from_slice(bytes);
        }
    }
    Ok(out)
}

/// The header of a section: its tag and the length of its body (before padding).
pub fn section_header(tag: u32, len: u32) -> [u8; 8] {
    let mut out = [0u8; 8];
    out[..4].copy_from_slice(&tag.to_le_bytes());
    out[4..].copy_from_slice(&len.to_le_bytes());
    out
}

/// An image's CRC-32 computed while it is written: the header from
/// [`encode_header`], then every byte after the header in order
/// ([`ImageChecksum::update`]); [`ImageChecksum::finish`] puts it in the header.
pub struct ImageChecksum {
    digest: crc::Digest<'static, u32>,
}

impl ImageChecksum {
    /// Starts with the header (its CRC field is not read).
    pub fn new(header: &[u8; MAP_IMAGE_HEADER_LEN]) -> Self {
        let mut digest = CRC32.digest();
        digest.update(&header[..CRC_AT]);
        Self { digest }
    }

    /// The next bytes after the header.
    pub fn update(&mut self, bytes: &[u8]) {
        self.digest.update(bytes);
    }

    /// Writes the CRC-32 into `header` (the one [`ImageChecksum::new`] started with).
    pub fn finish(self, header: &mut [u8; MAP_IMAGE_HEADER_LEN]) {
        header[CRC_AT..].copy_from_slice(&self.digest.finalize().to_le_bytes());
    }
}

/// The CRC-32 of an image: header without its CRC field, then the sections.
fn image_crc(bytes: &[u8]) -> Option<u32> {
    let mut digest = CRC32.digest();
    digest.update(bytes.get(..CRC_AT)?);
    digest.update(bytes.get(MAP_IMAGE_HEADER_LEN..)?);
    Some(digest.finalize())
}

impl<'a> MapImage<'a> {
    /// The image at the start of `region`, a flash region longer than the image (where
    /// a device writes its map): the bytes its header says it holds, checked as
    /// [`MapImage::parse`] checks them. An erased region is refused with
    /// [`MapImageError::BadMagic`].
    pub fn parse_at_start(region: &'a [u8]) -> Result<Self, MapImageError> {
        let header = region
            .get(..MAP_IMAGE_HEADER_LEN)
            .ok_or(MapImageError::Truncated)?;
        if header.get(..4) != Some(&MAP_IMAGE_MAGIC[..]) {
            return Err(MapImageError::BadMagic);
        }
        let payload = u32_at(header, 32).ok_or(MapImageError::Truncated)? as usize;
        let total = MAP_IMAGE_HEADER_LEN
            .checked_add(payload)
            .ok_or(MapImageError::Truncated)?;
        Self::parse(region.get(..total).ok_or(MapImageError::Truncated)?)
    }

    /// Checks `bytes` (magic, version, header, length, CRC-32, geometry, sections) and
    /// borrows the map from them.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, MapImageError> {
        if bytes.is_empty() {
            return Err(MapImageError::Missing);
        }
        let header = bytes
            .get(..MAP_IMAGE_HEADER_LEN)
            .ok_or(MapImageError::Truncated)?;
        if header.get(..4) != Some(&MAP_IMAGE_MAGIC[..]) {
            return Err(MapImageError::BadMagic);
        }
        let field = |at| u32_at(header, at).ok_or(MapImageError::Truncated);
        if u16_at(header, 4) != Some(MAP_IMAGE_VERSION) {
            return Err(MapImageError::UnsupportedVersion);
        }
        if u16_at(header, 6).map(usize::from) != Some(MAP_IMAGE_HEADER_LEN) {
            return Err(MapImageError::BadHeader);
        }
        let payload = field(32)? as usize;
        let total = MAP_IMAGE_HEADER_LEN
            .checked_add(payload)
            .ok_or(MapImageError::Truncated)?;
        if bytes.len() < total {
            return Err(MapImageError::Truncated);
        }
        if bytes.len() > total {
            return Err(MapImageError::TrailingBytes);
        }
        let checksum = field(CRC_AT)?;
        if image_crc(bytes) != Some(checksum) {
            return Err(MapImageError::ChecksumMismatch);
        }
        let real = |at| f32_at(header, at).ok_or(MapImageError::Truncated);
        let geometry = GridGeometry {
            width: field(8)? as usize,
            height: field(12)? as usize,
            resolution: real(16)?,
            origin_x: real(20)?,
            origin_y: real(24)?,
        };
        if !geometry.is_valid() || geometry.width.checked_mul(geometry.height).is_none() {
            return Err(MapImageError::InvalidGeometry);
        }
        let bitmap_len = occupancy_bytes(geometry.width, geometry.height);
        let occupied_above = i8::from_le_bytes([header[28]]);
        let free_below = i8::from_le_bytes([header[29]]);
        let sections = u16_at(header, 30).ok_or(MapImageError::Truncated)?;
        let (mut occupied, mut free) = (None, None);
        let mut at = MAP_IMAGE_HEADER_LEN;
        for _ in 0..sections {
            let tag = u32_at(bytes, at).ok_or(MapImageError::BadSection)?;
            let len = u32_at(bytes, at + 4).ok_or(MapImageError::BadSection)? as usize;
            let start = at + 8;
            let body = start
                .checked_add(len)
                .and_then(|end| bytes.get(start..end))
                .ok_or(MapImageError::BadSection)?;
            at = start
                .checked_add(len.next_multiple_of(4))
                .ok_or(MapImageError::BadSection)?;
            if tag == SECTION_OCCUPIED && occupied.is_none() {
                if body.len() != bitmap_len {
                    return Err(MapImageError::BitmapSizeMismatch);
                }
                occupied = Some(body);
            }
            if tag == SECTION_FREE && free.is_none() {
                if body.len() != bitmap_len {
                    return Err(MapImageError::BitmapSizeMismatch);
                }
                free = Some(body);
            }
        }
        if at > bytes.len() {
            return Err(MapImageError::BadSection);
        }
        let occupied = occupied.ok_or(MapImageError::MissingOccupancy)?;
        let mut view = GridView::from_occupancy_bits(occupied, geometry, occupied_above)
            .map_err(|_| MapImageError::BitmapSizeMismatch)?;
        if let Some(free) = free {
            view = view
                .with_free_bits(free)
                .map_err(|_| MapImageError::BitmapSizeMismatch)?;
        }
        Ok(Self {
            bytes,
            view,
            free_below,
            checksum,
        })
    }

    /// Size, resolution and origin.
    pub fn geometry(&self) -> &GridGeometry {
        self.view.geometry()
    }

    /// The map the particle filter scores against: a view of the occupied-cell bitmap
    /// ([`GridView::from_occupancy_bits`]), with the free-cell bitmap when the image has
    /// one ([`GridView::with_free_bits`]).
    pub fn view(&self) -> GridView<'a> {
        self.view
    }

    /// The occupied-cell bitmap.
    pub fn occupied_bits(&self) -> &'a [u8] {
        self.view.occupancy_bits().unwrap_or(&[])
    }

    /// The free threshold the image's layers were made with.
    pub fn free_below(&self) -> i8 {
        self.free_below
    }

    /// The body of the first section with `tag` (e.g. [`SECTION_MAX_POOL_LAYERS`]).
    pub fn section(&self, tag: u32) -> Option<&'a [u8]> {
        let mut at = MAP_IMAGE_HEADER_LEN;
        for _ in 0..u16_at(self.bytes, 30)? {
            let t = u32_at(self.bytes, at)?;
            let len = u32_at(self.bytes, at + 4)? as usize;
            let body = self.bytes.get(at + 8..(at + 8).checked_add(len)?)?;
            if t == tag {
                return Some(body);
            }
            at = (at + 8).checked_add(len.next_multiple_of(4))?;
        }
        None
    }

    /// The max-pooled layers of the global search, when the image has them; refused with
    /// [`MapImageError::BadLayers`] when the section is not a layers image of this map
    /// (size or occupied threshold). Their content is covered by the image's CRC-32.
    pub fn layers(&self) -> Option<Result<MaxPoolLayers<'a>, MapImageError>> {
        let bytes = self.section(SECTION_MAX_POOL_LAYERS)?;
        Some(
            MaxPoolLayers::from_bytes(bytes)
                .ok()
                .filter(|l| l.matches(&self.view))
                .ok_or(MapImageError::BadLayers),
        )
    }

    /// The image's CRC-32 (identifies the map, e.g. in a status reply).
    pub fn checksum(&self) -> u32 {
        self.checksum
    }

    /// Length of the whole image, bytes (its flash footprint).
    pub fn len_bytes(&self) -> usize {
        self.bytes.len()
    }
}

/// Writes a map image (version [`MAP_IMAGE_VERSION`]) of `width × height` log-odds
/// `cells` (row-major, row 0 at the bottom): occupied bits where a cell is above
/// `occupied_above`, then the `extra` sections `(tag, bytes)` as given; `free_below` is
/// recorded for layers made from the same cells. Refused with [`MapImageError::InvalidGeometry`] or
/// [`MapImageError::BitmapSizeMismatch`] when the geometry or the cells do not fit.
#[cfg(feature = "std")]
pub fn encode_map_image(
    cells: &[i8],
    geometry: &GridGeometry,
    occupied_above: i8,
    free_below: i8,
    extra: &[(u32, &[u8])],
) -> Result<std::vec::Vec<u8>, MapImageError> {
    let (w, h) = (geometry.width, geometry.height);
    if !geometry.is_valid() || u32::try_from(w).is_err() || u32::try_from(h).is_err() {
        return Err(MapImageError::InvalidGeometry);
    }
    let mut occupied = std::vec![0u8; occupancy_bytes(w, h)];
    super::fill_occupancy_bits(cells, w, h, occupied_above, &mut occupied)
        .map_err(|_| MapImageError::BitmapSizeMismatch)?;
    let mut sections: std::vec::Vec<(u32, &[u8])> = std::vec![(SECTION_OCCUPIED, &occupied[..])];
    sections.extend_from_slice(extra);
    encode_sections(geometry, occupied_above, free_below, &sections)
}

/// [`encode_map_image`] with the max-pooled layers of the global search
/// ([`MaxPoolLayers::build`] from the same cells, `levels` levels; 0: none) in a
/// [`SECTION_MAX_POOL_LAYERS`] section: what the firmware embeds and the host exports.
#[cfg(feature = "std")]
pub fn encode_map_image_with_layers(
    cells: &[i8],
    geometry: &GridGeometry,
    occupied_above: i8,
    free_below: i8,
    levels: u8,
) -> Result<std::vec::Vec<u8>, MapImageError> {
    if levels == 0 {
        return encode_map_image(cells, geometry, occupied_above, free_below, &[]);
    }
    let view = GridView::new(cells, *geometry, occupied_above).map_err(|e| match e {
        super::GridError::SizeMismatch => MapImageError::BitmapSizeMismatch,
        _ => MapImageError::InvalidGeometry,
    })?;
    let len = MaxPoolLayers::bytes_for(geometry.width, geometry.height, levels)
        .ok_or(MapImageError::BadLayers)?;
    let mut layers = std::vec![0u8; len];
    MaxPoolLayers::build(&view, free_below, levels, &mut layers)
        .map_err(|_| MapImageError::BadLayers)?;
    encode_map_image(
        cells,
        geometry,
        occupied_above,
        free_below,
        &[(SECTION_MAX_POOL_LAYERS, &layers)],
    )
}

/// A map image (e.g. the one a board saved at the end of its SLAM run, which carries an
/// occupied and a free bitmap but no layers) with the max-pooled layers of the global
/// search made from it (`levels` levels, [`MaxPoolLayers::build`] on
/// [`MapImage::view`]), replacing any it had: what the localizer firmware embeds. Refused
/// as [`MapImage::parse`] refuses, or with [`MapImageError::BadLayers`] when the layers
/// cannot be made (`levels` outside `1..=8`).
#[cfg(feature = "std")]
pub fn with_layers(image: &[u8], levels: u8) -> Result<std::vec::Vec<u8>, MapImageError> {
    let map = MapImage::parse(image)?;
    let view = map.view();
    let g = *map.geometry();
    let len =
        MaxPoolLayers::bytes_for(g.width, g.height, levels).ok_or(MapImageError::BadLayers)?;
    let mut layers = std::vec![0u8; len];
    MaxPoolLayers::build(&view, map.free_below(), levels, &mut layers)
        .map_err(|_| MapImageError::BadLayers)?;
    let mut sections: std::vec::Vec<(u32, &[u8])> = std::vec::Vec::new();
    sections.push((SECTION_OCCUPIED, map.occupied_bits()));
    if let Some(free) = view.free_bits() {
        sections.push((SECTION_FREE, free));
    }
    sections.push((SECTION_MAX_POOL_LAYERS, &layers));
    encode_sections(&g, view.occupied_above(), map.free_below(), &sections)
}

/// An image of `sections` `(tag, body)` in order, each padded to 4 bytes.
#[cfg(feature = "std")]
fn encode_sections(
    geometry: &GridGeometry,
    occupied_above: i8,
    free_below: i8,
    sections: &[(u32, &[u8])],
) -> Result<std::vec::Vec<u8>, MapImageError> {
    let mut body = std::vec::Vec::new();
    for (tag, bytes) in sections {
        let len = u32::try_from(bytes.len()).map_err(|_| MapImageError::BadSection)?;
        body.extend_from_slice(&section_header(*tag, len));
        body.extend_from_slice(bytes);
        body.resize(body.len().next_multiple_of(4), 0);
    }
    let count = u16::try_from(sections.len()).map_err(|_| MapImageError::BadSection)?;
    let payload = u32::try_from(body.len()).map_err(|_| MapImageError::BadSection)?;
    let mut header = encode_header(geometry, occupied_above, free_below, count, payload)?;
    let mut crc = ImageChecksum::new(&header);
    crc.update(&body);
    crc.finish(&mut header);
    let mut out = std::vec::Vec::with_capacity(MAP_IMAGE_HEADER_LEN + body.len());
    out.extend_from_slice(&header);
    out.extend_from_slice(&body);
    Ok(out)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    fn sample() -> (Vec<i8>, GridGeometry) {
        let g = GridGeometry {
            width: 13,
            height: 5,
            resolution: 0.05,
            origin_x: -1.5,
            origin_y: 2.25,
        };
        let cells = (0..13 * 5)
            .map(|i| ((i * 41 + 7) % 81) as i8 - 40)
            .collect();
        (cells, g)
    }

    #[test]
    fn layers_added_to_an_image_of_bitmaps_equal_those_of_its_cells() {
        let (cells, g) = sample();
        let mut free = std::vec![0u8; occupancy_bytes(g.width, g.height)];
        for (i, &c) in cells.iter().enumerate() {
            if c < -20 {
                free[(i / g.width) * g.width.div_ceil(8) + (i % g.width) / 8] |=
                    1 << (i % g.width % 8);
            }
        }
        let bitmaps = encode_map_image(&cells, &g, 20, -20, &[(SECTION_FREE, &free)]).unwrap();
        let added = with_layers(&bitmaps, 2).unwrap();
        let from_cells = encode_map_image_with_layers(&cells, &g, 20, -20, 2).unwrap();
        let (a, b) = (
            MapImage::parse(&added).unwrap(),
            MapImage::parse(&from_cells).unwrap(),
        );
        assert_eq!(
            a.section(SECTION_MAX_POOL_LAYERS),
            b.section(SECTION_MAX_POOL_LAYERS)
        );
        assert_eq!(a.section(SECTION_FREE), Some(&free[..]));
        assert_eq!(with_layers(&bitmaps, 0), Err(MapImageError::BadLayers));
        assert_eq!(
            with_layers(&bitmaps[..10], 2).err(),
            Some(MapImageError::Truncated)
        );
    }

    #[test]
    fn round_trip_keeps_geometry_and_occupancy() {
        let (cells, g) = sample();
        let bytes = encode_map_image(&cells, &g, 20, -20, &[(0x100, &[1, 2, 3])]).unwrap();
        let image = MapImage::parse(&bytes).unwrap();
        assert_eq!(*image.geometry(), g);
        let full = GridView::new(&cells, g, 20).unwrap();
        let view = image.view();
        for y in 0..5 {
            for x in 0..13 {
                assert_eq!(view.is_occupied(x, y), full.is_occupied(x, y), "{x} {y}");
            }
        }
        assert_eq!((view.occupied_above(), image.free_below()), (20, -20));
        assert_eq!(image.section(0x100), Some(&[1u8, 2, 3][..]));
        assert_eq!(image.section(0x101), None);
        assert_eq!(image.len_bytes(), bytes.len());
        assert_eq!(bytes.len() % 4, 0);
    }

    #[test]
    fn an_image_is_read_from_the_start_of_a_longer_flash_region() {
        let (cells, g) = sample();
        let bytes = encode_map_image(&cells, &g, 20, -20, &[]).unwrap();
        let mut region = vec![0xFF_u8; bytes.len() + 1000];
        assert_eq!(
            MapImage::parse_at_start(&region).err(),
            Some(MapImageError::BadMagic)
        );
        region[..bytes.len()].copy_from_slice(&bytes);
        let image = MapImage::parse_at_start(&region).unwrap();
        assert_eq!(image.len_bytes(), bytes.len());
        assert_eq!(
            image.checksum(),
            MapImage::parse(&bytes).unwrap().checksum()
        );
        // The image cut by the region's end, or a byte of it changed, is refused.
        assert_eq!(
            MapImage::parse_at_start(&bytes[..bytes.len() - 4]).err(),
            Some(MapImageError::Truncated)
        );
        region[bytes.len() - 1] ^= 1;
        assert_eq!(
            MapImage::parse_at_start(&region).err(),
            Some(MapImageError::ChecksumMismatch)
        );
    }

    #[test]
    fn every_corruption_is_refused_without_panic() {
        let (cells, g) = sample();
        let bytes = encode_map_image(&cells, &g, 20, -20, &[]).unwrap();
        assert_eq!(MapImage::parse(&[]).err(), Some(MapImageError::Missing));
        // Every truncation, every single-bit flip: an error, never a panic, never Ok.
        for n in 1..bytes.len() {
            assert!(MapImage::parse(&bytes[..n]).is_err(), "truncated to {n}");
        }
        for i in 0..bytes.len() {
            for bit in 0..8 {
                let mut b = bytes.clone();
                b[i] ^= 1 << bit;
                assert!(MapImage::parse(&b).is_err(), "byte {i} bit {bit}");
            }
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(
            MapImage::parse(&longer).err(),
            Some(MapImageError::TrailingBytes)
        );
        let mut v2 = bytes.clone();
        v2[4] = 2;
        assert_eq!(
            MapImage::parse(&v2).err(),
            Some(MapImageError::UnsupportedVersion)
        );
        let mut magic = bytes.clone();
        magic[0] = b'X';
        assert_eq!(MapImage::parse(&magic).err(), Some(MapImageError::BadMagic));
        let mut crc = bytes;
        crc[MAP_IMAGE_HEADER_LEN + 9] ^= 0x10;
        assert_eq!(
            MapImage::parse(&crc).err(),
            Some(MapImageError::ChecksumMismatch)
        );
    }

    #[test]
    fn layers_round_trip_and_match_the_map() {
        let (cells, g) = sample();
        let bytes = encode_map_image_with_layers(&cells, &g, 20, -20, 3).unwrap();
        let image = MapImage::parse(&bytes).unwrap();
        let layers = image.layers().unwrap().unwrap();
        assert_eq!(layers.levels(), 3);
        // Every byte equals layers built from the cells directly.
        let full = GridView::new(&cells, g, 20).unwrap();
        assert_eq!(layers.verify(&full), Ok(()));
        let plain = encode_map_image(&cells, &g, 20, -20, &[]).unwrap();
        assert!(MapImage::parse(&plain).unwrap().layers().is_none());
        // Layers of another map (other threshold) are refused.
        let mut other = vec![0u8; MaxPoolLayers::bytes_for(13, 5, 2).unwrap()];
        let view = GridView::new(&cells, g, 10).unwrap();
        MaxPoolLayers::build(&view, -20, 2, &mut other).unwrap();
        let wrong =
            encode_map_image(&cells, &g, 20, -20, &[(SECTION_MAX_POOL_LAYERS, &other)]).unwrap();
        assert_eq!(
            MapImage::parse(&wrong).unwrap().layers().map(|r| r.err()),
            Some(Some(MapImageError::BadLayers))
        );
    }

    #[test]
    fn wrong_cell_count_is_refused() {
        let (cells, g) = sample();
        assert_eq!(
            encode_map_image(&cells[1..], &g, 20, -20, &[]).err(),
            Some(MapImageError::BitmapSizeMismatch)
        );
    }

    #[test]
    fn checksum_is_zlib_crc32() {
        // The CRC-32 of "123456789" (the catalogue's check value).
        assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
    }
}
