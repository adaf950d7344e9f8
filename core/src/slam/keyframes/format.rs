//! The bytes of a keyframe store: the header, the size of a record, and ranges as
//! millimetres. The tables are in the module documentation of [`super`].

use super::StoreError;
use crate::geometry::Pose2;
use crate::sensors::lidar::{BeamStatus, LidarGeometry};

/// The first four bytes of every store.
pub const STORE_MAGIC: [u8; 4] = *b"MSKF";
/// The format version this code writes and reads.
pub const STORE_VERSION: u16 = 1;
/// Length of the store header, bytes (the first record follows at the next multiple of
/// [`SLOT_ALIGN`] and of the flash's write size: byte 56 on flash written in units of up
/// to 8 bytes).
pub const HEADER_BYTES: usize = 56;
/// The first two bytes of every record (`KF`): never `0xFF`, so a record that was started
/// never reads as erased.
pub const RECORD_TAG: [u8; 2] = *b"KF";
/// A range that was not stored (no usable return): read back as NaN.
pub const RANGE_MISSING: u16 = u16::MAX;
/// The longest range a record holds, millimetres (65.534 m); longer usable readings are
/// stored as [`RANGE_MISSING`].
pub const MAX_RANGE_MM: u16 = u16::MAX - 1;
/// Records start at multiples of this (and of the flash's write size, if larger), so that
/// a store written on flash with 1-, 2-, 4- or 8-byte words has the same layout
/// everywhere, and no two records share a flash word.
pub const SLOT_ALIGN: usize = 8;
/// The largest flash write or read unit the store handles, bytes (records are written
/// and read through a buffer of this size).
pub const MAX_WRITE_SIZE: usize = 64;

/// Bytes of a record before its ranges: tag, beam count, index, motion, pose.
pub(super) const RECORD_FIXED_BYTES: usize = 32;
/// Bytes of a record's CRC-32.
pub(super) const CRC_BYTES: usize = 4;
/// Where the header's CRC-32 is.
const HEADER_CRC_AT: usize = 52;

/// CRC-32 (ISO-HDLC, as zlib's) of headers and records.
pub(super) use crate::checksum::CRC32;

/// Bytes of one record of `beams` ranges, without the padding to its slot:
/// `32 + 2 · beams + 4` (90 beams: 216; 73 beams: 182).
pub const fn record_bytes(beams: usize) -> usize {
    beams
        .saturating_mul(2)
        .saturating_add(RECORD_FIXED_BYTES + CRC_BYTES)
}

/// `bytes` rounded up to a multiple of `align` (a power of two), saturating.
pub(super) const fn round_up(bytes: usize, align: usize) -> usize {
    let mask = align.saturating_sub(1);
    bytes.saturating_add(mask) & !mask
}

/// Bytes of storage one record of `beams` ranges takes on flash written in units of at
/// most [`SLOT_ALIGN`] bytes (and in RAM): [`record_bytes`] rounded up to a multiple of 8
/// (90 beams: 216; 73 beams: 184).
pub const fn slot_bytes(beams: usize) -> usize {
    round_up(record_bytes(beams), SLOT_ALIGN)
}

/// Bytes of storage a store of `keyframes` records of `beams` ranges takes on flash
/// written in units of at most 8 bytes: the header and the slots
/// (`56 + keyframes · slot_bytes(beams)`).
pub const fn store_bytes(beams: usize, keyframes: usize) -> usize {
    keyframes
        .saturating_mul(slot_bytes(beams))
        .saturating_add(HEADER_BYTES)
}

/// The alignment of slots on a storage written in units of `write_size` bytes.
pub(super) fn slot_align(write_size: usize) -> Result<usize, StoreError> {
    if write_size == 0 || !write_size.is_power_of_two() || write_size > MAX_WRITE_SIZE {
        return Err(StoreError::Misaligned);
    }
    Ok(write_size.max(SLOT_ALIGN))
}

/// The header's content: what the records are and where they are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Header {
    pub lidar: LidarGeometry,
    pub decimation: u16,
    pub beams: u16,
    /// Bytes from one record to the next.
    pub slot_bytes: u32,
    /// Where record 0 starts.
    pub first_record: u32,
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

/// A pose from 12 little-endian bytes at `at` (bit for bit).
pub(super) fn pose_at(b: &[u8], at: usize) -> Option<Pose2<f32>> {
    Some(Pose2::new(
        f32_at(b, at)?,
        f32_at(b, at + 4)?,
        f32_at(b, at + 8)?,
    ))
}

/// Writes `pose` as 12 little-endian bytes at `at`.
pub(super) fn put_pose(b: &mut [u8], at: usize, pose: &Pose2<f32>) {
    put(b, at, &pose.x.to_le_bytes());
    put(b, at + 4, &pose.y.to_le_bytes());
    put(b, at + 8, &pose.theta.to_le_bytes());
}

fn put(b: &mut [u8], at: usize, bytes: &[u8]) {
    if let Some(slot) = b.get_mut(at..at + bytes.len()) {
        slot.copy_from_slice(bytes);
    }
}

impl Header {
    /// The header's bytes, its CRC-32 included.
    pub fn encode(&self) -> [u8; HEADER_BYTES] {
        let mut b = [0u8; HEADER_BYTES];
        let g = &self.lidar;
        put(&mut b, 0, &STORE_MAGIC);
        put(&mut b, 4, &STORE_VERSION.to_le_bytes());
        put(&mut b, 6, &(HEADER_BYTES as u16).to_le_bytes());
        let fields = [
            g.first_angle,
            g.angle_increment,
            g.min_range,
            g.max_range,
            g.no_return_range,
        ];
        for (i, v) in fields.iter().enumerate() {
            put(&mut b, 8 + 4 * i, &v.to_le_bytes());
        }
        put_pose(&mut b, 28, &g.mount);
        put(&mut b, 40, &self.decimation.to_le_bytes());
        put(&mut b, 42, &self.beams.to_le_bytes());
        put(&mut b, 44, &self.slot_bytes.to_le_bytes());
        put(&mut b, 48, &self.first_record.to_le_bytes());
        let crc = CRC32.checksum(b.get(..HEADER_CRC_AT).unwrap_or(&[]));
        put(&mut b, HEADER_CRC_AT, &crc.to_le_bytes());
        b
    }

    /// Checks and reads a header: erased, magic, version, length, CRC-32, then the fields.
    pub fn decode(b: &[u8; HEADER_BYTES]) -> Result<Self, StoreError> {
        if b.iter().all(|&x| x == 0xFF) {
            return Err(StoreError::NoStore);
        }
        if b.get(..4) != Some(&STORE_MAGIC[..]) {
            return Err(StoreError::BadMagic);
        }
        if u16_at(b, 4) != Some(STORE_VERSION) {
            return Err(StoreError::UnsupportedVersion);
        }
        if u16_at(b, 6).map(usize::from) != Some(HEADER_BYTES) {
            return Err(StoreError::BadHeader);
        }
        let crc = CRC32.checksum(b.get(..HEADER_CRC_AT).unwrap_or(&[]));
        if u32_at(b, HEADER_CRC_AT) != Some(crc) {
            return Err(StoreError::HeaderChecksum);
        }
        let real = |at| f32_at(b, at).ok_or(StoreError::BadHeader);
        let lidar = LidarGeometry {
            first_angle: real(8)?,
            angle_increment: real(12)?,
            min_range: real(16)?,
            max_range: real(20)?,
            no_return_range: real(24)?,
            mount: pose_at(b, 28).ok_or(StoreError::BadHeader)?,
        };
        let header = Self {
            lidar,
            decimation: u16_at(b, 40).ok_or(StoreError::BadHeader)?,
            beams: u16_at(b, 42).ok_or(StoreError::BadHeader)?,
            slot_bytes: u32_at(b, 44).ok_or(StoreError::BadHeader)?,
            first_record: u32_at(b, 48).ok_or(StoreError::BadHeader)?,
        };
        let slot = header.slot_bytes as usize;
        if !lidar.is_valid()
            || header.decimation == 0
            || header.beams == 0
            || slot < record_bytes(usize::from(header.beams))
            || (header.first_record as usize) < HEADER_BYTES
        {
            return Err(StoreError::BadHeader);
        }
        Ok(header)
    }

    /// The header's CRC-32: it seeds every record's CRC, so records of another store
    /// (another geometry) never pass as this one's.
    pub fn crc(&self) -> u32 {
        let b = self.encode();
        u32_at(&b, HEADER_CRC_AT).unwrap_or(0)
    }

    /// Bytes of a record without padding.
    pub fn record_bytes(&self) -> usize {
        record_bytes(usize::from(self.beams))
    }
}

/// `range` (metres) as the millimetres a record stores, or [`RANGE_MISSING`] when the
/// lidar could not use it (NaN, ±∞, outside `[min_range, max_range)`, at or beyond the
/// no-return range) or it is beyond [`MAX_RANGE_MM`]. A usable range is rounded to the
/// nearest millimetre that reads back ([`millimetres_to_range`]) as usable too, so that
/// the beams a reader uses are exactly those the live scan had; when no millimetre in
/// the usable interval is within 1 mm (limits closer than that), it is stored missing.
pub fn range_to_millimetres(lidar: &LidarGeometry, range: f32) -> u16 {
    if lidar.classify(range) != BeamStatus::Valid {
        return RANGE_MISSING;
    }
    let mm = libm::roundf(range * 1000.0);
    // `range` is finite and ≥ min_range ≥ 0 here, but `range · 1000` may overflow to ∞.
    if mm.is_nan() || mm > f32::from(MAX_RANGE_MM) {
        return RANGE_MISSING;
    }
    let q = mm as u16;
    let usable =
        |q: u16| q <= MAX_RANGE_MM && lidar.classify(millimetres_to_range(q)) == BeamStatus::Valid;
    if usable(q) {
        return q;
    }
    // Rounding crossed a limit: one millimetre back inside, still within 1 mm of `range`.
    let inside = if millimetres_to_range(q) < lidar.min_range {
        q.checked_add(1)
    } else {
        q.checked_sub(1)
    };
    match inside {
        Some(q) if usable(q) => q,
        _ => RANGE_MISSING,
    }
}

/// The range (metres) a stored value stands for: `mm / 1000` rounded to the nearest
/// `f32`, or NaN for [`RANGE_MISSING`].
pub fn millimetres_to_range(mm: u16) -> f32 {
    if mm == RANGE_MISSING {
        f32::NAN
    } else {
        f32::from(mm) / 1000.0
    }
}
