//! A NOR flash stand-in in QEMU's SRAM ([`SramFlash`]): where the building-scale SLAM's
//! keyframes, its map image and the robot's saved pose go under QEMU (the
//! `building-slam` firmware and the `cost_slam` probe), as they would go to a board's
//! flash sectors. The firmware's start-up code never touches these bytes (they are
//! outside the RAM the linker knows), and QEMU keeps its RAM through a system reset, so
//! they survive a reset as flash does.

/// A NOR flash stand-in in QEMU's SRAM: mps2-an386 has 4 MB of SRAM at `0x2000_0000`, of
/// which the linker uses the first 128 KB (`memory-qemu.x`, the board's RAM); the bytes
/// from [`SramFlash::BASE`] stand in for the board's flash sectors. It keeps NOR flash's
/// rules (erase sets whole sectors to `0xFF`, a write only clears bits, word-aligned
/// writes), so code that runs on it runs on a board's flash.
pub struct SramFlash {
    bytes: &'static mut [u8],
}

impl SramFlash {
    /// Where the stand-in starts: 1 MB into QEMU's SRAM, far above the 128 KB the
    /// firmware's RAM (and its stack) use.
    pub const BASE: usize = 0x2010_0000;
    /// Erase sector, bytes.
    pub const SECTOR: usize = 4096;

    /// Where the second stand-in starts ([`SramFlash::take_map`]): 2 MB into QEMU's SRAM.
    pub const MAP_BASE: usize = 0x2020_0000;

    /// Where the third stand-in starts ([`SramFlash::take_poses`]): 3.5 MB into QEMU's
    /// SRAM.
    pub const POSE_BASE: usize = 0x2038_0000;

    /// The stand-in for the keyframes, `len` bytes (at most 1 MB: it ends where the
    /// map's begins), handed out once; `None` after.
    pub fn take(len: u32) -> Option<Self> {
        static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
        Self::take_at(Self::BASE, len, 1 << 20, &TAKEN)
    }

    /// A second stand-in from [`SramFlash::MAP_BASE`], for the map image the SLAM writes
    /// at the end of a run: `len` bytes (at most 1.5 MB), handed out once; `None` after.
    pub fn take_map(len: u32) -> Option<Self> {
        static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
        Self::take_at(Self::MAP_BASE, len, 3 << 19, &TAKEN)
    }

    /// A third stand-in from [`SramFlash::POSE_BASE`], for the robot's saved pose
    /// (`microslam::device::PoseStore`): `len` bytes (at most 512 KB), handed out once;
    /// `None` after.
    pub fn take_poses(len: u32) -> Option<Self> {
        static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
        Self::take_at(Self::POSE_BASE, len, 1 << 19, &TAKEN)
    }

    /// What the stand-in holds now.
    pub fn bytes(&self) -> &[u8] {
        self.bytes
    }

    /// What the stand-in holds, as a board's flash is read through its address (a map
    /// image a localizer borrows), for the rest of the program: no more writes.
    pub fn into_bytes(self) -> &'static [u8] {
        self.bytes
    }

    fn take_at(
        base: usize,
        len: u32,
        max: usize,
        taken: &core::sync::atomic::AtomicBool,
    ) -> Option<Self> {
        let len = len as usize;
        if len > max || taken.swap(true, core::sync::atomic::Ordering::AcqRel) {
            return None;
        }
        // SAFETY: QEMU's mps2-an386 maps SRAM at 0x2000_0000..0x2040_0000; nothing the
        // linker places reaches BASE (RAM ends at 0x2002_0000); the keyframes' region
        // (BASE, at most 1 MB) ends where the map's (MAP_BASE, at most 1.5 MB) begins,
        // which ends where the poses' (POSE_BASE, at most 512 KB) begins, which ends at
        // the SRAM's end; each flag hands its region out once, so this is the only
        // reference to these bytes.
        let bytes = unsafe { core::slice::from_raw_parts_mut(base as *mut u8, len) };
        Some(Self { bytes })
    }
}

impl embedded_storage::nor_flash::ErrorType for SramFlash {
    type Error = embedded_storage::nor_flash::NorFlashErrorKind;
}

impl embedded_storage::nor_flash::ReadNorFlash for SramFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let start = offset as usize;
        let src = self
            .bytes
            .get(start..start.saturating_add(bytes.len()))
            .ok_or(Self::Error::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl embedded_storage::nor_flash::NorFlash for SramFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = Self::SECTOR;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let (from, to) = (from as usize, to as usize);
        if !from.is_multiple_of(Self::SECTOR) || !to.is_multiple_of(Self::SECTOR) {
            return Err(Self::Error::NotAligned);
        }
        self.bytes
            .get_mut(from..to)
            .ok_or(Self::Error::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let start = offset as usize;
        if !start.is_multiple_of(Self::WRITE_SIZE) || !bytes.len().is_multiple_of(Self::WRITE_SIZE)
        {
            return Err(Self::Error::NotAligned);
        }
        let dst = self
            .bytes
            .get_mut(start..start.saturating_add(bytes.len()))
            .ok_or(Self::Error::OutOfBounds)?;
        // NOR flash programs by clearing bits.
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d &= s;
        }
        Ok(())
    }
}
