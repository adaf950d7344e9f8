//! Reassembly of lidar scans sent as several [`ScanChunk`] frames.

use core::fmt;

use super::messages::ScanChunk;

/// Why a chunk did not complete a scan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ScanError {
    /// The scan has more beams than the assembler holds; its chunks are skipped.
    TooManyBeams,
    /// A chunk did not continue the scan in progress (lost or reordered frame): the
    /// partial scan was dropped.
    MissingChunk,
    /// A chunk's beams run past the scan's `beam_total`, or it is empty.
    Malformed,
}

impl fmt::Display for ScanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::TooManyBeams => "scan has more beams than the assembler holds",
            Self::MissingChunk => "scan chunk missing or out of order",
            Self::Malformed => "scan chunk inconsistent with its scan",
        })
    }
}

impl core::error::Error for ScanError {}

/// A complete scan, borrowed from the assembler.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scan<'a> {
    /// The scan's id.
    pub scan_id: u16,
    /// Time stamp, µs.
    pub stamp_us: u64,
    /// Angle of beam 0, rad.
    pub angle_min: f32,
    /// Angle between beams, rad.
    pub angle_increment: f32,
    /// Ranges in millimetres, 0 = no return.
    pub ranges_mm: &'a [u16],
}

/// Puts the chunks of a scan (in order) back together, in a fixed buffer of `BEAMS` beams.
#[derive(Clone, Debug)]
pub struct ScanAssembler<const BEAMS: usize> {
    ranges_mm: [u16; BEAMS],
    filled: usize,
    total: usize,
    scan_id: u16,
    stamp_us: u64,
    angle_min: f32,
    angle_increment: f32,
    dropped: u32,
}

impl<const BEAMS: usize> Default for ScanAssembler<BEAMS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const BEAMS: usize> ScanAssembler<BEAMS> {
    /// An empty assembler.
    pub const fn new() -> Self {
        Self {
            ranges_mm: [0; BEAMS],
            filled: 0,
            total: 0,
            scan_id: 0,
            stamp_us: 0,
            angle_min: 0.0,
            angle_increment: 0.0,
            dropped: 0,
        }
    }

    /// Abandons a partial scan without counting it as dropped (e.g. after a reset).
    pub fn clear(&mut self) {
        self.filled = 0;
    }

    /// Scans dropped because of missing, inconsistent or oversize chunks.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Takes a chunk; returns the scan when this chunk completes it, `Ok(None)` while
    /// chunks are missing. A chunk that starts a new scan (offset 0) abandons a partial one.
    pub fn push(&mut self, chunk: &ScanChunk) -> Result<Option<Scan<'_>>, ScanError> {
        let offset = usize::from(chunk.beam_offset);
        let total = usize::from(chunk.beam_total);
        let n = chunk.ranges_mm.len();
        if offset == 0 {
            if self.filled > 0 {
                self.dropped = self.dropped.saturating_add(1);
            }
            self.filled = 0;
            self.total = total;
            self.scan_id = chunk.scan_id;
            self.stamp_us = chunk.stamp_us;
            self.angle_min = chunk.angle_min;
            self.angle_increment = chunk.angle_increment;
        } else if self.filled == 0
            || offset != self.filled
            || chunk.scan_id != self.scan_id
            || total != self.total
        {
            return Err(self.drop_scan(ScanError::MissingChunk));
        }
        if total > BEAMS {
            return Err(self.drop_scan(ScanError::TooManyBeams));
        }
        if n == 0 || offset + n > total {
            return Err(self.drop_scan(ScanError::Malformed));
        }
        let dest = self
            .ranges_mm
            .get_mut(offset..offset + n)
            .ok_or(ScanError::Malformed)?;
        dest.copy_from_slice(&chunk.ranges_mm);
        self.filled = offset + n;
        if self.filled < total {
            return Ok(None);
        }
        self.filled = 0;
        Ok(Some(Scan {
            scan_id: self.scan_id,
            stamp_us: self.stamp_us,
            angle_min: self.angle_min,
            angle_increment: self.angle_increment,
            ranges_mm: self.ranges_mm.get(..total).unwrap_or(&[]),
        }))
    }

    fn drop_scan(&mut self, e: ScanError) -> ScanError {
        // Counted once per scan: only when a partial scan (or its first chunk) is lost.
        self.dropped = self.dropped.saturating_add(1);
        self.filled = 0;
        e
    }
}
