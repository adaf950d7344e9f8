//! An LDROBOT LD06 / LD19 lidar on a UART.

use microslam::sensors::ld06::{Ld06Counters, Ld06Decoder, Ld06Setup, RevolutionBinner};
use microslam::sensors::lidar::LidarScan;

/// Bytes taken from the UART per read.
const CHUNK: usize = 64;

/// The lidar on a UART (230 400 Bd, 8N1): [`Ld06Uart::poll`] reads what the UART has and
/// says when a revolution is complete; [`Ld06Uart::scan`] is the last complete one, in
/// `BINS` beams.
///
/// ```
/// use microslam::sensors::ld06::{revolution_packets, AngleDirection, Ld06Setup};
/// use microslam::sensors::lidar::{LidarGeometry, LidarScan};
/// use microslam_hal::lidar::Ld06Uart;
///
/// // Two revolutions of a lidar 1.5 m from every wall, as its UART would deliver them.
/// let ranges = [1.5f32; 360];
/// let geometry = LidarGeometry { first_angle: 0.0, angle_increment: 1f32.to_radians(),
///     ..LidarGeometry::CARMEN_SICK_180 };
/// let mut bytes = Vec::new();
/// for turn in 0..2 {
///     revolution_packets(&LidarScan::new(&ranges, geometry), AngleDirection::Clockwise,
///         3600, turn * 100, |p| bytes.extend_from_slice(&p.encode())).unwrap();
/// }
/// let mut lidar = Ld06Uart::<_, 360>::new(bytes.as_slice(), Ld06Setup::LD06).unwrap();
/// while !lidar.poll()? {}
/// assert!(lidar.scan().ranges.iter().all(|&r| r == 1.5));
/// # Ok::<(), core::convert::Infallible>(())
/// ```
pub struct Ld06Uart<R, const BINS: usize> {
    uart: R,
    decoder: Ld06Decoder,
    binner: RevolutionBinner<BINS>,
    buf: [u8; CHUNK],
    /// Bytes of `buf` read but not yet decoded: `next..end`.
    next: usize,
    end: usize,
}

impl<R: embedded_io::Read, const BINS: usize> Ld06Uart<R, BINS> {
    /// The lidar on `uart`, its points put into `BINS` beams with `setup`; `None` for a
    /// setup the binner refuses ([`RevolutionBinner::new`]).
    pub fn new(uart: R, setup: Ld06Setup) -> Option<Self> {
        Some(Self {
            uart,
            decoder: Ld06Decoder::new(),
            binner: RevolutionBinner::new(setup)?,
            buf: [0; CHUNK],
            next: 0,
            end: 0,
        })
    }

    /// Decodes the bytes left from the last read, or else reads the UART once (which
    /// blocks until it has a byte, as `embedded_io::Read` does); `true` when a
    /// revolution was completed (the bytes after it wait for the next call, so none is
    /// lost and no revolution is skipped). An error of the UART is returned as it is.
    pub fn poll(&mut self) -> Result<bool, R::Error> {
        if self.next >= self.end {
            self.end = self.uart.read(&mut self.buf)?;
            self.next = 0;
        }
        while self.next < self.end {
            let byte = self.buf.get(self.next).copied().unwrap_or(0);
            self.next += 1;
            if let Some(packet) = self.decoder.push(byte)
                && self.binner.push(&packet)
            {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// The last complete revolution (every beam empty before the first).
    pub fn scan(&self) -> LidarScan<'_> {
        self.binner.scan()
    }

    /// The lidar's clock at the start of the last complete revolution, ms.
    pub fn stamp_ms(&self) -> u16 {
        self.binner.stamp_ms()
    }

    /// What the decoder has seen: packets, noise, bad CRCs.
    pub fn counters(&self) -> Ld06Counters {
        self.decoder.counters()
    }

    /// Revolutions completed.
    pub fn revolutions(&self) -> u32 {
        self.binner.revolutions()
    }

    /// Gives the UART back.
    pub fn release(self) -> R {
        self.uart
    }
}

/// The reader as a [`microslam::device::Session`]'s own lidar.
#[cfg(feature = "device")]
impl<R: embedded_io::Read, const BINS: usize> microslam::device::LidarSource for Ld06Uart<R, BINS> {
    fn next_revolution(&mut self) -> Option<LidarScan<'_>> {
        loop {
            match self.poll() {
                Ok(true) => return Some(self.scan()),
                Ok(false) => {}
                Err(_) => return None,
            }
        }
    }

    fn counters(&self) -> microslam::wire::LidarCounters {
        let c = self.decoder.counters();
        microslam::wire::LidarCounters {
            packets: c.packets,
            bad_packets: c.bad_crc.saturating_add(c.bad_angle),
            skipped_bytes: c.skipped_bytes,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use microslam::sensors::ld06::{AngleDirection, EMPTY_BIN, revolution_packets};
    use microslam::sensors::lidar::LidarGeometry;

    /// A UART that hands out at most `per_read` bytes a read.
    struct Trickle<'a> {
        bytes: &'a [u8],
        per_read: usize,
    }

    impl embedded_io::ErrorType for Trickle<'_> {
        type Error = embedded_io::ErrorKind;
    }

    impl embedded_io::Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
            let n = self.per_read.min(buf.len()).min(self.bytes.len());
            if n == 0 {
                return Err(embedded_io::ErrorKind::Other);
            }
            buf[..n].copy_from_slice(&self.bytes[..n]);
            self.bytes = &self.bytes[n..];
            Ok(n)
        }
    }

    fn stream(ranges: &[f32], turns: u32) -> Vec<u8> {
        let g = LidarGeometry {
            first_angle: 0.0,
            angle_increment: 1f32.to_radians(),
            ..LidarGeometry::CARMEN_SICK_180
        };
        let mut bytes = Vec::new();
        for t in 0..turns {
            revolution_packets(
                &LidarScan::new(ranges, g),
                AngleDirection::Clockwise,
                3600,
                t * 100,
                |p| bytes.extend_from_slice(&p.encode()),
            )
            .expect("1° beams");
        }
        bytes
    }

    #[test]
    fn every_revolution_is_delivered_whatever_the_reads_size() {
        let ranges: Vec<f32> = (0..360).map(|i| 1.0 + i as f32 * 0.01).collect();
        let bytes = stream(&ranges, 4);
        for per_read in [1, 7, 47, 64] {
            let uart = Trickle {
                bytes: &bytes,
                per_read,
            };
            let mut lidar = Ld06Uart::<_, 360>::new(uart, Ld06Setup::LD06).expect("setup");
            let mut finished = 0;
            while let Ok(done) = lidar.poll() {
                if done {
                    finished += 1;
                    let back = lidar.scan();
                    for (i, &r) in ranges.iter().enumerate() {
                        assert!((back.ranges[i] - r).abs() < 0.0006, "beam {i}");
                    }
                }
            }
            // The fourth revolution ends only when a fifth begins.
            assert_eq!(finished, 3, "{per_read} bytes a read");
            assert_eq!(lidar.revolutions(), 3);
            assert_eq!(lidar.counters().packets, 120);
        }
    }

    #[test]
    fn noise_on_the_line_loses_only_the_packets_it_hits() {
        let mut bytes = stream(&[2.0; 360], 3);
        // One flipped bit in a packet of the second revolution: that packet's 12 points
        // are lost, the revolution still ends.
        bytes[47 * 35 + 10] ^= 0x10;
        let mut lidar = Ld06Uart::<_, 360>::new(bytes.as_slice(), Ld06Setup::LD06).expect("setup");
        let mut scans = Vec::new();
        loop {
            let done = lidar.poll().expect("a slice never fails");
            if done {
                scans.push(
                    lidar
                        .scan()
                        .ranges
                        .iter()
                        .filter(|&&r| r != EMPTY_BIN)
                        .count(),
                );
            }
            if lidar.counters().packets == 89 {
                break;
            }
        }
        assert_eq!(scans, [360, 348]);
        assert_eq!(lidar.counters().bad_crc, 1);
    }
}
