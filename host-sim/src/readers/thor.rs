//! THOR (UCSD ECE276A) `.npz` logs: wheel encoders (40 Hz, 4 wheels) and IMU (~100 Hz).
//!
//! `replay --dataset thor:<dir> --run 20` integrates the encoder + IMU trajectory with
//! [`microslam::sensors`]: ticks → distance per interval ([`DiffDriveGeometry::THOR`]),
//! yaw rate through the seed's 10 Hz low-pass ([`YawRateLowPass`]), aligned to the
//! encoder clock as the mean of the two nearest IMU samples ([`ImuAligner`]), then the
//! seed's arc model. No lidar exists for these runs, so there is no SLAM here.

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

/// `host-sim replay --dataset thor:<dir> --run N`: trajectory.tum, trajectory.png (with a
/// 1 m grid), metrics.json (length, duration, end pose).
pub fn replay_cli(dir: &str, run: u32, out: &Path, quiet: bool) -> Result<()> {
    let start = std::time::Instant::now();
    let direct = Path::new(dir);
    let path = if direct.is_dir() {
        direct.to_path_buf()
    } else {
        crate::datasets::resolve("", dir)?
    };
    let traj = dead_reckoning(&path, run)?;
    std::fs::create_dir_all(out)?;
    let as_f32: Vec<(f64, Pose2<f32>)> = traj
        .iter()
        .map(|(t, p)| (*t, Pose2::new(p.x as f32, p.y as f32, p.theta as f32)))
        .collect();
    crate::output::grid_map::write_tum(&out.join("trajectory.tum"), &as_f32)?;
    let length: f64 = traj
        .windows(2)
        .map(|w| (w[1].1.x - w[0].1.x).hypot(w[1].1.y - w[0].1.y))
        .sum();
    let duration = traj.last().map_or(0.0, |l| l.0) - traj.first().map_or(0.0, |f| f.0);
    draw_trajectory(&out.join("trajectory.png"), &traj)?;
    let end = traj.last().map_or(Pose2::IDENTITY, |l| l.1);
    let metrics = serde_json::json!({
        "dataset": format!("thor/run{run}"),
        "samples": traj.len(),
        "duration_s": duration,
        "path_length_m": length,
        "end_pose": [end.x, end.y, end.theta],
        "wall_time_s": start.elapsed().as_secs_f64(),
    });
    std::fs::write(
        out.join("metrics.json"),
        serde_json::to_string_pretty(&metrics)? + "\n",
    )?;
    if !quiet {
        println!(
            "thor run {run}: {} encoder samples, {duration:.1} s, {length:.2} m driven; outputs in {}",
            traj.len(),
            out.display()
        );
    }
    Ok(())
}

fn draw_trajectory(path: &Path, traj: &[(f64, Pose2<f64>)]) -> Result<()> {
    use plotters::prelude::*;
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (_, p) in traj {
        x0 = x0.min(p.x);
        x1 = x1.max(p.x);
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    let pad = 0.05 * (x1 - x0).max(y1 - y0).max(1.0);
    let mut rgb = vec![0u8; 800 * 800 * 3];
    let root = BitMapBackend::with_buffer(&mut rgb, (800, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut chart = ChartBuilder::on(&root)
        .margin(10)
        .build_cartesian_2d(x0 - pad..x1 + pad, y0 - pad..y1 + pad)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    // No axes: the plotters build here has no font backend (a 1 m grid instead).
    let grid_style = ShapeStyle::from(&RGBColor(220, 220, 220)).stroke_width(1);
    for gx in (x0 - pad).ceil() as i64..=(x1 + pad).floor() as i64 {
        let gx = gx as f64;
        chart
            .draw_series(LineSeries::new(
                [(gx, y0 - pad), (gx, y1 + pad)],
                grid_style,
            ))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        // No axes: the plotters build here has no font backend (a 1 m grid instead).
        let grid_style = ShapeStyle::from(&RGBColor(220, 220, 220)).stroke_width(1);
        for gx in (x0 - pad).ceil() as i64..=(x1 + pad).floor() as i64 {
            let gx = gx as f64;
            chart
                .draw_series(LineSeries::new(
                    [(gx, y0 - pad), (gx, y1 + pad)],
                    grid_style,
                ))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
        for gy in (y0 - pad).ceil() as i64..=(y1 + pad).floor() as i64 {
            let gy = gy as f64;
            chart
                .draw_series(LineSeries::new(
                    [(x0 - pad, gy), (x1 + pad, gy)],
                    grid_style,
                ))
                .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        }
        chart
            .draw_series(LineSeries::new(traj.iter().map(|(_, p)| (p.x, p.y)), &RED))
            .map_err(|e| anyhow::anyhow!("{e:?}"))?;
        root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    }
    chart
        .draw_series(LineSeries::new(traj.iter().map(|(_, p)| (p.x, p.y)), &RED))
        .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    root.present().map_err(|e| anyhow::anyhow!("{e:?}"))?;
    drop(chart);
    drop(root);
    crate::output::write_png(path, 800, 800, &rgb)
}
