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

/// One array of an `.npz` file: its shape, its strides (how far the flat index moves along
/// each dimension: THOR's 2-D arrays are stored in Fortran, column-major, order) and its
/// values as `f64` in the order they are stored.
struct Array {
    shape: Vec<u64>,
    strides: Vec<u64>,
    values: Vec<f64>,
}

impl Array {
    /// The element at `row`, `col` of a 2-D array (`row` of a 1-D one), whatever the
    /// storage order; NaN outside the array ([`check_run`] has checked the shapes first).
    fn at(&self, row: usize, col: usize) -> f64 {
        let stride = |d: usize| self.strides.get(d).copied().unwrap_or(0) as usize;
        self.values
            .get(row * stride(0) + col * stride(1))
            .copied()
            .unwrap_or(f64::NAN)
    }
}

/// One array of an `.npz` file as `f64`, with its shape and strides.
fn npz_array(path: &Path, name: &str) -> Result<Array> {
    let mut npz =
        npyz::npz::NpzArchive::open(path).with_context(|| format!("opening {}", path.display()))?;
    let arr = npz
        .by_name(name)
        .with_context(|| format!("{}: reading {name}", path.display()))?
        .with_context(|| format!("{}: no array {name}", path.display()))?;
    let shape = arr.shape().to_vec();
    let strides = arr.strides().to_vec();
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
    Ok(Array {
        shape,
        strides,
        values,
    })
}

/// Checks the arrays of a THOR run against each other and their ranges before anything is
/// integrated, naming the file, the array and the index at fault: `time_stamps` one
/// dimension, finite and never decreasing; `counts` exactly `4 × n` for `n` encoder stamps
/// (at least two), whole tick counts within `i32`; `angular_velocity` exactly `3 × m` for
/// `m` IMU stamps, finite.
fn check_run(
    (enc, counts, enc_t): (&Path, &Array, &Array),
    (imu, rates, imu_t): (&Path, &Array, &Array),
) -> Result<()> {
    for (path, stamps) in [(enc, enc_t), (imu, imu_t)] {
        if stamps.shape.len() != 1 {
            bail!(
                "{}: time_stamps has shape {:?}; it must be one-dimensional",
                path.display(),
                stamps.shape
            );
        }
        let mut previous = f64::NEG_INFINITY;
        for (i, &t) in stamps.values.iter().enumerate() {
            if !t.is_finite() {
                bail!("{}: time_stamps[{i}] = {t} is not finite", path.display());
            }
            if t < previous {
                bail!(
                    "{}: time_stamps[{i}] = {t} s goes back before time_stamps[{}] = {previous} s",
                    path.display(),
                    i - 1
                );
            }
            previous = t;
        }
    }
    let n = enc_t.values.len() as u64;
    if n < 2 {
        bail!(
            "{}: {n} encoder time stamps: at least two are needed to integrate a step",
            enc.display()
        );
    }
    if counts.shape != [4, n] {
        bail!(
            "{}: counts has shape {:?}; with {n} time stamps it must be [4, {n}] (one row a wheel)",
            enc.display(),
            counts.shape
        );
    }
    let whole =
        |c: f64| c.fract() == 0.0 && (f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&c);
    for wheel in 0..4 {
        for k in 0..n as usize {
            let c = counts.at(wheel, k);
            if !whole(c) {
                bail!(
                    "{}: counts[{wheel}, {k}] = {c} is not a whole tick count within ±2³¹",
                    enc.display()
                );
            }
        }
    }
    let m = imu_t.values.len() as u64;
    if rates.shape != [3, m] {
        bail!(
            "{}: angular_velocity has shape {:?}; with {m} time stamps it must be [3, {m}] (one row an axis)",
            imu.display(),
            rates.shape
        );
    }
    for axis in 0..3 {
        for k in 0..m as usize {
            if !rates.at(axis, k).is_finite() {
                bail!(
                    "{}: angular_velocity[{axis}, {k}] is not finite",
                    imu.display()
                );
            }
        }
    }
    Ok(())
}

/// The encoder + IMU trajectory of a THOR run: `(encoder stamp, pose)`.
pub fn dead_reckoning(dir: &Path, run: u32) -> Result<Vec<(f64, Pose2<f64>)>> {
    let enc = dir.join(format!("Encoders{run}.npz"));
    let imu = dir.join(format!("Imu{run}.npz"));
    let counts = npz_array(&enc, "counts")?;
    let enc_t = npz_array(&enc, "time_stamps")?;
    let rates = npz_array(&imu, "angular_velocity")?;
    let imu_t = npz_array(&imu, "time_stamps")?;
    check_run((&enc, &counts, &enc_t), (&imu, &rates, &imu_t))?;
    let (enc_t, imu_t) = (enc_t.values, imu_t.values);
    let n = enc_t.len();
    let m = imu_t.len();
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
            if let Ok(y) = low_pass.update(imu_t[next_imu], rates.at(2, next_imu)) {
                let _ = aligner.push(imu_t[next_imu], y);
            }
            next_imu += 1;
        }
        let ticks = WheelTicks::from_thor_order([0, 1, 2, 3].map(|w| counts.at(w, k) as i32));
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An array stored in C order.
    fn array(shape: &[u64], values: &[f64]) -> Array {
        let strides = match shape {
            [_, cols] => vec![*cols, 1],
            _ => vec![1],
        };
        Array {
            shape: shape.to_vec(),
            strides,
            values: values.to_vec(),
        }
    }

    #[test]
    fn an_element_is_found_in_either_storage_order() {
        // [[1, 2, 3], [4, 5, 6]] in C order and in Fortran order.
        let c = array(&[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let fortran = Array {
            shape: vec![2, 3],
            strides: vec![1, 2],
            values: vec![1.0, 4.0, 2.0, 5.0, 3.0, 6.0],
        };
        for a in [&c, &fortran] {
            assert_eq!((a.at(0, 2), a.at(1, 0), a.at(1, 2)), (3.0, 4.0, 6.0));
        }
    }

    /// `check_run` on encoder arrays `(counts, stamps)` and IMU arrays `(rates, stamps)`.
    fn check(enc: Pair, imu: Pair) -> Result<(), String> {
        let (e, i) = (Path::new("Encoders20.npz"), Path::new("Imu20.npz"));
        check_run((e, &enc.0, &enc.1), (i, &imu.0, &imu.1)).map_err(|e| e.to_string())
    }

    /// An `.npz` file's two arrays: the data and its time stamps.
    type Pair = (Array, Array);

    fn good_imu() -> Pair {
        (array(&[3, 2], &[0.0; 6]), array(&[2], &[0.0, 0.01]))
    }

    #[test]
    fn arrays_that_disagree_or_hold_bad_values_are_refused_naming_file_array_and_index() {
        let counts = array(&[4, 3], &[1.0; 12]);
        let stamps = array(&[3], &[0.0, 0.025, 0.05]);
        check((counts, stamps), good_imu()).unwrap();
        let cases: Vec<(Pair, Pair, &str)> = vec![
            (
                (array(&[4, 2], &[1.0; 8]), array(&[3], &[0.0, 0.025, 0.05])),
                good_imu(),
                "Encoders20.npz: counts has shape [4, 2]; with 3 time stamps it must be [4, 3]",
            ),
            (
                (array(&[3, 4], &[1.0; 12]), array(&[3], &[0.0, 0.025, 0.05])),
                good_imu(),
                "counts has shape [3, 4]",
            ),
            (
                (array(&[4, 3], &[1.0; 12]), array(&[3], &[0.0, 0.05, 0.025])),
                good_imu(),
                "Encoders20.npz: time_stamps[2] = 0.025 s goes back before time_stamps[1] = 0.05 s",
            ),
            (
                (
                    array(&[4, 3], &[1.0; 12]),
                    array(&[3], &[0.0, f64::NAN, 0.05]),
                ),
                good_imu(),
                "Encoders20.npz: time_stamps[1] = NaN is not finite",
            ),
            (
                (
                    array(
                        &[4, 3],
                        &[1.0, 1.0, 1.0, 1.0, 2.5, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
                    ),
                    array(&[3], &[0.0, 0.025, 0.05]),
                ),
                good_imu(),
                "Encoders20.npz: counts[1, 1] = 2.5 is not a whole tick count",
            ),
            (
                (array(&[4, 1], &[1.0; 4]), array(&[1], &[0.0])),
                good_imu(),
                "1 encoder time stamps: at least two are needed",
            ),
            (
                (array(&[4, 3], &[1.0; 12]), array(&[3], &[0.0, 0.025, 0.05])),
                (array(&[3, 1], &[0.0; 3]), array(&[2], &[0.0, 0.01])),
                "Imu20.npz: angular_velocity has shape [3, 1]; with 2 time stamps it must be [3, 2]",
            ),
            (
                (array(&[4, 3], &[1.0; 12]), array(&[3], &[0.0, 0.025, 0.05])),
                (
                    array(&[3, 2], &[0.0, 0.0, 0.0, 0.0, 0.0, f64::INFINITY]),
                    array(&[2], &[0.0, 0.01]),
                ),
                "Imu20.npz: angular_velocity[2, 1] is not finite",
            ),
            (
                (
                    array(&[4, 3], &[1.0; 12]),
                    array(&[3, 1], &[0.0, 0.025, 0.05]),
                ),
                good_imu(),
                "Encoders20.npz: time_stamps has shape [3, 1]; it must be one-dimensional",
            ),
        ];
        for (enc, imu, expected) in cases {
            let err = check(enc, imu).unwrap_err();
            assert!(err.contains(expected), "expected {expected:?}, got {err:?}");
        }
    }
}
