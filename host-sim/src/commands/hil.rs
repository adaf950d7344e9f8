//! `host-sim hil`: streams a dataset to the firmware (under QEMU or on a board) through
//! [`crate::drivers::hil`], compares its estimates with the host's bit for bit, and writes
//! `hil.json` and `firmware.tum`.

use crate::drivers::hil::{
    compare, encode_all_corrupted, host_replies, messages_for, run_qemu, run_serial,
};
use crate::inputs::readers::DatasetSpec;
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::wire::{EkfSettings, ToHost};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The device's trajectory in TUM format (`t x y z qx qy qz qw`).
pub fn tum(replies: &[ToHost]) -> String {
    let mut out = String::new();
    for r in replies {
        if let ToHost::Estimate(e) = r {
            let [x, y, th] = e.pose.map(f64::from);
            let (s, c) = (th / 2.0).sin_cos();
            let t = e.stamp_us as f64 * 1e-6;
            out.push_str(&format!("{t:.6} {x} {y} 0 0 0 {s} {c}\n"));
        }
    }
    out
}

/// ATE (SE(2) alignment) of the estimates in `replies` against `truth`, and over how many
/// estimates (those inside the truth's time span).
pub fn device_ate(
    replies: &[ToHost],
    truth: &[crate::domain::recording::TruePose],
) -> (Option<f64>, usize) {
    let (est, gt): (Vec<Pose2<f64>>, Vec<Pose2<f64>>) = replies
        .iter()
        .filter_map(|r| match r {
            ToHost::Estimate(e) => {
                let [x, y, th] = e.pose.map(f64::from);
                let g =
                    crate::domain::recording::interpolate_pose(truth, e.stamp_us as f64 * 1e-6)?;
                Some((Pose2::new(x, y, th), g))
            }
            _ => None,
        })
        .unzip();
    let (_, se2) = crate::metrics::transforms(&est, &gt);
    let ate = se2.and_then(|t| crate::metrics::position_rmse(&t, &est, &gt));
    (ate, est.len())
}

/// Options of `host-sim hil`: exactly one of `qemu` and `serial`.
#[derive(Debug, Clone)]
pub struct HilOptions {
    /// Run this firmware ELF under `qemu-system-arm` (mps2-an386).
    pub qemu: Option<PathBuf>,
    /// Talk to a board on this serial port (e.g. /dev/ttyACM0).
    pub serial: Option<String>,
    /// Baud rate of the serial port.
    pub baud: u32,
    /// Dataset: `mrclam:<dir>`.
    pub dataset: DatasetSpec,
    /// Robot whose log is streamed.
    pub robot: u8,
    /// Output folder: hil.json (the comparison) and firmware.tum (the device's trajectory).
    pub out: PathBuf,
    /// Give up waiting for replies after this many seconds.
    pub timeout_s: u64,
    /// Fraction of the frames sent corrupted (one byte each).
    pub corrupt_frames: f64,
    /// Seed of the frame corruption.
    pub corrupt_seed: u64,
    /// Send the dataset's tuned EKF settings to the device first (`ConfigureEkf`).
    pub dataset_settings: bool,
    /// EKF settings (TOML) laid over the dataset's defaults, with `dataset_settings`.
    pub config: Option<PathBuf>,
}

/// `host-sim hil`.
pub fn run_cli(args: &HilOptions, quiet: bool) -> Result<()> {
    let recording = crate::inputs::readers::read(&args.dataset, args.robot)?;
    let settings = if args.dataset_settings {
        let family = args.dataset.family();
        let tuned =
            crate::domain::config::Settings::load_for(family, args.config.as_deref(), None)?;
        Some(EkfSettings::from_config(&tuned.ekf_config::<f32>()))
    } else {
        None
    };
    let messages = messages_for(&recording, settings);
    let (bytes, corrupted) =
        encode_all_corrupted(&messages, args.corrupt_frames, args.corrupt_seed);
    let host = host_replies(&bytes);
    let timeout = Duration::from_secs(args.timeout_s);
    if !quiet {
        println!(
            "{}: {} events → {} frames ({} bytes)",
            recording.name,
            recording.events.len(),
            messages.len(),
            bytes.len()
        );
    }
    let run = match (&args.qemu, &args.serial) {
        (Some(elf), None) => run_qemu(elf, bytes, host.len(), timeout)?,
        (None, Some(port)) => run_serial(port, args.baud, bytes, host.len(), timeout)?,
        _ => bail!("give exactly one of --qemu <elf> and --serial <port>"),
    };
    let mut comparison = compare(messages.len(), &run, &host);
    comparison.corrupted_frames = corrupted;
    (comparison.device_ate_se2_m, comparison.device_ate_poses) =
        device_ate(&run.replies, &recording.ground_truth);
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let report = args.out.join("hil.json");
    std::fs::write(&report, serde_json::to_string_pretty(&comparison)?)?;
    std::fs::write(args.out.join("firmware.tum"), tum(&run.replies))?;
    if !quiet {
        println!(
            "{} of {} replies received, {} identical to the host bit for bit; max pose \
             difference {:?}; device ATE(se2) {} over {} estimates; {:.1} s; report in {}",
            comparison.received,
            comparison.expected,
            comparison.identical,
            comparison.max_pose_difference,
            comparison
                .device_ate_se2_m
                .map_or_else(|| "–".to_string(), |a| format!("{a:.4} m")),
            comparison.device_ate_poses,
            comparison.seconds,
            report.display()
        );
    }
    if comparison
        .device_frames_bad
        .is_some_and(|bad| bad as usize != corrupted)
    {
        bail!(
            "the device counted {:?} bad frames for {corrupted} corrupted",
            comparison.device_frames_bad
        );
    }
    if comparison.received != comparison.expected || comparison.identical != comparison.expected {
        bail!(
            "the device's estimates differ from the host's ({} of {} identical)",
            comparison.identical,
            comparison.expected
        );
    }
    Ok(())
}

/// Where `cargo build -p firmware-example --profile firmware` puts the QEMU ELF.
pub fn default_firmware_elf() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../target/thumbv7em-none-eabihf/firmware/firmware-example")
}
