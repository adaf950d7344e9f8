//! A lidar recording read whole: a CARMEN log's front scans or a ROS 2 bag's scans, each
//! with the odometry pose at it, and the lidar's geometry and mount: what `host-sim hil`
//! streams to a firmware.

use super::DatasetSpec;
use super::carmen::{LaserMessage, read_log, resolve_log};
use super::rosbag::{self, BagOptions};
use anyhow::{Result, bail};
use microslam::sensors::lidar::LidarGeometry;
use std::path::PathBuf;

/// A lidar recording as `hil` streams it: a CARMEN log's front scans or a ROS 2 bag's
/// scans, with the odometry pose at each.
#[derive(Debug, Clone)]
pub struct LidarRecording {
    /// The file (a relations file is looked up beside it).
    pub path: PathBuf,
    /// The scans in file order.
    pub scans: Vec<LaserMessage>,
    /// The lidar's geometry and mount (a bag's from its scans and `/tf_static`, or
    /// `--lidar-mount`).
    pub lidar: LidarGeometry,
}

impl LidarRecording {
    /// Reads `spec` (`carmen:` or `rosbag:`; a bag with the topics of `bag`).
    pub fn read(spec: &DatasetSpec, bag: &BagOptions) -> Result<Self> {
        match spec {
            DatasetSpec::Carmen(file) => {
                let path = resolve_log(file)?;
                let log = read_log(&path)?;
                let scans = log.into_front_scans();
                if scans.is_empty() {
                    bail!("{}: no front laser scan to stream", path.display());
                }
                let lidar = crate::domain::grid::carmen_lidar(scans[0].ranges.len());
                Ok(Self { path, scans, lidar })
            }
            DatasetSpec::Rosbag(file) => {
                let path = resolve_log(file)?;
                let bag = rosbag::read(&path, bag)?;
                Ok(Self {
                    path,
                    scans: bag.scans,
                    lidar: bag.lidar,
                })
            }
            _ => bail!(
                "a lidar log is carmen:<file> or rosbag:<bag>, not {}",
                spec.family()
            ),
        }
    }

    /// The first `n` scans (all without `n`, all of them when it has fewer); `n` = 0 is
    /// refused: a run of no scan would use nothing it read.
    pub fn first(&self, n: Option<usize>) -> Result<Vec<&LaserMessage>> {
        if n == Some(0) {
            bail!("--scans 0: no scan of {} to stream", self.path.display());
        }
        let n = n.unwrap_or(self.scans.len()).min(self.scans.len());
        Ok(self.scans[..n].iter().collect())
    }

    /// Beams of a scan (its first; a log's scans have one length).
    pub fn beams(&self) -> usize {
        self.scans.first().map_or(0, |s| s.ranges.len())
    }
}
