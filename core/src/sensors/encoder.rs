//! Quadrature wheel encoders read through a hardware counter (an STM32 timer in encoder
//! mode, an ESP32 PCNT unit, …): the signed ticks since the last read, through the
//! counter's wrap-around ([`EncoderCounter`]), and the two wheels of a differential
//! drive as the [`WheelTicks`] the odometry model takes ([`DiffDriveEncoders`]).
//!
//! A counter of `bits` bits counts modulo `2^bits`; two reads are turned into the
//! difference of least magnitude, so a read must come before the wheel has turned half
//! the counter's range (a 16-bit timer and a 2 000-tick wheel: 16 turns). A difference
//! larger than the setting `max_ticks_per_read` is refused loudly
//! ([`EncoderError::TooManyTicks`]): a missed read, a glitch or a counter of another
//! width, never a silent jump of the estimate.
//!
//! ```
//! use microslam::sensors::encoder::{DiffDriveEncoders, EncoderCounter};
//!
//! // 16-bit timers; the left motor is mounted mirrored, so its counter runs backwards.
//! let counter = EncoderCounter::new(16, 5_000).expect("valid setup");
//! let mut wheels = DiffDriveEncoders::new(counter.inverted(), counter);
//! wheels.read(0, 65_530)?; // the first read sets the reference
//! let ticks = wheels.read(65_436, 94)?; // 100 ticks forward on each side
//! assert_eq!((ticks.front_left, ticks.front_right), (100, 100));
//! # Ok::<(), microslam::sensors::encoder::EncoderError>(())
//! ```

use super::wheel_odometry::WheelTicks;
use core::fmt;

/// Why a counter read was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncoderError {
    /// The raw value does not fit the counter's bits (a counter of another width).
    RawOutOfRange {
        /// The value read.
        raw: u32,
    },
    /// More ticks since the last read than `max_ticks_per_read`: a missed read or a
    /// glitch. The read becomes the new reference; the ticks in between are lost.
    TooManyTicks {
        /// The difference of least magnitude to the last read.
        ticks: i32,
    },
}

impl fmt::Display for EncoderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::RawOutOfRange { raw } => {
                write!(f, "encoder counter read {raw}, beyond the counter's bits")
            }
            Self::TooManyTicks { ticks } => write!(
                f,
                "encoder moved {ticks} ticks since the last read, more than the setting allows"
            ),
        }
    }
}

impl core::error::Error for EncoderError {}

/// One wheel's hardware counter, read now and then.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EncoderCounter {
    bits: u8,
    max_ticks_per_read: u32,
    inverted: bool,
    last: Option<u32>,
}

impl EncoderCounter {
    /// A counter of `bits` bits (1–32) whose reads may differ by at most
    /// `max_ticks_per_read` ticks (less than half its range); `None` otherwise.
    pub const fn new(bits: u8, max_ticks_per_read: u32) -> Option<Self> {
        if bits == 0 || bits > 32 {
            return None;
        }
        let half = 1u64 << (bits - 1);
        if max_ticks_per_read as u64 >= half {
            return None;
        }
        Some(Self {
            bits,
            max_ticks_per_read,
            inverted: false,
            last: None,
        })
    }

    /// The same counter counting the other way (a motor mounted mirrored).
    pub const fn inverted(self) -> Self {
        Self {
            inverted: !self.inverted,
            ..self
        }
    }

    /// Forgets the reference: the next read gives 0 ticks.
    pub fn reset(&mut self) {
        self.last = None;
    }

    /// The ticks since the last read (0 for the first read, which sets the reference),
    /// through the counter's wrap-around, with the sign of forward motion.
    pub fn read(&mut self, raw: u32) -> Result<i32, EncoderError> {
        let mask = if self.bits == 32 {
            u32::MAX
        } else {
            (1u32 << self.bits) - 1
        };
        if raw & !mask != 0 {
            return Err(EncoderError::RawOutOfRange { raw });
        }
        let Some(last) = self.last.replace(raw) else {
            return Ok(0);
        };
        // The difference modulo 2^bits, then into [−2^(bits−1), 2^(bits−1)).
        let diff = raw.wrapping_sub(last) & mask;
        let half = 1u64 << (self.bits - 1);
        let ticks = if u64::from(diff) >= half {
            i64::from(diff) - (1i64 << self.bits)
        } else {
            i64::from(diff)
        };
        let ticks = i32::try_from(ticks).unwrap_or(if ticks < 0 { i32::MIN } else { i32::MAX });
        if ticks.unsigned_abs() > self.max_ticks_per_read {
            return Err(EncoderError::TooManyTicks { ticks });
        }
        Ok(if self.inverted { -ticks } else { ticks })
    }
}

/// The two wheel counters of a differential drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DiffDriveEncoders {
    /// The left wheel's counter.
    pub left: EncoderCounter,
    /// The right wheel's counter.
    pub right: EncoderCounter,
}

impl DiffDriveEncoders {
    /// The two counters.
    pub const fn new(left: EncoderCounter, right: EncoderCounter) -> Self {
        Self { left, right }
    }

    /// Reads both counters: the ticks of each side since the last read, as
    /// [`WheelTicks`] with each side's front and rear wheel equal (the odometry model
    /// averages them). Both counters take their read even when one is refused (so that
    /// neither falls behind); the first error is returned.
    pub fn read(&mut self, left_raw: u32, right_raw: u32) -> Result<WheelTicks, EncoderError> {
        let left = self.left.read(left_raw);
        let right = self.right.read(right_raw);
        let (left, right) = (left?, right?);
        Ok(WheelTicks {
            front_right: right,
            front_left: left,
            rear_right: right,
            rear_left: left,
        })
    }
}

#[cfg(test)]
mod tests;
