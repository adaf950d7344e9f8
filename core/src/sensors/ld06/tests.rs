use super::*;
use proptest::prelude::*;

/// The example packet of LDROBOT's LD06 datasheet.
const DATASHEET: [u8; PACKET_BYTES] = [
    0x54, 0x2C, 0x68, 0x08, 0xAB, 0x7E, 0xE0, 0x00, 0xE4, 0xDC, 0x00, 0xE2, 0xD9, 0x00, 0xE5, 0xD5,
    0x00, 0xE3, 0xD3, 0x00, 0xE4, 0xD0, 0x00, 0xE9, 0xCD, 0x00, 0xE4, 0xCA, 0x00, 0xE2, 0xC7, 0x00,
    0xE9, 0xC5, 0x00, 0xE5, 0xC2, 0x00, 0xE5, 0xC0, 0x00, 0xE5, 0xBE, 0x82, 0x3A, 0x1A, 0x50,
];

/// The CRC bit by bit, as the polynomial defines it (the table is made another way).
fn crc8_bitwise(bytes: &[u8]) -> u8 {
    let mut c = 0u8;
    for &b in bytes {
        c ^= b;
        for _ in 0..8 {
            c = if c & 0x80 != 0 {
                (c << 1) ^ 0x4D
            } else {
                c << 1
            };
        }
    }
    c
}

#[test]
fn the_datasheets_packet_reads_as_the_datasheet_says() {
    assert_eq!(crc8(&DATASHEET[..46]), 0x50);
    let p = Ld06Packet::parse(&DATASHEET).expect("valid packet");
    assert_eq!(p.speed_deg_s, 2152);
    assert_eq!(p.start_angle, 32427);
    assert_eq!(p.end_angle, 33470);
    assert_eq!(p.stamp_ms, 6714);
    assert_eq!(
        p.points[0],
        Ld06Point {
            distance_mm: 224,
            intensity: 228
        }
    );
    assert_eq!(
        p.points[11],
        Ld06Point {
            distance_mm: 192,
            intensity: 229
        }
    );
    // The first and last points at the packet's angles, the others 10.43° / 11 apart.
    assert_eq!(p.point_angle(0), 32427);
    assert_eq!(p.point_angle(1), 32427 + 1043 / 11);
    assert_eq!(p.point_angle(11), 33470);
    assert_eq!(p.encode(), DATASHEET);
}

#[test]
fn the_crc_table_is_the_polynomials() {
    let mut bytes = [0u8; 300];
    let mut x = 0x1234_5678u32;
    for b in bytes.iter_mut() {
        x ^= x << 13;
        x ^= x >> 17;
        x ^= x << 5;
        *b = x as u8;
    }
    for n in [0, 1, 2, 46, 300] {
        assert_eq!(crc8(&bytes[..n]), crc8_bitwise(&bytes[..n]), "{n} bytes");
    }
}

#[test]
fn angles_through_zero_are_spread_over_the_wrap() {
    let p = Ld06Packet {
        start_angle: 35_900,
        end_angle: 1_000,
        ..Ld06Packet::default()
    };
    // 11 steps of 100 (1.00°): 359.00°, 0.00°, 1.00°, …, 10.00°.
    assert_eq!(p.point_angle(0), 35_900);
    assert_eq!(p.point_angle(1), 0);
    assert_eq!(p.point_angle(11), 1_000);
}

fn decode(bytes: &[u8]) -> (Vec<Ld06Packet>, Ld06Counters) {
    let mut d = Ld06Decoder::new();
    let packets = bytes.iter().filter_map(|&b| d.push(b)).collect();
    (packets, d.counters())
}

#[test]
fn noise_corrupt_and_cut_packets_are_dropped_and_the_next_one_found() {
    let good = DATASHEET;
    let mut corrupt = DATASHEET;
    corrupt[20] ^= 0x01;
    let mut stream = vec![0x00, 0x54, 0x54, 0x13];
    stream.extend_from_slice(&good);
    stream.extend_from_slice(&corrupt);
    // A packet cut short after 30 bytes, then a whole one: the whole one starts inside
    // the 47 bytes the decoder takes for the cut one.
    stream.extend_from_slice(&good[..30]);
    stream.extend_from_slice(&good);
    stream.extend_from_slice(&good[..10]); // the stream ends inside a packet
    let (packets, c) = decode(&stream);
    assert_eq!(packets.len(), 2, "{c:?}");
    assert!(packets.iter().all(|p| p.encode() == DATASHEET));
    assert_eq!(c.packets, 2);
    assert_eq!(c.bad_crc, 2, "the corrupt one and the cut one");
    // Skipped: the 4 bytes of noise, the corrupt packet (47) and the cut one (30).
    assert_eq!(c.skipped_bytes, 4 + 47 + 30);
}

#[test]
fn an_angle_past_a_full_turn_is_refused() {
    let bad = Ld06Packet {
        start_angle: 36_000,
        ..Ld06Packet::default()
    }
    .encode();
    assert_eq!(Ld06Packet::parse(&bad), Err(PacketError::BadAngle));
    let (packets, c) = decode(&bad);
    assert!(packets.is_empty());
    assert_eq!(c.bad_angle, 1);
}

/// Packets of one revolution (and the first packet of the next) of a lidar at the centre
/// of a square room of half-width `h` metres, its angles growing clockwise as the LD06's,
/// `per_turn` points a revolution.
fn square_room(h: f64, per_turn: u32, turns: u32) -> Vec<Ld06Packet> {
    let step = 36_000 / per_turn; // 0.01°
    let mut packets = Vec::new();
    let mut angle = 0u32;
    for k in 0..(turns * per_turn).div_ceil(POINTS_PER_PACKET as u32) {
        let start = angle % TURN;
        let mut points = [Ld06Point::default(); POINTS_PER_PACKET];
        for (i, p) in points.iter_mut().enumerate() {
            let a = (start + step * i as u32) % TURN;
            // Clockwise packet angle → counter-clockwise direction in the robot frame.
            let ccw = -(f64::from(a) / 100.0).to_radians();
            let r = h / ccw.cos().abs().max(ccw.sin().abs());
            *p = Ld06Point {
                distance_mm: (r * 1000.0).round() as u16,
                intensity: 200,
            };
        }
        packets.push(Ld06Packet {
            speed_deg_s: 3600,
            start_angle: start as u16,
            end_angle: ((start + step * 11) % TURN) as u16,
            stamp_ms: (k * 10 % 30_000) as u16,
            points,
        });
        angle += step * POINTS_PER_PACKET as u32;
    }
    packets
}

#[test]
fn a_revolution_becomes_a_scan_of_the_room() {
    let mut binner = RevolutionBinner::<360>::new(Ld06Setup::LD06).expect("valid setup");
    let packets = square_room(2.0, 480, 2);
    let finished: Vec<bool> = packets.iter().map(|p| binner.push(p)).collect();
    // 480 points a turn, 40 packets: the first revolution ends in packet 40.
    assert_eq!(finished.iter().position(|&f| f), Some(40));
    assert_eq!(binner.revolutions(), 1);
    assert_eq!(binner.points(), 480);
    let scan = binner.scan();
    let g = scan.geometry;
    let mut worst = 0.0f64;
    let mut valid = 0;
    for (i, &r) in scan.ranges.iter().enumerate() {
        let a = f64::from(g.beam_angle(i));
        let want = 2.0 / a.cos().abs().max(a.sin().abs());
        worst = worst.max((f64::from(r) - want).abs());
        valid += usize::from(g.classify(r) == crate::sensors::lidar::BeamStatus::Valid);
    }
    // Every beam got a point (480 points over 360 bins). The nearest point of a 1° bin is
    // at most half a degree off the beam's angle, where the range changes by at most
    // r · tan(45°) · 0.5° = 2.5 cm (near the corners), plus the millimetre rounding.
    assert_eq!(valid, 360);
    assert!(worst < 0.026, "{worst}");
}

#[test]
fn clockwise_angles_turn_into_counter_clockwise_beams() {
    // One point straight to the packets' 90° (clockwise: the robot's right), 1 m away.
    let mut points = [Ld06Point::default(); POINTS_PER_PACKET];
    points[0] = Ld06Point {
        distance_mm: 1000,
        intensity: 100,
    };
    let at = |start: u16| Ld06Packet {
        start_angle: start,
        end_angle: start + 110,
        points,
        ..Ld06Packet::default()
    };
    for (direction, beam) in [
        (AngleDirection::Clockwise, 270),
        (AngleDirection::CounterClockwise, 90),
    ] {
        let setup = Ld06Setup {
            direction,
            ..Ld06Setup::LD06
        };
        let mut binner = RevolutionBinner::<360>::new(setup).expect("valid setup");
        assert!(!binner.push(&at(9_000)));
        assert!(binner.push(&at(0)), "the next turn starts");
        let ranges = binner.scan().ranges;
        assert_eq!(ranges[beam], 1.0, "{direction:?}");
        assert_eq!(ranges.iter().filter(|&&r| r < EMPTY_BIN).count(), 1);
    }
}

#[test]
fn weak_short_and_missing_returns_are_left_out() {
    let setup = Ld06Setup {
        min_intensity: 50,
        ..Ld06Setup::LD06
    };
    let mut binner = RevolutionBinner::<360>::new(setup).expect("valid setup");
    let mut points = [Ld06Point {
        distance_mm: 1500,
        intensity: 100,
    }; POINTS_PER_PACKET];
    points[0].distance_mm = 0; // no return
    points[1].intensity = 10; // too weak
    points[2].distance_mm = 10; // 1 cm: inside the blind zone
    points[3].distance_mm = 13_000; // beyond 12 m
    let p = Ld06Packet {
        start_angle: 0,
        end_angle: 1_100,
        points,
        ..Ld06Packet::default()
    };
    binner.push(&p);
    binner.push(&Ld06Packet {
        start_angle: 0,
        end_angle: 0,
        ..Ld06Packet::default()
    });
    assert_eq!(binner.points(), 8);
    assert!(RevolutionBinner::<0>::new(Ld06Setup::LD06).is_none());
    let bad = Ld06Setup {
        max_range: f32::NAN,
        ..Ld06Setup::LD06
    };
    assert!(RevolutionBinner::<360>::new(bad).is_none());
}

proptest! {
    /// Any bytes: no panic, and every byte accounted for (in a packet, skipped, or still
    /// buffered: fewer than a packet's length).
    #[test]
    fn any_bytes_are_accounted_for(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        let (packets, c) = decode(&bytes);
        prop_assert_eq!(packets.len() as u32, c.packets);
        let used = c.packets as usize * PACKET_BYTES + c.skipped_bytes as usize;
        prop_assert!(used <= bytes.len() && bytes.len() - used < PACKET_BYTES,
            "{} bytes, {:?}", bytes.len(), c);
    }

    /// Good packets with noise between them are all found, in order.
    #[test]
    fn packets_among_noise_are_all_found(
        noise in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..20), 1..6)
    ) {
        let mut stream = Vec::new();
        let mut sent = Vec::new();
        for (k, n) in noise.iter().enumerate() {
            // Noise without the start character cannot hide a packet's start.
            stream.extend(n.iter().map(|&b| if b == START { 0 } else { b }));
            let p = Ld06Packet { stamp_ms: k as u16, ..Ld06Packet::parse(&DATASHEET).unwrap() };
            stream.extend_from_slice(&p.encode());
            sent.push(p);
        }
        let (packets, _) = decode(&stream);
        prop_assert_eq!(packets, sent);
    }
}

#[test]
fn a_front_scan_goes_through_the_lidars_packets_and_back() {
    use crate::sensors::lidar::LidarGeometry;
    // A CARMEN front laser: 180 beams from −90°, 1° apart.
    let g = LidarGeometry::CARMEN_SICK_180;
    let ranges: Vec<f32> = (0..180)
        .map(|i| match i {
            10 => f32::NAN,
            11 => 81.9, // no return
            _ => 1.0 + 0.0123 * i as f32,
        })
        .collect();
    let scan = LidarScan::new(&ranges, g);
    let mut bytes = Vec::new();
    for turn in 0..2u32 {
        let n = revolution_packets(&scan, AngleDirection::Clockwise, 3600, turn * 100, |p| {
            bytes.extend_from_slice(&p.encode())
        })
        .expect("1° beams make a revolution");
        assert_eq!(n, 30, "360 points a turn");
    }
    let mut decoder = Ld06Decoder::new();
    let mut binner = RevolutionBinner::<360>::new(Ld06Setup {
        max_range: 60.0,
        ..Ld06Setup::LD06
    })
    .expect("valid setup");
    let finished = bytes
        .iter()
        .filter_map(|&b| decoder.push(b))
        .filter(|p| binner.push(p))
        .count();
    assert_eq!(finished, 1, "the second turn's first packet ends the first");
    assert_eq!(decoder.counters().packets, 60);
    let back = binner.scan();
    for (i, &r) in ranges.iter().enumerate() {
        // Beam i of the scan is at −90° + i, counter-clockwise: bin (270 + i) mod 360.
        let got = back.ranges[(270 + i) % 360];
        if g.classify(r) == crate::sensors::lidar::BeamStatus::Valid {
            assert!((got - r).abs() <= 0.0005, "beam {i}: {got} for {r}");
        } else {
            assert_eq!(got, EMPTY_BIN, "beam {i}");
        }
    }
    // Behind the laser (90° … 270° counter-clockwise, but the end of its field of view
    // at +90°) nothing was seen.
    assert_eq!(
        back.ranges[90..270]
            .iter()
            .filter(|&&r| r != EMPTY_BIN)
            .count(),
        0
    );
    assert_eq!(binner.points(), 178);
    // Beams 1.5° apart make no whole number of points a turn in packets of 12.
    let odd = LidarGeometry {
        angle_increment: 1.5f32.to_radians() * 0.999,
        ..g
    };
    assert_eq!(
        revolution_packets(
            &LidarScan::new(&ranges, odd),
            AngleDirection::Clockwise,
            3600,
            0,
            |_| {}
        ),
        Err(RevolutionError::Spacing)
    );
}
