//! Writes seed inputs for the wire fuzz targets: valid frames of every message kind (a
//! fuzzer rarely forges a CRC by itself), alone and in streams; and for the ROS 2 bag
//! reader, a small MCAP bag (plain and zstd-compressed) and the same messages as a
//! structured SQLite bag (plain and each message zstd-compressed; the input layouts of
//! `microslam_replay_tests::fuzzing::rosbag_reader`).
//!
//! `cargo run -p microslam-replay-tests --example fuzz_seeds -- fuzz/corpus`

use microslam::wire::{
    Command, EkfSettings, EstimatorKind, MAX_FRAME_LEN, Odometry, ScanChunk, ToDevice, encode_frame,
};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: fuzz_seeds <corpus dir>")?,
    );
    let mut ranges = heapless::Vec::new();
    for i in 0..20u16 {
        ranges.push(1000 + 37 * i).map_err(|_| "chunk full")?;
    }
    let messages = [
        ToDevice::Odometry {
            seq: 1,
            stamp_us: 10,
            odometry: Odometry::Velocity {
                v: 0.3,
                omega: 0.1,
                dt: 0.05,
            },
        },
        ToDevice::Odometry {
            seq: 2,
            stamp_us: 20,
            odometry: Odometry::Increment {
                dx: 0.02,
                dy: 0.0,
                dtheta: 0.01,
            },
        },
        ToDevice::Landmark {
            seq: 3,
            stamp_us: 30,
            id: 11,
            range: 2.5,
            bearing: 0.3,
        },
        ToDevice::Landmark {
            seq: 4,
            stamp_us: 40,
            id: 11,
            range: 2.45,
            bearing: 0.31,
        },
        ToDevice::YawRate {
            seq: 5,
            stamp_us: 50,
            yaw_rate: 0.1,
        },
        ToDevice::Scan(ScanChunk {
            seq: 6,
            stamp_us: 60,
            scan_id: 1,
            beam_offset: 0,
            beam_total: 20,
            angle_min: -1.0,
            angle_increment: 0.1,
            ranges_mm: ranges,
        }),
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
            command: Command::SelectEstimator(EstimatorKind::Ekf),
        },
        ToDevice::Command {
            seq: 9,
            command: Command::ReportStatus,
        },
        ToDevice::Command {
            seq: 10,
            command: Command::ConfigureEkf(EkfSettings::from_config(
                &microslam::ekf::EkfConfig::MICROCONTROLLER,
            )),
        },
    ];
    let mut stream = Vec::new();
    for target in ["wire_session", "wire_decoder"] {
        std::fs::create_dir_all(root.join(target))?;
    }
    for (i, msg) in messages.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = encode_frame(msg, &mut buf)?;
        stream.extend_from_slice(frame);
        for target in ["wire_session", "wire_decoder"] {
            std::fs::write(root.join(target).join(format!("seed-frame-{i}")), frame)?;
        }
    }
    for target in ["wire_session", "wire_decoder"] {
        std::fs::write(root.join(target).join("seed-stream"), &stream)?;
    }
    println!("wrote {} frames to {}", messages.len(), root.display());
    rosbag_seeds(&root.join("rosbag_reader"))?;
    detections_bag_seeds(&root.join("detections_bag_reader"))?;
    Ok(())
}

/// A short run past two markers (velocity odometry, sightings, ground truth) written as a
/// bag of detections: ArucoMarkers (first byte 0: the MCAP file itself; 1: its messages
/// structured into SQLite) and Detection3DArray (2 and 3).
fn detections_bag_seeds(dir: &std::path::Path) -> Result<(), Box<dyn std::error::Error>> {
    use host_sim::domain::recording::{Recording, TruePose};
    use host_sim::output::detections_bag::{CameraMount, DetectionFormat, export};
    use microslam::event::{Event, EventKind, Identity, Sighting};
    use microslam::geometry::Pose2;
    use microslam::sensors::range_bearing::RangeBearing;
    std::fs::create_dir_all(dir)?;
    let mut events = Vec::new();
    let mut ground_truth = Vec::new();
    for k in 0..4 {
        let t = 100.0 + f64::from(k);
        events.push(Event::new(
            t,
            EventKind::Velocity {
                v: 0.2,
                omega: 0.05,
            },
        ));
        for (id, r, b) in [(3, 2.0 - 0.2 * f64::from(k), 0.2), (7, 3.0, -0.3)] {
            events.push(Event::new(
                t,
                EventKind::Sighting(Sighting {
                    identity: Identity::Unique(id),
                    z: RangeBearing::new(r, b),
                    covariance: None,
                }),
            ));
        }
        ground_truth.push(TruePose {
            stamp: t,
            pose: Pose2::new(0.2 * f64::from(k), 0.0, 0.05 * f64::from(k)),
        });
    }
    let recording = Recording {
        name: "seed".into(),
        events,
        ground_truth,
        ..Recording::default()
    };
    let mount = CameraMount {
        position: [0.1, 0.02, 0.3],
        rpy: [0.0, 0.05, 0.1],
    };
    let topics = ["/detections", "/odom", "/tf_static", "/ground_truth"];
    let work = tempfile::tempdir()?;
    for (mode, name, format) in [
        (0u8, "aruco", DetectionFormat::Aruco),
        (
            2u8,
            "detection3d",
            DetectionFormat::Detection3d {
                class: "sign".into(),
            },
        ),
    ] {
        let bag = work.path().join(format!("{name}.mcap"));
        export(&bag, &recording, &format, &mount, true)?;
        let bytes = std::fs::read(&bag)?;
        let mut file = vec![mode];
        file.extend_from_slice(&bytes);
        std::fs::write(dir.join(format!("seed-{name}-mcap-bag")), &file)?;
        let mut structured = vec![mode | 1];
        for m in mcap::MessageStream::new(&bytes)? {
            let m = m?;
            let topic = topics
                .iter()
                .position(|t| *t == m.channel.topic)
                .ok_or("an unexpected topic")?;
            structured.push(topic as u8);
            structured.extend_from_slice(&(m.log_time as i64).to_le_bytes());
            structured.extend_from_slice(&u16::try_from(m.data.len())?.to_le_bytes());
            structured.extend_from_slice(&m.data);
        }
        std::fs::write(dir.join(format!("seed-{name}-structured-db3")), &structured)?;
    }
    println!("wrote 4 detection bags to {}", dir.display());
    Ok(())
}

/// Two scans of five beams with their odometry and a static transform: as an MCAP bag
/// (first byte 0: the file itself), the same compressed with zstd, and as structured
/// SQLite messages (first byte 1), plain and each compressed with zstd.
fn rosbag_seeds(dir: &std::path::Path) -> Result<(), Box<dyn std::error::Error>> {
    use host_sim::inputs::readers::carmen::LaserMessage;
    use host_sim::output::rosbag::export;
    std::fs::create_dir_all(dir)?;
    let scans: Vec<LaserMessage> = (0..2)
        .map(|k| LaserMessage {
            rear: false,
            ranges: vec![1.0, 2.0, 81.9, 3.5, 4.0],
            pose: [0.1 * f64::from(k), 0.0, 0.05 * f64::from(k)],
            odom: [0.1 * f64::from(k), 0.0, 0.05 * f64::from(k)],
            stamp: 100.0 + f64::from(k),
        })
        .collect();
    let refs: Vec<&LaserMessage> = scans.iter().collect();
    let mut lidar = host_sim::domain::grid::carmen_lidar(5);
    lidar.mount = microslam::geometry::Pose2::new(0.1, 0.0, 0.0);
    let work = tempfile::tempdir()?;
    let bag = work.path().join("seed.mcap");
    export(
        &bag,
        &refs,
        &lidar,
        &host_sim::inputs::readers::rosbag::BagOptions::default(),
    )?;
    let bytes = std::fs::read(&bag)?;
    let mut file = vec![0u8];
    file.extend_from_slice(&bytes);
    std::fs::write(dir.join("seed-mcap-bag"), &file)?;
    // The same bag compressed whole, as rosbag2's `--compression-mode file` writes it.
    let mut compressed = vec![0u8];
    compressed.extend_from_slice(&zstd::encode_all(bytes.as_slice(), 3)?);
    std::fs::write(dir.join("seed-zstd-mcap-bag"), &compressed)?;
    // The same messages, structured: topic index, receive time, length, data.
    let topics = ["/scan", "/odom", "/imu", "/tf_static"];
    // And with each message compressed, as rosbag2's `--compression-mode message` stores it.
    let mut structured = vec![1u8];
    let mut compressed_messages = vec![1u8];
    for m in mcap::MessageStream::new(&bytes)? {
        let m = m?;
        let topic = topics
            .iter()
            .position(|t| *t == m.channel.topic)
            .ok_or("an unexpected topic")?;
        let frame = zstd::encode_all(&m.data[..], 3)?;
        for (out, data) in [
            (&mut structured, &m.data[..]),
            (&mut compressed_messages, &frame[..]),
        ] {
            out.push(topic as u8);
            out.extend_from_slice(&(m.log_time as i64).to_le_bytes());
            out.extend_from_slice(&u16::try_from(data.len())?.to_le_bytes());
            out.extend_from_slice(data);
        }
    }
    std::fs::write(dir.join("seed-structured-db3"), &structured)?;
    std::fs::write(
        dir.join("seed-structured-zstd-messages-db3"),
        &compressed_messages,
    )?;
    println!("wrote 4 bags to {}", dir.display());
    Ok(())
}
