//! Framing: `COBS(postcard(message) ‖ CRC-16) ‖ 0x00`.
//!
//! COBS removes every zero byte from the body, so `0x00` marks the end of a frame and a
//! receiver that starts in the middle of a stream (or after garbage) resynchronises at
//! the next zero. The CRC (CRC-16/IBM-SDLC, the X.25/HDLC checksum, little-endian)
//! covers the postcard bytes; a frame whose CRC does not match is dropped before it is
//! deserialised.

use core::fmt;

use serde::Serialize;
use serde::de::DeserializeOwned;

/// Longest postcard body of one message, bytes. Every [`ToDevice`](super::ToDevice) and
/// [`ToHost`](super::ToHost) fits (the largest, a full [`ScanChunk`](super::ScanChunk),
/// takes at most 130).
pub const MAX_PAYLOAD_LEN: usize = 192;

/// Bytes of the CRC after the body.
const CRC_LEN: usize = 2;

/// Longest frame on the wire, delimiter included: a receive buffer of this size holds any
/// valid frame.
pub const MAX_FRAME_LEN: usize = cobs::max_encoding_length(MAX_PAYLOAD_LEN + CRC_LEN) + 1;

const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_IBM_SDLC);

/// A message could not be framed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message is longer than [`MAX_PAYLOAD_LEN`] or the output buffer is too small.
    TooLong,
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("message does not fit in a frame")
    }
}

impl core::error::Error for EncodeError {}

/// Writes `msg` as one frame (delimiter included) into `out` and returns the frame.
/// A buffer of [`MAX_FRAME_LEN`] bytes always suffices.
pub fn encode_frame<'b, M: Serialize>(msg: &M, out: &'b mut [u8]) -> Result<&'b [u8], EncodeError> {
    let mut body = [0u8; MAX_PAYLOAD_LEN + CRC_LEN];
    let (payload, _) = body.split_at_mut(MAX_PAYLOAD_LEN);
    let n = postcard::to_slice(msg, payload)
        .map_err(|_| EncodeError::TooLong)?
        .len();
    let crc = CRC.checksum(body.get(..n).ok_or(EncodeError::TooLong)?);
    body.get_mut(n..n + CRC_LEN)
        .ok_or(EncodeError::TooLong)?
        .copy_from_slice(&crc.to_le_bytes());
    let source = body.get(..n + CRC_LEN).ok_or(EncodeError::TooLong)?;
    let m = cobs::try_encode(source, out).map_err(|_| EncodeError::TooLong)?;
    *out.get_mut(m).ok_or(EncodeError::TooLong)? = 0;
    out.get(..=m).ok_or(EncodeError::TooLong)
}

/// Why a received frame was skipped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Too short to hold a CRC and a message, or the message ends early.
    Truncated,
    /// Not valid COBS, or the CRC does not match.
    Corrupt,
    /// Longer than the decoder's buffer; skipped up to the next delimiter.
    Oversize,
    /// The CRC matches but the bytes are not a message this side knows (an unknown variant
    /// or trailing bytes: a peer speaking another version).
    Unknown,
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Truncated => "frame truncated",
            Self::Corrupt => "frame corrupt (COBS or CRC)",
            Self::Oversize => "frame longer than the receive buffer",
            Self::Unknown => "frame holds an unknown message",
        })
    }
}

impl core::error::Error for FrameError {}

/// What a [`FrameDecoder`] has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct WireCounters {
    /// Messages decoded.
    pub ok: u32,
    /// [`FrameError::Truncated`] frames.
    pub truncated: u32,
    /// [`FrameError::Corrupt`] frames.
    pub corrupt: u32,
    /// [`FrameError::Oversize`] frames.
    pub oversize: u32,
    /// [`FrameError::Unknown`] frames.
    pub unknown: u32,
}

impl WireCounters {
    /// All skipped frames.
    pub fn bad(&self) -> u32 {
        self.truncated
            .saturating_add(self.corrupt)
            .saturating_add(self.oversize)
            .saturating_add(self.unknown)
    }

    fn count(&mut self, e: FrameError) {
        let c = match e {
            FrameError::Truncated => &mut self.truncated,
            FrameError::Corrupt => &mut self.corrupt,
            FrameError::Oversize => &mut self.oversize,
            FrameError::Unknown => &mut self.unknown,
        };
        *c = c.saturating_add(1);
    }
}

/// A streaming frame decoder with a fixed buffer of `B` bytes (use [`MAX_FRAME_LEN`]).
///
/// Feed it bytes as they arrive with [`FrameDecoder::push`]; at each delimiter it returns
/// the message or why the frame was skipped. Empty frames (two delimiters in a row, often
/// sent to flush a line) are ignored silently. `const fn new`, no allocation, no panics.
#[derive(Clone, Debug)]
pub struct FrameDecoder<const B: usize> {
    buf: [u8; B],
    len: usize,
    overflow: bool,
    counters: WireCounters,
}

impl<const B: usize> Default for FrameDecoder<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const B: usize> FrameDecoder<B> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; B],
            len: 0,
            overflow: false,
            counters: WireCounters {
                ok: 0,
                truncated: 0,
                corrupt: 0,
                oversize: 0,
                unknown: 0,
            },
        }
    }

    /// Counters of decoded and skipped frames.
    pub fn counters(&self) -> WireCounters {
        self.counters
    }

    /// Clears the counters (the partial frame, if any, is kept).
    pub fn reset_counters(&mut self) {
        self.counters = WireCounters::default();
    }

    /// Takes one byte. Returns `None` inside a frame, and at a delimiter the decoded
    /// message or the reason the frame was skipped (already counted).
    pub fn push<M: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<M, FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => self.overflow = true,
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        let result = if overflow {
            Err(FrameError::Oversize)
        } else if len == 0 {
            return None;
        } else {
            self.decode(len)
        };
        match &result {
            Ok(_) => self.counters.ok = self.counters.ok.saturating_add(1),
            Err(e) => self.counters.count(*e),
        }
        Some(result)
    }

    /// Takes a slice of bytes and calls `on_frame` for every delimiter.
    pub fn feed<M: DeserializeOwned>(
        &mut self,
        bytes: &[u8],
        mut on_frame: impl FnMut(Result<M, FrameError>),
    ) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                on_frame(r);
            }
        }
    }

    fn decode<M: DeserializeOwned>(&mut self, len: usize) -> Result<M, FrameError> {
        let encoded = self.buf.get_mut(..len).ok_or(FrameError::Oversize)?;
        let n = cobs::decode_in_place(encoded).map_err(|_| FrameError::Corrupt)?;
        let body = self.buf.get(..n).ok_or(FrameError::Corrupt)?;
        if n <= CRC_LEN {
            return Err(FrameError::Truncated);
        }
        let (payload, crc) = body.split_at(n - CRC_LEN);
        if crc != CRC.checksum(payload).to_le_bytes() {
            return Err(FrameError::Corrupt);
        }
        match postcard::take_from_bytes::<M>(payload) {
            Ok((msg, [])) => Ok(msg),
            Ok(_) => Err(FrameError::Unknown),
            Err(postcard::Error::DeserializeUnexpectedEnd) => Err(FrameError::Truncated),
            Err(_) => Err(FrameError::Unknown),
        }
    }
}
