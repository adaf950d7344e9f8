//! [`KeyframeStore`]: create or open a store, append keyframes, read them back.

use super::format::{
    CRC_BYTES, CRC32, Header, RECORD_FIXED_BYTES, RECORD_TAG, millimetres_to_range, pose_at,
    put_pose, range_to_millimetres, record_bytes, round_up, slot_align,
};
use super::{HEADER_BYTES, KeyframeStorage, MAX_TORN_RECORDS, MAX_WRITE_SIZE, StoreError};
use crate::geometry::Pose2;
use crate::sensors::lidar::LidarGeometry;

/// Records are written and read through a buffer of this many bytes.
const CHUNK: usize = MAX_WRITE_SIZE;

/// One keyframe to append: where the robot is and how it got there, and its scan.
#[derive(Clone, Copy, Debug)]
pub struct Keyframe<'a> {
    /// The motion since the previous keyframe (the chain's edge), in the previous
    /// keyframe's frame; anything for the first.
    pub motion: Pose2<f32>,
    /// The filter's pose estimate at this keyframe.
    pub pose: Pose2<f32>,
    /// The whole scan as the lidar gave it (metres, beam 0 first): the store keeps every
    /// `decimation`-th range.
    pub ranges: &'a [f32],
}

impl<'a> Keyframe<'a> {
    /// A keyframe from its motion, pose and scan.
    pub const fn new(motion: Pose2<f32>, pose: Pose2<f32>, ranges: &'a [f32]) -> Self {
        Self {
            motion,
            pose,
            ranges,
        }
    }
}

/// What a record holds besides its ranges, bit for bit as appended.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeyframeMeta {
    /// The keyframe's index: 0 for the first appended, then 1, 2, …
    pub index: u32,
    /// The motion since the previous keyframe.
    pub motion: Pose2<f32>,
    /// The filter's pose estimate at the keyframe.
    pub pose: Pose2<f32>,
}

/// What a slot holds.
enum Slot {
    /// Every byte `0xFF`: never written.
    Erased,
    /// Written, but not a whole record of this store (torn by power loss, or damaged).
    Bad,
    /// A whole record.
    Valid(KeyframeMeta),
}

/// An append-only store of keyframe scans over a [`KeyframeStorage`]: the header, then
/// one fixed-size slot per record, so that keyframe `k` is found without an index. See
/// the [module documentation](super) for the layout and what power loss does.
///
/// RAM: the storage, plus 96 bytes.
#[derive(Debug)]
pub struct KeyframeStore<S> {
    storage: S,
    header: Header,
    /// The header's CRC-32, which seeds every record's.
    store_crc: u32,
    /// Slots the storage holds.
    slots: u32,
    /// Keyframes stored.
    len: u32,
    /// The slot the next record goes to.
    next_slot: u32,
    /// Slots skipped because a record there was torn, in increasing order.
    torn: [u32; MAX_TORN_RECORDS],
    torn_len: u8,
    /// Why appends are refused, if they are.
    refused: Option<StoreError>,
}

/// Streams a record into the storage through a [`CHUNK`]-byte buffer, computing its
/// CRC on the way.
struct RecordWriter {
    at: usize,
    buf: [u8; CHUNK],
    len: usize,
    digest: crc::Digest<'static, u32>,
}

impl RecordWriter {
    fn new(at: usize, store_crc: u32) -> Self {
        let mut digest = CRC32.digest();
        digest.update(&store_crc.to_le_bytes());
        Self {
            at,
            buf: [0xFF; CHUNK],
            len: 0,
            digest,
        }
    }

    fn push(&mut self, storage: &mut impl KeyframeStorage, bytes: &[u8]) -> Result<(), StoreError> {
        self.digest.update(bytes);
        self.buffer(storage, bytes)
    }

    fn buffer(
        &mut self,
        storage: &mut impl KeyframeStorage,
        bytes: &[u8],
    ) -> Result<(), StoreError> {
        for &b in bytes {
            if let Some(slot) = self.buf.get_mut(self.len) {
                *slot = b;
                self.len += 1;
            }
            if self.len == CHUNK {
                self.flush(storage)?;
            }
        }
        Ok(())
    }

    fn flush(&mut self, storage: &mut impl KeyframeStorage) -> Result<(), StoreError> {
        if self.len > 0 {
            storage.write(self.at, self.buf.get(..self.len).unwrap_or(&[]))?;
            self.at += self.len;
            self.len = 0;
        }
        Ok(())
    }

    /// Appends the CRC-32 and writes what is buffered.
    fn finish(mut self, storage: &mut impl KeyframeStorage) -> Result<(), StoreError> {
        let crc = self.digest.clone().finalize();
        self.buffer(storage, &crc.to_le_bytes())?;
        self.flush(storage)
    }
}

impl<S: KeyframeStorage> KeyframeStore<S> {
    /// Starts a store on `storage`: erases all of it (on flash this takes as long as
    /// erasing the region: seconds for large sectors), then writes the header. The
    /// store keeps every `decimation`-th range of scans taken with `lidar`, `beams`
    /// ranges per keyframe (`scan length.div_ceil(decimation)`).
    ///
    /// Refused with [`StoreError::InvalidGeometry`] for an invalid lidar geometry, or a
    /// decimation or beam count outside `1 ..= 65 535`; with [`StoreError::TooSmall`] when
    /// the storage cannot hold the header and one record; with
    /// [`StoreError::Misaligned`] for a write size the store cannot handle.
    pub fn create(
        mut storage: S,
        lidar: &LidarGeometry,
        decimation: usize,
        beams: usize,
    ) -> Result<Self, StoreError> {
        let positive = |n: usize| u16::try_from(n).ok().filter(|&n| n > 0);
        let (Some(decimation), Some(beams)) = (positive(decimation), positive(beams)) else {
            return Err(StoreError::InvalidGeometry);
        };
        if !lidar.is_valid() {
            return Err(StoreError::InvalidGeometry);
        }
        let align = slot_align(storage.write_size())?;
        let slot = round_up(record_bytes(usize::from(beams)), align);
        let first = round_up(HEADER_BYTES, align);
        let header = Header {
            lidar: *lidar,
            decimation,
            beams,
            slot_bytes: u32::try_from(slot).map_err(|_| StoreError::TooSmall)?,
            first_record: u32::try_from(first).map_err(|_| StoreError::TooSmall)?,
        };
        if storage.capacity() < first.saturating_add(slot) {
            return Err(StoreError::TooSmall);
        }
        storage.erase_all()?;
        storage.write(0, &header.encode())?;
        Ok(Self::with_header(storage, header))
    }

    /// Opens the store on `storage` (after a reset, or to read a finished map): checks
    /// the header, then reads every slot up to the first erased one and checks its CRC to
    /// count the keyframes (every used byte is read once: 216 KB for a thousand 90-beam
    /// keyframes). A slot torn by power loss is skipped; see the
    /// [module documentation](super).
    ///
    /// Refused with [`StoreError::NoStore`] when the header bytes are erased,
    /// [`StoreError::BadMagic`], [`StoreError::UnsupportedVersion`],
    /// [`StoreError::HeaderChecksum`] or [`StoreError::BadHeader`] when they are not a
    /// header this code wrote, [`StoreError::Misaligned`] when its slots do not fit the
    /// storage's write size, [`StoreError::TooSmall`] when the storage is shorter than a
    /// header. The storage is dropped with the error: lend it (`open(&mut storage)`,
    /// [`KeyframeStorage`] is implemented for `&mut` one) to create a store after
    /// [`StoreError::NoStore`].
    pub fn open(storage: S) -> Result<Self, StoreError> {
        let mut bytes = [0u8; HEADER_BYTES];
        if storage.capacity() < HEADER_BYTES {
            return Err(StoreError::TooSmall);
        }
        storage.read(0, &mut bytes)?;
        let header = Header::decode(&bytes)?;
        let unit = storage.write_size();
        slot_align(unit)?;
        if !(header.slot_bytes as usize).is_multiple_of(unit)
            || !(header.first_record as usize).is_multiple_of(unit)
        {
            return Err(StoreError::Misaligned);
        }
        let mut store = Self::with_header(storage, header);
        while store.next_slot < store.slots {
            match store.visit_slot(store.next_slot, |_, _| {})? {
                Slot::Erased => break,
                Slot::Valid(meta) if meta.index == store.len => store.len += 1,
                Slot::Valid(_) => {
                    // A whole record, but not the next keyframe: the store's sequence is
                    // broken, so where it ends is unknown.
                    store.refused = Some(StoreError::Damaged);
                    break;
                }
                Slot::Bad => {
                    if !store.skip_torn(store.next_slot) {
                        store.refused = Some(StoreError::TooManyTorn);
                        break;
                    }
                    continue;
                }
            }
            store.next_slot += 1;
        }
        Ok(store)
    }

    fn with_header(storage: S, header: Header) -> Self {
        let room = storage
            .capacity()
            .saturating_sub(header.first_record as usize);
        let slots = room / (header.slot_bytes as usize).max(1);
        Self {
            storage,
            store_crc: header.crc(),
            header,
            slots: u32::try_from(slots).unwrap_or(u32::MAX),
            len: 0,
            next_slot: 0,
            torn: [0; MAX_TORN_RECORDS],
            torn_len: 0,
            refused: None,
        }
    }

    /// Records slot `slot` as torn and moves past it; `false` when the table is full.
    fn skip_torn(&mut self, slot: u32) -> bool {
        match self.torn.get_mut(usize::from(self.torn_len)) {
            Some(entry) => {
                *entry = slot;
                self.torn_len += 1;
                self.next_slot = slot + 1;
                true
            }
            None => false,
        }
    }

    /// Appends a keyframe (its scan decimated and quantised to millimetres) and returns
    /// its index (0, 1, 2, … in order of appending).
    ///
    /// Refused, with nothing written, with [`StoreError::BeamCount`] when
    /// `ranges.len().div_ceil(decimation)` is not the store's beam count,
    /// [`StoreError::NonFinitePose`] for a NaN or infinite motion or pose,
    /// [`StoreError::Full`] when no slot is left, or the reason appends are refused
    /// ([`KeyframeStore::append_refused`]).
    ///
    /// When the storage fails during the write, the slot is read back: still erased, it
    /// is used by the next append; holding the whole record, the append succeeded after
    /// all (the index is returned); anything else is a torn record, skipped like one
    /// found by [`KeyframeStore::open`], and the storage's error is returned. When the
    /// slot cannot even be read back, appends are refused from then on
    /// ([`StoreError::Damaged`]).
    pub fn append(&mut self, keyframe: &Keyframe<'_>) -> Result<u32, StoreError> {
        if let Some(reason) = self.refused {
            return Err(reason);
        }
        let beams = usize::from(self.header.beams);
        let decimation = usize::from(self.header.decimation);
        if keyframe.ranges.len().div_ceil(decimation) != beams {
            return Err(StoreError::BeamCount);
        }
        if !keyframe.motion.is_finite() || !keyframe.pose.is_finite() {
            return Err(StoreError::NonFinitePose);
        }
        if self.next_slot >= self.slots {
            return Err(StoreError::Full);
        }
        let (slot, index) = (self.next_slot, self.len);
        let Err(error) = self.write_record(slot, index, keyframe) else {
            self.len += 1;
            self.next_slot += 1;
            return Ok(index);
        };
        match self.visit_slot(slot, |_, _| {}) {
            Ok(Slot::Erased) => Err(error),
            Ok(Slot::Valid(meta)) if meta.index == index => {
                self.len += 1;
                self.next_slot += 1;
                Ok(index)
            }
            Ok(_) => {
                if !self.skip_torn(slot) {
                    self.refused = Some(StoreError::TooManyTorn);
                }
                Err(error)
            }
            Err(_) => {
                self.refused = Some(StoreError::Damaged);
                Err(error)
            }
        }
    }

    fn write_record(
        &mut self,
        slot: u32,
        index: u32,
        keyframe: &Keyframe<'_>,
    ) -> Result<(), StoreError> {
        let mut fixed = [0u8; RECORD_FIXED_BYTES];
        if let Some(tag) = fixed.get_mut(..2) {
            tag.copy_from_slice(&RECORD_TAG);
        }
        if let Some(beams) = fixed.get_mut(2..4) {
            beams.copy_from_slice(&self.header.beams.to_le_bytes());
        }
        if let Some(at) = fixed.get_mut(4..8) {
            at.copy_from_slice(&index.to_le_bytes());
        }
        put_pose(&mut fixed, 8, &keyframe.motion);
        put_pose(&mut fixed, 20, &keyframe.pose);
        let mut writer = RecordWriter::new(self.slot_offset(slot)?, self.store_crc);
        writer.push(&mut self.storage, &fixed)?;
        let lidar = self.header.lidar;
        let decimation = usize::from(self.header.decimation);
        for range in keyframe.ranges.iter().step_by(decimation) {
            let mm = range_to_millimetres(&lidar, *range);
            writer.push(&mut self.storage, &mm.to_le_bytes())?;
        }
        writer.finish(&mut self.storage)
    }

    /// Where slot `slot` starts.
    fn slot_offset(&self, slot: u32) -> Result<usize, StoreError> {
        (slot as usize)
            .checked_mul(self.header.slot_bytes as usize)
            .and_then(|o| o.checked_add(self.header.first_record as usize))
            .ok_or(StoreError::OutOfBounds)
    }

    /// Reads slot `slot`, handing each stored range to `range(beam, millimetres)`, and
    /// says what it holds. Ranges are handed over before the CRC is checked.
    fn visit_slot(&self, slot: u32, mut range: impl FnMut(usize, u16)) -> Result<Slot, StoreError> {
        let base = self.slot_offset(slot)?;
        let stride = self.header.slot_bytes as usize;
        let record = self.header.record_bytes();
        let crc_at = record - CRC_BYTES;
        let mut fixed = [0u8; RECORD_FIXED_BYTES];
        let mut stored_crc = [0u8; CRC_BYTES];
        let mut digest = CRC32.digest();
        digest.update(&self.store_crc.to_le_bytes());
        let (mut erased, mut low) = (true, 0u8);
        let mut buf = [0u8; CHUNK];
        let mut at = 0;
        while at < stride {
            let n = (stride - at).min(CHUNK);
            let chunk = buf.get_mut(..n).ok_or(StoreError::OutOfBounds)?;
            self.storage.read(base + at, chunk)?;
            erased &= chunk.iter().all(|&b| b == 0xFF);
            digest.update(chunk.get(..crc_at.saturating_sub(at).min(n)).unwrap_or(&[]));
            for (p, &b) in (at..).zip(chunk.iter()) {
                if let Some(f) = fixed.get_mut(p) {
                    *f = b;
                } else if p < crc_at {
                    let k = p - RECORD_FIXED_BYTES;
                    if k.is_multiple_of(2) {
                        low = b;
                    } else {
                        range(k / 2, u16::from_le_bytes([low, b]));
                    }
                } else if let Some(c) = stored_crc.get_mut(p - crc_at) {
                    *c = b;
                }
            }
            at += n;
        }
        if erased {
            return Ok(Slot::Erased);
        }
        let whole = fixed.get(..2) == Some(&RECORD_TAG[..])
            && fixed.get(2..4) == Some(&self.header.beams.to_le_bytes()[..])
            && u32::from_le_bytes(stored_crc) == digest.finalize();
        let index = fixed.get(4..8).and_then(|b| b.try_into().ok());
        match (whole, index, pose_at(&fixed, 8), pose_at(&fixed, 20)) {
            (true, Some(index), Some(motion), Some(pose)) => Ok(Slot::Valid(KeyframeMeta {
                index: u32::from_le_bytes(index),
                motion,
                pose,
            })),
            _ => Ok(Slot::Bad),
        }
    }

    /// The slot keyframe `index` is in: past the torn slots before it.
    fn slot_of(&self, index: u32) -> u32 {
        let torn = self.torn.get(..usize::from(self.torn_len)).unwrap_or(&[]);
        torn.iter()
            .fold(index, |slot, &t| if t <= slot { slot + 1 } else { slot })
    }

    /// Reads slot of keyframe `index`, checks it, and hands its ranges over.
    fn read_with(
        &self,
        index: u32,
        range: impl FnMut(usize, u16),
    ) -> Result<KeyframeMeta, StoreError> {
        if index >= self.len {
            return Err(StoreError::NoKeyframe);
        }
        match self.visit_slot(self.slot_of(index), range)? {
            Slot::Valid(meta) if meta.index == index => Ok(meta),
            _ => Err(StoreError::Corrupt),
        }
    }

    /// Reads keyframe `index`: its motion and pose bit for bit, its ranges in metres into
    /// `ranges[..beams()]` (beam `j` is beam `j · decimation` of the scan), NaN where no
    /// usable range was stored. Within 1 mm of what was appended (millimetres read back
    /// as `mm / 1000`); the beams that are usable are exactly those that were.
    ///
    /// Refused with [`StoreError::NoKeyframe`] past the last keyframe,
    /// [`StoreError::BufferTooShort`] when `ranges` holds fewer than
    /// [`KeyframeStore::beams`], [`StoreError::Corrupt`] when the record no longer checks
    /// (then `ranges[..beams()]` are NaN).
    pub fn read(&self, index: u32, ranges: &mut [f32]) -> Result<KeyframeMeta, StoreError> {
        let beams = usize::from(self.header.beams);
        let out = ranges.get_mut(..beams).ok_or(StoreError::BufferTooShort)?;
        let result = self.read_with(index, |j, mm| {
            if let Some(r) = out.get_mut(j) {
                *r = millimetres_to_range(mm);
            }
        });
        if result.is_err() {
            out.fill(f32::NAN);
        }
        result
    }

    /// Reads keyframe `index` into the layout of the scan it came from: `scan[j ·
    /// decimation]` holds stored range `j`, every other entry is NaN. With `scan` as
    /// long as the appended scans (at least [`KeyframeStore::scan_len`]),
    /// `LidarScan::new(scan, store.lidar()).beams(store.decimation())` gives the same
    /// beams, at the same angles bit for bit, as the appended scan with its ranges
    /// rounded to millimetres: the points a loop closure matches are those the filter
    /// saw. Errors as [`KeyframeStore::read`] (then all of `scan` is NaN).
    pub fn read_scan(&self, index: u32, scan: &mut [f32]) -> Result<KeyframeMeta, StoreError> {
        if scan.len() < self.scan_len() {
            return Err(StoreError::BufferTooShort);
        }
        scan.fill(f32::NAN);
        let decimation = usize::from(self.header.decimation);
        let result = self.read_with(index, |j, mm| {
            if let Some(r) = scan.get_mut(j * decimation) {
                *r = millimetres_to_range(mm);
            }
        });
        if result.is_err() {
            scan.fill(f32::NAN);
        }
        result
    }

    /// The motion and pose of keyframe `index` (the whole record is read and checked).
    pub fn meta(&self, index: u32) -> Result<KeyframeMeta, StoreError> {
        self.read_with(index, |_, _| {})
    }

    /// Number of keyframes stored.
    pub fn len(&self) -> u32 {
        self.len
    }

    /// `true` before the first keyframe.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Slots the storage holds: the number of keyframes it takes when no record is torn.
    pub fn capacity(&self) -> u32 {
        self.slots
    }

    /// Keyframes that can still be appended.
    pub fn remaining(&self) -> u32 {
        self.slots.saturating_sub(self.next_slot)
    }

    /// The lidar geometry the ranges belong to, bit for bit as given to
    /// [`KeyframeStore::create`].
    pub fn lidar(&self) -> LidarGeometry {
        self.header.lidar
    }

    /// The geometry of the stored ranges alone ([`KeyframeStore::read`]): the lidar's,
    /// with its beams `decimation` times as far apart (the kept beams point where a scan
    /// of them alone would).
    pub fn beam_geometry(&self) -> LidarGeometry {
        let lidar = self.header.lidar;
        LidarGeometry {
            angle_increment: lidar.angle_increment * self.decimation() as f32,
            ..lidar
        }
    }

    /// Every how many beams of a scan one is kept.
    pub fn decimation(&self) -> usize {
        usize::from(self.header.decimation)
    }

    /// Ranges per keyframe.
    pub fn beams(&self) -> usize {
        usize::from(self.header.beams)
    }

    /// The shortest scan buffer [`KeyframeStore::read_scan`] fills:
    /// `(beams − 1) · decimation + 1`.
    pub fn scan_len(&self) -> usize {
        self.beams().saturating_sub(1) * self.decimation() + 1
    }

    /// Bytes of storage per keyframe (a record and its padding to the slot).
    pub fn slot_bytes(&self) -> usize {
        self.header.slot_bytes as usize
    }

    /// Records torn by power loss (or a failed write) that were skipped.
    pub fn torn_records(&self) -> usize {
        usize::from(self.torn_len)
    }

    /// Why appends are refused ([`StoreError::TooManyTorn`], [`StoreError::Damaged`]),
    /// or `None` when they are not. Reads work either way.
    pub fn append_refused(&self) -> Option<StoreError> {
        self.refused
    }

    /// The storage.
    pub fn storage(&self) -> &S {
        &self.storage
    }

    /// The storage back (e.g. to open it again after a simulated reset).
    pub fn into_storage(self) -> S {
        self.storage
    }
}
