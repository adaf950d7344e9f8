//! THOR (UCSD ECE276A) `.npz` logs: wheel encoders (40 Hz, 4 wheels) and IMU (~100 Hz).
//!
//! `replay --dataset thor:<dir> --run 20` integrates the encoder + IMU trajectory with
//! [`microslam::sensors`]: ticks → distance per interval ([`DiffDriveGeometry::THOR`]),
//! yaw rate through the 10 Hz low-pass of Du (n.d.) ([`YawRateLowPass`]), aligned to the
//! encoder clock as the mean of the two nearest IMU samples ([`ImuAligner`]), then its
//! arc model (eq. 6). No lidar exists for these runs, so there is no SLAM here.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The encoder and IMU processing, §III-B and §III-C, and the arc
//!   model, eq. 6.

use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::pf::prediction::drive_arc;
use microslam::sensors::imu::{Alignment, ImuAligner, YawRateLowPass};
use microslam::sensors::wheel_odometry::{DiffDriveGeometry, WheelTicks};
use std::path::Path;

/// One array of an `.npz` file as `f64`.
fn npz_array(path: &Path, name: &str) -> Result<(Vec<u64>, Vec<f64>)> {
    let mut npz =
        npyz::npz::NpzArchive::open(path).with_context(|| format!("opening {}", path.display()))?;
    let arr = npz
        .by_name(name)
        .with_context(|| format!("{}: reading {name}", path.display()))?
        .with_context(|| format!("{}: no array {name}", path.display()))?;
    let shape = arr.shape().to_vec();
    let values: Vec<f64> = match arr.dtype() {
        npyz::DType::Plain(t) if t.type_char() == npyz::TypeChar::Float => arr.into_vec::<f64>()?,
        npyz::DType::Plain(t) if t.size_field() == 2 => {
            arr.into_vec::<i16>()?.into_iter().map(f64::from).collect()
        }
        npyz::DType::Plain(t) if t.size_field() == 4 => {
            arr.into_vec::<i32>()?.into_iter().map(f64::from).collect()
        }
        npyz::DType::Plain(_) => arr
            .into_vec::<i64>()?
            .into_iter()
            .map(|v| v as f64)
            .collect(),
        other => bail!("{}: {name} has unsupported dtype {other:?}", path.display()),
    };
    Ok((shape, values))
}

/// The encoder + IMU trajectory of a THOR run: `(encoder stamp, pose)`.
pub fn dead_reckoning(dir: &Path, run: u32) -> Result<Vec<(f64, Pose2<f64>)>> {
    let enc = dir.join(format!("Encoders{run}.npz"));
    let imu = dir.join(format!("Imu{run}.npz"));
    let (shape, counts) = npz_array(&enc, "counts")?;
    let (_, enc_t) = npz_array(&enc, "time_stamps")?;
    let (ishape, rates) = npz_array(&imu, "angular_velocity")?;
    let (_, imu_t) = npz_array(&imu, "time_stamps")?;
    let n = enc_t.len();
    if shape.first() != Some(&4) || counts.len() != 4 * n {
        bail!("{}: counts must be 4 × {n}", enc.display());
    }
    let m = imu_t.len();
    if ishape.first() != Some(&3) || rates.len() != 3 * m {
        bail!("{}: angular_velocity must be 3 × {m}", imu.display());
    }
    let geometry = DiffDriveGeometry::THOR;
    let mut low_pass = YawRateLowPass::new(10.0f64);
    let mut aligner = ImuAligner::<f64, 8>::new();
    let mut next_imu = 0;
    let mut pose = Pose2::<f32>::IDENTITY;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let t = enc_t[k];
        // Feed IMU samples up to half an IMU period past the encoder stamp.
        while next_imu < m && imu_t[next_imu] <= t + 0.005 {
            if let Ok(y) = low_pass.update(imu_t[next_imu], rates[2 * m + next_imu]) {
                let _ = aligner.push(imu_t[next_imu], y);
            }
            next_imu += 1;
        }
        let ticks = WheelTicks::from_thor_order([0, 1, 2, 3].map(|w| counts[w * n + k] as i32));
        let motion = geometry.motion(&ticks)?;
        if k > 0 {
            let dt = t - enc_t[k - 1];
            let heading = match aligner.rate_at(t, Alignment::MeanOfTwoNearest) {
                Ok(w) if dt > 0.0 => w * dt,
                _ => motion.heading_change,
            };
            pose = drive_arc(&pose, motion.distance as f32, heading as f32, 0.0);
        }
        out.push((
            t,
            Pose2::new(f64::from(pose.x), f64::from(pose.y), f64::from(pose.theta)),
        ));
    }
    Ok(out)
}
