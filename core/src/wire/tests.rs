//! Round trips, worst-case sizes, corruption, resynchronisation after garbage.

use super::*;
use crate::ekf::health::HealthStatus;
use heapless::Vec;
use proptest::prelude::*;

fn chunk(seq: u32, scan_id: u16, offset: u16, total: u16, n: usize, mm: u16) -> ScanChunk {
    let mut ranges_mm = Vec::new();
    for i in 0..n {
        ranges_mm.push(mm.wrapping_add(i as u16)).unwrap();
    }
    ScanChunk {
        seq,
        stamp_us: 1_000_000 + u64::from(seq),
        scan_id,
        beam_offset: offset,
        beam_total: total,
        angle_min: -1.57,
        angle_increment: 0.0349,
        ranges_mm,
    }
}

fn samples() -> std::vec::Vec<ToDevice> {
    vec![
        ToDevice::Odometry {
            seq: 1,
            stamp_us: 10,
            odometry: Odometry::Increment {
                dx: 0.1,
                dy: -0.01,
                dtheta: 0.02,
            },
        },
        ToDevice::Odometry {
            seq: 2,
            stamp_us: 20,
            odometry: Odometry::Velocity {
                v: 0.3,
                omega: -0.2,
                dt: 0.02,
            },
        },
        ToDevice::Odometry {
            seq: 3,
            stamp_us: 30,
            odometry: Odometry::EncoderTicks {
                front_left: 12,
                front_right: -13,
                rear_left: 0,
                rear_right: i32::MIN,
                dt: 0.025,
            },
        },
        ToDevice::YawRate {
            seq: 4,
            stamp_us: 40,
            yaw_rate: f32::NAN,
        },
        ToDevice::Landmark {
            seq: 5,
            stamp_us: 50,
            id: 17,
            range: 2.5,
            bearing: -0.3,
        },
        ToDevice::Scan(chunk(6, 3, 32, 90, 32, 1500)),
        ToDevice::Command {
            seq: 7,
            command: Command::Reset {
                x: 1.0,
                y: 2.0,
                theta: 0.5,
            },
        },
        ToDevice::Command {
            seq: 8,
            command: Command::SelectEstimator(EstimatorKind::Grid),
        },
        ToDevice::Command {
            seq: u32::MAX,
            command: Command::ReportStatus,
        },
        ToDevice::Command {
            seq: 9,
            command: Command::SaveMap,
        },
        ToDevice::Command {
            seq: 10,
            command: Command::ReadMap { offset: u32::MAX },
        },
        ToDevice::Command {
            seq: 11,
            command: Command::Restart,
        },
    ]
}

fn same(a: &ToDevice, b: &ToDevice) -> bool {
    // NaN ≠ NaN: compare the encodings instead.
    body_of(a) == body_of(b)
}

fn body_of<M: serde::Serialize>(m: &M) -> std::vec::Vec<u8> {
    let mut buf = [0u8; 512];
    postcard::to_slice(m, &mut buf).unwrap().to_vec()
}

/// `body` framed by hand as a sender would, whatever it holds: its CRC appended, COBS
/// encoded, the delimiter.
fn framed(body: &[u8]) -> std::vec::Vec<u8> {
    let mut body = body.to_vec();
    let crc = crc::Crc::<u16>::new(&crc::CRC_16_IBM_SDLC).checksum(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut enc = vec![0u8; body.len() + body.len() / 254 + 2];
    let n = cobs::encode(&body, &mut enc);
    enc.truncate(n);
    enc.push(0);
    enc
}

fn frame_of<M: serde::Serialize>(m: &M) -> std::vec::Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    encode_frame(m, &mut buf).unwrap().to_vec()
}

#[test]
fn every_message_round_trips_and_frames_have_one_zero_at_the_end() {
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    for m in samples() {
        let f = frame_of(&m);
        assert_eq!(f.last(), Some(&0));
        assert!(!f[..f.len() - 1].contains(&0));
        let mut got = None;
        dec.feed::<ToDevice>(&f, |r| got = Some(r.unwrap()));
        assert!(same(&got.unwrap(), &m));
    }
    assert_eq!(dec.counters().ok, samples().len() as u32);
    assert_eq!(dec.counters().bad(), 0);
}

#[test]
fn largest_messages_fit_the_declared_limits() {
    let worst_scan = ToDevice::Scan(ScanChunk {
        seq: u32::MAX,
        stamp_us: u64::MAX,
        scan_id: u16::MAX,
        beam_offset: u16::MAX,
        beam_total: u16::MAX,
        angle_min: 1.0,
        angle_increment: 1.0,
        ranges_mm: Vec::from_slice(&[u16::MAX; SCAN_CHUNK_BEAMS]).unwrap(),
    });
    let payload = body_of(&worst_scan);
    // 1 tag + 5 + 10 + 3·3 + 2·4 + 1 length + 32·3 varint bytes.
    assert_eq!(payload.len(), 130);
    assert!(payload.len() <= MAX_PAYLOAD_LEN);
    let status = Status {
        frames_ok: u32::MAX,
        frames_bad: u32::MAX,
        events: u32::MAX,
        rejected: u32::MAX,
        landmarks: u16::MAX,
        resamples: u32::MAX,
    };
    let worst_estimate = ToHost::Estimate(Estimate {
        seq: u32::MAX,
        stamp_us: u64::MAX,
        estimator: EstimatorKind::Grid,
        result: StepResult::Rejected { reason: 255 },
        pose: [1.0; 3],
        covariance: [1.0; 6],
        status,
        health: HealthStatus {
            flags: u8::MAX,
            refused_in_row: u16::MAX,
            recoveries: u16::MAX,
            downweighted: u32::MAX,
            gated: u32::MAX,
        },
    });
    let payload = body_of(&worst_estimate);
    assert!(payload.len() <= MAX_PAYLOAD_LEN, "{}", payload.len());
    assert!(frame_of(&worst_estimate).len() <= MAX_FRAME_LEN);
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut got = None;
    dec.feed::<ToHost>(&frame_of(&worst_estimate), |r| got = Some(r));
    assert_eq!(got, Some(Ok(worst_estimate)));
    let ToHost::Estimate(estimate) = worst_estimate else {
        unreachable!()
    };
    let worst_localization = ToHost::Localization {
        estimate,
        localizer: LocalizerReport {
            state: TrackingState::Relocalized,
            hit_fraction: 1.0,
            lost_events: u32::MAX,
            relocalizations: u32::MAX,
            search_scans: u8::MAX,
        },
    };
    let payload = body_of(&worst_localization);
    assert!(payload.len() <= MAX_PAYLOAD_LEN, "{}", payload.len());
    let mut got = None;
    dec.feed::<ToHost>(&frame_of(&worst_localization), |r| got = Some(r));
    assert_eq!(got, Some(Ok(worst_localization)));
    let worst_chunk = ToHost::MapChunk {
        seq: u32::MAX,
        offset: u32::MAX,
        len: u8::MAX,
        bytes: MapBytes([u8::MAX; MAP_CHUNK_BYTES]),
    };
    let payload = body_of(&worst_chunk);
    // 1 tag + 5 + 5 varint bytes + 1 + a 1-byte length and 64 raw bytes.
    assert_eq!(payload.len(), 77);
    assert!(frame_of(&worst_chunk).len() <= MAX_FRAME_LEN);
    let mut got = None;
    dec.feed::<ToHost>(&frame_of(&worst_chunk), |r| got = Some(r));
    assert_eq!(got, Some(Ok(worst_chunk)));
}

/// A host reads the version of any device from its status: the variant index and the
/// first two fields stay where they are (see [`PROTOCOL_VERSION`]).
#[test]
fn a_status_starts_with_its_sequence_number_and_the_protocol_version() {
    let status = ToHost::Status {
        seq: 5,
        protocol: PROTOCOL_VERSION,
        estimator: EstimatorKind::Grid,
        status: Status::default(),
        stack_peak_bytes: 0,
        map_checksum: Some(0xDEAD_BEEF),
        lidar: LidarCounters::default(),
    };
    let body = body_of(&status);
    // Variant 1, then seq and protocol as varints (one byte each while below 128).
    const { assert!(PROTOCOL_VERSION < 128) };
    assert_eq!(body[..3], [1, 5, PROTOCOL_VERSION as u8]);
}

#[test]
fn encoding_into_a_short_buffer_is_an_error() {
    let m = &samples()[5];
    let mut small = [0u8; 20];
    assert_eq!(encode_frame(m, &mut small), Err(EncodeError::TooLong));
}

#[test]
fn every_single_bit_flip_is_caught_and_the_next_frame_decodes() {
    let m = &samples()[4];
    let good = frame_of(m);
    for byte in 0..good.len() - 1 {
        for bit in 0..8 {
            let mut bad = good.clone();
            bad[byte] ^= 1 << bit;
            let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
            let mut out = std::vec::Vec::new();
            dec.feed::<ToDevice>(&bad, |r| out.push(r));
            dec.feed::<ToDevice>(&good, |r| out.push(r));
            let (last, before) = out.split_last().unwrap();
            assert!(same(last.as_ref().unwrap(), m));
            assert!(before.iter().all(|r| r.is_err()), "flip {byte}.{bit}");
            assert_eq!(dec.counters().ok, 1);
            assert_eq!(dec.counters().bad() as usize, before.len());
        }
    }
}

#[test]
fn truncated_oversize_and_unknown_frames_are_counted_by_kind() {
    let good = frame_of(&samples()[1]);
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut out = std::vec::Vec::new();
    // A frame cut short (the line dropped its tail), then the delimiter.
    dec.feed::<ToDevice>(&good[..5], |r| out.push(r));
    dec.feed::<ToDevice>(&[0], |r| out.push(r));
    // Two bytes: shorter than a CRC.
    dec.feed::<ToDevice>(&[0x03, 0x11, 0x22, 0x00], |r| out.push(r));
    // Longer than the buffer.
    dec.feed::<ToDevice>(&[0x55; 3 * MAX_FRAME_LEN], |r| out.push(r));
    dec.feed::<ToDevice>(&[0], |r| out.push(r));
    // A well-framed body with a variant this side does not know (tag 200).
    dec.feed::<ToDevice>(&framed(&[200u8, 1, 2, 3]), |r| out.push(r));
    // The same message with a trailing byte: also unknown.
    let payload = body_of(&samples()[1]);
    let mut body = payload.to_vec();
    body.push(9);
    dec.feed::<ToDevice>(&framed(&body), |r| out.push(r));
    // A message whose body ends early but whose CRC is right (a buggy sender).
    dec.feed::<ToDevice>(&framed(&payload[..payload.len() - 3]), |r| out.push(r));
    // And the line recovers.
    dec.feed::<ToDevice>(&good, |r| out.push(r));
    let errs: std::vec::Vec<_> = out.iter().filter_map(|r| r.as_ref().err()).collect();
    assert_eq!(
        errs,
        [
            &FrameError::Corrupt,
            &FrameError::Truncated,
            &FrameError::Oversize,
            &FrameError::Unknown,
            &FrameError::Unknown,
            &FrameError::Truncated,
        ]
    );
    assert!(same(out.last().unwrap().as_ref().unwrap(), &samples()[1]));
    let c = dec.counters();
    assert_eq!(
        (c.ok, c.truncated, c.corrupt, c.oversize, c.unknown),
        (1, 2, 1, 1, 2)
    );
}

#[test]
fn empty_frames_are_ignored() {
    let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
    let mut n = 0;
    dec.feed::<ToDevice>(&[0, 0, 0], |_| n += 1);
    assert_eq!(n, 0);
    assert_eq!(dec.counters(), WireCounters::default());
}

fn arb_message() -> impl Strategy<Value = ToDevice> {
    (0..samples().len(), any::<u32>(), any::<u64>(), any::<f32>()).prop_map(|(i, seq, t, x)| {
        match samples()[i].clone() {
            ToDevice::Landmark { id, bearing, .. } => ToDevice::Landmark {
                seq,
                stamp_us: t,
                id,
                range: x,
                bearing,
            },
            ToDevice::YawRate { .. } => ToDevice::YawRate {
                seq,
                stamp_us: t,
                yaw_rate: x,
            },
            other => other,
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Any byte stream: no panic, and every non-empty segment between delimiters is
    /// either a message or one counted error.
    #[test]
    fn random_bytes_never_panic_and_are_all_accounted(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
        let mut results = 0u32;
        dec.feed::<ToDevice>(&bytes, |_| results += 1);
        let segments = bytes.split(|&b| b == 0).count() - 1; // the tail is unterminated
        let nonempty = bytes.split(|&b| b == 0).take(segments).filter(|s| !s.is_empty()).count();
        prop_assert_eq!(results as usize, nonempty);
        let c = dec.counters();
        prop_assert_eq!(c.ok + c.bad(), results);
    }

    /// Valid frames with garbage between them (and a delimiter after each piece of
    /// garbage, as a sender that resynchronises sends one): every frame comes through, in order.
    #[test]
    fn frames_survive_garbage_between_them(
        items in proptest::collection::vec(
            (arb_message(), proptest::collection::vec(any::<u8>(), 0..300)), 1..12)
    ) {
        let mut stream = std::vec::Vec::new();
        for (m, garbage) in &items {
            stream.extend_from_slice(garbage);
            stream.push(0);
            stream.extend_from_slice(&frame_of(m));
        }
        let mut dec = FrameDecoder::<MAX_FRAME_LEN>::new();
        let mut got = std::vec::Vec::new();
        dec.feed::<ToDevice>(&stream, |r| if let Ok(m) = r { got.push(m) });
        // Sent messages are a subsequence of the decoded ones (garbage could, with
        // probability ~2⁻¹⁶ per segment, pass the CRC and decode as something).
        let mut it = got.iter();
        for (m, _) in &items {
            prop_assert!(it.any(|g| same(g, m)), "lost {:?}", m);
        }
    }
}

#[test]
fn scan_chunks_reassemble_and_gaps_drop_the_scan() {
    let mut asm = ScanAssembler::<96>::new();
    assert_eq!(asm.push(&chunk(1, 9, 0, 90, 32, 1000)), Ok(None));
    assert_eq!(asm.push(&chunk(2, 9, 32, 90, 32, 2000)), Ok(None));
    let scan = asm.push(&chunk(3, 9, 64, 90, 26, 3000)).unwrap().unwrap();
    assert_eq!(scan.ranges_mm.len(), 90);
    assert_eq!(scan.ranges_mm[0], 1000);
    assert_eq!(scan.ranges_mm[33], 2001);
    assert_eq!(scan.ranges_mm[89], 3025);
    assert_eq!(scan.scan_id, 9);
    assert_eq!(asm.dropped(), 0);
    // The middle chunk is lost: the scan is dropped, the next one is fine.
    assert_eq!(asm.push(&chunk(4, 10, 0, 90, 32, 1)), Ok(None));
    assert_eq!(
        asm.push(&chunk(6, 10, 64, 90, 26, 1)),
        Err(ScanError::MissingChunk)
    );
    assert_eq!(asm.dropped(), 1);
    assert_eq!(asm.push(&chunk(7, 11, 0, 40, 32, 1)), Ok(None));
    assert!(asm.push(&chunk(8, 11, 32, 40, 8, 1)).unwrap().is_some());
    // A scan larger than the buffer, and a chunk running past its scan.
    assert_eq!(
        asm.push(&chunk(9, 12, 0, 200, 32, 1)),
        Err(ScanError::TooManyBeams)
    );
    assert_eq!(
        asm.push(&chunk(10, 13, 0, 20, 32, 1)),
        Err(ScanError::Malformed)
    );
    assert_eq!(asm.dropped(), 3);
}

/// `settings` with its value number `i` (in wire order) set to `v`.
fn with_value(mut s: EkfSettings, i: usize, v: f32) -> EkfSettings {
    match i {
        0..=4 => s.increment_noise[i] = v,
        5..=9 => s.velocity_noise[i - 5] = v,
        10 => s.range_std = v,
        11 => s.bearing_std = v,
        12..=14 => s.sensor_mount[i - 12] = v,
        15 => s.gate_threshold = v,
        _ => s.calibration[i - 16] = v,
    }
    s
}

#[test]
fn an_invalid_ekf_setting_is_named_by_its_position_on_the_wire() {
    let good = EkfSettings::from_config(&crate::ekf::EkfConfig::MICROCONTROLLER)
        .with_calibration([0.02, 0.02, 0.2, 2.0]);
    assert_eq!(good.invalid_field(), None);
    for i in 0..EkfSettings::FIELD_NAMES.len() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            // An infinite gate threshold is a gate that passes every sighting.
            let want = (i != 15 || bad != f32::INFINITY).then_some(i as u8);
            assert_eq!(with_value(good, i, bad).invalid_field(), want, "{i}: {bad}");
        }
        // Every value but the mount's must not be negative; the gate not 0 either.
        let negative = with_value(good, i, -0.5).invalid_field();
        let zero = with_value(good, i, 0.0).invalid_field();
        match i {
            12..=14 => assert_eq!((negative, zero), (None, None), "{i}"),
            15 => assert_eq!((negative, zero), (Some(15), Some(15))),
            _ => assert_eq!((negative, zero), (Some(i as u8), None), "{i}"),
        }
    }
    // The wire's rules are the configuration's, value by value.
    let values = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -0.5,
        -0.0,
        0.0,
        1e-30,
        0.5,
        1e30,
    ];
    for i in 0..16 {
        for v in values {
            let s = with_value(good, i, v);
            assert_eq!(
                s.invalid_field().is_some(),
                !s.to_config().is_valid(),
                "{i}: {v}"
            );
        }
    }
    // The first bad value is named; the configuration refuses what the wire refuses.
    let two_bad = with_value(with_value(good, 3, -1.0), 11, f32::NAN);
    assert_eq!(two_bad.invalid_field(), Some(3));
    assert!(!two_bad.to_config().is_valid());
    let refusal = Refusal::InvalidEkfSetting { field: 11 };
    assert_eq!(
        std::format!("{refusal}"),
        "EKF setting `bearing_std` is out of its range"
    );
}
