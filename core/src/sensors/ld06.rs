//! The LDROBOT LD06 and LD19 lidars on a UART (230 400 Bd, 8N1): their packets found and
//! checked in the byte stream ([`Ld06Decoder`]), and a revolution's points put into the
//! fixed beams of a [`LidarScan`] ([`RevolutionBinner`]). Both `no_std`, fixed memory,
//! never panicking on any byte stream.
//!
//! # Packet (LDROBOT's LD06 datasheet, "Communication protocol")
//!
//! The lidar sends, unasked, one 47-byte packet per 12 measurements, little-endian:
//!
//! | offset | bytes | field |
//! | --- | --- | --- |
//! | 0 | 1 | start character `0x54` |
//! | 1 | 1 | `0x2C`: 3 reserved bits, then the number of points (12) in the low 5 bits |
//! | 2 | 2 | rotation speed, degrees a second |
//! | 4 | 2 | angle of the first point, 0.01° |
//! | 6 | 36 | 12 points: distance (mm, `u16`; 0 when nothing returned), intensity (`u8`) |
//! | 42 | 2 | angle of the last point, 0.01° |
//! | 44 | 2 | time stamp, ms (counts up to 30 000, then starts again at 0) |
//! | 46 | 1 | CRC-8 (polynomial `0x4D`, initial value 0, not reflected) of bytes 0–45 |
//!
//! The points between the first and the last are evenly spread over the angle between
//! them (which wraps through 360°). The datasheet's angles grow clockwise seen from
//! above; [`AngleDirection`] says how the binner turns them into the counter-clockwise
//! beam angles of [`LidarGeometry`].
//!
//! # Resynchronisation
//!
//! A byte that cannot start a packet is skipped (counted); a packet whose CRC or angles
//! are wrong is dropped (counted) and the search for the next start character begins at
//! the byte after the bad packet's start character, so that a packet that begins inside
//! the bytes of a corrupt one is still found.

use super::lidar::{LidarGeometry, LidarScan};
use crate::geometry::Pose2;

/// Bytes of one packet.
pub const PACKET_BYTES: usize = 47;
/// Points in one packet.
pub const POINTS_PER_PACKET: usize = 12;
/// The first byte of every packet.
pub const START: u8 = 0x54;
/// The second byte: the number of points (12) in the low five bits.
pub const VER_LEN: u8 = 0x2C;
/// A full turn in the packets' unit, 0.01°.
const TURN: u32 = 36_000;

/// The CRC-8 of the packets (polynomial `0x4D`, most significant bit first), as a table
/// made at compile time.
const CRC_TABLE: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u8;
        let mut bit = 0;
        while bit < 8 {
            c = if c & 0x80 != 0 {
                (c << 1) ^ 0x4D
            } else {
                c << 1
            };
            bit += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// The packets' CRC-8 of `bytes`.
pub fn crc8(bytes: &[u8]) -> u8 {
    bytes
        .iter()
        .fold(0u8, |c, &b| CRC_TABLE[usize::from(c ^ b)])
}

/// One measurement of a packet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ld06Point {
    /// Distance, millimetres (0: nothing returned).
    pub distance_mm: u16,
    /// Intensity of the return (0–255; the datasheet gives about 200 for a white surface
    /// within 6 m).
    pub intensity: u8,
}

/// One packet: 12 measurements and the angles and time they were taken at.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ld06Packet {
    /// Rotation speed, degrees a second.
    pub speed_deg_s: u16,
    /// Angle of the first point, 0.01° (below 36 000).
    pub start_angle: u16,
    /// Angle of the last point, 0.01° (below 36 000).
    pub end_angle: u16,
    /// Time stamp, ms (the lidar counts up to 30 000, then starts again).
    pub stamp_ms: u16,
    /// The measurements, first to last.
    pub points: [Ld06Point; POINTS_PER_PACKET],
}

/// Why a packet was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PacketError {
    /// The first byte is not [`START`] or the second not [`VER_LEN`].
    BadStart,
    /// The CRC-8 does not match the bytes.
    BadCrc,
    /// An angle is 360° or more.
    BadAngle,
}

impl core::fmt::Display for PacketError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::BadStart => "LD06 packet does not start with 0x54 0x2C",
            Self::BadCrc => "LD06 packet's CRC-8 does not match its bytes",
            Self::BadAngle => "LD06 packet has an angle of 360° or more",
        })
    }
}

impl core::error::Error for PacketError {}

fn u16_at(bytes: &[u8; PACKET_BYTES], at: usize) -> u16 {
    let lo = bytes.get(at).copied().unwrap_or(0);
    let hi = bytes.get(at + 1).copied().unwrap_or(0);
    u16::from_le_bytes([lo, hi])
}

impl Ld06Packet {
    /// Reads and checks one packet: start bytes, CRC, angles below 360°.
    pub fn parse(bytes: &[u8; PACKET_BYTES]) -> Result<Self, PacketError> {
        if bytes[0] != START || bytes[1] != VER_LEN {
            return Err(PacketError::BadStart);
        }
        if crc8(&bytes[..PACKET_BYTES - 1]) != bytes[PACKET_BYTES - 1] {
            return Err(PacketError::BadCrc);
        }
        let mut points = [Ld06Point::default(); POINTS_PER_PACKET];
        for (i, p) in points.iter_mut().enumerate() {
            let at = 6 + 3 * i;
            *p = Ld06Point {
                distance_mm: u16_at(bytes, at),
                intensity: bytes.get(at + 2).copied().unwrap_or(0),
            };
        }
        let packet = Self {
            speed_deg_s: u16_at(bytes, 2),
            start_angle: u16_at(bytes, 4),
            end_angle: u16_at(bytes, 42),
            stamp_ms: u16_at(bytes, 44),
            points,
        };
        if u32::from(packet.start_angle) >= TURN || u32::from(packet.end_angle) >= TURN {
            return Err(PacketError::BadAngle);
        }
        Ok(packet)
    }

    /// The packet's bytes, CRC included (what the lidar sends; for tests and for a host
    /// that turns a recording into the lidar's own stream).
    pub fn encode(&self) -> [u8; PACKET_BYTES] {
        let mut b = [0u8; PACKET_BYTES];
        b[0] = START;
        b[1] = VER_LEN;
        b[2..4].copy_from_slice(&self.speed_deg_s.to_le_bytes());
        b[4..6].copy_from_slice(&self.start_angle.to_le_bytes());
        for (i, p) in self.points.iter().enumerate() {
            let at = 6 + 3 * i;
            b[at..at + 2].copy_from_slice(&p.distance_mm.to_le_bytes());
            b[at + 2] = p.intensity;
        }
        b[42..44].copy_from_slice(&self.end_angle.to_le_bytes());
        b[44..46].copy_from_slice(&self.stamp_ms.to_le_bytes());
        b[PACKET_BYTES - 1] = crc8(&b[..PACKET_BYTES - 1]);
        b
    }

    /// The angle of point `i` (0–11), 0.01°, below 36 000: the first and last points at
    /// the packet's angles, the others evenly between them (through 0° when the last
    /// angle is below the first).
    pub fn point_angle(&self, i: usize) -> u32 {
        let (start, end) = (u32::from(self.start_angle), u32::from(self.end_angle));
        let span = (end + TURN - start) % TURN;
        let last = (POINTS_PER_PACKET - 1) as u32;
        let i = (i as u32).min(last);
        (start + span * i / last) % TURN
    }
}

/// What an [`Ld06Decoder`] has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ld06Counters {
    /// Packets that passed every check.
    pub packets: u32,
    /// Bytes skipped while looking for a packet's start.
    pub skipped_bytes: u32,
    /// Packets dropped for a wrong CRC.
    pub bad_crc: u32,
    /// Packets dropped for an angle of 360° or more.
    pub bad_angle: u32,
}

/// Finds the packets in the lidar's byte stream, one byte at a time, in a 47-byte
/// buffer.
///
/// ```
/// use microslam::sensors::ld06::{Ld06Decoder, Ld06Packet};
///
/// // A packet of the LD06 datasheet, after three bytes of noise.
/// let packet: [u8; 47] = [
///     0x54, 0x2C, 0x68, 0x08, 0xAB, 0x7E, 0xE0, 0x00, 0xE4, 0xDC, 0x00, 0xE2, 0xD9, 0x00,
///     0xE5, 0xD5, 0x00, 0xE3, 0xD3, 0x00, 0xE4, 0xD0, 0x00, 0xE9, 0xCD, 0x00, 0xE4, 0xCA,
///     0x00, 0xE2, 0xC7, 0x00, 0xE9, 0xC5, 0x00, 0xE5, 0xC2, 0x00, 0xE5, 0xC0, 0x00, 0xE5,
///     0xBE, 0x82, 0x3A, 0x1A, 0x50,
/// ];
/// let mut decoder = Ld06Decoder::new();
/// let mut found = None;
/// for &b in [0x00, 0x54, 0x13].iter().chain(packet.iter()) {
///     if let Some(p) = decoder.push(b) {
///         found = Some(p);
///     }
/// }
/// let p: Ld06Packet = found.expect("one packet");
/// assert_eq!((p.speed_deg_s, p.start_angle, p.end_angle), (2152, 32427, 33470));
/// assert_eq!(p.points[0].distance_mm, 224);
/// assert_eq!(decoder.counters().skipped_bytes, 3);
/// ```
#[derive(Clone, Debug)]
pub struct Ld06Decoder {
    buf: [u8; PACKET_BYTES],
    len: usize,
    counters: Ld06Counters,
}

impl Default for Ld06Decoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Ld06Decoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; PACKET_BYTES],
            len: 0,
            counters: Ld06Counters {
                packets: 0,
                skipped_bytes: 0,
                bad_crc: 0,
                bad_angle: 0,
            },
        }
    }

    /// What it has seen so far.
    pub fn counters(&self) -> Ld06Counters {
        self.counters
    }

    /// Takes the next byte; returns a packet when this byte completed one that passed
    /// every check.
    pub fn push(&mut self, byte: u8) -> Option<Ld06Packet> {
        match self.len {
            0 if byte != START => {
                self.counters.skipped_bytes = self.counters.skipped_bytes.saturating_add(1);
                return None;
            }
            1 if byte != VER_LEN => {
                // The start character was noise; this byte may start a packet itself.
                self.counters.skipped_bytes = self.counters.skipped_bytes.saturating_add(1);
                self.len = 0;
                return self.push(byte);
            }
            _ => {}
        }
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            self.len += 1;
        }
        if self.len < PACKET_BYTES {
            return None;
        }
        match Ld06Packet::parse(&self.buf) {
            Ok(packet) => {
                self.len = 0;
                self.counters.packets = self.counters.packets.saturating_add(1);
                Some(packet)
            }
            Err(e) => {
                if e == PacketError::BadAngle {
                    self.counters.bad_angle = self.counters.bad_angle.saturating_add(1);
                } else {
                    self.counters.bad_crc = self.counters.bad_crc.saturating_add(1);
                }
                self.resync();
                None
            }
        }
    }

    /// After a bad packet: keeps the bytes from the next start character after its first
    /// byte (a packet may begin inside a corrupt one), counting the ones before it as
    /// skipped.
    fn resync(&mut self) {
        let next = (1..self.len)
            .find(|&i| {
                self.buf.get(i) == Some(&START)
                    && (i + 1 == self.len || self.buf.get(i + 1) == Some(&VER_LEN))
            })
            .unwrap_or(self.len);
        self.counters.skipped_bytes = self
            .counters
            .skipped_bytes
            .saturating_add(u32::try_from(next).unwrap_or(u32::MAX));
        self.buf.copy_within(next..self.len, 0);
        self.len -= next;
    }
}

/// Which way the packets' angles grow, seen from above.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AngleDirection {
    /// Clockwise, as the LD06 datasheet draws them: beam angle = −packet angle.
    Clockwise,
    /// Counter-clockwise (a lidar mounted upside down): beam angle = packet angle.
    CounterClockwise,
}

/// How a [`RevolutionBinner`] turns points into beams.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Ld06Setup {
    /// Which way the packets' angles grow.
    pub direction: AngleDirection,
    /// Returns weaker than this are dropped (0: keep every return).
    pub min_intensity: u8,
    /// Shorter readings are dropped, metres (the datasheet's range starts at 0.02 m).
    pub min_range: f32,
    /// Readings at or beyond this are dropped, metres (the datasheet's: 12 m).
    pub max_range: f32,
    /// Where the lidar sits on the robot.
    pub mount: Pose2<f32>,
}

impl Ld06Setup {
    /// The LD06 as the datasheet gives it, mounted upright at the robot's origin facing
    /// forward.
    pub const LD06: Self = Self {
        direction: AngleDirection::Clockwise,
        min_intensity: 0,
        min_range: 0.02,
        max_range: 12.0,
        mount: Pose2::new(0.0, 0.0, 0.0),
    };
}

/// A bin no point fell into holds this, metres: beyond any distance a packet can carry
/// (65.535 m), at the geometry's no-return range.
pub const EMPTY_BIN: f32 = 65.536;

/// Puts the points of each revolution into `BINS` beams evenly spread over the turn
/// (beam `i` at `i · 360° / BINS` counter-clockwise from the lidar's forward axis), the
/// nearest return of a beam's angular bin in it: a [`LidarScan`] per revolution for the
/// grid filters. A revolution ends when a point's angle comes back below the one before
/// it (the lidar passed 0°). Fixed memory: two `BINS`-beam buffers (the revolution being
/// filled, the last finished one).
#[derive(Clone, Debug)]
pub struct RevolutionBinner<const BINS: usize> {
    setup: Ld06Setup,
    filling: [f32; BINS],
    finished: [f32; BINS],
    /// Angle of the last point, 0.01°, in the packets' direction.
    last_angle: Option<u32>,
    /// Time stamp of the first packet of the revolution being filled, and of the
    /// finished one, ms.
    filling_stamp: Option<u16>,
    finished_stamp: u16,
    /// Points of the revolution being filled that landed in a beam, and of the finished.
    filling_points: u32,
    finished_points: u32,
    revolutions: u32,
}

impl<const BINS: usize> RevolutionBinner<BINS> {
    /// An empty binner; refuses `BINS = 0` and a setup whose ranges are not finite and
    /// ordered (`None`).
    pub fn new(setup: Ld06Setup) -> Option<Self> {
        let geometry_ok = BINS > 0
            && setup.min_range.is_finite()
            && setup.min_range >= 0.0
            && setup.max_range.is_finite()
            && setup.max_range > setup.min_range
            && setup.max_range < EMPTY_BIN
            && setup.mount.is_finite();
        geometry_ok.then_some(Self {
            setup,
            filling: [EMPTY_BIN; BINS],
            finished: [EMPTY_BIN; BINS],
            last_angle: None,
            filling_stamp: None,
            finished_stamp: 0,
            filling_points: 0,
            finished_points: 0,
            revolutions: 0,
        })
    }

    /// The beams' geometry: `BINS` beams from 0° counter-clockwise, the setup's ranges and
    /// mount, [`EMPTY_BIN`] as no return.
    pub fn geometry(&self) -> LidarGeometry {
        LidarGeometry {
            first_angle: 0.0,
            angle_increment: core::f32::consts::TAU / BINS as f32,
            min_range: self.setup.min_range,
            max_range: self.setup.max_range,
            no_return_range: EMPTY_BIN,
            mount: self.setup.mount,
        }
    }

    /// Adds a packet's points; `true` when a revolution finished with them (then
    /// [`RevolutionBinner::scan`] is that revolution until the next one finishes).
    pub fn push(&mut self, packet: &Ld06Packet) -> bool {
        let mut finished = false;
        if self.filling_stamp.is_none() {
            self.filling_stamp = Some(packet.stamp_ms);
        }
        for (i, p) in packet.points.iter().enumerate() {
            let angle = packet.point_angle(i);
            if self.last_angle.is_some_and(|last| angle < last) {
                self.finish(packet.stamp_ms);
                finished = true;
            }
            self.last_angle = Some(angle);
            self.add(angle, p);
        }
        finished
    }

    fn finish(&mut self, next_stamp: u16) {
        core::mem::swap(&mut self.filling, &mut self.finished);
        self.filling.fill(EMPTY_BIN);
        self.finished_stamp = self.filling_stamp.unwrap_or(next_stamp);
        self.filling_stamp = Some(next_stamp);
        self.finished_points = self.filling_points;
        self.filling_points = 0;
        self.revolutions = self.revolutions.saturating_add(1);
    }

    fn add(&mut self, angle: u32, p: &Ld06Point) {
        if p.distance_mm == 0 || p.intensity < self.setup.min_intensity {
            return;
        }
        let range = f32::from(p.distance_mm) / 1000.0;
        if range < self.setup.min_range || range >= self.setup.max_range {
            return;
        }
        // Counter-clockwise angle in 0.01°, then the nearest beam.
        let ccw = match self.setup.direction {
            AngleDirection::Clockwise => (TURN - angle) % TURN,
            AngleDirection::CounterClockwise => angle,
        };
        let bins = BINS as u64;
        let bin = ((u64::from(ccw) * bins + u64::from(TURN) / 2) / u64::from(TURN)) % bins;
        if let Some(slot) = self.filling.get_mut(bin as usize) {
            if range < *slot {
                *slot = range;
            }
            self.filling_points = self.filling_points.saturating_add(1);
        }
    }

    /// The last finished revolution (all [`EMPTY_BIN`] before the first).
    pub fn scan(&self) -> LidarScan<'_> {
        LidarScan::new(&self.finished, self.geometry())
    }

    /// Time stamp of the last finished revolution's first packet, ms (the lidar's clock).
    pub fn stamp_ms(&self) -> u16 {
        self.finished_stamp
    }

    /// Points of the last finished revolution that landed in a beam.
    pub fn points(&self) -> u32 {
        self.finished_points
    }

    /// Revolutions finished.
    pub fn revolutions(&self) -> u32 {
        self.revolutions
    }
}

/// Why a scan cannot be sent as an LD06 revolution ([`revolution_packets`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RevolutionError {
    /// The beams are not a whole number of 0.01° steps of a turn that 12 divides (e.g.
    /// 1° or 0.5° apart), or the geometry is invalid.
    Spacing,
}

impl core::fmt::Display for RevolutionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(
            "the scan's beams are not evenly spaced over a turn in 0.01° steps and packets of 12",
        )
    }
}

impl core::error::Error for RevolutionError {}

/// The packets an LD06 would send for one revolution over `scan`: a full turn of points
/// at the scan's beam spacing, starting at 0° in the packets' `direction`, each the
/// scan's reading at that angle (no distance where the scan has no beam or no usable
/// reading, millimetres otherwise, intensity 200), 12 to a packet, stamped from
/// `stamp_ms` on at the rotation speed `speed_deg_s` (the lidar's clock, modulo
/// 30 000 ms). For a host that turns a recording into the lidar's own byte stream
/// ([`Ld06Packet::encode`]); [`RevolutionBinner`] with as many bins as the turn has
/// points gives the scan's beams back. Returns the number of packets passed to `emit`.
pub fn revolution_packets(
    scan: &LidarScan<'_>,
    direction: AngleDirection,
    speed_deg_s: u16,
    stamp_ms: u32,
    mut emit: impl FnMut(Ld06Packet),
) -> Result<usize, RevolutionError> {
    let g = scan.geometry;
    if !g.is_valid() || g.angle_increment == 0.0 {
        return Err(RevolutionError::Spacing);
    }
    let step_rad = f64::from(g.angle_increment).abs();
    let per_turn = core::f64::consts::TAU / step_rad;
    let n = libm::round(per_turn);
    // Whole points a turn, a whole number of 0.01° apart, whole packets a turn.
    if (per_turn - n).abs() > 1e-3 || n < 12.0 || n > f64::from(TURN) {
        return Err(RevolutionError::Spacing);
    }
    let n = n as u32;
    if !TURN.is_multiple_of(n) || !n.is_multiple_of(POINTS_PER_PACKET as u32) {
        return Err(RevolutionError::Spacing);
    }
    let step = TURN / n; // 0.01°
    let first = f64::from(g.first_angle);
    let reading = |k: u32| -> Ld06Point {
        let angle = f64::from(k * step).to_radians() / 100.0;
        let ccw = match direction {
            AngleDirection::Clockwise => -angle,
            AngleDirection::CounterClockwise => angle,
        };
        // The beam at this angle: (ccw − first) / increment, within a turn.
        let t = (ccw - first) / f64::from(g.angle_increment);
        let turn = f64::from(n);
        let t = t - libm::floor(t / turn) * turn;
        let i = libm::round(t);
        let i = if i >= f64::from(n) { 0.0 } else { i };
        let range = if (t - i).abs() < 0.25 || (f64::from(n) - t).abs() < 0.25 {
            scan.ranges.get(i as usize).copied()
        } else {
            None
        };
        let distance_mm = match range {
            Some(r) if g.classify(r) == super::lidar::BeamStatus::Valid => {
                libm::round(f64::from(r) * 1000.0).clamp(1.0, 65_535.0) as u16
            }
            _ => 0,
        };
        Ld06Point {
            distance_mm,
            intensity: if distance_mm > 0 { 200 } else { 0 },
        }
    };
    let packets = n / POINTS_PER_PACKET as u32;
    let last = POINTS_PER_PACKET as u32 - 1;
    // A turn takes 360 000 / speed ms.
    let turn_ms = if speed_deg_s > 0 {
        360_000 / u32::from(speed_deg_s)
    } else {
        0
    };
    for j in 0..packets {
        let first_k = j * POINTS_PER_PACKET as u32;
        let mut points = [Ld06Point::default(); POINTS_PER_PACKET];
        for (i, p) in points.iter_mut().enumerate() {
            *p = reading(first_k + i as u32);
        }
        let stamp = stamp_ms.wrapping_add(turn_ms * j / packets) % 30_000;
        emit(Ld06Packet {
            speed_deg_s,
            start_angle: (first_k * step) as u16,
            end_angle: ((first_k + last) * step) as u16,
            stamp_ms: stamp as u16,
            points,
        });
    }
    Ok(packets as usize)
}

#[cfg(test)]
mod tests;
