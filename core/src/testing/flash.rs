//! A NOR flash in RAM for the tests (the keyframe store's, the saved pose's): erase sets `0xFF`, programming only clears bits,
//! each `W`-byte word is programmed at most once between erases (as on flash with ECC),
//! reads and writes must be aligned, and power can be cut after a number of bytes.

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash, check_erase, check_read,
    check_write,
};

/// Where and how power is cut during programming.
#[derive(Clone, Copy, Debug)]
pub struct Cut {
    /// Bytes programmed in full before the cut.
    pub after_bytes: usize,
    /// The byte being programmed at the cut gets some of its bits (`data | 0xF0`).
    pub partial: bool,
    /// The flash stays off after the cut (a reset follows); otherwise only this write
    /// fails (a transient driver error) and reads still work.
    pub power_off: bool,
}

/// What the mock refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MockError {
    /// Misaligned or out of bounds, as `check_*` say.
    Check(NorFlashErrorKind),
    /// Power was cut, or is off.
    PowerCut,
    /// A word programmed a second time without an erase.
    ProgrammedTwice,
}

impl NorFlashError for MockError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::Check(kind) => *kind,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The flash: `W` write size, `R` read size, `E` erase size.
#[derive(Clone, Debug)]
pub struct MockFlash<const W: usize, const R: usize, const E: usize> {
    /// The bytes, as the flash holds them.
    pub mem: Vec<u8>,
    /// Per `W`-byte word: programmed (even partly) since the last erase.
    programmed: Vec<bool>,
    cut: Option<Cut>,
    programmed_bytes: usize,
    powered: bool,
    /// Times a word was programmed twice (the store must never do it).
    pub double_writes: usize,
    /// Reads or writes refused as misaligned (the adapter must never do one).
    pub misaligned: usize,
}

impl<const W: usize, const R: usize, const E: usize> MockFlash<W, R, E> {
    /// `bytes` of erased flash.
    pub fn new(bytes: usize) -> Self {
        Self {
            mem: vec![0xFF; bytes],
            programmed: vec![false; bytes / W],
            cut: None,
            programmed_bytes: 0,
            powered: true,
            double_writes: 0,
            misaligned: 0,
        }
    }

    /// Cuts power after `cut.after_bytes` more bytes are programmed.
    pub fn arm(&mut self, cut: Cut) {
        self.cut = Some(cut);
        self.programmed_bytes = 0;
    }

    /// `true` while a cut is armed and has not happened.
    pub fn armed(&self) -> bool {
        self.cut.is_some()
    }

    /// The same flash after a reset: same bytes and programmed words, power on.
    pub fn reboot(&self) -> Self {
        Self {
            cut: None,
            powered: true,
            ..self.clone()
        }
    }

    fn checked<T>(&mut self, r: Result<T, NorFlashErrorKind>) -> Result<T, MockError> {
        r.map_err(|kind| {
            if kind == NorFlashErrorKind::NotAligned {
                self.misaligned += 1;
            }
            MockError::Check(kind)
        })
    }
}

impl<const W: usize, const R: usize, const E: usize> ErrorType for MockFlash<W, R, E> {
    type Error = MockError;
}

impl<const W: usize, const R: usize, const E: usize> ReadNorFlash for MockFlash<W, R, E> {
    const READ_SIZE: usize = R;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), MockError> {
        let check = check_read(self, offset, bytes.len());
        self.checked(check)?;
        if !self.powered {
            return Err(MockError::PowerCut);
        }
        let at = offset as usize;
        bytes.copy_from_slice(&self.mem[at..at + bytes.len()]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl<const W: usize, const R: usize, const E: usize> NorFlash for MockFlash<W, R, E> {
    const WRITE_SIZE: usize = W;
    const ERASE_SIZE: usize = E;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), MockError> {
        let check = check_erase(self, from, to);
        self.checked(check)?;
        if !self.powered {
            return Err(MockError::PowerCut);
        }
        let (from, to) = (from as usize, to as usize);
        self.mem[from..to].fill(0xFF);
        self.programmed[from / W..to / W].fill(false);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), MockError> {
        let check = check_write(self, offset, bytes.len());
        self.checked(check)?;
        if !self.powered {
            return Err(MockError::PowerCut);
        }
        let start = offset as usize;
        for (w, word) in bytes.chunks(W).enumerate() {
            let word_index = start / W + w;
            if self.programmed[word_index] {
                self.double_writes += 1;
                return Err(MockError::ProgrammedTwice);
            }
            for (j, &b) in word.iter().enumerate() {
                let at = start + w * W + j;
                if let Some(cut) = self.cut
                    && self.programmed_bytes == cut.after_bytes
                {
                    if cut.partial {
                        self.mem[at] &= b | 0xF0;
                        self.programmed[word_index] = true;
                    }
                    self.powered = !cut.power_off;
                    self.cut = None;
                    return Err(MockError::PowerCut);
                }
                self.programmed[word_index] = true;
                self.mem[at] &= b;
                self.programmed_bytes += 1;
            }
        }
        Ok(())
    }
}
