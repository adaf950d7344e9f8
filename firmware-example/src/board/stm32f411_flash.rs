//! The STM32F411's own flash as the regions the building-scale SLAM keeps across a reset
//! (feature `building-slam`): its keyframes, the map image it writes at `SaveMap` and the
//! robot's saved pose, each a [`Region`] of whole sectors behind `embedded-storage`'s
//! `NorFlash` traits, erased and programmed through `stm32f4xx-hal`'s flash driver.
//!
//! The F411's 512 KB are sectors 0–3 of 16 KB, 4 of 64 KB and 5–7 of 128 KB
//! (RM0383 §3.3). This build's linker script (`memory-stm32f411-slam.x`) gives the
//! firmware sectors 0 and 3–5: the vector table in sector 0, the code from sector 3 on
//! (`_stext`), 208 KB for code and constants, so that:
//!
//! | sectors | what | bytes |
//! | --- | --- | --- |
//! | 1, 2 | the saved pose ([`pose_flash`]: `microslam::device::PoseStore`, one sector each) | 2 × 16 KB |
//! | 6 | the map image ([`map_flash`]) | 128 KB |
//! | 7 | the keyframes ([`keyframe_flash`]) | 128 KB |
//!
//! The regions are made here from these constants and the linker script keeps the code
//! out of them: change one, change the other.
//!
//! QEMU's `netduinoplus2` does not model the flash interface, so this driver runs on a
//! board only (the building-slam firmware runs under QEMU with its SRAM stand-in,
//! `crate::flash::SramFlash`, the same regions' rules).

use core::sync::atomic::{AtomicBool, Ordering};
use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use stm32f4xx_hal::flash::FlashExt;
use stm32f4xx_hal::pac;

/// Where the flash is mapped.
const FLASH_BASE: usize = 0x0800_0000;

/// The saved pose: sectors 1 and 2 (16 KB each, 512 records of 32 bytes a sector).
pub const POSE_START: u32 = 0x0000_4000;
/// Bytes of each of the pose store's two sectors.
pub const POSE_SECTOR_BYTES: u32 = 16 * 1024;
/// The map image: sector 6, the profile's `SLAM_MAP_BYTES` (31 tiles of 128 × 128 cells).
pub const MAP_START: u32 = 0x0004_0000;
/// Bytes of the map image's region.
pub const MAP_BYTES: u32 = crate::config::SLAM_MAP_BYTES;
/// The keyframes: sector 7, the profile's `SLAM_KEYFRAME_BYTES` (606 keyframes of 90
/// beams; a longer run's later keyframes are refused and counted,
/// `GraphCounters::keyframes_refused`, and the run goes on).
pub const KEYFRAME_START: u32 = 0x0006_0000;
/// Bytes of the keyframes' region.
pub const KEYFRAME_BYTES: u32 = crate::config::SLAM_KEYFRAME_BYTES;

/// Why a region refused an operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// Beyond the region's end.
    OutOfBounds,
    /// An erase not on the region's sector boundaries.
    NotAligned,
    /// The flash interface reported an error (its status register's flag).
    Interface(InterfaceError),
}

/// The flash interface's error flags (`FLASH_SR`), as `stm32f4xx-hal` reports them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum InterfaceError {
    /// PGSERR: programming sequence.
    ProgrammingSequence,
    /// PGPERR: programming parallelism (size against voltage range).
    ProgrammingParallelism,
    /// PGAERR: programming alignment.
    ProgrammingAlignment,
    /// WRPERR: the sector is write-protected (option bytes).
    WriteProtection,
    /// OPERR: operation error.
    Operation,
}

impl From<stm32f4xx_hal::flash::Error> for FlashError {
    fn from(e: stm32f4xx_hal::flash::Error) -> Self {
        use stm32f4xx_hal::flash::Error as E;
        Self::Interface(match e {
            E::ProgrammingSequence => InterfaceError::ProgrammingSequence,
            E::ProgrammingParallelism => InterfaceError::ProgrammingParallelism,
            E::ProgrammingAlignment => InterfaceError::ProgrammingAlignment,
            E::WriteProtection => InterfaceError::WriteProtection,
            E::Operation => InterfaceError::Operation,
        })
    }
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            Self::NotAligned | Self::Interface(InterfaceError::ProgrammingAlignment) => {
                NorFlashErrorKind::NotAligned
            }
            Self::Interface(_) => NorFlashErrorKind::Other,
        }
    }
}

/// `len` bytes of the F411's flash from `start` (offsets from the flash's base), whole
/// sectors of `SECTOR` bytes each, handed out once ([`pose_flash`], [`map_flash`],
/// [`keyframe_flash`]). Offsets given to its `NorFlash` methods are from its start.
pub struct Region<const SECTOR: usize> {
    start: u32,
    len: u32,
}

impl<const SECTOR: usize> Region<SECTOR> {
    fn take(start: u32, len: u32, taken: &AtomicBool) -> Option<Self> {
        if taken.swap(true, Ordering::AcqRel) {
            return None;
        }
        Some(Self { start, len })
    }

    /// What the region holds now, read through the flash's address.
    pub fn bytes(&self) -> &[u8] {
        // The borrow of `self` excludes `erase` and `write` (`&mut self`) while it lasts.
        self.mapped()
    }

    /// What the region holds, for the rest of the program (a map image a localizer
    /// borrows): the region is given up, nothing writes it again.
    pub fn into_bytes(self) -> &'static [u8] {
        // `self` is consumed and was the only handle that could write these sectors
        // (each region is handed out once).
        self.mapped()
    }

    /// The region's bytes at their flash address. Sound only while nothing writes them:
    /// its callers tie the slice to a borrow of the region, or consume it.
    fn mapped(&self) -> &'static [u8] {
        // SAFETY: the region lies within the F411's 512 KB of flash, mapped for reading at
        // FLASH_BASE; the bytes change only through the region's `&mut self` methods, which
        // `bytes` (a borrow) and `into_bytes` (a move) exclude.
        #[allow(unsafe_code)]
        unsafe {
            core::slice::from_raw_parts(
                (FLASH_BASE + self.start as usize) as *const u8,
                self.len as usize,
            )
        }
    }

    /// The absolute offsets of `from..from + len` within the region.
    fn span(&self, from: u32, len: usize) -> Result<(u32, u32), FlashError> {
        let len = u32::try_from(len).map_err(|_| FlashError::OutOfBounds)?;
        let end = from.checked_add(len).ok_or(FlashError::OutOfBounds)?;
        if end > self.len {
            return Err(FlashError::OutOfBounds);
        }
        Ok((self.start + from, self.start + end))
    }

    /// Runs `op` on the unlocked flash interface, its error flags cleared first (they
    /// stay set after a failed operation, and the driver would report them again).
    fn unlocked<T>(op: impl FnOnce(&mut stm32f4xx_hal::flash::UnlockedFlash<'_>) -> T) -> T {
        // SAFETY: the regions are the only users of the flash interface (`board::init`
        // leaves `FLASH` untouched once the clocks are set), and they are used from the
        // main loop only, never from an interrupt, so no two operations overlap.
        #[allow(unsafe_code)]
        let mut flash = unsafe { pac::FLASH::steal() };
        flash.sr().write(|w| {
            w.operr()
                .clear_bit_by_one()
                .wrperr()
                .clear_bit_by_one()
                .pgaerr()
                .clear_bit_by_one()
                .pgperr()
                .clear_bit_by_one()
                .pgserr()
                .clear_bit_by_one()
        });
        // Locked again when `unlocked` is dropped, on the way out.
        let mut unlocked = flash.unlocked();
        op(&mut unlocked)
    }
}

impl<const SECTOR: usize> ErrorType for Region<SECTOR> {
    type Error = FlashError;
}

impl<const SECTOR: usize> ReadNorFlash for Region<SECTOR> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let (from, to) = self.span(offset, bytes.len())?;
        let (from, to) = ((from - self.start) as usize, (to - self.start) as usize);
        bytes.copy_from_slice(&self.bytes()[from..to]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.len as usize
    }
}

impl<const SECTOR: usize> NorFlash for Region<SECTOR> {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if from > to {
            return Err(FlashError::NotAligned);
        }
        if !(from as usize).is_multiple_of(SECTOR) || !(to as usize).is_multiple_of(SECTOR) {
            return Err(FlashError::NotAligned);
        }
        let (from, to) = self.span(from, (to - from) as usize)?;
        if from == to {
            return Ok(());
        }
        Self::unlocked(|flash| NorFlash::erase(flash, from, to))?;
        flush_data_cache();
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let (from, _) = self.span(offset, bytes.len())?;
        Self::unlocked(|flash| NorFlash::write(flash, from, bytes))?;
        Ok(())
    }
}

/// Resets the flash's data cache after an erase, so that no line of the erased sectors'
/// old bytes is read back (RM0383 §3.4.2: the cache must be disabled to be reset).
fn flush_data_cache() {
    // SAFETY: as in `Region::unlocked`: the regions alone use the flash interface, from
    // the main loop.
    #[allow(unsafe_code)]
    let flash = unsafe { pac::FLASH::steal() };
    let enabled = flash.acr().read().dcen().bit_is_set();
    flash.acr().modify(|_, w| w.dcen().clear_bit());
    flash.acr().modify(|_, w| w.dcrst().set_bit());
    flash.acr().modify(|_, w| w.dcrst().clear_bit());
    if enabled {
        flash.acr().modify(|_, w| w.dcen().set_bit());
    }
}

/// The flash a pose store takes: sectors 1 and 2, erased one at a time.
pub type PoseFlash = Region<{ POSE_SECTOR_BYTES as usize }>;
/// The flash the building-scale SLAM keeps its keyframes and its map image in: one
/// 128 KB sector each.
pub type SlamFlash = Region<{ 128 * 1024 }>;

// The profile's regions are one 128 KB sector each.
const _: () = assert!(MAP_BYTES as usize == 128 * 1024 && KEYFRAME_BYTES as usize == 128 * 1024);

/// The pose store's two sectors (1 and 2), handed out once; `None` after.
pub fn pose_flash() -> Option<PoseFlash> {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    Region::take(POSE_START, 2 * POSE_SECTOR_BYTES, &TAKEN)
}

/// The map image's sector (6), handed out once; `None` after.
pub fn map_flash() -> Option<SlamFlash> {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    Region::take(MAP_START, MAP_BYTES, &TAKEN)
}

/// The keyframes' sector (7), handed out once; `None` after.
pub fn keyframe_flash() -> Option<SlamFlash> {
    static TAKEN: AtomicBool = AtomicBool::new(false);
    Region::take(KEYFRAME_START, KEYFRAME_BYTES, &TAKEN)
}
