//! A lidar log as the packet stream of the device's own lidar (an LDROBOT LD06 on its
//! second UART): [`ld06_packets`] turns scans into the lidar's packets (one revolution a
//! scan), [`Ld06Stream::new`] lays them end to end with the line faults a real UART
//! suffers ([`LineFaults`]: noise between packets, corrupted bytes, lost packets), and
//! [`host_reader`] is the firmware's reader (`microslam-hal`'s `Ld06Uart`) over the same
//! bytes, for the host reference of `hil --own-lidar`.

use anyhow::{Result, bail};
use microslam::profile::{LIDAR_BINS, LIDAR_SETUP};
use microslam::sensors::ld06::{AngleDirection, Ld06Packet, PACKET_BYTES, revolution_packets};
use microslam::sensors::lidar::{LidarGeometry, LidarScan};
use microslam_hal::lidar::Ld06Uart;
use rand_core::{RngCore, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::inputs::readers::carmen::LaserMessage;

/// The packets of one revolution per scan of `scans` (a lidar of geometry `lidar`), the
/// angles clockwise as the LD06's, stamped from the first scan on (ms), at the rotation
/// speed of the scans' median interval. Also that speed, °/s. Errors name the scan whose
/// beams cannot be a revolution of packets.
pub fn ld06_packets(
    scans: &[&LaserMessage],
    lidar: &LidarGeometry,
) -> Result<(Vec<Vec<Ld06Packet>>, u16)> {
    let mut gaps: Vec<f64> = scans
        .windows(2)
        .map(|w| w[1].stamp - w[0].stamp)
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    gaps.sort_by(f64::total_cmp);
    let period = gaps.get(gaps.len() / 2).copied().unwrap_or(0.1);
    let speed_deg_s = (360.0 / period).round().clamp(1.0, f64::from(u16::MAX)) as u16;
    let Some(first_stamp) = scans.first().map(|s| s.stamp) else {
        bail!("no scan to send as lidar packets");
    };
    let mut revolutions = Vec::with_capacity(scans.len());
    for (i, laser) in scans.iter().enumerate() {
        let stamp_ms = ((laser.stamp - first_stamp) * 1000.0).round().max(0.0) as u32;
        let mut packets = Vec::with_capacity(32);
        revolution_packets(
            &LidarScan::new(&laser.ranges, *lidar),
            AngleDirection::Clockwise,
            speed_deg_s,
            stamp_ms,
            |p| packets.push(p),
        )
        .map_err(|e| anyhow::anyhow!("scan {i} ({} beams): {e}", laser.ranges.len()))?;
        revolutions.push(packets);
    }
    Ok((revolutions, speed_deg_s))
}

/// Faults of the line between the lidar and the device, each a fraction of the packets
/// (0 to 1), drawn from `seed`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct LineFaults {
    /// Packets followed by 1–16 bytes of noise.
    pub noise: f64,
    /// Packets with one byte after the header changed (the checksum fails).
    pub corrupt: f64,
    /// Packets lost.
    pub drop: f64,
    /// Seed of the draws.
    pub seed: u64,
}

impl LineFaults {
    /// The first fraction that is not within 0–1, by its option's name.
    pub fn invalid(&self) -> Option<&'static str> {
        [
            ("--lidar-noise", self.noise),
            ("--lidar-corrupt", self.corrupt),
            ("--lidar-drop", self.drop),
        ]
        .into_iter()
        .find(|(_, f)| !(0.0..=1.0).contains(f))
        .map(|(name, _)| name)
    }
}

/// The bytes the device's lidar UART receives, and what was done to them.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Ld06Stream {
    /// The bytes.
    #[serde(skip)]
    pub bytes: Vec<u8>,
    /// Packets sent whole.
    pub packets: usize,
    /// Packets sent with a byte changed.
    pub corrupted: usize,
    /// Packets left out.
    pub dropped: usize,
    /// Bytes of noise sent between packets.
    pub noise_bytes: usize,
    /// Revolutions the device's reader completes on these bytes (one per scan: a last
    /// revolution is sent again after the scans, since a revolution ends where the next
    /// one starts).
    pub revolutions: usize,
}

impl Ld06Stream {
    /// The packets of `revolutions` end to end with `faults`, then the last revolution
    /// again (whole), so that the reader finishes every one of them. Fails when the
    /// faults leave the reader fewer revolutions than there are scans (whole revolutions
    /// lost: the device would wait for one that never comes).
    pub fn new(revolutions: &[Vec<Ld06Packet>], faults: &LineFaults) -> Result<Self> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(faults.seed);
        let mut uniform = move || (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        let mut s = Self::default();
        for packets in revolutions {
            for p in packets {
                if uniform() < faults.drop {
                    s.dropped += 1;
                    continue;
                }
                let mut bytes = p.encode();
                if uniform() < faults.corrupt {
                    // A byte after the start and length: the checksum no longer matches.
                    let at = 2 + (uniform() * (PACKET_BYTES - 2) as f64) as usize;
                    let at = at.min(PACKET_BYTES - 1);
                    let change = 1 + (uniform() * 255.0) as u8;
                    bytes[at] = bytes[at].wrapping_add(change);
                    s.corrupted += 1;
                } else {
                    s.packets += 1;
                }
                s.bytes.extend_from_slice(&bytes);
                if uniform() < faults.noise {
                    let n = 1 + (uniform() * 16.0) as usize;
                    for _ in 0..n.min(16) {
                        s.bytes.push((uniform() * 256.0) as u8);
                    }
                    s.noise_bytes += n.min(16);
                }
            }
        }
        // The revolution after the last: it ends the last one.
        if let Some(last) = revolutions.last() {
            for p in last {
                s.bytes.extend_from_slice(&p.encode());
            }
        }
        let mut reader = host_reader(&s.bytes);
        while microslam::device::LidarSource::next_revolution(&mut reader).is_some() {
            s.revolutions += 1;
        }
        if s.revolutions < revolutions.len() {
            bail!(
                "the line faults leave {} revolutions of {}: lower --lidar-drop",
                s.revolutions,
                revolutions.len()
            );
        }
        s.revolutions = revolutions.len();
        Ok(s)
    }
}

/// Bytes that end: a read past them is an error (the lidar went quiet), as a UART read
/// that times out, so that a reader waiting for a revolution stops.
pub struct EndingBytes<'b>(&'b [u8]);

impl embedded_io::ErrorType for EndingBytes<'_> {
    type Error = embedded_io::ErrorKind;
}

impl embedded_io::Read for EndingBytes<'_> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        if self.0.is_empty() {
            return Err(embedded_io::ErrorKind::TimedOut);
        }
        let n = buf.len().min(self.0.len());
        let (now, rest) = self.0.split_at(n);
        buf.get_mut(..n)
            .ok_or(embedded_io::ErrorKind::InvalidInput)?
            .copy_from_slice(now);
        self.0 = rest;
        Ok(n)
    }
}

/// The firmware's lidar reader (the board profile's [`LIDAR_SETUP`], [`LIDAR_BINS`]
/// beams) over `bytes`.
pub fn host_reader(bytes: &[u8]) -> Ld06Uart<EndingBytes<'_>, LIDAR_BINS> {
    // LIDAR_SETUP is valid (the firmware halts at boot otherwise; a test holds it).
    Ld06Uart::new(EndingBytes(bytes), LIDAR_SETUP)
        .unwrap_or_else(|| unreachable!("profile::LIDAR_SETUP is refused by the LD06 binner"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use microslam::device::LidarSource;

    fn scan(stamp: f64, range: f32) -> LaserMessage {
        LaserMessage {
            rear: false,
            ranges: vec![range; 180],
            pose: [0.0; 3],
            odom: [0.0; 3],
            stamp,
        }
    }

    fn revolutions(n: usize) -> Vec<Vec<Ld06Packet>> {
        let scans: Vec<LaserMessage> = (0..n)
            .map(|i| scan(i as f64 * 0.2, 2.0 + i as f32 * 0.1))
            .collect();
        let refs: Vec<&LaserMessage> = scans.iter().collect();
        ld06_packets(&refs, &crate::domain::grid::carmen_lidar(180))
            .expect("1° beams")
            .0
    }

    #[test]
    fn every_scan_comes_back_as_a_revolution_of_the_readers_beams() {
        let revs = revolutions(5);
        assert_eq!(revs.iter().map(Vec::len).collect::<Vec<_>>(), [30; 5]);
        let stream = Ld06Stream::new(&revs, &LineFaults::default()).expect("clean line");
        assert_eq!((stream.packets, stream.revolutions), (150, 5));
        let mut reader = host_reader(&stream.bytes);
        for i in 0..5 {
            let scan = reader.next_revolution().expect("a revolution");
            // The SICK's beam at 0° (straight ahead) is bin 0; its range is the scan's.
            let want = 2.0 + i as f32 * 0.1;
            assert!(
                (scan.ranges[0] - want).abs() < 6e-4,
                "scan {i}: {}",
                scan.ranges[0]
            );
            // Behind the robot the 180° scanner sees nothing.
            assert!(scan.ranges[180] > LIDAR_SETUP.max_range);
        }
        assert!(reader.next_revolution().is_none(), "the stream ends");
    }

    #[test]
    fn the_reader_counts_every_corrupted_packet_and_keeps_the_rest() {
        let revs = revolutions(20);
        let faults = LineFaults {
            noise: 0.05,
            corrupt: 0.03,
            drop: 0.02,
            seed: 7,
        };
        let stream = Ld06Stream::new(&revs, &faults).expect("few faults");
        assert!(stream.corrupted > 0 && stream.dropped > 0 && stream.noise_bytes > 0);
        let mut reader = host_reader(&stream.bytes);
        while reader.next_revolution().is_some() {}
        let c = LidarSource::counters(&reader);
        // Every changed packet fails its checksum; every whole one (and the closing
        // revolution's 30) is decoded.
        assert_eq!(c.bad_packets as usize, stream.corrupted);
        assert_eq!(c.packets as usize, stream.packets + 30);
    }

    #[test]
    fn fractions_out_of_range_are_named() {
        let bad = LineFaults {
            drop: 1.5,
            ..LineFaults::default()
        };
        assert_eq!(bad.invalid(), Some("--lidar-drop"));
        assert_eq!(LineFaults::default().invalid(), None);
    }
}
