//! Localization against a fixed map: the grid filter without map writes, with lost
//! detection and global relocalization ([`super::global`]).
//!
//! **Lost detection.** After every scan the localizer computes the *hit fraction*: the
//! best particle's correlation divided by the total weight of the scan's beams (1.0: every
//! beam ends in an occupied cell). While tracking it keeps a running mean of it, the
//! *expected* hit fraction of this map and lidar. A scan whose hit fraction is below
//! [`LostDetection::ratio`] × expected is *low*; [`LostDetection::scans`] consecutive low
//! scans declare the robot lost ([`LocalizerState::Lost`]).
//!
//! **Relocalization.** With max-pooled layers of the map
//! ([`GridLocalizer::with_layers`]), a lost robot (automatically, or on
//! [`GridLocalizer::relocalize`], or from the start with
//! [`GridLocalizer::without_pose`]) starts the global search on its next scan — one node
//! budget a scan, on that scan, for up to [`RelocalizationConfig::search_scans`] scans,
//! the particles waiting meanwhile — then spreads the particles over the best hypotheses,
//! moved by the odometry since the search's scan, and goes on filtering from there
//! ([`LocalizerState::Relocalized`]); [`LostDetection::confirm_scans`] scans that are not
//! low make it [`LocalizerState::Tracking`] again. [`GridLocalizer::status`] reports the
//! state and counters for the estimates.

use super::correlation::{
    ScanPoints, search_window, search_window_packed, search_window_sparse_rows,
};
use super::filter::ShiftSearch;
use super::global::{
    GlobalError, GlobalSearch, GlobalSearchConfig, Hypotheses, Hypothesis, SearchReport,
};
use super::orientation::DirectionHistogram;
use super::prediction::{arc_between, drive_arc};
use super::{GridPfConfig, LOCALIZER_SHIFT_WINDOW, ParticleFilter, PfError, StepReport};
use crate::error::InvalidSetting;
use crate::geometry::Pose2;
use crate::grid::{GridView, MaxPoolLayers, ScanIntegration};
use crate::sensors::lidar::LidarScan;

/// Most hypotheses the localizer seeds its particles around.
pub const MAX_HYPOTHESES: usize = 8;

/// Where the localizer stands.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LocalizerState {
    /// The scans fit the map at the estimate.
    #[default]
    Tracking,
    /// The scans stopped fitting (or no pose was ever given, or a relocalization was
    /// asked for): the estimate is not to be trusted. With layers, the next scan starts the
    /// global search (which may span scans).
    Lost,
    /// The particles were seeded from a global search; not yet confirmed by
    /// [`LostDetection::confirm_scans`] good scans.
    Relocalized,
}

/// When the localizer declares itself lost.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LostDetection {
    /// A scan is low when its hit fraction is below `ratio` × the expected one (0..1).
    pub ratio: f32,
    /// Consecutive low scans that declare the robot lost (0: never).
    pub scans: u8,
    /// Expected hit fraction before the first tracked scans have measured it (0..1].
    pub initial_expected: f32,
    /// Weight of each tracked scan in the running expected hit fraction (0..1].
    pub learning_rate: f32,
    /// Consecutive scans that are not low after which a relocalized (or lost) localizer
    /// is tracking again.
    pub confirm_scans: u8,
}

impl LostDetection {
    /// Settings measured on the Intel log and the simulator's office (see
    /// `docs/global-localization.md`).
    pub const DEFAULT: Self = Self {
        ratio: 0.5,
        scans: 5,
        initial_expected: 0.7,
        learning_rate: 0.05,
        confirm_scans: 5,
    };

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range (the field's name and its rule), `None` when every
    /// one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        InvalidSetting::first([
            InvalidSetting::fraction("ratio", self.ratio),
            InvalidSetting::positive_fraction("initial_expected", self.initial_expected),
            InvalidSetting::positive_fraction("learning_rate", self.learning_rate),
        ])
    }
}

/// Settings of lost detection and relocalization.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RelocalizationConfig {
    /// The global search.
    pub search: GlobalSearchConfig,
    /// When the robot is lost.
    pub lost: LostDetection,
    /// Search by itself when lost (otherwise only on [`GridLocalizer::relocalize`]).
    pub automatic: bool,
    /// Hypotheses the particles are spread over (1..=[`MAX_HYPOTHESES`]).
    pub hypotheses: u8,
    /// Position spread of the particles around each hypothesis, metres (0: one cell).
    pub spread_m: f32,
    /// Heading spread around each hypothesis, radians (0: the search's heading step).
    pub spread_rad: f32,
    /// Scans one global search may span (≥ 1): each scan runs
    /// [`GlobalSearchConfig::work_budget`] more work of the same search (on the scan it
    /// started with) until it is over or has run this many; the hypotheses are then
    /// moved by the odometry since that scan. Bounds the instructions per scan by one
    /// work budget while giving the search several (a microcontroller cannot spend a
    /// whole search between two scans).
    pub search_scans: u8,
    /// Half-width, cells, of the shift window while the localizer is
    /// [`LocalizerState::Relocalized`] (until [`LostDetection::confirm_scans`] good
    /// scans): the particles of a hypothesis, which is only as good as the search's cell
    /// and heading step, are pulled onto the walls from further than the tracking window
    /// ([`GridPfConfig::for_localizer`]) reaches. 0: the tracking window throughout.
    pub pull_in_window_cells: u8,
}

impl RelocalizationConfig {
    /// Automatic relocalization with [`GlobalSearchConfig::DEFAULT`] and
    /// [`LostDetection::DEFAULT`], particles over the 4 best hypotheses, a search
    /// spanning up to 10 scans (see `docs/global-localization.md` for how that was chosen).
    pub const DEFAULT: Self = Self {
        search: GlobalSearchConfig::DEFAULT,
        lost: LostDetection::DEFAULT,
        automatic: true,
        hypotheses: 4,
        spread_m: 0.0,
        spread_rad: 0.0,
        search_scans: 10,
        pull_in_window_cells: 4,
    };

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range — this one's, or a field of its
    /// [`GlobalSearchConfig`] or [`LostDetection`] — `None` when every one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        // The rules' texts below name these limits.
        const _: () = assert!(MAX_HYPOTHESES == 8 && super::correlation::MAX_SHIFT_WINDOW == 7);
        self.search
            .invalid_setting()
            .or_else(|| self.lost.invalid_setting())
            .or_else(|| {
                InvalidSetting::first([
                    (
                        "hypotheses",
                        "within 1 ..= 8",
                        (1..=MAX_HYPOTHESES).contains(&usize::from(self.hypotheses)),
                    ),
                    InvalidSetting::non_negative("spread_m", self.spread_m),
                    InvalidSetting::non_negative("spread_rad", self.spread_rad),
                    ("search_scans", "1 or more", self.search_scans >= 1),
                    (
                        "pull_in_window_cells",
                        "at most 7",
                        self.pull_in_window_cells <= super::correlation::MAX_SHIFT_WINDOW,
                    ),
                ])
            })
    }
}

impl Default for RelocalizationConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// State and counters of lost detection and relocalization (for the estimates).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LocalizerStatus {
    /// Tracking, lost or relocalized.
    pub state: LocalizerState,
    /// Hit fraction of the last scan (best particle's correlation / total beam weight).
    pub hit_fraction: f32,
    /// Running expected hit fraction while tracking.
    pub expected_hit_fraction: f32,
    /// Consecutive low scans so far.
    pub low_scans: u8,
    /// Consecutive scans that were not low.
    pub good_scans: u8,
    /// Times the localizer declared itself lost.
    pub lost_events: u32,
    /// Global searches that seeded the particles.
    pub relocalizations: u32,
    /// Global searches that did not seed the particles: no hypothesis above the minimum
    /// score, or a search that could not start or go on (e.g. a scan with no beam within
    /// the search's range). The localizer stays lost and searches again on the next scan.
    pub failed_searches: u32,
    /// `true` when the next scan runs the global search (starts it, or runs its next slice
    /// when it spans scans).
    pub search_pending: bool,
    /// The last global search, if any.
    pub last_search: Option<SearchReport>,
}

impl LocalizerStatus {
    const fn new(state: LocalizerState, expected: f32) -> Self {
        Self {
            state,
            hit_fraction: 0.0,
            expected_hit_fraction: expected,
            low_scans: 0,
            good_scans: 0,
            lost_events: 0,
            relocalizations: 0,
            failed_searches: 0,
            search_pending: false,
            last_search: None,
        }
    }
}

/// Localizer with `P` particles and at most `B` beams per scan on a borrowed map (owned
/// grid's [`crate::grid::OccupancyGrid::view`] or a `&'static` map in flash).
///
/// On a microcontroller give the map its occupied-cell bitmap
/// ([`GridView::with_occupancy_bits`], computed once with
/// [`crate::grid::fill_occupancy_bits`] into a RAM buffer of
/// [`crate::grid::occupancy_bytes`] bytes, or kept in flash next to the map): the shift
/// search is then the sparse one, a third of the instructions for the same scores.
///
/// For global localization give it the map's max-pooled layers
/// ([`GridLocalizer::with_layers`]; see the module documentation).
///
/// RAM: `28·P + 24·B` bytes plus ~6 000 (lost detection, relocalization, the map's wall
/// directions, a global search spanning scans: 4 656); the map and its layers are not
/// copied. A scan that runs the global search adds ≈ 3.5 KB of stack.
///
/// ```
/// use core::f32::consts::PI;
/// use microslam::geometry::Pose2;
/// use microslam::grid::{GridGeometry, GridView};
/// use microslam::pf::{GridLocalizer, GridPfConfig};
/// use microslam::sensors::lidar::{LidarGeometry, LidarScan};
///
/// // A map of 64 × 64 cells of 5 cm (e.g. a `static` array in flash, or a SLAM run's
/// // `OccupancyGrid::cells`): a round wall of radius 1.5 m around the origin.
/// let geometry = GridGeometry::centred(64, 64, 0.05);
/// let mut cells = [0_i8; 64 * 64];
/// for (i, cell) in cells.iter_mut().enumerate() {
///     let (x, y) = geometry.cell_centre((i % 64) as i32, (i / 64) as i32);
///     if ((x * x + y * y).sqrt() - 1.5).abs() < 0.04 {
///         *cell = 100;
///     }
/// }
/// let config = GridPfConfig::MICROCONTROLLER;
/// let map = GridView::new(&cells, geometry, config.log_odds.occupied_above)?;
///
/// // Told the robot is 10 cm off the centre; it is at the centre.
/// let mut localizer = GridLocalizer::<32, 90>::new(map, config, Pose2::new(0.1, 0.0, 0.0))?;
/// let lidar = LidarGeometry {
///     first_angle: -PI,
///     angle_increment: 2.0 * PI / 90.0,
///     min_range: 0.1,
///     max_range: 8.0,
///     no_return_range: f32::INFINITY,
///     mount: Pose2::new(0.0, 0.0, 0.0),
/// };
/// let report = localizer.observe(&LidarScan::new(&[1.5_f32; 90], lidar))?;
/// assert!(report.pose.x.abs() < 0.05 && report.pose.y.abs() < 0.05);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
pub struct GridLocalizer<'m, const P: usize, const B: usize> {
    map: GridView<'m>,
    filter: ParticleFilter<P>,
    points: ScanPoints<B>,
    config: GridPfConfig,
    pose: Pose2<f32>,
    layers: Option<MaxPoolLayers<'m>>,
    /// The map's wall directions, made with the layers (the search's heading prior).
    walls: DirectionHistogram,
    relocalization: RelocalizationConfig,
    status: LocalizerStatus,
    hypotheses: Hypotheses<MAX_HYPOTHESES>,
    /// The shift search: the general one, or the one for the map's row length
    /// ([`GridLocalizer::with_bitmap_row_bytes`]).
    search: ShiftSearch,
    /// The same for the pull-in window after a relocalization
    /// ([`RelocalizationConfig::pull_in_window_cells`]).
    pull_in_search: ShiftSearch,
    /// The global search under way when it spans scans
    /// ([`RelocalizationConfig::search_scans`]).
    relocalizing: Option<Relocalizing>,
}

/// A global search spanning scans: the search, the scans it has run on, and the robot's
/// motion since its scan (odometry without noise, in the frame of the robot then).
struct Relocalizing {
    search: GlobalSearch<MAX_HYPOTHESES>,
    scans: u8,
    moved: Pose2<f32>,
}

impl<'m, const P: usize, const B: usize> GridLocalizer<'m, P, B> {
    /// A localizer on `map` with all particles at `start` (see
    /// [`GridLocalizer::reset_around`] for an uncertain start).
    pub fn new(
        map: GridView<'m>,
        config: GridPfConfig,
        start: Pose2<f32>,
    ) -> Result<Self, PfError> {
        if !config.is_valid() {
            return Err(PfError::InvalidConfig);
        }
        let relocalization = RelocalizationConfig::DEFAULT;
        Ok(Self {
            map,
            filter: ParticleFilter::new(config.filter, start)?,
            points: ScanPoints::new(),
            config,
            pose: start,
            layers: None,
            walls: DirectionHistogram::new(),
            relocalization,
            status: LocalizerStatus::new(
                LocalizerState::Tracking,
                relocalization.lost.initial_expected,
            ),
            hypotheses: Hypotheses::new(),
            search: search_window,
            pull_in_search: search_window,
            relocalizing: None,
        })
    }

    /// The same localizer with the shift search for a map whose occupied-cell bitmap has
    /// `S` bytes a row (`⌈width / 8⌉`), for a map whose size is known when the program is
    /// built (a map in flash): [`search_window_sparse_rows`] for a 9 × 9 window,
    /// [`search_window_packed`] for the localizer's 3 × 3
    /// ([`GridPfConfig::for_localizer`]), the same estimates in fewer instructions (per
    /// step on the Cortex-M4F a fifth fewer on a room's thin walls, a tenth on a
    /// building's map, where the occupied cells dominate). Refused with
    /// [`PfError::MapMismatch`] when the map has no bitmap or rows of another length.
    ///
    /// ```
    /// use microslam::geometry::Pose2;
    /// use microslam::grid::{GridGeometry, GridView, fill_occupancy_bits, occupancy_bytes};
    /// use microslam::pf::{GridLocalizer, GridPfConfig, PfError};
    ///
    /// // 256 × 64 cells: bitmap rows of 32 bytes.
    /// let geometry = GridGeometry::centred(256, 64, 0.05);
    /// let cells = [0_i8; 256 * 64];
    /// let mut bits = [0_u8; occupancy_bytes(256, 64)];
    /// let config = GridPfConfig::MICROCONTROLLER;
    /// fill_occupancy_bits(&cells, 256, 64, config.log_odds.occupied_above, &mut bits)?;
    /// let map = GridView::new(&cells, geometry, config.log_odds.occupied_above)?
    ///     .with_occupancy_bits(&bits)?;
    /// let start = Pose2::new(0.0, 0.0, 0.0);
    /// let localizer = GridLocalizer::<32, 90>::new(map, config, start)?;
    /// let localizer = localizer.with_bitmap_row_bytes::<32>()?;
    /// let other = GridLocalizer::<32, 90>::new(map, config, start)?;
    /// assert_eq!(other.with_bitmap_row_bytes::<64>().err(), Some(PfError::MapMismatch));
    /// # Ok::<(), Box<dyn core::error::Error>>(())
    /// ```
    pub fn with_bitmap_row_bytes<const S: usize>(mut self) -> Result<Self, PfError> {
        let rows_fit = self.map.geometry().width.div_ceil(8) == S;
        if self.map.occupancy_bits().is_none() || !rows_fit {
            return Err(PfError::MapMismatch);
        }
        // The window of the settings gets its copy: 3 × 3 (`GridPfConfig::for_localizer`)
        // or 9 × 9 (the presets'); another size takes the general path in either.
        self.search = if self.config.filter.shift_window_cells == LOCALIZER_SHIFT_WINDOW {
            search_window_packed::<{ 2 * LOCALIZER_SHIFT_WINDOW as usize + 1 }, S>
        } else {
            search_window_sparse_rows::<S>
        };
        self.pull_in_search = search_window_sparse_rows::<S>;
        Ok(self)
    }

    /// A localizer that knows no pose: it is [`LocalizerState::Lost`] and its first scan
    /// starts the global search over `layers` (made from `map`).
    pub fn without_pose(
        map: GridView<'m>,
        config: GridPfConfig,
        layers: MaxPoolLayers<'m>,
        relocalization: RelocalizationConfig,
    ) -> Result<Self, GlobalError> {
        let (cx, cy) = map.geometry().cell_centre(
            map.geometry().width as i32 / 2,
            map.geometry().height as i32 / 2,
        );
        let mut loc = Self::new(map, config, Pose2::new(cx, cy, 0.0))
            .map_err(|_| GlobalError::InvalidConfig)?
            .with_layers(layers, relocalization)?;
        loc.status.state = LocalizerState::Lost;
        loc.status.search_pending = true;
        Ok(loc)
    }

    /// The same localizer able to search globally: `layers` are the max-pooled layers of
    /// its map ([`MaxPoolLayers::build`] or [`MaxPoolLayers::from_bytes`]), refused when
    /// made for another map.
    pub fn with_layers(
        mut self,
        layers: MaxPoolLayers<'m>,
        relocalization: RelocalizationConfig,
    ) -> Result<Self, GlobalError> {
        if !relocalization.is_valid() {
            return Err(GlobalError::InvalidConfig);
        }
        if !layers.matches(&self.map) {
            return Err(GlobalError::LayersMismatch);
        }
        self.layers = Some(layers);
        self.walls = DirectionHistogram::of_map(&self.map);
        self.set_relocalization(relocalization)?;
        Ok(self)
    }

    /// Changes the lost-detection and relocalization settings (the running expected hit
    /// fraction is kept; a global search under way starts again on the next scan).
    pub fn set_relocalization(
        &mut self,
        relocalization: RelocalizationConfig,
    ) -> Result<(), GlobalError> {
        if !relocalization.is_valid() {
            return Err(GlobalError::InvalidConfig);
        }
        self.relocalization = relocalization;
        self.relocalizing = None;
        Ok(())
    }

    /// Asks for a global relocalization (e.g. after the robot was carried): the state
    /// becomes [`LocalizerState::Lost`] and the next scan runs the global search (a
    /// search under way starts again).
    /// Refused with [`GlobalError::NoLayers`] when the localizer has no layers.
    pub fn relocalize(&mut self) -> Result<(), GlobalError> {
        if self.layers.is_none() {
            return Err(GlobalError::NoLayers);
        }
        self.status.state = LocalizerState::Lost;
        self.status.search_pending = true;
        self.status.low_scans = 0;
        self.status.good_scans = 0;
        self.relocalizing = None;
        Ok(())
    }

    /// State and counters of lost detection and relocalization.
    pub fn status(&self) -> &LocalizerStatus {
        &self.status
    }

    /// Scans the global search under way has run so far (one slice each,
    /// [`RelocalizationConfig::search_scans`] at most); 0 when no search is under way —
    /// with [`LocalizerStatus::search_pending`] set, a search then starts on the next scan.
    pub fn search_scans_run(&self) -> u8 {
        self.relocalizing.as_ref().map_or(0, |run| run.scans)
    }

    /// Tracking, lost or relocalized.
    pub fn state(&self) -> LocalizerState {
        self.status.state
    }

    /// The hypotheses of the last global search, best first (moved by the odometry since
    /// its scan when it spanned scans).
    pub fn hypotheses(&self) -> &[Hypothesis] {
        self.hypotheses.as_slice()
    }

    /// The max-pooled layers, when the localizer has them.
    pub fn layers(&self) -> Option<&MaxPoolLayers<'m>> {
        self.layers.as_ref()
    }

    /// Spreads the particles around `pose` (Gaussian, `std_xy` m, `std_theta` rad): the
    /// pose is given, so the localizer is [`LocalizerState::Tracking`] and no global
    /// search is pending (a lost or relocalizing state is cleared; the counters stay).
    pub fn reset_around(
        &mut self,
        pose: Pose2<f32>,
        std_xy: f32,
        std_theta: f32,
    ) -> Result<(), PfError> {
        self.filter.reset_around(pose, std_xy, std_theta)?;
        self.pose = pose;
        self.relocalizing = None;
        let s = &mut self.status;
        s.state = LocalizerState::Tracking;
        s.search_pending = false;
        s.low_scans = 0;
        s.good_scans = 0;
        Ok(())
    }

    /// The estimate (heaviest particle after the last scan).
    pub fn pose(&self) -> Pose2<f32> {
        self.pose
    }

    /// The particles.
    pub fn filter(&self) -> &ParticleFilter<P> {
        &self.filter
    }

    /// The map.
    pub fn map(&self) -> &GridView<'m> {
        &self.map
    }

    /// Prediction with the arc `(distance, heading_change)`.
    pub fn predict(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
        self.filter.predict(distance, heading_change)?;
        self.track_motion(distance, heading_change);
        Ok(())
    }

    /// Prediction with `(v, ω)` held for `dt` seconds.
    pub fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        self.filter.predict_velocity(v, omega, dt)?;
        if dt > 0.0 {
            self.track_motion(v * dt, omega * dt);
        }
        Ok(())
    }

    /// Prediction with odometry poses before and after the step.
    pub fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
        self.filter.predict_odometry(from, to)?;
        let (d, t) = arc_between(from, to);
        self.track_motion(d, t);
        Ok(())
    }

    /// While a global search spans scans, the robot's motion since its scan.
    fn track_motion(&mut self, distance: f32, heading_change: f32) {
        if let Some(run) = self.relocalizing.as_mut() {
            let moved = drive_arc(&run.moved, distance, heading_change, 0.0);
            if moved.is_finite() {
                run.moved = moved;
            }
        }
    }

    /// Scores the scan against the map, shifts, reweights and resamples; before that, when
    /// a search is pending (lost, [`GridLocalizer::relocalize`], no pose), runs the global
    /// search (starts it on this scan, or runs its next slice) and, once it is over,
    /// spreads the particles over its hypotheses. Then updates the lost detection
    /// ([`GridLocalizer::status`]). While a search spanning scans goes on, the scan is not
    /// filtered: the report carries the last estimate and a score of 0.
    pub fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError> {
        let beams = self.config.load_scan(&mut self.points, scan)?;
        if self.status.search_pending && !self.search_and_seed() {
            // The search goes on with the next scan: the particles wait for it.
            return Ok(StepReport {
                pose: self.pose,
                n_eff: self.filter.n_eff(),
                resampled: false,
                beams,
                score: 0,
                map: ScanIntegration::default(),
            });
        }
        // Right after a relocalization the wider pull-in window, then the tracking one.
        let pull_in = self.relocalization.pull_in_window_cells;
        let (search, k) = if self.status.state == LocalizerState::Relocalized && pull_in > 0 {
            (self.pull_in_search, pull_in)
        } else {
            (self.search, self.config.filter.shift_window_cells)
        };
        let u =
            self.filter
                .update_in_window(&self.map, self.points.as_slice(), (search, 0.0), k)?;
        self.pose = u.best_pose;
        self.track_score(u.best_shift.score);
        Ok(StepReport {
            pose: u.best_pose,
            n_eff: u.n_eff,
            resampled: u.resampled,
            beams,
            score: u.best_shift.score,
            map: ScanIntegration::default(),
        })
    }
}

impl<const P: usize, const B: usize> GridLocalizer<'_, P, B> {
    /// Runs the global search on the loaded points, or its next slice when it spans scans
    /// ([`RelocalizationConfig::search_scans`]); when it is over and found hypotheses,
    /// spreads the particles over them (moved by the odometry since the search's scan).
    /// `false` while the search goes on: the scan is then not filtered.
    fn search_and_seed(&mut self) -> bool {
        let Some(layers) = self.layers else {
            self.status.search_pending = false;
            return true;
        };
        let r = self.relocalization;
        let run = match self.relocalizing.take() {
            Some(run) => Ok(run),
            None => GlobalSearch::start(
                &self.map,
                &layers,
                Some(&self.walls),
                self.points.as_slice(),
                &r.search,
            )
            .map(|search| Relocalizing {
                search,
                scans: 0,
                moved: Pose2::new(0.0, 0.0, 0.0),
            }),
        };
        let mut run = match run {
            Ok(run) => run,
            Err(_) => {
                self.status.failed_searches = self.status.failed_searches.wrapping_add(1);
                return true;
            }
        };
        if run
            .search
            .resume(&self.map, &layers, r.search.work_budget)
            .is_err()
        {
            self.status.failed_searches = self.status.failed_searches.wrapping_add(1);
            return true;
        }
        run.scans = run.scans.saturating_add(1);
        if !run.search.is_done() && run.scans < r.search_scans {
            self.status.last_search = Some(*run.search.report());
            self.relocalizing = Some(run);
            return false;
        }
        run.search.conclude();
        let report = *run.search.report();
        self.status.last_search = Some(report);
        let mut found = *run.search.hypotheses();
        if run.scans > 1 {
            found.move_by(&run.moved);
        }
        let used = found
            .as_slice()
            .get(..usize::from(r.hypotheses))
            .unwrap_or(found.as_slice());
        let mut centres = [Pose2::new(0.0f32, 0.0, 0.0); MAX_HYPOTHESES];
        for (c, h) in centres.iter_mut().zip(used) {
            *c = h.pose;
        }
        let centres = centres.get(..used.len()).unwrap_or(&[]);
        let spread_m = if r.spread_m > 0.0 {
            r.spread_m
        } else {
            self.map.geometry().resolution
        };
        let spread_rad = if r.spread_rad > 0.0 {
            r.spread_rad
        } else {
            report.heading_step
        };
        self.hypotheses = found;
        if self
            .filter
            .reset_among(centres, spread_m, spread_rad)
            .is_err()
        {
            self.status.failed_searches = self.status.failed_searches.wrapping_add(1);
            return true;
        }
        self.status.search_pending = false;
        self.status.state = LocalizerState::Relocalized;
        self.status.relocalizations = self.status.relocalizations.wrapping_add(1);
        self.status.low_scans = 0;
        self.status.good_scans = 0;
        true
    }

    /// Lost detection after an update whose best particle scored `score`.
    fn track_score(&mut self, score: u32) {
        let total: u64 = self
            .points
            .as_slice()
            .iter()
            .map(|p| u64::from(p.weight))
            .sum();
        let fraction = if total > 0 {
            (score as f32 / total as f32).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let lost = self.relocalization.lost;
        let s = &mut self.status;
        s.hit_fraction = fraction;
        let low = fraction < lost.ratio * s.expected_hit_fraction;
        if low {
            s.low_scans = s.low_scans.saturating_add(1);
            s.good_scans = 0;
        } else {
            s.low_scans = 0;
            s.good_scans = s.good_scans.saturating_add(1);
            if s.state == LocalizerState::Tracking {
                s.expected_hit_fraction +=
                    lost.learning_rate * (fraction - s.expected_hit_fraction);
            } else if s.good_scans >= lost.confirm_scans && !s.search_pending {
                s.state = LocalizerState::Tracking;
            }
        }
        if lost.scans > 0 && s.low_scans >= lost.scans && s.state != LocalizerState::Lost {
            s.state = LocalizerState::Lost;
            s.lost_events = s.lost_events.wrapping_add(1);
            s.search_pending = self.layers.is_some() && self.relocalization.automatic;
        }
    }
}

#[cfg(test)]
mod pull_in_tests {
    use super::*;
    use crate::pf::tests::{LIDAR, simulate, true_map};

    /// After a relocalization the localizer scores over the pull-in window: particles
    /// three cells off the truth in x and in y reach it with one scan; with the tracking
    /// window (3 × 3) alone they move by one cell.
    #[test]
    fn a_relocalized_localizer_pulls_in_from_further_than_it_tracks() {
        let sim = simulate(5);
        let config = GridPfConfig::DEFAULT;
        let map = true_map(&sim, &config);
        let k = 40;
        let truth = sim.truth[k];
        let off = Pose2::new(truth.x + 0.15, truth.y - 0.15, truth.theta);
        let error_after_one_scan = |pull_in: u8| {
            let mut loc =
                GridLocalizer::<32, 180>::new(map.view(), config.for_localizer(), off).unwrap();
            loc.relocalization.pull_in_window_cells = pull_in;
            loc.status.state = LocalizerState::Relocalized;
            loc.observe(&LidarScan::new(&sim.scans[k], LIDAR)).unwrap();
            let p = loc.pose();
            (p.x - truth.x).hypot(p.y - truth.y)
        };
        let (wide, narrow) = (error_after_one_scan(4), error_after_one_scan(0));
        std::println!(
            "one scan from 0.21 m off: pull-in window {wide:.3} m, tracking window {narrow:.3} m"
        );
        assert!(wide <= 0.05, "{wide}");
        // The 3 × 3 window moves a particle by at most one cell (0.05 m) in x and in y.
        assert!(narrow >= 0.13, "{narrow}");
    }
}
