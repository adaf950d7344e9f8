//! A map to localize in: a ROS `map_server` map (`map.yaml` + its image) read into cells,
//! with the occupied-cell bitmap the shift search reads, as the firmware's map in flash
//! carries it; or a map image (`map.bin`, `microslam::grid::map_image`: what
//! `host-sim export-map` writes and the board draws at the end of a SLAM run), read as
//! the firmware reads it.

use anyhow::{Result, anyhow, bail};
use microslam::grid::map_image::{MAP_IMAGE_MAGIC, MapImage};
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
    /// The bytes of a map image (then `cells` and `bits` are empty).
    image: Option<Vec<u8>>,
}

impl LocalizationMap {
    /// Reads `yaml` (or a map image: a file that starts with `MSMP`) with the log-odds
    /// model of `config` and checks that its resolution is the configured one (and an
    /// image's occupied threshold the configured one); errors name the file.
    pub fn read(yaml: &Path, config: &GridPfConfig) -> Result<Self> {
        let bytes = std::fs::read(yaml).map_err(|e| anyhow!("{}: {e}", yaml.display()))?;
        if bytes.starts_with(&MAP_IMAGE_MAGIC) {
            return Self::from_image(yaml, bytes, config);
        }
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
            image: None,
        })
    }

    /// A map image's bytes, checked as the firmware checks them.
    fn from_image(path: &Path, bytes: Vec<u8>, config: &GridPfConfig) -> Result<Self> {
        let image = MapImage::parse(&bytes).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        let geometry = *image.geometry();
        let occupied_above = image.view().occupied_above();
        if (geometry.resolution - config.resolution).abs() > 1e-6 {
            bail!(
                "{}: map resolution {} differs from the configured {}",
                path.display(),
                geometry.resolution,
                config.resolution
            );
        }
        if occupied_above != config.log_odds.occupied_above {
            bail!(
                "{}: the image's occupied threshold {occupied_above} differs from the \
                 configured log-odds model's {}",
                path.display(),
                config.log_odds.occupied_above
            );
        }
        Ok(Self {
            path: path.to_path_buf(),
            cells: Vec::new(),
            bits: Vec::new(),
            geometry,
            occupied_above,
            image: Some(bytes),
        })
    }

    /// The map as the localizer reads it: cells, geometry and occupied-cell bitmap.
    pub fn view(&self) -> Result<GridView<'_>> {
        if let Some(bytes) = &self.image {
            return MapImage::parse(bytes)
                .map(|image| image.view())
                .map_err(|e| anyhow!("{}: {e}", self.path.display()));
        }
        GridView::new(&self.cells, self.geometry, self.occupied_above)
            .and_then(|v| v.with_occupancy_bits(&self.bits))
            .map_err(|e| anyhow!("{}: {e}", self.path.display()))
    }
}
