//! An append-only store of keyframe scans: while the robot maps, each keyframe (a scan
//! every half metre or so, with the filter's pose and the motion since the previous one)
//! is appended once and never changed; the loop closure and the map export read them
//! back by index, as often as they like.
//!
//! On a microcontroller the store is a region of on-chip NOR flash
//! ([`NorFlashStorage`] over any `embedded_storage::nor_flash::NorFlash`), erased once
//! when mapping starts ([`KeyframeStore::create`]) and then programmed record by record
//! ([`KeyframeStore::append`]); on the host and in tests it is RAM ([`RamStorage`]).
//! Every record has the same size, so keyframe `k` is read without an index
//! ([`KeyframeStore::read`]). Ranges are kept as millimetres in a `u16` (1 mm resolution,
//! up to 65.534 m): at decimation 2 a record's ranges take a quarter of the scan's
//! `f32` bytes.
//!
//! ```
//! use microslam::geometry::Pose2;
//! use microslam::sensors::lidar::LidarGeometry;
//! use microslam::slam::keyframes::{Keyframe, KeyframeStore, RamStorage, StoreError};
//!
//! // RAM here; on the robot a region of flash (`NorFlashStorage`).
//! let mut storage = RamStorage::<4096>::new();
//! // 181 beams, every second one kept: 91 per keyframe, 224 bytes of storage each.
//! let lidar = LidarGeometry::CARMEN_SICK_180;
//! // Lent (`&mut`), so that the storage is still ours when `open` fails.
//! let mut store = match KeyframeStore::open(&mut storage) {
//!     Ok(store) => store,
//!     Err(StoreError::NoStore) => KeyframeStore::create(&mut storage, &lidar, 2, 91)?,
//!     Err(other) => return Err(other),
//! };
//! let scan = [2.5f32; 181];
//! let step = Pose2::new(0.5, 0.0, 0.1);
//! let k = store.append(&Keyframe::new(step, Pose2::new(3.0, 1.0, 0.2), &scan))?;
//! let mut ranges = [0.0f32; 91];
//! let meta = store.read(k, &mut ranges)?;
//! assert_eq!((meta.motion, ranges[90]), (step, 2.5));
//!
//! // After a reset: the same bytes, opened again.
//! let store = KeyframeStore::open(store.into_storage())?;
//! assert_eq!(store.len(), 1);
//! # Ok::<(), StoreError>(())
//! ```
//!
//! # Layout (version 1, little-endian)
//!
//! The header, [`HEADER_BYTES`] = 56 bytes at offset 0:
//!
//! | offset | bytes | field |
//! | --- | --- | --- |
//! | 0 | 4 | magic `MSKF` |
//! | 4 | 2 | format version (1) |
//! | 6 | 2 | header length (56) |
//! | 8 | 4 | lidar `first_angle`, rad (`f32`) |
//! | 12 | 4 | lidar `angle_increment`, rad (`f32`) |
//! | 16 | 4 | lidar `min_range`, m (`f32`) |
//! | 20 | 4 | lidar `max_range`, m (`f32`) |
//! | 24 | 4 | lidar `no_return_range`, m (`f32`) |
//! | 28 | 12 | lidar mount pose `x, y` (m), `θ` (rad) (`3 × f32`) |
//! | 40 | 2 | decimation: every how many beams of a scan one is kept (`u16`) |
//! | 42 | 2 | beams `B` per record (`u16`) |
//! | 44 | 4 | slot bytes: from one record to the next (`u32`) |
//! | 48 | 4 | offset of record 0 (`u32`): 56, or 64 on flash with 16- to 64-byte words |
//! | 52 | 4 | CRC-32 (ISO-HDLC, as zlib's) of bytes 0–51 |
//!
//! Keyframe `k` is in slot `k` plus the number of torn slots before it (see power loss,
//! below), at `first_record + slot · slot_bytes`. A record is
//! [`record_bytes`]`(B) = 36 + 2 · B` bytes, padded with erased bytes to
//! [`slot_bytes`]`(B)`, a multiple of 8 (of the flash's write size if larger), so that
//! no two records share a flash word:
//!
//! | offset | bytes | field |
//! | --- | --- | --- |
//! | 0 | 2 | tag `KF` ([`RECORD_TAG`]): a record that was started never reads as erased |
//! | 2 | 2 | beams `B` (`u16`, as in the header) |
//! | 4 | 4 | keyframe index (`u32`): 0, 1, 2, … in order of appending |
//! | 8 | 12 | motion since the previous keyframe `x, y, θ` (`3 × f32`, bit for bit) |
//! | 20 | 12 | the filter's pose at the keyframe `x, y, θ` (`3 × f32`, bit for bit) |
//! | 32 | 2 B | ranges, mm (`u16`); [`RANGE_MISSING`] (`0xFFFF`) for no usable return |
//! | 32 + 2 B | 4 | CRC-32 of the header's CRC (4 bytes) followed by record bytes 0 … 31 + 2 B |
//!
//! | beams | record | slot | keyframes in 128 KB |
//! | --- | --- | --- | --- |
//! | 73 | 182 B | 184 B | 712 |
//! | 90 | 216 B | 216 B | 606 |
//! | 181 (SICK, every beam) | 398 B | 400 B | 327 |
//!
//! A range is stored when the lidar would use it
//! ([`crate::sensors::lidar::LidarGeometry::classify`] says `Valid`) and it is below
//! 65.535 m, rounded to the nearest millimetre that still reads back as usable
//! ([`range_to_millimetres`]). NaN, ±∞, ranges outside `[min_range, max_range)` or at
//! the no-return range are stored as missing and read back as NaN: the scan → points
//! path ([`crate::sensors::lidar::LidarScan::beams`]) skips them as it skipped the
//! originals. [`KeyframeStore::read_scan`] puts a record back into the layout of its
//! scan, so the points come out at the same beam angles, bit for bit.
//!
//! # Power loss
//!
//! A record is programmed in one go, in increasing order of address; a reset in the
//! middle leaves a *torn* record: some bytes programmed, its CRC wrong. NOR flash cannot
//! program a word twice between erases, so nothing is ever written over it. Instead:
//!
//! - [`KeyframeStore::open`] reads the slots in order: a whole record (tag, beam count,
//!   CRC, and the next index in sequence) counts; a slot that is written but not a whole
//!   record is torn and skipped; the first erased slot is the end, and the next append
//!   goes there. So the keyframes before the cut are all kept and indices stay dense
//!   (`0 .. len`): the torn record is lost, nothing else. Up to [`MAX_TORN_RECORDS`]
//!   torn slots are remembered (32 bytes of RAM); past that, and when a whole record is
//!   out of sequence (bytes damaged some other way), `open` still succeeds and every
//!   keyframe before is readable, but appends are refused
//!   ([`KeyframeStore::append_refused`]): export the map and create the store anew.
//! - A write that fails while powered is handled the same way by
//!   [`KeyframeStore::append`] itself (the slot is read back).
//! - A header torn while the store was created fails `open` ([`StoreError::NoStore`],
//!   [`StoreError::BadMagic`], [`StoreError::HeaderChecksum`], …): create it again.
//!
//! A cut so early that no bit changed leaves the slot erased, and the next record is
//! programmed there. That is right for flash whose words can be programmed wherever they
//! read erased (the STM32F4's); flash with an ECC per word (STM32L4, G4, H7) may instead
//! leave a word that reads erased but cannot be programmed, or does not read at all: this
//! store does not handle that.
//!
//! Records also carry the header's CRC in theirs: a record left from a store of another
//! geometry (an erase cut short) never passes as one of this store's.

mod error;
mod format;
mod storage;
mod store;
#[cfg(test)]
mod tests;

pub use error::StoreError;
pub use format::{
    HEADER_BYTES, MAX_RANGE_MM, MAX_WRITE_SIZE, RANGE_MISSING, RECORD_TAG, SLOT_ALIGN, STORE_MAGIC,
    STORE_VERSION, millimetres_to_range, range_to_millimetres, record_bytes, slot_bytes,
    store_bytes,
};
pub use storage::{KeyframeStorage, NorFlashStorage, RamStorage};
pub use store::{Keyframe, KeyframeMeta, KeyframeStore};

/// Torn records a store skips before it refuses appends ([`StoreError::TooManyTorn`]):
/// at most one per power loss that falls inside an append (a write of a few milliseconds
/// per keyframe), so eight is more than a mapping run meets.
pub const MAX_TORN_RECORDS: usize = 8;
