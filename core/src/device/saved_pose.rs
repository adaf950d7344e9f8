//! The robot's pose kept in NOR flash across resets and power loss ([`PoseStore`]).
//!
//! A device that made a map, or localizes in one, writes where the robot is every few
//! scans; after a reset it starts the localizer there instead of searching the whole map.
//! What is written must never be read back wrong: a record is written in one piece and
//! checked with a CRC-32, and power lost in the middle of a write leaves the record
//! before it as the one loaded.
//!
//! # Layout
//!
//! Two sectors of the same size (each a multiple of the flash's erase unit), written in
//! turn: records are appended to one sector until it is full; the next record erases the
//! other sector and starts it. The newest valid record (the highest sequence number)
//! of the two is the saved pose, so an erase or a write cut short loses at most the
//! record being written. Each record is [`RECORD_BYTES`] bytes, little-endian:
//!
//! | offset | size | content |
//! |---|---|---|
//! | 0 | 4 | magic `b"MSPS"` |
//! | 4 | 1 | format version, [`VERSION`] |
//! | 5 | 3 | zero |
//! | 8 | 4 | sequence number (`u32`, one more than the record before) |
//! | 12 | 12 | x, y (m), heading (rad) (`f32`, finite) |
//! | 24 | 4 | the CRC-32 of the map image the pose is in ([`crate::grid::MapImage::checksum`]) |
//! | 28 | 4 | CRC-32 of bytes 0–27 |
//!
//! The first byte (`M`, `0x4D`) is never `0xFF`, even when power is cut while it is
//! being programmed, so a slot that reads as erased was never written: the store never
//! programs a flash word twice between erases.

use crate::checksum::CRC32;
use crate::geometry::{Pose2, wrap_angle};
use crate::wire::{ToHost, TrackingState};
use core::fmt;
use embedded_storage::nor_flash::NorFlash;

/// Bytes of one record.
pub const RECORD_BYTES: usize = 32;
/// Format version of the records this build writes and reads.
pub const VERSION: u8 = 1;
const MAGIC: [u8; 4] = *b"MSPS";
const CRC_AT: usize = 28;

/// A pose read back from flash.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SavedPose {
    /// Where the robot was, in the map's frame.
    pub pose: Pose2<f32>,
    /// The CRC-32 of the map image the pose is in: a pose is used only with that map.
    pub map_checksum: u32,
    /// The record's sequence number (one more than the one before it).
    pub sequence: u32,
}

/// Why the store refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PoseStoreError {
    /// The sectors do not start and end on the flash's erase units, or hold no record, or
    /// the flash's read or write unit does not divide [`RECORD_BYTES`].
    Misaligned,
    /// The two sectors are not inside the flash.
    OutOfBounds,
    /// A pose that is not finite: not written.
    NotFinite,
    /// The flash driver failed (a write or erase cut short, a bus error). The record
    /// being written is lost; the one before stays the saved pose.
    Flash,
}

impl fmt::Display for PoseStoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Misaligned => {
                "pose store sectors are not aligned to the flash's erase, read and write units"
            }
            Self::OutOfBounds => "pose store sectors are not inside the flash",
            Self::NotFinite => "the pose to save is not finite",
            Self::Flash => "the flash refused a write or an erase of the pose store",
        })
    }
}

impl core::error::Error for PoseStoreError {}

/// The robot's last pose in two sectors of NOR flash (see the [module docs](self)).
#[derive(Debug)]
pub struct PoseStore<F> {
    flash: F,
    start: u32,
    sector: u32,
    /// Where the next record goes: sector (0 or 1) and slot.
    next: (u32, u32),
    latest: Option<SavedPose>,
    /// Records read at open that were not valid (torn by a power cut, or corrupt).
    torn: u32,
}

impl<F: NorFlash> PoseStore<F> {
    /// The store in the two sectors of `sector_bytes` each from `start` of `flash`,
    /// reading what they hold: [`PoseStore::latest`] is the newest valid record.
    pub fn open(flash: F, start: u32, sector_bytes: u32) -> Result<Self, PoseStoreError> {
        let erase = F::ERASE_SIZE.max(1);
        let aligned = |x: u32| (x as usize).is_multiple_of(erase);
        let unit_ok = |u: usize| u > 0 && RECORD_BYTES.is_multiple_of(u);
        if !aligned(start)
            || !aligned(sector_bytes)
            || (sector_bytes as usize) < RECORD_BYTES
            || !unit_ok(F::READ_SIZE)
            || !unit_ok(F::WRITE_SIZE)
        {
            return Err(PoseStoreError::Misaligned);
        }
        let end = sector_bytes
            .checked_mul(2)
            .and_then(|len| start.checked_add(len))
            .ok_or(PoseStoreError::OutOfBounds)?;
        if end as usize > flash.capacity() {
            return Err(PoseStoreError::OutOfBounds);
        }
        let mut store = Self {
            flash,
            start,
            sector: sector_bytes,
            next: (0, 0),
            latest: None,
            torn: 0,
        };
        store.scan()?;
        Ok(store)
    }

    /// The newest valid pose of the store, when there is one.
    pub fn latest(&self) -> Option<SavedPose> {
        self.latest
    }

    /// The newest valid pose saved in the map with CRC-32 `map_checksum`: `None` when
    /// the newest pose is in another map (or there is none).
    pub fn latest_in(&self, map_checksum: u32) -> Option<Pose2<f32>> {
        self.latest
            .filter(|s| s.map_checksum == map_checksum)
            .map(|s| s.pose)
    }

    /// Records found at open that were not valid: torn by a power cut, or corrupt.
    pub fn torn_records(&self) -> u32 {
        self.torn
    }

    /// Records a sector holds.
    pub fn records_per_sector(&self) -> u32 {
        self.sector / RECORD_BYTES as u32
    }

    /// The flash back.
    pub fn into_inner(self) -> F {
        self.flash
    }

    /// Saves `pose` (in the map with CRC-32 `map_checksum`) as the newest record. On an
    /// error the record is lost and the one before it stays the saved pose; the next
    /// save goes on after it.
    pub fn save(&mut self, pose: Pose2<f32>, map_checksum: u32) -> Result<(), PoseStoreError> {
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return Err(PoseStoreError::NotFinite);
        }
        let sequence = self.latest.map_or(0, |s| s.sequence.wrapping_add(1));
        let (mut sector, mut slot) = self.next;
        if slot >= self.records_per_sector() {
            // The sector is full: the other one is erased and started. Until the record
            // is in it, the full sector keeps the newest pose.
            sector ^= 1;
            slot = 0;
            let from = self.start + sector * self.sector;
            self.flash
                .erase(from, from + self.sector)
                .map_err(|_| PoseStoreError::Flash)?;
        }
        // From here the slot may be partly programmed whatever happens: never again.
        self.next = (sector, slot + 1);
        let record = encode(pose, map_checksum, sequence);
        self.flash
            .write(self.address(sector, slot), &record)
            .map_err(|_| PoseStoreError::Flash)?;
        self.latest = Some(SavedPose {
            pose,
            map_checksum,
            sequence,
        });
        Ok(())
    }

    fn address(&self, sector: u32, slot: u32) -> u32 {
        self.start + sector * self.sector + slot * RECORD_BYTES as u32
    }

    /// Reads both sectors: the newest valid record, and where the next one goes (after
    /// the last slot written in the newest record's sector).
    fn scan(&mut self) -> Result<(), PoseStoreError> {
        let mut written = [0u32; 2];
        let mut newest: Option<(u32, SavedPose)> = None;
        for sector in 0..2 {
            for slot in 0..self.records_per_sector() {
                let mut bytes = [0u8; RECORD_BYTES];
                self.flash
                    .read(self.address(sector, slot), &mut bytes)
                    .map_err(|_| PoseStoreError::Flash)?;
                if bytes.iter().all(|&b| b == 0xFF) {
                    continue;
                }
                written[sector as usize] = slot + 1;
                match decode(&bytes) {
                    Some(saved) => {
                        if newest.is_none_or(|(_, n)| newer(saved.sequence, n.sequence)) {
                            newest = Some((sector, saved));
                        }
                    }
                    None => self.torn = self.torn.saturating_add(1),
                }
            }
        }
        self.latest = newest.map(|(_, s)| s);
        self.next = match newest {
            Some((sector, _)) => (sector, written[sector as usize]),
            // Nothing valid: the next record erases sector 0 and starts it.
            None => (1, self.records_per_sector()),
        };
        Ok(())
    }
}

/// When a firmware writes the robot's pose into its [`PoseStore`]: the rule, in one
/// place, that the firmware follows and a host reproduces to know where the device
/// starts after a reset.
///
/// - After [`ToHost::MapSaved`]: the pose at the end of the run, in the map just saved.
/// - While the localizer tracks ([`ToHost::Localization`], [`TrackingState::Tracking`]):
///   its pose, whenever it is [`PoseKeeping::MIN_DISTANCE_M`] or
///   [`PoseKeeping::MIN_TURN_RAD`] from the pose last written. A robot standing still
///   writes nothing (flash wears with every erase), a driving one about every half
///   metre: a power cut loses at most that much of its way.
/// - Before a reset it was told to make ([`PoseKeeping::before_restart`]): the newest
///   tracked pose, so that nothing is lost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseKeeping {
    map_checksum: Option<u32>,
    last: Option<Pose2<f32>>,
    /// The newest tracked pose, written or not.
    newest: Option<Pose2<f32>>,
}

impl PoseKeeping {
    /// Distance from the pose last written at which the next is written, m.
    pub const MIN_DISTANCE_M: f32 = 0.5;
    /// Turn from the pose last written at which the next is written, rad.
    pub const MIN_TURN_RAD: f32 = 0.5;

    /// Keeping poses in the map with CRC-32 `map_checksum` (the map the localizer runs
    /// on; `None` while mapping), `last` the pose written last (loaded at boot).
    pub fn new(map_checksum: Option<u32>, last: Option<Pose2<f32>>) -> Self {
        Self {
            map_checksum,
            last,
            newest: last,
        }
    }

    /// The pose to write before a reset the firmware was told to make (`Restart`): the
    /// newest tracked pose when it was not written yet, so that the localizer starts
    /// after the reset exactly where it stopped. `None` when nothing is to be written.
    pub fn before_restart(&mut self) -> Option<(Pose2<f32>, u32)> {
        let pose = self.newest.filter(|n| Some(*n) != self.last)?;
        let checksum = self.map_checksum?;
        self.last = Some(pose);
        Some((pose, checksum))
    }

    /// The pose to write after `reply`, and the CRC-32 of the map it is in; `None` when
    /// nothing is to be written.
    pub fn after(&mut self, reply: &ToHost) -> Option<(Pose2<f32>, u32)> {
        let (pose, checksum) = match reply {
            ToHost::MapSaved { checksum, pose, .. } => {
                self.map_checksum = Some(*checksum);
                (Pose2::new(pose[0], pose[1], pose[2]), *checksum)
            }
            ToHost::Localization {
                estimate,
                localizer,
            } if localizer.state == TrackingState::Tracking => {
                let [x, y, theta] = estimate.pose;
                let pose = Pose2::new(x, y, theta);
                self.newest = Some(pose);
                let far = self.last.is_none_or(|last| {
                    libm::hypotf(pose.x - last.x, pose.y - last.y) >= Self::MIN_DISTANCE_M
                        || libm::fabsf(wrap_angle(pose.theta - last.theta)) >= Self::MIN_TURN_RAD
                });
                (pose, self.map_checksum.filter(|_| far)?)
            }
            _ => return None,
        };
        self.last = Some(pose);
        self.newest = Some(pose);
        Some((pose, checksum))
    }
}

/// `a` is a later sequence number than `b` (through the wrap of `u32`).
fn newer(a: u32, b: u32) -> bool {
    let d = a.wrapping_sub(b);
    d != 0 && d < u32::MAX / 2
}

fn encode(pose: Pose2<f32>, map_checksum: u32, sequence: u32) -> [u8; RECORD_BYTES] {
    let mut b = [0u8; RECORD_BYTES];
    let fields: [(usize, [u8; 4]); 5] = [
        (8, sequence.to_le_bytes()),
        (12, pose.x.to_le_bytes()),
        (16, pose.y.to_le_bytes()),
        (20, pose.theta.to_le_bytes()),
        (24, map_checksum.to_le_bytes()),
    ];
    b[..4].copy_from_slice(&MAGIC);
    b[4] = VERSION;
    for (at, v) in fields {
        b[at..at + 4].copy_from_slice(&v);
    }
    let crc = CRC32.checksum(&b[..CRC_AT]);
    b[CRC_AT..].copy_from_slice(&crc.to_le_bytes());
    b
}

fn decode(b: &[u8; RECORD_BYTES]) -> Option<SavedPose> {
    let word = |at: usize| -> Option<[u8; 4]> { b.get(at..at + 4)?.try_into().ok() };
    if b.get(..4)? != MAGIC || b[4] != VERSION {
        return None;
    }
    if u32::from_le_bytes(word(CRC_AT)?) != CRC32.checksum(b.get(..CRC_AT)?) {
        return None;
    }
    let f = |at: usize| word(at).map(f32::from_le_bytes);
    let pose = Pose2::new(f(12)?, f(16)?, f(20)?);
    if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
        return None;
    }
    Some(SavedPose {
        pose,
        map_checksum: u32::from_le_bytes(word(24)?),
        sequence: u32::from_le_bytes(word(8)?),
    })
}

#[cfg(test)]
mod tests;
