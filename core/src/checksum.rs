//! The one checksum of everything the crate keeps in flash (keyframe records, map
//! images, saved poses): CRC-32 as zlib, PNG and Ethernet compute it (ISO-HDLC,
//! polynomial `0x04C11DB7` reflected, check value `0xCBF43926`), so that a host tool can
//! check an image with any CRC-32 library.

/// The CRC-32 (ISO-HDLC) every flash format of the crate is checked with.
pub(crate) static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
