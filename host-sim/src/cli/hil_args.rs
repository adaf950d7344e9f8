//! `host-sim hil`'s options.

use super::BagArgs;
use crate::commands::hil::HilOptions;
use crate::drivers::hil_lidar::LineFaults;
use crate::inputs::readers::DatasetSpec;
use clap::Args;
use std::path::PathBuf;

/// Options of `host-sim hil`.
#[derive(Debug, Clone, Args)]
#[command(group(clap::ArgGroup::new("link").required(true).args(["qemu", "serial"])))]
pub struct HilArgs {
    /// Run this firmware ELF under `qemu-system-arm` (mps2-an386).
    #[arg(long)]
    pub qemu: Option<PathBuf>,
    /// Talk to a board on this serial port (e.g. /dev/ttyACM0).
    #[arg(long)]
    pub serial: Option<String>,
    /// Baud rate of the serial port.
    #[arg(long, default_value_t = 115_200)]
    pub baud: u32,
    /// Dataset: `mrclam:<dir>` or `mrclam:<dir>/robot<k>`, `landmarks:<file>`, or
    /// `rosbag:<bag>` with ArucoMarkers detections (EKF), as for `replay`; or a lidar log,
    /// `carmen:<log>` or `rosbag:<bag>` with scans: with `--map` the localizer on the map in
    /// the firmware's flash, without it the building-scale grid SLAM (a firmware built
    /// with `--features building-slam`). A bag's lidar mounted off the robot's centre is
    /// streamed in its own frame (the device estimates the lidar's pose; the trajectory
    /// written is the robot's).
    #[arg(long, short)]
    pub dataset: DatasetSpec,
    /// With `carmen:`: the map the firmware was built with (`MICROSLAM_MAP`), for the
    /// host reference.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// With `carmen:` and no `--map` (grid SLAM): reference trajectory for ATE (a TUM file
    /// or a corrected CARMEN log, e.g. `intel/intel.gfs.log`), matched to the scans by
    /// stamp.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Seconds added to the reference's stamps (976052857.337 for `intel.gfs.log`
    /// against `intel-raw-part.clf`).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub reference_offset: f64,
    /// With `carmen:`: stream only the first N scans.
    #[arg(long)]
    pub scans: Option<usize>,
    /// With `carmen:`: restart the device after N scans (`Restart`). Without `--map` (the
    /// building-scale SLAM firmware) the map is saved into its flash first (`SaveMap`):
    /// it boots on the map and pose it kept and localizes the rest of the log. With
    /// `--map` (the localizer firmware) it resumes from the pose it kept. Compared with
    /// the host bit for bit.
    #[arg(long, value_name = "N")]
    pub restart_after: Option<usize>,
    /// Robot whose log is streamed (1–5 in MRCLAM).
    #[arg(long, default_value_t = 1)]
    pub robot: u8,
    /// Output folder: hil.json (the comparison) and firmware.tum (the device's trajectory).
    #[arg(long, short, default_value = "out/hil")]
    pub out: PathBuf,
    /// Give up waiting for replies after this many seconds.
    #[arg(long, default_value_t = 900)]
    pub timeout_s: u64,
    /// Corrupt this fraction of the frames sent (one byte each): the device must count
    /// exactly that many bad frames and still answer every other frame like the host.
    #[arg(long, default_value_t = 0.0)]
    pub corrupt_frames: f64,
    /// Seed of the frame corruption.
    #[arg(long, default_value_t = 1)]
    pub corrupt_seed: u64,
    /// Send the dataset's tuned EKF settings (`host-sim/configs/<dataset>.toml`, or
    /// `--config`) to the device first (`ConfigureEkf`), instead of running the
    /// firmware's own (`EkfConfig::MICROCONTROLLER`).
    #[arg(long)]
    pub dataset_settings: bool,
    /// EKF settings (TOML) laid over the dataset's defaults, with `--dataset-settings`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Record the device's estimates into this MCAP file (Foxglove schemas).
    #[arg(long)]
    pub mcap: Option<PathBuf>,
    /// Topics and lidar mount of a `rosbag:` dataset.
    #[command(flatten)]
    pub bag: BagArgs,
    /// The device's own lidar.
    #[command(flatten)]
    pub own_lidar: OwnLidarArgs,
}

/// Options of `host-sim hil --own-lidar`.
#[derive(Debug, Clone, Args)]
pub struct OwnLidarArgs {
    /// With a lidar log and `--map` under `--qemu`: send the scans as an LDROBOT LD06's
    /// packets on the device's second UART (UART1), which the localizer firmware reads
    /// itself (`NextRevolution` in the link's stream where each scan's chunks would be);
    /// the host reference decodes the same bytes with the same reader.
    #[arg(long)]
    pub own_lidar: bool,
    /// With `--own-lidar`: the fraction of packets followed by 1–16 bytes of noise.
    #[arg(long, default_value_t = 0.0, requires = "own_lidar")]
    pub lidar_noise: f64,
    /// With `--own-lidar`: the fraction of packets sent with one byte changed (each must
    /// be counted by the device's reader as a bad checksum).
    #[arg(long, default_value_t = 0.0, requires = "own_lidar")]
    pub lidar_corrupt: f64,
    /// With `--own-lidar`: the fraction of packets lost on the line.
    #[arg(long, default_value_t = 0.0, requires = "own_lidar")]
    pub lidar_drop: f64,
    /// Seed of the line faults.
    #[arg(long, default_value_t = 1, requires = "own_lidar")]
    pub lidar_seed: u64,
}

impl From<&HilArgs> for HilOptions {
    fn from(a: &HilArgs) -> Self {
        Self {
            qemu: a.qemu.clone(),
            serial: a.serial.clone(),
            baud: a.baud,
            dataset: a.dataset.clone(),
            bag: (&a.bag).into(),
            robot: a.robot,
            out: a.out.clone(),
            timeout_s: a.timeout_s,
            corrupt_frames: a.corrupt_frames,
            corrupt_seed: a.corrupt_seed,
            dataset_settings: a.dataset_settings,
            config: a.config.clone(),
            map: a.map.clone(),
            scans: a.scans,
            reference: a.reference.clone(),
            reference_offset: a.reference_offset,
            restart_after: a.restart_after,
            mcap: a.mcap.clone(),
            own_lidar: a.own_lidar.own_lidar.then_some(LineFaults {
                noise: a.own_lidar.lidar_noise,
                corrupt: a.own_lidar.lidar_corrupt,
                drop: a.own_lidar.lidar_drop,
                seed: a.own_lidar.lidar_seed,
            }),
        }
    }
}
