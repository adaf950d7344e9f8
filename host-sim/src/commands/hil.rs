//! `host-sim hil`: streams a dataset to the firmware (under QEMU or on a board) through
//! [`crate::drivers::hil`], compares its estimates with the host's bit for bit, and writes
//! `hil.json` and `firmware.tum`.

use crate::drivers::hil::{
    Device, Expected, compare, encode_all_corrupted, host_replies, messages_with_car,
};
use crate::inputs::readers::DatasetSpec;
use crate::inputs::readers::detections_bag;
use crate::inputs::readers::lidar_recording::LidarRecording;
use crate::inputs::readers::rosbag::BagOptions;
use crate::output::tum_text;
use anyhow::{Context, Result, bail};
use microslam::geometry::Pose2;
use microslam::wire::{EkfSettings, ToHost};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The device's trajectory in TUM format (`t x y z qx qy qz qw`).
pub fn tum(replies: &[ToHost]) -> String {
    tum_text(replies.iter().filter_map(|r| match r {
        ToHost::Estimate(e) => {
            let [x, y, th] = e.pose.map(f64::from);
            Some((e.stamp_us as f64 * 1e-6, Pose2::new(x, y, th)))
        }
        _ => None,
    }))
}

/// The device's estimates (EKF or localizer replies): stamp, pose, covariance.
pub fn device_estimates(replies: &[ToHost]) -> Vec<crate::output::mcap::scene::DeviceEstimate> {
    replies
        .iter()
        .filter_map(|r| match r {
            ToHost::Estimate(e) | ToHost::Localization { estimate: e, .. } => {
                let [x, y, th] = e.pose.map(f64::from);
                Some((
                    e.stamp_us as f64 * 1e-6,
                    Pose2::new(x, y, th),
                    Some(e.covariance.map(f64::from)),
                ))
            }
            _ => None,
        })
        .collect()
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
    /// Dataset: `mrclam:<dir>`, `landmarks:<file>` or `rosbag:<bag>` of detections (EKF),
    /// or `carmen:<log>` or `rosbag:<bag>` of scans (the localizer with `map`, the
    /// building-scale grid SLAM without).
    pub dataset: DatasetSpec,
    /// Topics and lidar mount of a `rosbag:` dataset.
    pub bag: BagOptions,
    /// Robot whose log is streamed.
    pub robot: u8,
    /// Record the device's estimates into this MCAP file.
    pub mcap: Option<PathBuf>,
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
    /// With a `carmen:` dataset: the map the localizer firmware was built with.
    pub map: Option<PathBuf>,
    /// With a `carmen:` dataset: stream only the first N scans.
    pub scans: Option<usize>,
    /// With a `carmen:` dataset and no `map` (the building-scale SLAM): reference
    /// trajectory for ATE.
    pub reference: Option<PathBuf>,
    /// Seconds added to the reference's stamps.
    pub reference_offset: f64,
    /// With a `carmen:` dataset and no `map`: save the map and restart the device after
    /// this many scans (it localizes in its own map for the rest).
    pub restart_after: Option<usize>,
    /// With a lidar log and `map` under QEMU: the scans go to the device's own lidar (an
    /// LD06's packets on its second UART) with these line faults.
    pub own_lidar: Option<crate::drivers::hil_lidar::LineFaults>,
}

/// The landmark settings of a run (the dataset's file, `--config` over it), read at most
/// once, when a step needs them: a bag's camera mount, a car's `[vehicle]`,
/// `--dataset-settings`.
struct LandmarkSettings<'a> {
    family: &'static str,
    config: Option<&'a Path>,
    loaded: Option<crate::domain::config::Settings>,
}

impl LandmarkSettings<'_> {
    fn get(&mut self) -> Result<&crate::domain::config::Settings> {
        if self.loaded.is_none() {
            let settings =
                crate::domain::config::Settings::load_for(self.family, self.config, None)?;
            self.loaded = Some(settings);
        }
        self.loaded
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("the landmark settings were not loaded"))
    }
}

/// What `--own-lidar` needs.
const OWN_LIDAR_NEEDS: &str = "--own-lidar streams a lidar log (carmen: or rosbag:) to the \
     localizer firmware (with --map), which reads the lidar on its second UART";

/// `host-sim hil`.
pub fn run_cli(args: &HilOptions, quiet: bool) -> Result<()> {
    if let Some(faults) = &args.own_lidar {
        let lidar_spec = matches!(
            args.dataset,
            DatasetSpec::Carmen(_) | DatasetSpec::Rosbag(_)
        );
        if !lidar_spec || args.map.is_none() {
            bail!(OWN_LIDAR_NEEDS);
        }
        if args.qemu.is_none() {
            bail!(
                "--own-lidar feeds the lidar UART of a firmware under QEMU (--qemu); a board \
                 reads the lidar wired to it"
            );
        }
        if args.restart_after.is_some() {
            bail!("--own-lidar runs without --restart-after");
        }
        if let Some(option) = faults.invalid() {
            bail!("{option}: a fraction of the packets, 0 to 1");
        }
    }
    let device = Device::from_options(args.qemu.as_deref(), args.serial.as_deref(), args.baud)?;
    if let Device::Qemu(elf) = device {
        check_firmware_elf(elf)?;
    }
    crate::commands::replay::bag_options_apply(&args.dataset, &args.bag)?;
    // A bag with a detections topic is a landmark recording; one without is a lidar bag.
    let landmark_bag = detections_bag::landmark_bag(&args.dataset, &args.bag)?;
    let lidar_log = landmark_bag.is_none()
        && matches!(
            args.dataset,
            DatasetSpec::Carmen(_) | DatasetSpec::Rosbag(_)
        );
    if args.own_lidar.is_some() && !lidar_log {
        bail!(OWN_LIDAR_NEEDS);
    }
    if lidar_log && args.map.is_none() {
        use crate::commands::hil_slam::{SlamHilOptions, run_cli};
        // What this mode does not do is refused, never ignored.
        if args.mcap.is_some() || args.dataset_settings || args.corrupt_frames != 0.0 {
            bail!(
                "the building-scale SLAM HIL (a lidar log without --map) takes neither \
                 --mcap, --dataset-settings nor --corrupt-frames"
            );
        }
        let lidar = LidarRecording::read(&args.dataset, &args.bag)?;
        let options = SlamHilOptions {
            device,
            lidar: &lidar,
            scans: args.scans,
            out: &args.out,
            timeout_s: args.timeout_s,
            reference: args.reference.as_deref(),
            reference_offset: args.reference_offset,
            restart_after: args.restart_after,
        };
        return run_cli(&options, quiet);
    }
    if args.reference.is_some() {
        bail!("--reference scores the building-scale SLAM (a lidar log without --map)");
    }
    if args.restart_after.is_some() && !lidar_log {
        bail!(
            "--restart-after restarts a firmware with a lidar log (carmen: or rosbag:): the \
             building-scale SLAM's (without --map) or the localizer's (with --map)"
        );
    }
    if lidar_log {
        use crate::commands::hil_localizer::{LocalizerHilOptions, run_cli};
        let lidar = LidarRecording::read(&args.dataset, &args.bag)?;
        let options = LocalizerHilOptions {
            device,
            map: args.map.as_deref(),
            lidar: &lidar,
            scans: args.scans,
            out: &args.out,
            timeout_s: args.timeout_s,
            mcap: args.mcap.as_deref(),
            restart_after: args.restart_after,
            own_lidar: args.own_lidar,
        };
        return run_cli(&options, quiet);
    }
    let mut settings = LandmarkSettings {
        family: args.dataset.landmark_settings_family(),
        config: args.config.as_deref(),
        loaded: None,
    };
    let mut recording = match &landmark_bag {
        Some(path) => {
            let mount = settings.get()?.sighting.mount;
            detections_bag::recording(path, &args.bag, mount)?
        }
        None => crate::inputs::readers::read(&args.dataset, args.robot)?,
    };
    // A car's speed and steering go through the car of the settings' `[vehicle]`, which
    // the device is given first (a firmware built with the feature `car`).
    let car = if recording
        .events
        .iter()
        .any(|e| matches!(e.kind, microslam::event::EventKind::Ackermann { .. }))
    {
        let Some(car) = settings.get()?.vehicle::<f32>() else {
            bail!(
                "{}: a car's speed and steering (ackermann records) need the car's \
                 wheelbase and noise: a [vehicle] section in --config",
                recording.name
            );
        };
        if let Some(bad) = car.invalid_setting() {
            bail!("[vehicle]: {bad}");
        }
        Some(microslam::wire::CarSettings::from_model(&car))
    } else {
        None
    };
    let unidentified = recording
        .events
        .iter()
        .filter(|e| {
            matches!(
                &e.kind,
                microslam::event::EventKind::Sighting(s)
                    if !matches!(s.identity, microslam::event::Identity::Unique(_))
            )
        })
        .count();
    if unidentified > 0 {
        bail!(
            "{}: {unidentified} sightings carry no landmark id (a class or nothing): the \
             firmware's landmark session pairs sightings by id; replay hidden ids with \
             `host-sim replay -a jcbb`",
            recording.name
        );
    }
    let settings = if args.dataset_settings {
        let tuned = settings.get()?;
        if tuned.sighting.has_bias_mean() {
            bail!(
                "the wire protocol's EkfSettings carries the calibration priors' standard \
                 deviations, not a range bias mean: set range_bias_offset_mean and \
                 range_bias_curvature_mean to 0 for --dataset-settings"
            );
        }
        // The host is the device's front end: it sends the odometry when the robot
        // moves, the settings' latency after the readings (velocities are held between
        // samples on the device; `replay` interpolates them when the settings say so).
        if let Some(events) =
            crate::drivers::odometry::delay_odometry(&recording.events, tuned.odometry.latency_s)
        {
            recording.events = events;
        }
        Some(
            EkfSettings::from_config(&tuned.ekf_config::<f32>())
                .with_calibration(tuned.calibration_priors()),
        )
    } else {
        None
    };
    let messages = messages_with_car(&recording, settings, car);
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
    let run = device.run(bytes, Expected::host(&host), timeout)?;
    let mut comparison = compare(messages.len(), &run, &host);
    comparison.corrupted_frames = corrupted;
    (comparison.device_ate_se2_m, comparison.device_ate_poses) =
        device_ate(&run.replies, &recording.ground_truth);
    crate::output::create_folder(&args.out)?;
    let report = args.out.join("hil.json");
    crate::output::write_report(&report, &comparison)?;
    std::fs::write(args.out.join("firmware.tum"), tum(&run.replies))?;
    if let Some(mut file) = super::open_mcap(args.mcap.as_deref())? {
        crate::output::mcap::scene::record_estimates(
            &mut file,
            "",
            &device_estimates(&run.replies),
            &recording.ground_truth,
            None,
            0.1,
        )?;
        super::close_mcap(Some(file), quiet)?;
    }
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
    crate::drivers::hil::check_protocol(&comparison)?;
    crate::drivers::hil::check_refusals(&run.replies)?;
    if comparison
        .device_frames_bad
        .is_some_and(|bad| bad as usize != corrupted)
    {
        bail!(
            "the device counted {:?} bad frames for {corrupted} corrupted",
            comparison.device_frames_bad
        );
    }
    if comparison.received == 0 && comparison.expected > 0 {
        let device = match (&args.qemu, &args.serial) {
            (Some(elf), _) => format!("QEMU could not load or run {}", elf.display()),
            (_, Some(port)) => format!("the board on {port} did not answer"),
            _ => "the device did not answer".to_string(),
        };
        bail!(
            "no reply from the device in {} s: {device} (0 of {} replies)",
            args.timeout_s,
            comparison.expected
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

/// Where `cargo build -p firmware-example --target thumbv7em-none-eabihf --profile
/// firmware` puts the QEMU ELF: under `$CARGO_TARGET_DIR` when set (relative to the
/// workspace), else the workspace's `target/`.
pub fn default_firmware_elf() -> PathBuf {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .filter(|v| !v.is_empty())
        .map_or_else(|| PathBuf::from("target"), PathBuf::from);
    workspace
        .join(target)
        .join("thumbv7em-none-eabihf/firmware/firmware-example")
}

/// `EM_ARM`, the ELF machine of a Cortex-M binary.
const ELF_MACHINE_ARM: u16 = 40;

/// Checks that `elf` is a 32-bit little-endian ARM ELF file before QEMU is asked to run
/// it: a missing or wrong file is reported as such, with how to build the firmware.
pub fn check_firmware_elf(elf: &Path) -> Result<()> {
    let build = format!(
        "build it with `bash .ci/firmware.sh` (then {}) or `cargo build -p firmware-example \
         --target thumbv7em-none-eabihf --profile firmware` (then {})",
        Path::new("target/firmware-elf/qemu.elf").display(),
        default_firmware_elf().display()
    );
    let mut header = [0u8; 20];
    let read = std::fs::File::open(elf).and_then(|mut f| {
        use std::io::Read;
        f.read_exact(&mut header)
    });
    match read {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("firmware ELF {} not found: {build}", elf.display())
        }
        Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            bail!("{} is not an ELF file (too short)", elf.display())
        }
        Err(e) => return Err(e).with_context(|| format!("reading {}", elf.display())),
        Ok(()) => {}
    }
    if header[..4] != *b"\x7fELF" {
        bail!("{} is not an ELF file: {build}", elf.display());
    }
    // e_ident[EI_CLASS] = 1 (32-bit), [EI_DATA] = 1 (little-endian); e_machine at 18.
    let machine = u16::from_le_bytes([header[18], header[19]]);
    if header[4] != 1 || header[5] != 1 || machine != ELF_MACHINE_ARM {
        bail!(
            "{} is not a 32-bit ARM ELF (class {}, data {}, machine {machine}): not a \
             Cortex-M firmware; {build}",
            elf.display(),
            header[4],
            header[5]
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(path: &Path) -> String {
        format!("{:#}", check_firmware_elf(path).expect_err("refused"))
    }

    #[test]
    fn a_missing_or_wrong_elf_is_named_as_such() {
        let dir = tempfile::tempdir().expect("temporary folder");
        let missing = dir.path().join("qemu.elf");
        assert!(error(&missing).contains("not found"), "{}", error(&missing));
        assert!(error(&missing).contains(".ci/firmware.sh"));

        let text = dir.path().join("notes.txt");
        std::fs::write(&text, "not a firmware, just text").expect("write");
        assert!(
            error(&text).contains("is not an ELF file"),
            "{}",
            error(&text)
        );

        let short = dir.path().join("short.elf");
        std::fs::write(&short, b"\x7fELF").expect("write");
        assert!(error(&short).contains("too short"), "{}", error(&short));

        // This test binary: an ELF, but for the host, not a Cortex-M.
        let host = std::env::current_exe().expect("the test binary");
        assert!(
            error(&host).contains("not a 32-bit ARM ELF"),
            "{}",
            error(&host)
        );

        let mut arm = vec![0u8; 52];
        arm[..6].copy_from_slice(b"\x7fELF\x01\x01");
        arm[18..20].copy_from_slice(&ELF_MACHINE_ARM.to_le_bytes());
        let arm_path = dir.path().join("arm.elf");
        std::fs::write(&arm_path, &arm).expect("write");
        check_firmware_elf(&arm_path).expect("an ARM ELF header passes");
    }
}
