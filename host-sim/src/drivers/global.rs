//! Global localization trials: the localizer started **without a pose** at random scans of
//! a recording, on a saved map with its max-pooled layers ([`microslam::grid::MaxPoolLayers`]),
//! scored against a reference trajectory (the localizer's own tracked run from the true
//! start). Also measures lost detection on the reference run.
//!
//! A trial succeeds when, within [`TrialSettings::max_scans`] scans, the estimate comes
//! within the tolerance of the reference and stays there up to the last of those scans;
//! `scans_to_converge` is the first scan (1-based) from which it stays.

use super::grid::{GridInput, state_name};
use crate::domain::grid::{GlobalOptions, MAX_BEAMS};
use anyhow::{Result, anyhow, bail};
use microslam::geometry::{Pose2, wrap_angle};
use microslam::grid::{GridView, MaxPoolLayers};
use microslam::pf::global::SearchReport;
use microslam::pf::{GridLocalizer, GridPfConfig, LocalizerState, RelocalizationConfig};
use microslam::sensors::lidar::{LidarGeometry, LidarScan};
use rand_core::{RngCore, SeedableRng};
use std::time::Instant;

/// How the trials run.
#[derive(Clone, Debug)]
pub struct TrialSettings {
    /// Particles of the localizer.
    pub particles: usize,
    /// Number of trials.
    pub trials: usize,
    /// Seed of the start-scan draw.
    pub seed: u64,
    /// Scans a trial may take to converge.
    pub max_scans: usize,
    /// Position tolerance, metres.
    pub tolerance_m: f64,
    /// Heading tolerance, degrees.
    pub tolerance_deg: f64,
    /// Levels of the max-pooled layers.
    pub levels: u8,
    /// Filter settings.
    pub config: GridPfConfig,
    /// Lost detection and global search settings.
    pub relocalization: RelocalizationConfig,
    /// Lidar geometry of the recording.
    pub lidar: LidarGeometry,
    /// Run on the map's occupied-cell bitmap alone (the firmware's view of a map image).
    pub bitmap_only: bool,
}

/// One trial.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Trial {
    /// Index of the first scan.
    pub start: usize,
    /// Its time stamp.
    pub stamp: f64,
    /// First scan (1-based) from which the estimate stays within tolerance, if any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scans_to_converge: Option<usize>,
    /// Position error after each scan, metres.
    pub error_m: Vec<f64>,
    /// Heading error after each scan, degrees.
    pub error_deg: Vec<f64>,
    /// The localizer's state after each scan (`lost`, `relocalized`, `tracking`).
    pub state: Vec<&'static str>,
    /// Position error of the search's best hypothesis, metres (none when the search
    /// ended without one).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub best_hypothesis_error_m: Option<f64>,
    /// Hypotheses the particles were spread over.
    pub hypotheses: usize,
    /// The search that seeded the particles (none when every search of the trial ended
    /// without a hypothesis: see `failed_searches`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub search: Option<SearchSummary>,
    /// Searches of the trial that ended without a hypothesis above the minimum score (the
    /// localizer then searches again from the next scan).
    pub failed_searches: u32,
    /// Wall time of the scans that ran the search, seconds.
    pub search_wall_s: f64,
    /// Scans that ran the search (more than one when it spans scans, or searched again
    /// after finding nothing).
    pub search_scans: usize,
}

/// The search's cost figures (a [`SearchReport`] as JSON).
#[derive(Clone, Debug, serde::Serialize)]
pub struct SearchSummary {
    /// Beams used.
    pub beams: u16,
    /// Candidate headings.
    pub headings: u32,
    /// Heading windows searched.
    pub heading_windows: u8,
    /// Candidate headings inside them.
    pub headings_searched: u32,
    /// Heading step, degrees.
    pub heading_step_deg: f32,
    /// Node evaluations.
    pub nodes: u32,
    /// Work done (beams looked at, plus `NODE_WORK` per node evaluation).
    pub work: u32,
    /// Leaf scores.
    pub leaves: u32,
    /// End-cell rotations.
    pub rotations: u32,
    /// Node evaluations per level.
    pub nodes_per_level: Vec<u32>,
    /// `false` when the work budget stopped it.
    pub complete: bool,
    /// Passes run (minimum scores tried, highest first).
    pub passes: u8,
    /// `true` when every heading was searched after the windows.
    pub full_turn: bool,
    /// Minimum score of the last pass, as a fraction of the beams' total weight.
    pub min_score_fraction: f32,
    /// Score of the best hypothesis, as a fraction of the beams' total weight (0 when
    /// none was found).
    pub best_score_fraction: f32,
    /// Estimated Cortex-M4F instructions.
    pub estimated_m4_instructions: u64,
}

impl From<&SearchReport> for SearchSummary {
    fn from(r: &SearchReport) -> Self {
        Self {
            beams: r.beams,
            headings: r.headings,
            heading_windows: r.heading_windows,
            headings_searched: r.headings_searched,
            heading_step_deg: r.heading_step.to_degrees(),
            nodes: r.nodes,
            work: r.work,
            leaves: r.leaves,
            rotations: r.rotations,
            nodes_per_level: r.nodes_per_level.to_vec(),
            complete: r.complete,
            passes: r.passes,
            full_turn: r.full_turn,
            min_score_fraction: fraction(r.min_score, r.total_weight),
            best_score_fraction: 0.0,
            estimated_m4_instructions: r.estimated_instructions(),
        }
    }
}

/// `part / total`, 0 when `total` is 0.
fn fraction(part: u32, total: u32) -> f32 {
    if total == 0 {
        0.0
    } else {
        part as f32 / total as f32
    }
}

/// The reference run and what lost detection did on it.
#[derive(Clone, Debug)]
pub struct Reference {
    /// Estimate after every scan.
    pub poses: Vec<Pose2<f32>>,
    /// Hit fraction after every scan.
    pub hit_fractions: Vec<f32>,
    /// Times the localizer declared itself lost (false alarms: the run is tracked).
    pub lost_events: u32,
    /// Scans spent in the lost state.
    pub lost_scans: usize,
    /// Expected hit fraction at the end.
    pub expected_hit_fraction: f32,
}

/// The layers of `map` with `levels` levels (built here, as the host would for flash).
pub fn build_layers(map: &GridView<'_>, config: &GridPfConfig, levels: u8) -> Result<Vec<u8>> {
    let g = map.geometry();
    let n = MaxPoolLayers::bytes_for(g.width, g.height, levels)
        .ok_or_else(|| anyhow!("--levels {levels}: 1 ..= 8 levels"))?;
    let mut bytes = vec![0u8; n];
    MaxPoolLayers::build(map, config.log_odds.free_below, levels, &mut bytes)
        .map_err(|e| anyhow!("max-pool layers: {e}"))?;
    Ok(bytes)
}

macro_rules! dispatch {
    ($p:expr, $f:ident, $($arg:expr),*) => {
        match $p {
            16 => $f::<16>($($arg),*),
            32 => $f::<32>($($arg),*),
            64 => $f::<64>($($arg),*),
            128 => $f::<128>($($arg),*),
            200 => $f::<200>($($arg),*),
            other => bail!("--particles {other}: global trials support 16, 32, 64, 128, 200"),
        }
    };
}

/// Most beams per scan.
const BEAMS: usize = MAX_BEAMS;

/// Feeds `frames[i]` (predicting from `previous`).
fn step<const P: usize>(
    loc: &mut GridLocalizer<'_, P, BEAMS>,
    previous: &mut Option<Pose2<f32>>,
    frame: &GridInput<'_>,
    lidar: &LidarGeometry,
) -> Result<()> {
    if frame.odometry.is_finite()
        && let Some(p) = previous.replace(frame.odometry)
    {
        loc.predict_odometry(&p, &frame.odometry)
            .map_err(|e| anyhow!("prediction at {}: {e}", frame.stamp))?;
    }
    // A scan without a usable beam is skipped (the search, if pending, waits).
    let _ = loc.observe(&LidarScan::new(frame.ranges, *lidar));
    Ok(())
}

/// The localizer tracked from `start` over all frames, with lost detection reporting only
/// (no automatic relocalization).
pub fn reference_run(
    frames: &[GridInput<'_>],
    map: &GridView<'_>,
    layers: &[u8],
    start: Pose2<f32>,
    settings: &TrialSettings,
) -> Result<Reference> {
    dispatch!(
        settings.particles,
        reference_p,
        frames,
        map,
        layers,
        start,
        settings
    )
}

fn reference_p<const P: usize>(
    frames: &[GridInput<'_>],
    map: &GridView<'_>,
    layers: &[u8],
    start: Pose2<f32>,
    settings: &TrialSettings,
) -> Result<Reference> {
    let layers = MaxPoolLayers::from_bytes(layers).map_err(|e| anyhow!("{e}"))?;
    let reloc = RelocalizationConfig {
        automatic: false,
        ..settings.relocalization
    };
    let mut loc = GridLocalizer::<P, BEAMS>::new(*map, settings.config, start)
        .map_err(|e| anyhow!("localizer: {e}"))?
        .with_layers(layers, reloc)
        .map_err(|e| anyhow!("localizer: {e}"))?;
    let mut r = Reference {
        poses: Vec::with_capacity(frames.len()),
        hit_fractions: Vec::with_capacity(frames.len()),
        lost_events: 0,
        lost_scans: 0,
        expected_hit_fraction: 0.0,
    };
    let mut previous = None;
    for f in frames {
        step(&mut loc, &mut previous, f, &settings.lidar)?;
        r.poses.push(loc.pose());
        r.hit_fractions.push(loc.status().hit_fraction);
        if loc.state() == LocalizerState::Lost {
            r.lost_scans += 1;
        }
    }
    r.lost_events = loc.status().lost_events;
    r.expected_hit_fraction = loc.status().expected_hit_fraction;
    Ok(r)
}

/// Start scans of the trials: uniform over the scans that leave `max_scans` to run.
pub fn start_scans(frames: usize, settings: &TrialSettings) -> Vec<usize> {
    let span = frames.saturating_sub(settings.max_scans).max(1) as u64;
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(settings.seed);
    (0..settings.trials)
        .map(|_| (rng.next_u64() % span) as usize)
        .collect()
}

/// Runs the trials (each from a start scan of [`start_scans`]) against `reference`.
pub fn run_trials(
    frames: &[GridInput<'_>],
    map: &GridView<'_>,
    layers: &[u8],
    reference: &[Pose2<f32>],
    settings: &TrialSettings,
    progress: &dyn Fn(usize),
) -> Result<Vec<Trial>> {
    let mut out = Vec::new();
    for (i, s) in start_scans(frames.len(), settings).into_iter().enumerate() {
        out.push(dispatch!(
            settings.particles,
            trial_p,
            frames,
            map,
            layers,
            reference,
            s,
            settings
        )?);
        progress(i);
    }
    Ok(out)
}

fn errors(a: &Pose2<f32>, b: &Pose2<f32>) -> (f64, f64) {
    (
        f64::from(a.x - b.x).hypot(f64::from(a.y - b.y)),
        f64::from(wrap_angle(a.theta - b.theta)).abs().to_degrees(),
    )
}

fn trial_p<const P: usize>(
    frames: &[GridInput<'_>],
    map: &GridView<'_>,
    layers: &[u8],
    reference: &[Pose2<f32>],
    start: usize,
    settings: &TrialSettings,
) -> Result<Trial> {
    let layers = MaxPoolLayers::from_bytes(layers).map_err(|e| anyhow!("{e}"))?;
    let mut loc = GridLocalizer::<P, BEAMS>::without_pose(
        *map,
        settings.config,
        layers,
        settings.relocalization,
    )
    .map_err(|e| anyhow!("localizer: {e}"))?;
    let mut trial = Trial {
        start,
        stamp: frames.get(start).map_or(f64::NAN, |f| f.stamp),
        scans_to_converge: None,
        error_m: Vec::new(),
        error_deg: Vec::new(),
        state: Vec::new(),
        best_hypothesis_error_m: None,
        hypotheses: 0,
        search: None,
        failed_searches: 0,
        search_wall_s: 0.0,
        search_scans: 0,
    };
    let mut previous = None;
    let end = (start + settings.max_scans)
        .min(frames.len())
        .min(reference.len());
    for i in start..end {
        let Some(f) = frames.get(i) else { break };
        let searching = loc.status().search_pending;
        let t0 = Instant::now();
        step(&mut loc, &mut previous, f, &settings.lidar)?;
        let Some(want) = reference.get(i) else { break };
        if searching {
            trial.search_wall_s += t0.elapsed().as_secs_f64();
            trial.search_scans += 1;
        }
        if searching && !loc.status().search_pending {
            trial.search = loc.status().last_search.as_ref().map(|r| SearchSummary {
                best_score_fraction: loc
                    .hypotheses()
                    .first()
                    .map_or(0.0, |h| fraction(h.score, r.total_weight)),
                ..SearchSummary::from(r)
            });
            trial.hypotheses = loc
                .hypotheses()
                .len()
                .min(usize::from(settings.relocalization.hypotheses));
            trial.best_hypothesis_error_m =
                loc.hypotheses().first().map(|h| errors(&h.pose, want).0);
        }
        let (m, d) = errors(&loc.pose(), want);
        trial.error_m.push(m);
        trial.error_deg.push(d);
        trial.state.push(state_name(loc.state()));
    }
    trial.failed_searches = loc.status().failed_searches;
    let within: Vec<bool> = trial
        .error_m
        .iter()
        .zip(&trial.error_deg)
        .map(|(m, d)| *m <= settings.tolerance_m && *d <= settings.tolerance_deg)
        .collect();
    // The first scan from which every later one (up to the last) is within tolerance.
    let stays_from = within.iter().rposition(|w| !w).map_or(0, |i| i + 1);
    if stays_from < within.len() {
        trial.scans_to_converge = Some(stays_from + 1);
    }
    Ok(trial)
}

/// Trial settings from the options.
pub fn settings_from(
    args: &GlobalOptions,
    particles: usize,
    config: GridPfConfig,
    lidar: LidarGeometry,
) -> Result<TrialSettings> {
    let mut relocalization = RelocalizationConfig::DEFAULT;
    let search = &mut relocalization.search;
    if let Some(b) = args.work_budget {
        search.work_budget = b;
    }
    if let Some(m) = args.min_score {
        search.min_score_fraction = m;
    }
    if let Some(r) = args.search_range {
        search.max_range = r;
    }
    if let Some(b) = args.search_beams {
        search.max_beams = b;
    }
    if let Some(p) = args.heading_peaks {
        search.heading_peaks = p;
    }
    if let Some(w) = args.heading_window_deg {
        search.heading_window = w.to_radians();
    }
    if let Some(f) = args.first_pass {
        search.first_pass_fraction = f;
    }
    if let Some(f) = args.full_turn_below {
        search.full_turn_below = f;
    }
    if let Some(h) = args.hypotheses {
        relocalization.hypotheses = h;
    }
    if let Some(n) = args.search_scans {
        relocalization.search_scans = n;
    }
    if let Some(invalid) = relocalization.invalid_setting() {
        // The option that sets it.
        let option = match invalid.name {
            "work_budget" => " (--work-budget)",
            "min_score_fraction" => " (--min-score)",
            "max_range" => " (--search-range)",
            "max_beams" => " (--search-beams)",
            "heading_peaks" => " (--heading-peaks)",
            "heading_window" => " (--heading-window, in degrees)",
            "first_pass_fraction" => " (--first-pass)",
            "full_turn_below" => " (--full-turn-below)",
            "hypotheses" => " (--hypotheses)",
            "search_scans" => " (--search-scans)",
            _ => "",
        };
        bail!("global search settings: {invalid}{option}");
    }
    if args.trials == 0 || args.max_scans == 0 {
        bail!("--trials and --max-scans must be at least 1");
    }
    Ok(TrialSettings {
        particles,
        trials: args.trials,
        seed: args.trial_seed,
        max_scans: args.max_scans,
        tolerance_m: 0.3,
        tolerance_deg: 10.0,
        levels: args.levels,
        config,
        relocalization,
        lidar,
        bitmap_only: args.bitmap_only,
    })
}
