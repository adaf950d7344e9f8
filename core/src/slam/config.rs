//! Settings of building-scale grid SLAM ([`super::GraphSlam`]).

use super::graph::SolverSettings;
use super::matcher::MatchWindow;
use crate::error::InvalidSetting;
use crate::pf::GridPfConfig;

/// When a scan becomes a keyframe: once the estimate has moved this far or turned this
/// much since the last keyframe.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct KeyframeSpacing {
    /// Distance driven, metres (> 0).
    pub distance_m: f32,
    /// Turn, radians (> 0).
    pub turn_rad: f32,
}

/// Noise of the chain edges: the particle filter's motion between two keyframes.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ChainNoise {
    /// Position standard deviation of every edge, metres (> 0) …
    pub position_std_m: f32,
    /// … plus this per metre driven.
    pub position_std_per_m: f32,
    /// Heading standard deviation of every edge, radians (> 0).
    pub heading_std_rad: f32,
}

/// Loop closure: when a new keyframe is matched against the old ones near it, how, and
/// what a match does.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LoopClosureConfig {
    /// `false`: keyframes and the graph are kept, but no match is tried.
    pub enabled: bool,
    /// Old keyframes are at least this many keyframes older than the new one: the map of
    /// the place as it was first built, before the drift since.
    pub min_age_keyframes: u16,
    /// A match is tried when an old keyframe lies within this distance of the new one's
    /// graph pose, metres.
    pub candidate_radius_m: f32,
    /// The map matched against: the end points of the old keyframes within this distance
    /// of the new one, metres.
    pub submap_radius_m: f32,
    /// The window searched around the new keyframe's graph pose.
    pub window: MatchWindow,
    /// Old keyframes a scan draws into the map a closure matches against, at most (> 0):
    /// the old map is drawn over the scans after the keyframe, so that no scan pays for
    /// drawing every old keyframe near a place visited many times.
    pub old_keyframes_per_scan: u16,
    /// Each old end point is widened to the cells this many cells around it (0: none; 1:
    /// 3 × 3) before the match: a keyframe keeps a thinned scan, so its walls are dotted
    /// lines that a new scan's end points fall between.
    pub old_map_dilation_cells: u8,
    /// End-point look-ups of the match a scan does at most (it stops at the first block
    /// of 16 × 16 translations past this), > 0; the rest waits for the next scans, so that no
    /// scan pays for a whole match. `u32::MAX`: the whole match at the keyframe's scan.
    pub work_per_scan: u32,
    /// The loop edge's covariance is the match's plus this standard deviation of the
    /// position, metres (> 0) …
    pub position_std_floor_m: f32,
    /// … and of the heading, radians (> 0).
    pub heading_std_floor_rad: f32,
    /// The graph's solver.
    pub solver: SolverSettings,
}

/// A search over the heading before each scan is scored: for robots that turn faster
/// than their odometry follows (the particles' heading noise covers the odometry's usual
/// errors, not a turn off by ten degrees).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct HeadingSearchConfig {
    /// Offsets up to this far either way, radians, at every scan (0 with
    /// `span_per_radian` 0: no search) …
    pub span_rad: f32,
    /// … plus this much per radian the odometry turned since the last scan …
    pub span_per_radian: f32,
    /// … at most this far, radians.
    pub max_span_rad: f32,
    /// Step between offsets, radians (> 0).
    pub step_rad: f32,
    /// Every this many steps first, then the steps between around the best (≥ 1; 1:
    /// every step, 2: half the work, the answer on the same lattice).
    pub coarse_steps: u8,
    /// An offset is taken when its best shift scores more than `1 + min_gain` times no
    /// offset's.
    pub min_gain: f32,
}

/// Which particles the estimate averages: those within these distances of the
/// heaviest.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EstimateRadius {
    /// Along x and along y, metres (≥ 0; 0: the heaviest particle alone).
    pub position_m: f32,
    /// In heading, radians (≥ 0).
    pub heading_rad: f32,
}

/// Every setting of [`super::GraphSlam`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct GraphSlamConfig {
    /// The particle filter and the map (cell size, log-odds).
    pub grid: GridPfConfig,
    /// When a scan becomes a keyframe.
    pub keyframes: KeyframeSpacing,
    /// Noise of the chain of keyframes.
    pub chain: ChainNoise,
    /// Loop closure.
    pub loop_closure: LoopClosureConfig,
    /// The estimate's average over the particles near the heaviest.
    pub estimate_radius: EstimateRadius,
    /// The heading search before each scan is scored.
    pub heading_search: HeadingSearchConfig,
}

impl GraphSlamConfig {
    /// The settings for the 32-particle filter of a microcontroller
    /// ([`GridPfConfig::MICROCONTROLLER`]) with a keyframe every 0.65 m or 0.35 rad (640
    /// keyframes hold about 400 m of driving), the loop closure of `docs/results-grid.md`
    /// spread over the scans (32 old keyframes drawn, 200 000 end-point look-ups of the
    /// match, or one solve of at most 64 iterations a step, a scan: every scan of the
    /// board profile under 10 M instructions), the old map widened by a cell, and a
    /// heading search at every scan of ±0.1 rad plus the odometry's turn (at most
    /// ±0.35 rad, every 0.01 rad), taken when it scores 25 % better: the MIT CSAIL log's
    /// odometry is off by 0.02 rad a scan on straight runs and by up to 0.3 rad in its
    /// fast turns, which 32 particles' heading noise does not cover. Chosen on the Intel
    /// and MIT CSAIL logs together (`docs/results-grid.md`).
    pub const MICROCONTROLLER: Self = Self {
        grid: GridPfConfig::MICROCONTROLLER,
        keyframes: KeyframeSpacing {
            distance_m: 0.65,
            turn_rad: 0.35,
        },
        chain: ChainNoise {
            position_std_m: 0.005,
            position_std_per_m: 0.005,
            heading_std_rad: 0.001,
        },
        loop_closure: LoopClosureConfig {
            enabled: true,
            min_age_keyframes: 40,
            candidate_radius_m: 2.0,
            submap_radius_m: 6.0,
            window: MatchWindow {
                half_width_cells: 60,
                half_angle: 0.2,
                angle_step: 0.01,
                min_hit_fraction: 0.6,
                work_budget: 2_000_000,
                distinct_cells: 10,
                max_runner_up: 0.85,
            },
            old_keyframes_per_scan: 32,
            old_map_dilation_cells: 1,
            work_per_scan: 200_000,
            position_std_floor_m: 0.05,
            heading_std_floor_rad: 0.01,
            solver: SolverSettings {
                max_iterations: 64,
                ..SolverSettings::DEFAULT
            },
        },
        estimate_radius: EstimateRadius {
            position_m: 0.1,
            heading_rad: 0.05,
        },
        heading_search: HeadingSearchConfig {
            span_rad: 0.1,
            span_per_radian: 1.0,
            max_span_rad: 0.35,
            step_rad: 0.01,
            coarse_steps: 1,
            min_gain: 0.25,
        },
    };

    /// Every setting zero: not valid, only the zero bytes of [`super::GraphSlam::zeroed`]
    /// (a `static` in `.bss`) until [`super::GraphSlam::init`] replaces them.
    pub(crate) const ZEROED: Self = Self {
        grid: GridPfConfig::ZEROED,
        keyframes: KeyframeSpacing {
            distance_m: 0.0,
            turn_rad: 0.0,
        },
        chain: ChainNoise {
            position_std_m: 0.0,
            position_std_per_m: 0.0,
            heading_std_rad: 0.0,
        },
        loop_closure: LoopClosureConfig {
            enabled: false,
            min_age_keyframes: 0,
            candidate_radius_m: 0.0,
            submap_radius_m: 0.0,
            window: MatchWindow {
                half_width_cells: 0,
                half_angle: 0.0,
                angle_step: 0.0,
                min_hit_fraction: 0.0,
                work_budget: 0,
                distinct_cells: 0,
                max_runner_up: 0.0,
            },
            old_keyframes_per_scan: 0,
            old_map_dilation_cells: 0,
            work_per_scan: 0,
            position_std_floor_m: 0.0,
            heading_std_floor_rad: 0.0,
            solver: SolverSettings {
                max_iterations: 0,
                relative_tolerance: 0.0,
            },
        },
        estimate_radius: EstimateRadius {
            position_m: 0.0,
            heading_rad: 0.0,
        },
        heading_search: HeadingSearchConfig {
            span_rad: 0.0,
            span_per_radian: 0.0,
            max_span_rad: 0.0,
            step_rad: 0.0,
            coarse_steps: 0,
            min_gain: 0.0,
        },
    };

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range (its name and rule), `None` when every one is valid.
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        let l = &self.loop_closure;
        let w = &l.window;
        self.grid.invalid_setting().or_else(|| {
            InvalidSetting::first([
                InvalidSetting::positive("keyframe_distance_m", self.keyframes.distance_m),
                InvalidSetting::positive("keyframe_turn_rad", self.keyframes.turn_rad),
                InvalidSetting::positive("chain_position_std_m", self.chain.position_std_m),
                InvalidSetting::non_negative(
                    "chain_position_std_per_m",
                    self.chain.position_std_per_m,
                ),
                InvalidSetting::positive("chain_heading_std_rad", self.chain.heading_std_rad),
                InvalidSetting::non_negative("candidate_radius_m", l.candidate_radius_m),
                InvalidSetting::non_negative("submap_radius_m", l.submap_radius_m),
                InvalidSetting::non_negative("window_half_angle_rad", w.half_angle),
                InvalidSetting::positive("window_angle_step_rad", w.angle_step),
                InvalidSetting::positive(
                    "old_keyframes_per_scan",
                    f32::from(l.old_keyframes_per_scan),
                ),
                InvalidSetting::positive("work_per_scan", l.work_per_scan as f32),
                InvalidSetting::fraction("min_hit_fraction", w.min_hit_fraction),
                InvalidSetting::fraction("max_runner_up", w.max_runner_up),
                InvalidSetting::positive("position_std_floor_m", l.position_std_floor_m),
                InvalidSetting::positive("heading_std_floor_rad", l.heading_std_floor_rad),
                InvalidSetting::non_negative("estimate_radius_m", self.estimate_radius.position_m),
                InvalidSetting::non_negative(
                    "estimate_radius_rad",
                    self.estimate_radius.heading_rad,
                ),
                InvalidSetting::non_negative("heading_span_rad", self.heading_search.span_rad),
                InvalidSetting::non_negative(
                    "heading_span_per_radian",
                    self.heading_search.span_per_radian,
                ),
                InvalidSetting::non_negative(
                    "heading_max_span_rad",
                    self.heading_search.max_span_rad,
                ),
                InvalidSetting::positive("heading_step_rad", self.heading_search.step_rad),
                InvalidSetting::positive(
                    "heading_coarse_steps",
                    f32::from(self.heading_search.coarse_steps),
                ),
                InvalidSetting::non_negative("heading_min_gain", self.heading_search.min_gain),
            ])
            .or_else(|| l.solver.invalid_setting())
        })
    }
}

impl Default for GraphSlamConfig {
    fn default() -> Self {
        Self::MICROCONTROLLER
    }
}
