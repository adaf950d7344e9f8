//! The messages that cross the serial line between a host and a robot's microcontroller,
//! and their framing.
//!
//! - [`messages`]: what is sent, as serde types encoded with postcard: sensor events and
//!   commands to the device ([`ToDevice`]), estimates and status from it ([`ToHost`]).
//! - [`frame`]: how it is framed: `COBS(postcard(message) ‖ CRC-16)` followed by a `0x00`
//!   delimiter. [`encode_frame`] writes one frame into a caller's buffer;
//!   [`FrameDecoder`] takes bytes as they arrive, in a fixed buffer, and hands back whole
//!   messages. Truncated, corrupt, oversize and unknown frames are counted in
//!   [`WireCounters`] and skipped: the decoder resynchronises on the next delimiter, never
//!   panics and never allocates.
//! - [`scan`]: a lidar scan is longer than one frame; [`ScanAssembler`] puts the chunks of
//!   one scan back together and drops a scan with a missing chunk.
//! - [`events`]: [`EventsToWire`] turns the core's event stream into messages (for a
//!   host streaming a dataset to a device).
//!
//! This is the bottom layer of the link: bytes ↔ messages. The program that answers the
//! messages on the device, turning them into estimator steps, is
//! [`crate::device::Session`], one layer above.
//!
//! ```
//! use microslam::wire::{encode_frame, FrameDecoder, Odometry, ToDevice, MAX_FRAME_LEN};
//!
//! let msg = ToDevice::Odometry { seq: 7, stamp_us: 1_000, odometry: Odometry::Velocity { v: 0.2, omega: 0.1, dt: 0.05 } };
//! let mut buf = [0u8; MAX_FRAME_LEN];
//! let frame = encode_frame(&msg, &mut buf)?;
//!
//! let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
//! let mut got = None;
//! for &b in b"\x13garbage\x00".iter().chain(frame.iter()) {
//!     if let Some(Ok(m)) = decoder.push::<ToDevice>(b) {
//!         got = Some(m);
//!     }
//! }
//! assert_eq!(got, Some(msg));
//! assert_eq!(decoder.counters().ok, 1);
//! assert_eq!(decoder.counters().bad(), 1); // the garbage before it
//! # Ok::<(), microslam::wire::EncodeError>(())
//! ```

pub mod events;
pub mod frame;
pub mod messages;
pub mod scan;

pub use events::EventsToWire;
pub use frame::{
    EncodeError, FrameDecoder, FrameError, MAX_FRAME_LEN, MAX_PAYLOAD_LEN, WireCounters,
    encode_frame,
};
pub use messages::{
    CarSettings, Command, EkfSettings, Estimate, EstimatorKind, LidarCounters, LocalizerReport,
    MAP_CHUNK_BYTES, MapBytes, Odometry, PROTOCOL_VERSION, Refusal, SCAN_CHUNK_BEAMS, ScanChunk,
    Status, StepResult, ToDevice, ToHost, TrackingState,
};
pub use scan::{Scan, ScanAssembler, ScanError};

#[cfg(test)]
mod tests;
