//! The checks run by the fuzz targets in `fuzz/`, shared with `cargo test`, which replays
//! every input kept in `fuzz/regressions/<target>/` through them.
//!
//! Each function takes raw fuzzer bytes, drives one public API with them and panics when an
//! invariant breaks: a panic inside the library, a non-finite or asymmetric covariance, a
//! negative variance, an error that changed the state, or a non-finite input that was
//! accepted.

use microslam::association::{KnownIds, observe_known};
use microslam::device::Session;
use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use microslam::wire::{FrameDecoder, MAX_FRAME_LEN, ToDevice, encode_frame};
use nalgebra::{DMatrix, Matrix2, Matrix3, Vector3};

/// Landmarks of the fuzzed filters: small, so that the table fills up.
const L: usize = 4;
type Slam = EkfSlam<f32, { state_dim(L) }, { factor_len(L) }>;

/// Reads little-endian `f32`s off the front of `bytes`.
fn take_f32s<const K: usize>(bytes: &mut &[u8]) -> Option<[f32; K]> {
    let mut out = [0.0; K];
    for v in &mut out {
        let (head, rest) = bytes.split_first_chunk::<4>()?;
        *v = f32::from_le_bytes(*head);
        *bytes = rest;
    }
    Some(out)
}

/// The active covariance of `ekf` as a dense matrix (both triangles), as read through
/// its view.
pub fn dense<const N: usize, const P: usize>(ekf: &EkfSlam<f32, N, P>) -> DMatrix<f32> {
    let p = ekf.active_covariance();
    DMatrix::from_fn(p.dim(), p.dim(), |i, j| p.get(i, j).unwrap_or(f32::NAN))
}

/// Panics unless the filter's active state is finite, its covariance finite and exactly
/// symmetric with a non-negative diagonal, the factor's pivots `D` non-negative, and the
/// storage beyond the active part of the factor untouched (zero).
pub fn assert_ekf_sane<const N: usize, const P: usize>(ekf: &EkfSlam<f32, N, P>) {
    let p = dense(ekf);
    let k = p.nrows();
    assert!(
        ekf.active_mean().iter().all(|v| v.is_finite()),
        "non-finite mean {:?}",
        ekf.active_mean()
    );
    for i in 0..k {
        assert!(p[(i, i)] >= 0.0, "negative variance {} at {i}", p[(i, i)]);
        for j in 0..k {
            assert!(p[(i, j)].is_finite(), "non-finite covariance at ({i}, {j})");
            assert_eq!(p[(i, j)], p[(j, i)], "asymmetric at ({i}, {j})");
        }
    }
    let view = ekf.active_covariance();
    for i in 0..k {
        let Some((d, mut row)) = view.factor_row(i) else {
            panic!("no factor row {i} inside the active block");
        };
        assert!(d >= 0.0, "negative pivot {d} at {i}");
        assert!(row.all(|v| v.is_finite()), "non-finite factor row {i}");
    }
    let storage = ekf.factor_storage();
    let active = k * (k + 1) / 2;
    assert!(
        storage.iter().skip(active).all(|v| *v == 0.0),
        "storage beyond the active factor written"
    );
}

/// Panics unless [`assert_ekf_sane`] holds and the covariance read back is positive
/// semi-definite up to the rounding of reading it.
///
/// Each entry read is a sum of at most `k` products `L_ic D_c L_jc` (`D ≥ 0`) in `f32`,
/// so its error is at most `γ_k √(P_ii P_jj)` (Cauchy–Schwarz), `γ_k ≤ (k + 1) ε`; the
/// error matrix then has spectral norm at most `(k + 1) ε · trace P ≤ (k + 1) k ε · max
/// variance`, and by Weyl's inequality that bounds how negative the smallest eigenvalue
/// of what is read can be. The check is relative to the current variances: no history.
pub fn assert_ekf_healthy<const N: usize, const P: usize>(ekf: &EkfSlam<f32, N, P>) {
    assert_ekf_sane(ekf);
    let p = dense(ekf);
    let k = p.nrows();
    let trace: f64 = (0..k).map(|i| f64::from(p[(i, i)])).sum();
    let wide = DMatrix::from_fn(k, k, |i, j| f64::from(p[(i, j)]));
    let min_eig = wide.symmetric_eigen().eigenvalues.min();
    let tolerance = (k + 1) as f64 * f64::from(f32::EPSILON) * trace;
    assert!(
        min_eig >= -tolerance,
        "not PSD: min eigenvalue {min_eig}, trace {trace}, tolerance {tolerance}"
    );
}

/// Fuzzes the EKF step API: one header byte, then ops of one selector byte and three
/// `f32`s, arbitrary bit patterns (NaN, ±∞, subnormal, huge). With bit 2 of the header
/// set there are seven ops, the seventh a pose-covariance inflation (recovery); otherwise
/// six (so that inputs kept from before the inflation existed replay the same steps).
/// Bits 3 and 4 of the header add the self-calibration states (odometry scale factors,
/// sighting range bias) before any step.
pub fn ekf_steps(data: &[u8]) {
    let Some((&header, mut bytes)) = data.split_first() else {
        return;
    };
    let ops = if header & 4 != 0 { 7 } else { 6 };
    let mut ekf = Box::new(Slam::new(EkfConfig::DEFAULT_F32));
    // Bits 3 and 4: self-calibration states (odometry scale factors, sighting range bias)
    // in the slots before the landmarks, as the MRCLAM settings run them.
    if header & 8 != 0 {
        ekf.estimate_odometry_scale(0.05, 0.05)
            .expect("scale states on a fresh filter");
    }
    if header & 16 != 0 {
        ekf.estimate_range_bias(0.1, 0.5)
            .expect("bias states on a fresh filter");
    }
    let mut ids = KnownIds::<L>::new();
    while let Some((&op, rest)) = bytes.split_first() {
        bytes = rest;
        let Some([a, b, c]) = take_f32s::<3>(&mut bytes) else {
            return;
        };
        let finite = a.is_finite() && b.is_finite() && c.is_finite();
        let before = (ekf.active_mean().to_vec(), dense(&ekf));
        let index = usize::from(op >> 3);
        // What the EKF accepts as a sighting: finite, range within 5 cm ..= 1 km, bearing
        // within one turn.
        let valid_z = a.is_finite()
            && b.is_finite()
            && (0.05..=1e3).contains(&a)
            && b.abs() <= std::f32::consts::TAU;
        let (refused, must_refuse) = match op % ops {
            0 => (ekf.predict_velocity(a, b, c).is_err(), !finite || c < 0.0),
            1 => (
                ekf.predict_increment(&Pose2::new(a, b, c)).is_err(),
                !finite,
            ),
            2 => (
                ekf.update(index, &RangeBearing::new(a, b)).is_err(),
                !valid_z,
            ),
            3 => (
                ekf.add_landmark(&RangeBearing::new(a, b)).is_err(),
                !valid_z,
            ),
            4 => {
                let r = Matrix2::new(c.abs(), 0.0, 0.0, c.abs());
                let z = RangeBearing::new(a, b);
                (
                    ekf.update_with_covariance(index, &z, &r).is_err(),
                    !valid_z || !c.is_finite(),
                )
            }
            5 => {
                let z = RangeBearing::new(a, b);
                let out = observe_known(&mut ekf, &mut ids, u32::from(op >> 3), &z);
                (out.is_err(), !valid_z)
            }
            _ => {
                // A recovery step: a diagonal inflation of the pose covariance.
                let added = Matrix3::from_diagonal(&Vector3::new(a, b, c));
                let must = !finite || a < 0.0 || b < 0.0 || c < 0.0;
                (ekf.inflate_pose_covariance(&added).is_err(), must)
            }
        };
        if must_refuse {
            assert!(refused, "op {op}: bad input ({a}, {b}, {c}) accepted");
        }
        if refused {
            assert_eq!(
                ekf.active_mean(),
                &before.0[..],
                "op {op}: a refused step changed the mean"
            );
            assert_eq!(dense(&ekf), before.1, "op {op}: a refused step changed P");
        }
        assert_ekf_healthy(&ekf);
    }
}

/// Fuzzes the device side of the serial protocol: arbitrary bytes into a [`Session`]
/// (decoder + EKF). No panic; the filter stays healthy; every frame is counted once.
pub fn wire_session(data: &[u8]) {
    let mut ekf = Box::new(Slam::new(EkfConfig::DEFAULT_F32));
    let mut session = Session::<_, _, L>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    for &b in data {
        let _ = session.receive(b);
    }
    let status = session.status();
    let delimiters = data.iter().filter(|&&b| b == 0).count() as u64;
    assert!(
        u64::from(status.frames_ok) + u64::from(status.frames_bad) <= delimiters,
        "{} frames counted for {delimiters} delimiters",
        status.frames_ok + status.frames_bad
    );
    assert_ekf_healthy(session.ekf());
}

/// Fuzzes the frame decoder alone: every message it accepts re-encodes to a frame that
/// decodes to the same message.
pub fn wire_decoder(data: &[u8]) {
    let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
    for &b in data {
        if let Some(Ok(msg)) = decoder.push::<ToDevice>(b) {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let frame = encode_frame(&msg, &mut buf).expect("a decoded message fits a frame");
            let mut again = FrameDecoder::<MAX_FRAME_LEN>::new();
            let mut got = None;
            for &c in frame {
                if let Some(r) = again.push::<ToDevice>(c) {
                    got = Some(r);
                }
            }
            // NaN payloads compare unequal: compare the encodings instead.
            let got = got
                .expect("one frame out")
                .expect("re-encoded frame decodes");
            let mut buf2 = [0u8; MAX_FRAME_LEN];
            assert_eq!(encode_frame(&got, &mut buf2).expect("fits"), frame);
        }
    }
}

/// Fuzzes the LD06 lidar's packet decoder and the revolution binner behind it: every
/// byte is accounted for (in a packet, skipped, or still buffered: fewer than a packet's
/// length); every packet re-encodes to bytes that decode to the same packet; every beam
/// of every finished revolution is empty or a range within the setup's limits, and a
/// revolution holds no more points than its packets carried.
pub fn ld06_decoder(data: &[u8]) {
    use microslam::sensors::ld06::{
        EMPTY_BIN, Ld06Decoder, Ld06Packet, Ld06Setup, PACKET_BYTES, POINTS_PER_PACKET,
        RevolutionBinner,
    };
    let mut decoder = Ld06Decoder::new();
    let setup = Ld06Setup::LD06;
    let mut binner = RevolutionBinner::<360>::new(setup).expect("the LD06 setup is valid");
    let mut packets = 0usize;
    for &b in data {
        let Some(p) = decoder.push(b) else { continue };
        packets += 1;
        assert_eq!(
            Ld06Packet::parse(&p.encode()),
            Ok(p),
            "re-encoded packet decodes"
        );
        if binner.push(&p) {
            let scan = binner.scan();
            assert!(
                scan.ranges
                    .iter()
                    .all(|&r| r == EMPTY_BIN || (r >= setup.min_range && r < setup.max_range)),
                "a beam out of the setup's limits"
            );
            assert!(binner.points() as usize <= packets * POINTS_PER_PACKET);
        }
    }
    let c = decoder.counters();
    assert_eq!(c.packets as usize, packets);
    let used = packets * PACKET_BYTES + c.skipped_bytes as usize;
    assert!(
        used <= data.len() && data.len() - used < PACKET_BYTES,
        "{c:?}"
    );
}

/// Fuzzes the grid SLAM step API on a small map: each op is a selector byte and three
/// `f32`s (predictions), or a scan whose ranges are the next bytes read as `f32`s and
/// whose geometry comes from the input too. No panic; refused input changes nothing; the
/// estimate and every particle stay finite; the weights stay normalised (Σ w = 1). A twin
/// filter on a grid with an occupied-cell bitmap (the sparse shift search) gets the same
/// ops and must stay identical: same answers, particles, weights and cells.
pub fn grid_steps(data: &[u8]) {
    use microslam::grid::{LogOdds, OccupancyGrid, occupancy_bytes};
    use microslam::pf::{GridPfConfig, GridSlam};
    use microslam::sensors::lidar::{LidarGeometry, LidarScan};
    const BITMAP: usize = occupancy_bytes(64, 64);
    let config = GridPfConfig::MICROCONTROLLER;
    let mut map = Box::new(OccupancyGrid::<64, 64>::new(
        config.resolution,
        -1.6,
        -1.6,
        LogOdds::SYMMETRIC,
    ));
    let mut map_with_bits = Box::new(OccupancyGrid::<64, 64, BITMAP>::new(
        config.resolution,
        -1.6,
        -1.6,
        LogOdds::SYMMETRIC,
    ));
    let start = Pose2::new(0.0, 0.0, 0.0);
    let (Ok(mut slam), Ok(mut twin)) = (
        GridSlam::<64, 64, 8, 64>::new(&mut map, config, start),
        GridSlam::<64, 64, 8, 64, BITMAP>::new(&mut map_with_bits, config, start),
    ) else {
        panic!("the MICROCONTROLLER preset is valid");
    };
    let mut bytes = data;
    while let Some((&op, rest)) = bytes.split_first() {
        bytes = rest;
        let Some([a, b, c]) = take_f32s::<3>(&mut bytes) else {
            return;
        };
        let before = (slam.pose(), *slam.filter().poses());
        let (refused, twin_refused) = match op % 4 {
            0 => (slam.predict(a, b).is_err(), twin.predict(a, b).is_err()),
            1 => (
                slam.predict_velocity(a, b, c).is_err(),
                twin.predict_velocity(a, b, c).is_err(),
            ),
            _ => {
                let n = usize::from(op >> 2).min(bytes.len() / 4);
                let mut ranges = Vec::with_capacity(n);
                for _ in 0..n {
                    let Some([r]) = take_f32s::<1>(&mut bytes) else {
                        break;
                    };
                    ranges.push(if op % 4 == 2 { r } else { r.abs() % 4.0 });
                }
                let geometry = LidarGeometry {
                    first_angle: a,
                    angle_increment: b,
                    min_range: 0.05,
                    max_range: c.abs().min(30.0),
                    no_return_range: 30.0,
                    mount: Pose2::new(0.0, 0.0, 0.0),
                };
                let scan = LidarScan {
                    ranges: &ranges,
                    geometry,
                };
                let (one, other) = (slam.observe(&scan), twin.observe(&scan));
                assert_eq!(
                    one, other,
                    "op {op}: the sparse search answered differently"
                );
                (one.is_err(), other.is_err())
            }
        };
        assert_eq!(refused, twin_refused);
        assert_eq!(slam.filter().poses(), twin.filter().poses());
        assert_eq!(
            slam.filter().log_weights().map(f32::to_bits),
            twin.filter().log_weights().map(f32::to_bits)
        );
        assert_eq!(slam.map().cells(), twin.map().cells());
        if refused && op % 4 < 2 {
            assert_eq!(
                before.0,
                slam.pose(),
                "op {op}: a refused prediction moved the estimate"
            );
        }
        let pose = slam.pose();
        assert!(
            pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite(),
            "estimate {pose:?}"
        );
        assert!(
            slam.filter()
                .poses()
                .iter()
                .all(|p| p.x.is_finite() && p.y.is_finite() && p.theta.is_finite())
        );
        let w = slam.filter().log_weights();
        assert!(
            w.iter().all(|v| !v.is_nan() && *v <= 1e-3),
            "log-weights {w:?}"
        );
        let max = w.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        let log_sum = max + w.iter().map(|&v| (v - max).exp()).sum::<f32>().ln();
        assert!(
            log_sum.abs() < 1e-3,
            "weights not normalised (log Σ w = {log_sum}): {w:?}"
        );
    }
}

/// Fuzzes the CARMEN log parser with arbitrary text: no panic; an error names its line.
pub fn carmen_reader(data: &[u8]) {
    match host_sim::inputs::readers::carmen::parse(std::io::BufReader::new(data)) {
        Ok(log) => {
            for laser in log.lasers() {
                let _ = laser.ranges.len();
            }
        }
        Err(e) => {
            let text = e.to_string();
            assert!(
                text.contains("line")
                    || text.contains("UTF-8")
                    || text.contains("utf-8")
                    || text.contains("stream"),
                "error without a line: {text}"
            );
        }
    }
}

/// Fuzzes the benchmark relations parser: no panic; every relation read is finite, or the
/// file is refused with an error naming its line.
pub fn relations_reader(data: &[u8]) {
    match host_sim::metrics::relations::parse(std::io::BufReader::new(data)) {
        Ok(relations) => {
            for r in &relations {
                assert!(
                    r.t1.is_finite() && r.t2.is_finite() && r.pose.iter().all(|v| v.is_finite()),
                    "non-finite relation accepted: {r:?}"
                );
            }
        }
        Err(e) => {
            let text = e.to_string();
            assert!(text.contains("line"), "error without a line: {text}");
        }
    }
}

/// Fuzzes the MRCLAM reader on a folder of four files cut from the input at `0xFF` bytes
/// (barcodes, odometry, measurements, ground truth): no panic; an error names a file.
pub fn mrclam_reader(data: &[u8]) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let mut parts = data.split(|&b| b == 0xFF);
    for name in [
        "Barcodes.dat",
        "Robot1_Odometry.dat",
        "Robot1_Measurement.dat",
        "Robot1_Groundtruth.dat",
        "Landmark_Groundtruth.dat",
    ] {
        let part = parts.next().unwrap_or(&[]);
        std::fs::write(dir.path().join(name), part).expect("write fuzz file");
    }
    if let Err(e) = host_sim::inputs::readers::mrclam::read(dir.path(), 1) {
        let text = format!("{e:#}");
        assert!(text.contains(".dat"), "error without a file name: {text}");
    }
}

/// Fuzzes the plain landmark log reader (`landmarks:<file>`) and the EKF replay of what
/// it reads: the input is written as `fuzz.txt` and read. No panic; an error names the
/// file and a line; a log read has a motion record and a sighting, finite values in
/// stamp order, and replays (known ids, the built-in `landmarks` settings) without
/// panicking.
pub fn landmark_log_reader(data: &[u8]) {
    use host_sim::domain::AssociationMode;
    use microslam::event::EventKind;
    let dir = tempfile::tempdir().expect("temporary folder");
    let path = dir.path().join("fuzz.txt");
    std::fs::write(&path, data).expect("write fuzz file");
    match host_sim::inputs::readers::landmarks::read(&path) {
        Ok(recording) => {
            let motion = |k: &EventKind<f64>| {
                matches!(
                    k,
                    EventKind::Velocity { .. }
                        | EventKind::Increment(_)
                        | EventKind::Ackermann { .. }
                )
            };
            assert!(
                recording.events.iter().any(|e| motion(&e.kind)),
                "no motion accepted"
            );
            assert!(
                recording
                    .events
                    .iter()
                    .any(|e| matches!(e.kind, EventKind::Sighting(_))),
                "no sighting accepted"
            );
            assert!(
                recording
                    .events
                    .windows(2)
                    .all(|w| w[0].stamp <= w[1].stamp),
                "events out of order"
            );
            let settings = host_sim::domain::config::Settings::load_for(
                "landmarks",
                None,
                Some(AssociationMode::Known),
            )
            .expect("built-in landmarks settings");
            let _ = host_sim::drivers::ekf::replay(
                &recording,
                &settings,
                AssociationMode::Known,
                host_sim::domain::Precision::F64,
                None,
            );
        }
        Err(e) => {
            let text = e.to_string();
            assert!(
                text.contains("fuzz.txt:"),
                "error without the file and line: {text}"
            );
        }
    }
}

/// Fuzzes the npz reader: the input is written as THOR's `Encoders20.npz` and
/// `Imu20.npz` (cut at the first `0xFF 0xFE` pair) and read as run 20: no panic.
pub fn npz_reader(data: &[u8]) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let cut = data
        .windows(2)
        .position(|w| w == [0xFF, 0xFE])
        .unwrap_or(data.len());
    let (enc, imu) = data.split_at(cut);
    std::fs::write(dir.path().join("Encoders20.npz"), enc).expect("write fuzz file");
    std::fs::write(dir.path().join("Imu20.npz"), imu.get(2..).unwrap_or(&[]))
        .expect("write fuzz file");
    let _ = host_sim::inputs::readers::thor::dead_reckoning(dir.path(), 20);
}

/// Fuzzes the map reader (`microslam::grid::ros_map`, used by `host-sim localize` and the firmware's build script): the input up to the first `0xFF`
/// is written as `map.yaml`, the rest as the PGM it names (`image: map.pgm` is put first
/// so that most inputs reach the PGM parser). No panic; an error names `map.yaml` or
/// `map.pgm`; a map read has `width · height` cells.
pub fn map_reader(data: &[u8]) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let cut = data.iter().position(|&b| b == 0xFF).unwrap_or(data.len());
    let (yaml, pgm) = data.split_at(cut);
    let mut text = b"image: map.pgm\n".to_vec();
    text.extend_from_slice(yaml);
    std::fs::write(dir.path().join("map.yaml"), text).expect("write fuzz file");
    std::fs::write(dir.path().join("map.pgm"), pgm.get(1..).unwrap_or(&[]))
        .expect("write fuzz file");
    let log_odds = microslam::grid::LogOdds::SYMMETRIC;
    match microslam::grid::ros_map::RosMap::read(&dir.path().join("map.yaml"), &log_odds) {
        Ok(microslam::grid::ros_map::RosMap { cells, geometry }) => {
            assert_eq!(cells.len(), geometry.width * geometry.height);
            assert!(geometry.resolution.is_finite() && geometry.resolution > 0.0);
        }
        Err(e) => {
            let text = format!("{e:#}");
            assert!(
                text.contains("map.yaml") || text.contains("map.pgm"),
                "error without a file name: {text}"
            );
        }
    }
}

/// A fuzz target's check: panics when an invariant breaks.
pub type FuzzCheck = fn(&[u8]);

/// The topics of the structured bags of [`rosbag_reader`]: name and type (the last one a
/// topic the reader does not read).
const BAG_TOPICS: [(&str, &str); 5] = [
    ("/scan", "sensor_msgs/msg/LaserScan"),
    ("/odom", "nav_msgs/msg/Odometry"),
    ("/imu", "sensor_msgs/msg/Imu"),
    ("/tf_static", "tf2_msgs/msg/TFMessage"),
    ("/chatter", "std_msgs/msg/String"),
];

/// Writes the messages encoded in `data` into a rosbag2 SQLite file at `path` (the oldest
/// tables): per message a topic byte (modulo the number of `topics`, e.g. [`BAG_TOPICS`]), a receive time (`i64`, LE),
/// a length (`u16`, LE) and that many bytes of data; a message cut short ends the list.
fn structured_db3(path: &std::path::Path, topics: &[(&str, &str)], mut data: &[u8]) {
    let db = rusqlite::Connection::open(path).expect("create the fuzz bag");
    db.execute_batch(
        "PRAGMA journal_mode = OFF; PRAGMA synchronous = OFF; BEGIN;
         CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
             serialization_format TEXT NOT NULL);
         CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL,
             timestamp INTEGER NOT NULL, data BLOB NOT NULL);",
    )
    .expect("create the fuzz bag's tables");
    for (k, (name, kind)) in topics.iter().enumerate() {
        db.execute(
            "INSERT INTO topics (id, name, type, serialization_format) VALUES (?1, ?2, ?3, 'cdr')",
            rusqlite::params![k as i64 + 1, name, kind],
        )
        .expect("insert a topic");
    }
    while let Some((&topic, rest)) = data.split_first() {
        let Some((stamp, rest)) = rest.split_first_chunk::<8>() else {
            break;
        };
        let Some((len, rest)) = rest.split_first_chunk::<2>() else {
            break;
        };
        let len = usize::from(u16::from_le_bytes(*len)).min(rest.len());
        let (blob, rest) = rest.split_at(len);
        db.execute(
            "INSERT INTO messages (topic_id, timestamp, data) VALUES (?1, ?2, ?3)",
            rusqlite::params![
                (usize::from(topic) % topics.len()) as i64 + 1,
                i64::from_le_bytes(*stamp),
                blob
            ],
        )
        .expect("insert a message");
        data = rest;
    }
    db.execute_batch("COMMIT").expect("commit the fuzz bag");
}

/// Fuzzes the ROS 2 bag reader (`host-sim --dataset rosbag:`). An even first byte: the
/// rest is the bag file itself (MCAP, SQLite 3 or neither, as its first bytes say); an odd
/// one: the rest lists messages that are stored into a rosbag2 SQLite file
/// (`structured_db3`), so that the fuzzer reaches the reader's own checks past
/// SQLite's. No panic; an error names the file; a bag read has scans that all have the
/// first scan's beam count, and a valid lidar geometry.
pub fn rosbag_reader(data: &[u8]) {
    let dir = tempfile::tempdir().expect("temporary folder");
    let path = dir.path().join("fuzzed-bag");
    match data.split_first() {
        Some((mode, rest)) if mode % 2 == 1 => structured_db3(&path, &BAG_TOPICS, rest),
        Some((_, rest)) => std::fs::write(&path, rest).expect("write fuzz file"),
        None => std::fs::write(&path, data).expect("write fuzz file"),
    }
    let options = host_sim::inputs::readers::rosbag::BagOptions::default();
    match host_sim::inputs::readers::rosbag::read(&path, &options) {
        Ok(bag) => {
            assert!(!bag.scans.is_empty(), "a bag read without a scan");
            let beams = bag.lidar_beams();
            assert!(bag.scans.iter().all(|s| s.ranges.len() == beams));
            assert!(bag.lidar.is_valid(), "{:?}", bag.lidar);
        }
        Err(e) => {
            let text = format!("{e:#}");
            assert!(
                text.contains("fuzzed-bag"),
                "error without the file: {text}"
            );
        }
    }
}

/// The topics of the structured bags of [`detections_bag_reader`] (the first one's type
/// chosen by the mode byte; the last one a topic the reader does not read).
fn detection_topics(detection3d: bool) -> [(&'static str, &'static str); 5] {
    use host_sim::inputs::readers::detections_bag::msg;
    [
        (
            "/detections",
            if detection3d {
                msg::DETECTION3D_ARRAY
            } else {
                msg::ARUCO_MARKERS
            },
        ),
        ("/odom", "nav_msgs/msg/Odometry"),
        ("/tf_static", "tf2_msgs/msg/TFMessage"),
        ("/ground_truth", "nav_msgs/msg/Odometry"),
        ("/chatter", "std_msgs/msg/String"),
    ]
}

/// Fuzzes the ROS 2 bag reader of landmark detections (`host-sim --dataset rosbag:` for
/// the landmark EKF). The first byte: bit 0 set, the rest lists messages stored into a
/// rosbag2 SQLite file (`structured_db3`, topics of `detection_topics`), else it is the
/// bag file itself; bit 1, the detections are `Detection3DArray` (else `ArucoMarkers`);
/// bit 2, the settings give the camera mount. No panic; an error names the file; a bag
/// read has at least one sighting, every sighting a finite positive range and a finite
/// bearing, and its events in time order.
pub fn detections_bag_reader(data: &[u8]) {
    use host_sim::inputs::readers::detections_bag;
    use microslam::event::EventKind;
    let dir = tempfile::tempdir().expect("temporary folder");
    let path = dir.path().join("fuzzed-bag");
    let mode = data.first().copied().unwrap_or(0);
    let rest = data.get(1..).unwrap_or(&[]);
    if mode & 1 == 1 {
        structured_db3(&path, &detection_topics(mode & 2 == 2), rest);
    } else {
        std::fs::write(&path, rest).expect("write fuzz file");
    }
    let options = host_sim::inputs::readers::rosbag::BagOptions::default();
    let mount = (mode & 4 == 4).then_some([0.1, 0.0, 0.05]);
    match detections_bag::read(&path, &options, mount) {
        Ok(bag) => {
            let events = &bag.recording.events;
            let mut sightings = 0;
            for e in events {
                if let EventKind::Sighting(s) = e.kind {
                    sightings += 1;
                    assert!(
                        s.z.range.is_finite() && s.z.range > 0.0 && s.z.bearing.is_finite(),
                        "{s:?}"
                    );
                }
            }
            assert!(sightings > 0, "a bag read without a sighting");
            assert!(events.windows(2).all(|w| w[0].stamp <= w[1].stamp));
        }
        Err(e) => {
            let text = format!("{e:#}");
            assert!(
                text.contains("fuzzed-bag"),
                "error without the file: {text}"
            );
        }
    }
}

/// Every fuzz target by name, for the regression replay.
pub const TARGETS: &[(&str, FuzzCheck)] = &[
    ("ld06_decoder", ld06_decoder),
    ("grid_steps", grid_steps),
    ("carmen_reader", carmen_reader),
    ("relations_reader", relations_reader),
    ("mrclam_reader", mrclam_reader),
    ("landmark_log_reader", landmark_log_reader),
    ("npz_reader", npz_reader),
    ("map_reader", map_reader),
    ("rosbag_reader", rosbag_reader),
    ("detections_bag_reader", detections_bag_reader),
    ("ekf_steps", ekf_steps),
    ("wire_session", wire_session),
    ("wire_decoder", wire_decoder),
];
