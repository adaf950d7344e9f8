//! Why a keyframe store, or the storage under it, refused an operation.

use core::fmt;

/// Why a keyframe store operation was refused. The store is unchanged whenever one is
/// returned, except as [`super::KeyframeStore::append`] documents for a failed write.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The storage reported a failure (a flash driver error, or power lost in a test).
    Storage,
    /// An offset or length outside the storage.
    OutOfBounds,
    /// A flash region, read or write not aligned to the flash's sizes, or a write or read
    /// size that is not a power of two up to [`super::MAX_WRITE_SIZE`].
    Misaligned,
    /// A write to bytes that are not erased: the storage contract was broken.
    NotErased,
    /// The header bytes are erased: no store was ever created here.
    NoStore,
    /// The first four bytes are not [`super::STORE_MAGIC`].
    BadMagic,
    /// A format version this code does not read.
    UnsupportedVersion,
    /// The header's CRC-32 does not match its bytes (e.g. a creation cut short).
    HeaderChecksum,
    /// The header is checksummed but its fields do not make a store (lengths, sizes).
    BadHeader,
    /// A lidar geometry that is not valid, or a decimation or beam count outside
    /// `1 ..= 65 535`.
    InvalidGeometry,
    /// The storage cannot hold the header and one record.
    TooSmall,
    /// No room for another record: nothing was written.
    Full,
    /// The scan, decimated, does not have the store's number of beams.
    BeamCount,
    /// The motion or the pose holds NaN or ±∞.
    NonFinitePose,
    /// No keyframe with this index.
    NoKeyframe,
    /// The buffer for the ranges is shorter than a record's.
    BufferTooShort,
    /// A record read back fails its CRC or carries another index: the bytes changed
    /// since the store was opened.
    Corrupt,
    /// Appends refused: more records were torn by power loss than the store skips
    /// ([`super::MAX_TORN_RECORDS`]). The keyframes stay readable; recreate the store to
    /// map again.
    TooManyTorn,
    /// Appends refused: where the next record goes is not known for sure (a record out
    /// of sequence, or a failed write that could not be read back). The keyframes stay
    /// readable; recreate the store to map again.
    Damaged,
}

impl fmt::Display for StoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Storage => "keyframe storage failed",
            Self::OutOfBounds => "keyframe storage access out of bounds",
            Self::Misaligned => "keyframe storage access not aligned to the flash",
            Self::NotErased => "keyframe storage written where it is not erased",
            Self::NoStore => "no keyframe store (the header is erased)",
            Self::BadMagic => "not a microslam keyframe store (magic is not MSKF)",
            Self::UnsupportedVersion => "keyframe store format version is not supported",
            Self::HeaderChecksum => "keyframe store header checksum does not match",
            Self::BadHeader => "keyframe store header fields are inconsistent",
            Self::InvalidGeometry => "keyframe store lidar geometry, decimation or beams invalid",
            Self::TooSmall => "keyframe storage cannot hold the header and one record",
            Self::Full => "keyframe store is full",
            Self::BeamCount => "scan does not have the keyframe store's number of beams",
            Self::NonFinitePose => "keyframe pose or motion is not finite",
            Self::NoKeyframe => "no keyframe with this index",
            Self::BufferTooShort => "range buffer is shorter than a keyframe's",
            Self::Corrupt => "keyframe record is corrupt",
            Self::TooManyTorn => "too many torn keyframe records: recreate the store",
            Self::Damaged => "keyframe store end is uncertain: recreate the store",
        })
    }
}

impl core::error::Error for StoreError {}
