//! Dataset readers: files → a time-ordered [`Event`] stream plus ground truth.
//!
//! Readers do no estimation; the replay loop does no parsing. A truncated or corrupt line
//! is an error naming the file and the line number.

pub mod bag_storage;
pub mod carmen;
pub mod detections_bag;
pub mod landmarks;
pub mod lidar_recording;
pub mod map;
pub mod mrclam;
pub mod reference;
pub mod rosbag;
mod text;
pub mod thor;

pub use text::ReadError;

use crate::domain::recording::Recording;

use anyhow::{Result, bail};
use microslam::event::Event;
use std::str::FromStr;

/// A dataset named on the command line: `<family>:<location>`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DatasetSpec {
    /// UTIAS MRCLAM: a folder with `Robot<k>_Odometry.dat` etc.
    Mrclam(String),
    /// A CARMEN lidar log (`.clf`, `.log`, `.log.gz`): a path, or relative to the
    /// datasets folder (e.g. `carmen:intel/intel-raw-part.clf`).
    Carmen(String),
    /// THOR `.npz` files: a folder, or a name under the datasets folder (`thor:thor`).
    Thor(String),
    /// A ROS 2 bag with `sensor_msgs/msg/LaserScan` and `nav_msgs/msg/Odometry` messages
    /// ([`rosbag`]), or with landmark detections and odometry ([`detections_bag`]): an
    /// MCAP or SQLite 3 file, or a rosbag2 bag folder (`rosbag:<bag>`).
    Rosbag(String),
    /// A plain landmark log ([`landmarks`], documented in docs/guide.md): a file.
    Landmarks(String),
}

impl FromStr for DatasetSpec {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.split_once(':') {
            Some(("mrclam", dir)) if !dir.is_empty() => Ok(Self::Mrclam(dir.to_owned())),
            Some(("carmen", file)) if !file.is_empty() => Ok(Self::Carmen(file.to_owned())),
            Some(("thor", dir)) if !dir.is_empty() => Ok(Self::Thor(dir.to_owned())),
            Some(("rosbag", file)) if !file.is_empty() => Ok(Self::Rosbag(file.to_owned())),
            Some(("landmarks", file)) if !file.is_empty() => Ok(Self::Landmarks(file.to_owned())),
            _ => Err(format!(
                "unknown dataset `{s}`: expected `mrclam:<dir>` (e.g. mrclam:dataset6, or mrclam:dataset6/robot3 for one robot), `carmen:<file>`, `thor:<dir>`, `rosbag:<bag>` (an .mcap or .db3 file, or a rosbag2 bag folder) or `landmarks:<file>` (a plain landmark log)"
            )),
        }
    }
}

impl DatasetSpec {
    /// The family name (`mrclam`), as used for default config files.
    pub fn family(&self) -> &'static str {
        match self {
            Self::Mrclam(_) => "mrclam",
            Self::Carmen(_) => "carmen",
            Self::Thor(_) => "thor",
            Self::Rosbag(_) => "rosbag",
            Self::Landmarks(_) => "landmarks",
        }
    }

    /// The settings a landmark run of this dataset starts from (`host-sim/configs/<name>.toml`):
    /// its family's, and for a bag of one's own robot the plain landmark log's.
    pub fn landmark_settings_family(&self) -> &'static str {
        match self {
            Self::Rosbag(_) => "landmarks",
            _ => self.family(),
        }
    }
}

/// Reads the dataset named by `spec` for `robot`. An MRCLAM recording may name stress
/// variants after it (`mrclam:dataset6/robot3+8hz+turn1.4`, [`crate::inputs::stress`]).
pub fn read(spec: &DatasetSpec, robot: u8) -> Result<Recording> {
    match spec {
        DatasetSpec::Mrclam(dir) => {
            let (dir, variants) = crate::inputs::stress::split(dir)?;
            let (dir, robot) = mrclam_robot(dir, robot)?;
            let path = crate::domain::datasets::resolve("mrclam", dir)?;
            Ok(crate::inputs::stress::apply(
                mrclam::read(&path, robot)?,
                &variants,
            ))
        }
        DatasetSpec::Landmarks(file) => Ok(landmarks::read(std::path::Path::new(file))?),
        DatasetSpec::Carmen(_) | DatasetSpec::Thor(_) | DatasetSpec::Rosbag(_) => {
            bail!(
                "`{}` datasets are replayed with `--filter grid-slam`",
                spec.family()
            )
        }
    }
}

/// The MRCLAM folder and robot of `mrclam:<dir>`: a trailing `/robot<k>` (e.g.
/// `dataset6/robot3`) names the robot and overrides `robot` (the `--robot` option).
pub fn mrclam_robot(dir: &str, robot: u8) -> Result<(&str, u8)> {
    let Some((folder, last)) = dir.trim_end_matches('/').rsplit_once('/') else {
        return Ok((dir, robot));
    };
    let Some(k) = last.strip_prefix("robot") else {
        return Ok((dir, robot));
    };
    match k.parse::<u8>() {
        Ok(k) if (1..=5).contains(&k) => Ok((folder, k)),
        _ => bail!("`mrclam:{dir}`: `{last}` is not a robot; MRCLAM robots are robot1 … robot5"),
    }
}

/// Sorts events by stamp, keeping file order for equal stamps; refuses NaN stamps.
pub fn sort_events(events: &mut [Event<f64>]) -> Result<()> {
    if events.iter().any(|e| !e.stamp.is_finite()) {
        bail!("an event has a non-finite time stamp");
    }
    events.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
    Ok(())
}
