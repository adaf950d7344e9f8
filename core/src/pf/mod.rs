//! Grid particle filter (Du n.d.): occupancy-grid SLAM and localization with map
//! correlation and a local shift search.
//!
//! - [`ParticleFilter`]: `P` poses with log-weights and a seeded generator
//!   (Xoshiro128++, bit for bit `rand_xoshiro`'s, Gaussians from `rand_distr`, math in
//!   `f32` and through `libm`, so the same inputs and seed give the same output on every
//!   target).
//! - [`correlation`]: the observation model and the fast shift search, with its
//!   brute-force reference.
//! - [`prediction`]: the differential-drive model with noise on the inputs.
//! - [`resampling`]: stratified and systematic resampling.
//! - [`GridSlam`]: the SLAM of Du (n.d.): the best particle writes each scan into the one
//!   shared grid, which starts from the first scan.
//! - [`GridLocalizer`]: the same filter against a fixed map ([`crate::grid::GridView`],
//!   e.g. in flash); it never writes the map. It detects when it is lost and finds
//!   itself again anywhere in the map with [`global`], the exact correlative search.
//! - [`GridEstimator`]: the interface a drive loop uses for either of them.
//!
//! All settings are in [`GridPfConfig`]; [`GridPfConfig::UNTUNED`] reproduces the settings
//! of Du (n.d.) exactly.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The particle filter (prediction eq. 6, correlation eqs. 21–24,
//!   resampling eq. 25), the shared map written by the best particle, and the settings of
//!   [`GridPfConfig::UNTUNED`].

pub mod correlation;
mod estimator;
mod filter;
pub mod global;
mod localizer;
pub mod orientation;
pub mod prediction;
pub mod resampling;
mod rng;
mod slam;

pub use correlation::{ScanPoint, ScanPoints, ShiftScore};
pub use estimator::{GridEstimator, SavedMap};
pub(crate) use filter::HeadingSearch;
pub use filter::{ParticleFilter, UpdateReport};
pub use localizer::{
    GridLocalizer, LocalizerState, LocalizerStatus, LostDetection, MAX_HYPOTHESES,
    RelocalizationConfig,
};
pub use prediction::MotionNoise;
pub use resampling::Resampling;
pub use slam::{GridSlam, StepReport};
pub(crate) use slam::{score_scan as score_slam_scan, shift_search as slam_shift_search};

use crate::error::InvalidSetting;
use crate::grid::LogOdds;
use core::fmt;

/// Half-width, cells, of a localizer's shift window ([`GridPfConfig::for_localizer`]):
/// 1, a 3 × 3 window.
pub const LOCALIZER_SHIFT_WINDOW: u8 = 1;

/// Settings of the particle filter proper.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FilterConfig {
    /// Input noise of the prediction.
    pub motion_noise: MotionNoise,
    /// Half-width `k` of the shift window, cells: `(2k+1)²` shifts (Du n.d.: 4 → 9 × 9; at
    /// most [`correlation::MAX_SHIFT_WINDOW`]).
    pub shift_window_cells: u8,
    /// Log-likelihood per unit of correlation (per occupied hit of weight 1): the
    /// `weight ∝ exp(corr)` of Du (n.d., eq. 23) is 1.0. Smaller values keep more
    /// particles alive.
    pub log_likelihood_per_unit: f32,
    /// Resample when `N_eff ≤ fraction · P` (Du n.d.: 0.75).
    pub resample_neff_fraction: f32,
    /// Resampling scheme (Du n.d.: stratified).
    pub resampling: Resampling,
    /// Seed of the random number generator.
    pub seed: u64,
}

impl FilterConfig {
    /// Every setting zero (the first resampling scheme, discriminant 0): not valid, only
    /// the zero bytes of a filter in a `static` until its settings replace it.
    pub(crate) const ZEROED: Self = Self {
        motion_noise: MotionNoise {
            distance_std: 0.0,
            distance_std_per_metre: 0.0,
            distance_std_per_radian: 0.0,
            heading_std: 0.0,
            heading_std_per_radian: 0.0,
            heading_std_per_metre: 0.0,
            sideways_std_per_metre: 0.0,
        },
        shift_window_cells: 0,
        log_likelihood_per_unit: 0.0,
        resample_neff_fraction: 0.0,
        resampling: Resampling::Stratified,
        seed: 0,
    };

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range (this one's or a [`MotionNoise`] field), `None`
    /// when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        // The rule's text below names the largest window.
        const _: () = assert!(correlation::MAX_SHIFT_WINDOW == 7);
        self.motion_noise.invalid_setting().or_else(|| {
            InvalidSetting::first([
                (
                    "shift_window_cells",
                    "at most 7 (a 15 × 15 window)",
                    self.shift_window_cells <= correlation::MAX_SHIFT_WINDOW,
                ),
                InvalidSetting::non_negative(
                    "log_likelihood_per_unit",
                    self.log_likelihood_per_unit,
                ),
                InvalidSetting::fraction("resample_neff_fraction", self.resample_neff_fraction),
            ])
        })
    }
}

/// Every setting of the grid filters in one place. Particle count `P` and the largest
/// number of beams `B` are type parameters of [`GridSlam`] / [`GridLocalizer`]; the grid
/// size `W × H` is the [`crate::grid::OccupancyGrid`]'s.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GridPfConfig {
    /// Cell edge length, metres (Du n.d.: 0.05); build the grid with it.
    pub resolution: f32,
    /// Log-odds model of the grid (Du n.d.: ±log 4, thresholds ±2 log 4).
    pub log_odds: LogOdds,
    /// Use every n-th beam (1: all).
    pub beam_decimation: usize,
    /// Range weighting exponent γ of the correlation (Du n.d.: 2; 0 = plain count).
    pub range_weight_exponent: f32,
    /// The particle filter.
    pub filter: FilterConfig,
    /// Standard deviation, cells, of the Gaussian prior on each particle's shift in the
    /// SLAM update (0: none, as in Du n.d.): the shift search then maximises
    /// `log_likelihood_per_unit · corr − (dx² + dy²) / (2σ²)` instead of `corr`
    /// ([`correlation::best_shift_with_prior`]).
    pub shift_prior_std_cells: f32,
}

impl GridPfConfig {
    /// Every setting zero ([`FilterConfig::ZEROED`]): not valid, only the zero bytes of an
    /// estimator in a `static` until its settings replace it.
    pub(crate) const ZEROED: Self = Self {
        resolution: 0.0,
        log_odds: LogOdds::ZEROED,
        beam_decimation: 0,
        range_weight_exponent: 0.0,
        filter: FilterConfig::ZEROED,
        shift_prior_std_cells: 0.0,
    };

    /// The grid filter as published, before any tuning: it reproduces the settings of
    /// Du (n.d.) exactly. 0.05 m cells, ±log 4 ([`LogOdds::SYMMETRIC`]), 9 × 9 shifts,
    /// range weighting γ = 2, the untempered likelihood `weight ∝ exp(corr)`, stratified
    /// resampling at N_eff ≤ 0.75 P, input noise 0.5 × |input|
    /// ([`MotionNoise::PROPORTIONAL`]); use with P = 200. Diverges on the Intel log (see
    /// `DESIGN.md`); [`GridPfConfig::DEFAULT`] is the same structure tuned to work there.
    pub const UNTUNED: Self = Self {
        resolution: 0.05,
        log_odds: LogOdds::SYMMETRIC,
        beam_decimation: 1,
        range_weight_exponent: 2.0,
        filter: FilterConfig {
            motion_noise: MotionNoise::PROPORTIONAL,
            shift_window_cells: 4,
            log_likelihood_per_unit: 1.0,
            resample_neff_fraction: 0.75,
            resampling: Resampling::Stratified,
            seed: 0,
        },
        shift_prior_std_cells: 0.0,
    };

    /// The structure of [`GridPfConfig::UNTUNED`] (0.05 m cells, 9 × 9 shifts,
    /// N_eff ≤ 0.75 P) with the changes
    /// that make it work on real data, tuned on the Intel log with P = 200:
    /// - realistic motion noise ([`MotionNoise::INDOOR`]: floors and heading noise per
    ///   metre instead of 0.5 × |input|);
    /// - a tempered likelihood, 0.03 per unit of correlation instead of `exp(corr)`, so
    ///   the weights do not collapse onto one particle every step;
    /// - range weighting γ = 1 (γ = 2 over-trusts the few far beams of a 180-beam lidar);
    /// - free rays at −3/10 log 4 per pass instead of −log 4 (hit +log 4 unchanged): thin
    ///   walls crossed by grazing rays are no longer erased;
    /// - systematic resampling.
    pub const DEFAULT: Self = Self {
        resolution: 0.05,
        log_odds: LogOdds {
            miss: 3,
            ..LogOdds::SYMMETRIC
        },
        beam_decimation: 1,
        range_weight_exponent: 1.0,
        filter: FilterConfig {
            motion_noise: MotionNoise::INDOOR,
            shift_window_cells: 4,
            log_likelihood_per_unit: 0.03,
            resample_neff_fraction: 0.75,
            resampling: Resampling::Systematic,
            seed: 0,
        },
        shift_prior_std_cells: 0.0,
    };

    /// [`GridPfConfig::DEFAULT`] adjusted for few particles and beams (the firmware's
    /// P = 32 and 90 beams, tuned on the Intel log with every second beam): more heading
    /// noise (0.4° per step + 0.1 rad/m) so 32 particles still cover the odometry's heading
    /// drift, likelihood 0.05 per unit to make up for half the beams, resampling at
    /// N_eff ≤ 0.9 P, and a Gaussian prior of σ = 1.5 cells on each particle's shift
    /// ([`GridPfConfig::shift_prior_std_cells`]): without it the few particles slide along
    /// corridors and backwards at the map's frontier, and the map bends (Intel raw part,
    /// ATE against the GMapping-corrected poses 0.38–0.58 m without, 0.06–0.11 m with;
    /// see `docs/results-grid.md`).
    pub const MICROCONTROLLER: Self = Self {
        filter: FilterConfig {
            motion_noise: MotionNoise {
                heading_std: 0.007,
                heading_std_per_metre: 0.1,
                ..MotionNoise::INDOOR
            },
            log_likelihood_per_unit: 0.05,
            resample_neff_fraction: 0.9,
            ..Self::DEFAULT.filter
        },
        shift_prior_std_cells: 1.5,
        ..Self::DEFAULT
    };

    /// These settings for a localizer on a fixed map: the shift window narrowed to
    /// [`LOCALIZER_SHIFT_WINDOW`] (3 × 3), everything else unchanged. Grid SLAM needs the
    /// 9 × 9 window while its map is young; a localizer on a finished map needs its
    /// window only to pull each particle onto the walls it predicts, a cell or two away,
    /// scan after scan. On the Intel log, on the map of a host SLAM run, the relation
    /// error is the same with 3 × 3, 5 × 5 and 9 × 9 (P = 64, 90 beams, `MICROCONTROLLER`,
    /// filter seeds 0–4: 0.027–0.029 m, 0.027–0.028 m, 0.027–0.030 m), also with a third
    /// of the scans, with the odometry's distances 10 % too long, with 200 particles and
    /// on the simulator's office; no shift at all loses the robot. On the Cortex-M4F the
    /// step costs less than half as much as with 9 × 9 (`docs/firmware-localizer.md`).
    /// Right after a global relocalization the localizer widens the window for a few
    /// scans ([`RelocalizationConfig::pull_in_window_cells`]).
    ///
    /// ```
    /// use microslam::pf::{GridPfConfig, LOCALIZER_SHIFT_WINDOW};
    ///
    /// let c = GridPfConfig::MICROCONTROLLER.for_localizer();
    /// assert_eq!(c.filter.shift_window_cells, LOCALIZER_SHIFT_WINDOW);
    /// assert_eq!(c.filter.motion_noise, GridPfConfig::MICROCONTROLLER.filter.motion_noise);
    /// ```
    pub const fn for_localizer(self) -> Self {
        let mut c = self;
        c.filter.shift_window_cells = LOCALIZER_SHIFT_WINDOW;
        c
    }

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range — this one's, or a field of [`LogOdds`],
    /// [`FilterConfig`] or [`MotionNoise`], named as `host-sim`'s settings files name it —
    /// `None` when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let own = |checks| InvalidSetting::first(checks);
        own([InvalidSetting::positive("resolution", self.resolution)])
            .or_else(|| self.log_odds.invalid_setting())
            .or_else(|| {
                own([InvalidSetting::non_negative(
                    "range_weight_exponent",
                    self.range_weight_exponent,
                )])
            })
            .or_else(|| self.filter.invalid_setting())
            .or_else(|| {
                own([InvalidSetting::non_negative(
                    "shift_prior_std_cells",
                    self.shift_prior_std_cells,
                )])
            })
    }

    /// Loads the usable beams of `scan` into `points` with these settings' decimation
    /// and range weighting: the first step of every grid filter's `observe`. Refuses an
    /// invalid geometry and a scan with no usable beam.
    pub(crate) fn load_scan<const B: usize>(
        &self,
        points: &mut correlation::ScanPoints<B>,
        scan: &crate::sensors::lidar::LidarScan<'_>,
    ) -> Result<usize, PfError> {
        if !scan.geometry.is_valid() {
            return Err(PfError::InvalidScan);
        }
        match points.load(scan, self.beam_decimation, self.range_weight_exponent) {
            0 => Err(PfError::EmptyScan),
            beams => Ok(beams),
        }
    }

    /// The shift prior as a penalty in correlation units (fixed point) per cell² (0:
    /// none): `1 / (2σ² · log_likelihood_per_unit)` units of 1.0.
    pub fn shift_penalty(&self) -> f32 {
        let s = self.shift_prior_std_cells;
        let l = self.filter.log_likelihood_per_unit;
        if s > 0.0 && l > 0.0 {
            correlation::WEIGHT_ONE as f32 / (2.0 * s * s * l)
        } else {
            0.0
        }
    }
}

impl Default for GridPfConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a particle-filter step was refused. The filter is unchanged when one is returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PfError {
    /// A setting is out of range or not finite.
    InvalidConfig,
    /// `P = 0`.
    NoParticles,
    /// An input (odometry, pose) is NaN or ±∞.
    NonFiniteInput,
    /// A velocity step with a negative duration.
    NegativeTimeStep,
    /// The scan has no usable beam: nothing to score (the map is not written either).
    EmptyScan,
    /// The scan geometry is invalid (ranges limits, angles, mount pose).
    InvalidScan,
    /// The map's geometry differs from the configuration (resolution).
    MapMismatch,
    /// A building-scale SLAM's keyframe store, pose graph or local map refused the step
    /// (the [`crate::slam::SlamError`] is kept by [`crate::slam::WithKeyframes`]); the
    /// scan may have been scored.
    Slam,
}

impl fmt::Display for PfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::InvalidConfig => "particle filter setting out of range",
            Self::NoParticles => "particle filter has no particles",
            Self::NonFiniteInput => "input contains NaN or infinity",
            Self::NegativeTimeStep => "negative time step",
            Self::EmptyScan => "scan has no usable beam",
            Self::InvalidScan => "scan geometry is invalid",
            Self::MapMismatch => "map geometry does not match the configuration",
            Self::Slam => "keyframe store, pose graph or local map refused the step",
        })
    }
}

impl core::error::Error for PfError {}

#[cfg(test)]
mod relocalization_tests;
#[cfg(test)]
mod tests;
