//! Where a keyframe store's bytes live: the [`KeyframeStorage`] trait, RAM
//! ([`RamStorage`]) and a region of NOR flash ([`NorFlashStorage`]).

use super::{MAX_WRITE_SIZE, StoreError};
use core::cell::RefCell;
use embedded_storage::nor_flash::{NorFlash, NorFlashError, NorFlashErrorKind};

/// Bytes a keyframe store lives in, with the rules of NOR flash: erasing sets every byte
/// to `0xFF`, and a byte is written once between erases.
///
/// The store keeps to this contract, which implementations may rely on:
/// - it writes only bytes that are erased, in increasing order of offset;
/// - every write starts at a multiple of [`KeyframeStorage::write_size`]; a write whose
///   length is not a multiple of it ends a record, and the storage pads it with erased
///   bytes (`0xFF`) up to the next multiple — the store never writes into that padding.
pub trait KeyframeStorage {
    /// Bytes the storage holds.
    fn capacity(&self) -> usize;

    /// The unit the storage programs at once, bytes (the flash word): a power of two up
    /// to [`MAX_WRITE_SIZE`]; 1 for RAM.
    fn write_size(&self) -> usize {
        1
    }

    /// Reads `bytes.len()` bytes from `offset`.
    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError>;

    /// Programs `bytes` at `offset` (see the trait's contract).
    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError>;

    /// Erases every byte to `0xFF`.
    fn erase_all(&mut self) -> Result<(), StoreError>;
}

impl<T: KeyframeStorage + ?Sized> KeyframeStorage for &mut T {
    fn capacity(&self) -> usize {
        T::capacity(self)
    }

    fn write_size(&self) -> usize {
        T::write_size(self)
    }

    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        T::read(self, offset, bytes)
    }

    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        T::write(self, offset, bytes)
    }

    fn erase_all(&mut self) -> Result<(), StoreError> {
        T::erase_all(self)
    }
}

/// `BYTES` bytes of RAM behaving as erased-once flash: the host's and the tests' storage,
/// and a small store in a `static` on a microcontroller.
///
/// The bytes are kept inverted (an erased `0xFF` is a zero in RAM), so that
/// [`RamStorage::new`] is all zeros: a `static` goes to `.bss` and costs no flash for
/// its initial value. A write to a byte that is not erased is refused
/// ([`StoreError::NotErased`]), as the store never does one.
#[derive(Clone, Debug)]
pub struct RamStorage<const BYTES: usize> {
    inverted: [u8; BYTES],
}

impl<const BYTES: usize> Default for RamStorage<BYTES> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BYTES: usize> RamStorage<BYTES> {
    /// Erased storage.
    pub const fn new() -> Self {
        Self {
            inverted: [0; BYTES],
        }
    }

    /// Replaces the content with `image` (e.g. a store read out of a robot's flash) and
    /// erases the rest; refused with [`StoreError::OutOfBounds`] when it is longer.
    pub fn load_image(&mut self, image: &[u8]) -> Result<(), StoreError> {
        if image.len() > BYTES {
            return Err(StoreError::OutOfBounds);
        }
        for (i, b) in self.inverted.iter_mut().enumerate() {
            *b = !image.get(i).copied().unwrap_or(0xFF);
        }
        Ok(())
    }

    fn span(&self, offset: usize, len: usize) -> Result<core::ops::Range<usize>, StoreError> {
        let end = offset.checked_add(len).ok_or(StoreError::OutOfBounds)?;
        if end > BYTES {
            return Err(StoreError::OutOfBounds);
        }
        Ok(offset..end)
    }
}

impl<const BYTES: usize> KeyframeStorage for RamStorage<BYTES> {
    fn capacity(&self) -> usize {
        BYTES
    }

    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        let span = self.span(offset, bytes.len())?;
        let source = self.inverted.get(span).ok_or(StoreError::OutOfBounds)?;
        for (out, b) in bytes.iter_mut().zip(source) {
            *out = !*b;
        }
        Ok(())
    }

    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        let span = self.span(offset, bytes.len())?;
        let target = self.inverted.get_mut(span).ok_or(StoreError::OutOfBounds)?;
        if target.iter().any(|&b| b != 0) {
            return Err(StoreError::NotErased);
        }
        for (t, b) in target.iter_mut().zip(bytes) {
            *t = !*b;
        }
        Ok(())
    }

    fn erase_all(&mut self) -> Result<(), StoreError> {
        self.inverted.fill(0);
        Ok(())
    }
}

/// A region of NOR flash (`embedded_storage::nor_flash::NorFlash`, which the HALs
/// implement for on-chip flash) as keyframe storage.
///
/// The region starts and ends on erase-unit boundaries (`ERASE_SIZE`); reads and writes
/// of any offset and length are turned into the aligned ones the flash accepts
/// (`READ_SIZE`, `WRITE_SIZE`, powers of two up to [`MAX_WRITE_SIZE`]), the partial
/// words at either end going through a buffer: a read of a partial word reads the whole
/// word, a write ending in a partial word pads it with `0xFF`. Reads borrow the flash
/// through a [`RefCell`] (the driver's `read` takes `&mut self`), so that the store can
/// be read through `&self`.
#[derive(Debug)]
pub struct NorFlashStorage<F> {
    flash: RefCell<F>,
    start: u32,
    len: u32,
}

fn flash_error<E: NorFlashError>(e: E) -> StoreError {
    match e.kind() {
        NorFlashErrorKind::NotAligned => StoreError::Misaligned,
        NorFlashErrorKind::OutOfBounds => StoreError::OutOfBounds,
        _ => StoreError::Storage,
    }
}

fn valid_unit(size: usize) -> bool {
    size.is_power_of_two() && size <= MAX_WRITE_SIZE
}

impl<F: NorFlash> NorFlashStorage<F> {
    /// The `len` bytes of `flash` from `start`. Refused with [`StoreError::Misaligned`]
    /// when the region does not start and end on erase-unit boundaries or the flash's
    /// read or write size is not a power of two up to [`MAX_WRITE_SIZE`], with
    /// [`StoreError::OutOfBounds`] when it is not inside the flash.
    pub fn new(flash: F, start: u32, len: u32) -> Result<Self, StoreError> {
        let end = start.checked_add(len).ok_or(StoreError::OutOfBounds)?;
        if end as usize > flash.capacity() {
            return Err(StoreError::OutOfBounds);
        }
        let erase = F::ERASE_SIZE.max(1);
        let aligned = |x: u32| (x as usize).is_multiple_of(erase);
        if !valid_unit(F::READ_SIZE)
            || !valid_unit(F::WRITE_SIZE)
            || !aligned(start)
            || !aligned(len)
            || !(len as usize).is_multiple_of(F::READ_SIZE)
        {
            return Err(StoreError::Misaligned);
        }
        Ok(Self {
            flash: RefCell::new(flash),
            start,
            len,
        })
    }

    /// The flash back.
    pub fn into_inner(self) -> F {
        self.flash.into_inner()
    }

    /// The flash address of region offset `offset` when `len` bytes from it are inside
    /// the region.
    fn address(&self, offset: usize, len: usize) -> Result<u32, StoreError> {
        let end = offset.checked_add(len).ok_or(StoreError::OutOfBounds)?;
        if end > self.len as usize {
            return Err(StoreError::OutOfBounds);
        }
        let offset = u32::try_from(offset).map_err(|_| StoreError::OutOfBounds)?;
        self.start
            .checked_add(offset)
            .ok_or(StoreError::OutOfBounds)
    }
}

impl<F: NorFlash> KeyframeStorage for NorFlashStorage<F> {
    fn capacity(&self) -> usize {
        self.len as usize
    }

    fn write_size(&self) -> usize {
        F::WRITE_SIZE
    }

    fn read(&self, offset: usize, bytes: &mut [u8]) -> Result<(), StoreError> {
        self.address(offset, bytes.len())?;
        let mut flash = self
            .flash
            .try_borrow_mut()
            .map_err(|_| StoreError::Storage)?;
        let unit = F::READ_SIZE;
        let mut scratch = [0u8; MAX_WRITE_SIZE];
        let (mut at, mut out) = (offset, bytes);
        while !out.is_empty() {
            let skip = at % unit;
            let taken = if skip == 0 && out.len() >= unit {
                // Whole words straight into the caller's buffer.
                let n = out.len() - out.len() % unit;
                let target = out.get_mut(..n).ok_or(StoreError::OutOfBounds)?;
                flash
                    .read(self.address(at, n)?, target)
                    .map_err(flash_error)?;
                n
            } else {
                // A partial word: read it whole, keep the bytes asked for.
                let word = scratch.get_mut(..unit).ok_or(StoreError::Misaligned)?;
                flash
                    .read(self.address(at - skip, unit)?, word)
                    .map_err(flash_error)?;
                let n = (unit - skip).min(out.len());
                let part = word.get(skip..skip + n).ok_or(StoreError::Misaligned)?;
                out.get_mut(..n)
                    .ok_or(StoreError::OutOfBounds)?
                    .copy_from_slice(part);
                n
            };
            at += taken;
            out = out.get_mut(taken..).unwrap_or(&mut []);
        }
        Ok(())
    }

    fn write(&mut self, offset: usize, bytes: &[u8]) -> Result<(), StoreError> {
        let unit = F::WRITE_SIZE;
        if !offset.is_multiple_of(unit) {
            return Err(StoreError::Misaligned);
        }
        let whole = bytes.len() - bytes.len() % unit;
        let padded = bytes.len().next_multiple_of(unit);
        let address = self.address(offset, padded)?;
        let tail_address = self.address(offset + whole, padded - whole)?;
        let (body, tail) = bytes.split_at(whole);
        let flash = self.flash.get_mut();
        if !body.is_empty() {
            flash.write(address, body).map_err(flash_error)?;
        }
        if !tail.is_empty() {
            // The last, partial word: padded with erased bytes.
            let mut word = [0xFFu8; MAX_WRITE_SIZE];
            word.get_mut(..tail.len())
                .ok_or(StoreError::Misaligned)?
                .copy_from_slice(tail);
            let word = word.get(..unit).ok_or(StoreError::Misaligned)?;
            flash.write(tail_address, word).map_err(flash_error)?;
        }
        Ok(())
    }

    fn erase_all(&mut self) -> Result<(), StoreError> {
        let end = self.start.saturating_add(self.len);
        self.flash
            .get_mut()
            .erase(self.start, end)
            .map_err(flash_error)
    }
}
