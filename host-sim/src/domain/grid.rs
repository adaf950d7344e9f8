//! Settings of the grid particle filter on the host: the TOML overrides of
//! [`GridPfConfig`], the particle counts and beam capacity compiled in, and the lidar
//! geometry of CARMEN logs.

use anyhow::{Context, Result, bail};
use microslam::pf::{GridPfConfig, MotionNoise};
use microslam::sensors::lidar::LidarGeometry;
use std::path::Path;

/// Grid edge in cells on the host: 1024 × 1024 cells (51.2 m at 5 cm), 1 MB.
pub const GRID_CELLS: usize = 1024;
/// Most beams a scan may use (the Intel/ACES SICK has 180; more are decimated).
pub const MAX_BEAMS: usize = 361;

/// Settings of a grid run besides [`GridPfConfig`].
#[derive(Clone, Debug)]
pub struct GridRunOptions {
    /// Particles (one of [`SUPPORTED_PARTICLES`]).
    pub particles: usize,
    /// Filter settings.
    pub config: GridPfConfig,
    /// Lidar geometry of the log.
    pub lidar: LidarGeometry,
}

/// Particle counts compiled in (the count is a type parameter of the filter).
pub const SUPPORTED_PARTICLES: [usize; 8] = [8, 16, 32, 64, 100, 128, 200, 400];

/// Optional TOML overrides of the grid filter (`--config FILE`), every key optional:
/// `resolution`, `hit`, `miss`, `occupied_above`, `range_weight_exponent`,
/// `log_likelihood_per_unit`, `resample_neff_fraction`, `seed`, `shift_window_cells`,
/// `beam_decimation`, and the [`MotionNoise`] fields.
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridToml {
    resolution: Option<f32>,
    hit: Option<i8>,
    miss: Option<i8>,
    occupied_above: Option<i8>,
    range_weight_exponent: Option<f32>,
    log_likelihood_per_unit: Option<f32>,
    resample_neff_fraction: Option<f32>,
    seed: Option<u64>,
    shift_window_cells: Option<u8>,
    beam_decimation: Option<usize>,
    distance_std: Option<f32>,
    distance_std_per_metre: Option<f32>,
    heading_std: Option<f32>,
    heading_std_per_radian: Option<f32>,
    heading_std_per_metre: Option<f32>,
    sideways_std_per_metre: Option<f32>,
    /// `"seed"` starts from [`GridPfConfig::SEED`], `"microcontroller"` from
    /// [`GridPfConfig::MICROCONTROLLER`], otherwise [`GridPfConfig::DEFAULT`].
    base: Option<String>,
}

impl GridToml {
    /// Reads a TOML file.
    pub fn read(path: &Path) -> Result<Self> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        toml::from_str(&text).with_context(|| format!("parsing {}", path.display()))
    }

    /// The configuration these overrides give.
    pub fn apply(&self) -> Result<GridPfConfig> {
        let mut c = match self.base.as_deref() {
            None | Some("default") => GridPfConfig::DEFAULT,
            Some("seed") => GridPfConfig::SEED,
            Some("microcontroller") => GridPfConfig::MICROCONTROLLER,
            Some(other) => bail!("unknown base config `{other}` (default, seed, microcontroller)"),
        };
        let n: &mut MotionNoise = &mut c.filter.motion_noise;
        macro_rules! set {
            ($($field:ident => $target:expr),* $(,)?) => {$(if let Some(v) = self.$field { $target = v; })*};
        }
        set!(distance_std => n.distance_std, distance_std_per_metre => n.distance_std_per_metre,
            heading_std => n.heading_std, heading_std_per_radian => n.heading_std_per_radian,
            heading_std_per_metre => n.heading_std_per_metre, sideways_std_per_metre => n.sideways_std_per_metre);
        set!(resolution => c.resolution, hit => c.log_odds.hit, miss => c.log_odds.miss,
            occupied_above => c.log_odds.occupied_above, range_weight_exponent => c.range_weight_exponent,
            log_likelihood_per_unit => c.filter.log_likelihood_per_unit,
            resample_neff_fraction => c.filter.resample_neff_fraction, seed => c.filter.seed,
            shift_window_cells => c.filter.shift_window_cells, beam_decimation => c.beam_decimation);
        if !c.is_valid() {
            bail!("grid filter settings out of range: {c:?}");
        }
        Ok(c)
    }
}

/// The lidar geometry of a CARMEN log's front laser: `n` beams over 180° from −90°
/// (Intel, ACES: 180 × 1°), no return at ≥ 81.8 m.
pub fn carmen_lidar(beams: usize) -> LidarGeometry {
    LidarGeometry {
        angle_increment: core::f32::consts::PI / beams.max(1) as f32,
        ..LidarGeometry::CARMEN_SICK_180
    }
}

/// `beams` wanted → decimation of an `n`-beam scan.
pub fn decimation_for(n: usize, beams: Option<usize>) -> usize {
    match beams {
        Some(b) if b > 0 => n.div_ceil(b).max(1),
        _ => 1,
    }
}

/// Options of the grid particle filter shared by `replay` and `localize`.
#[derive(Debug, Clone, Default)]
pub struct GridOptions {
    /// Particles (one of [`SUPPORTED_PARTICLES`]).
    pub particles: usize,
    /// Half-width k of the (2k+1)² shift window, cells (default 4: 9 × 9).
    pub window: Option<u8>,
    /// Beams used per scan (decimated from the log's; default all).
    pub beams: Option<usize>,
    /// Benchmark relations file (default: a `*.relations` file next to the log).
    pub relations: Option<std::path::PathBuf>,
}
