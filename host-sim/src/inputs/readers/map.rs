//! A map to localize in: a ROS `map_server` map (`map.yaml` + its image) read into cells,
//! with the occupied-cell bitmap the shift search reads, as the firmware's map in flash
//! carries it.

use anyhow::{Result, anyhow, bail};
use microslam::grid::ros_map::RosMap;
use microslam::grid::{GridGeometry, GridView};
use microslam::pf::GridPfConfig;
use std::path::{Path, PathBuf};

/// A map read from a `map.yaml`, ready for [`LocalizationMap::view`].
#[derive(Clone, Debug)]
pub struct LocalizationMap {
    path: PathBuf,
    cells: Vec<i8>,
    bits: Vec<u8>,
    geometry: GridGeometry,
    occupied_above: i8,
}

impl LocalizationMap {
    /// Reads `yaml` with the log-odds model of `config` and checks that its resolution is
    /// the configured one; errors name the file.
    pub fn read(yaml: &Path, config: &GridPfConfig) -> Result<Self> {
        let map = RosMap::read(yaml, &config.log_odds)?;
        let occupied_above = config.log_odds.occupied_above;
        let bits = map.occupancy_bits(occupied_above);
        let RosMap { cells, geometry } = map;
        if (geometry.resolution - config.resolution).abs() > 1e-6 {
            bail!(
                "{}: map resolution {} differs from the configured {}",
                yaml.display(),
                geometry.resolution,
                config.resolution
            );
        }
        Ok(Self {
            path: yaml.to_path_buf(),
            cells,
            bits,
            geometry,
            occupied_above,
        })
    }

    /// The map as the localizer reads it: cells, geometry and occupied-cell bitmap.
    pub fn view(&self) -> Result<GridView<'_>> {
        GridView::new(&self.cells, self.geometry, self.occupied_above)
            .and_then(|v| v.with_occupancy_bits(&self.bits))
            .map_err(|e| anyhow!("{}: {e}", self.path.display()))
    }
}
