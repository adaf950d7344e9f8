//! Writes seed inputs for the wire fuzz targets: valid frames of every message kind (a
//! fuzzer rarely forges a CRC by itself), alone and in streams.
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
    Ok(())
}
