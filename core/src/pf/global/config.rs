//! The settings of the global search ([`GlobalSearchConfig`]), their validation, and
//! the limits they are checked against.

#[cfg(doc)]
use super::SearchReport;
use crate::error::InvalidSetting;

/// Most beams the search uses (more are thinned evenly).
pub const MAX_SEARCH_BEAMS: usize = 128;
/// Work a node evaluation counts besides the beams it looks at
/// ([`GlobalSearchConfig::work_budget`]): what making, bounding and stacking a node costs
/// besides its beams, in beams (measured on the Cortex-M4F, see
/// `docs/global-localization.md`).
pub const NODE_WORK: u32 = 10;
/// Most candidate headings (a finer configured or derived step is coarsened to this).
pub const MAX_HEADINGS: u32 = 8192;
/// Most peaks of the wall-direction correlation a search visits.
pub const MAX_HEADING_PEAKS: usize = 4;

/// Settings of the global search.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GlobalSearchConfig {
    /// Beams measured farther than this are left out, metres: the farthest beam used sets
    /// the heading step, so this bounds the number of headings.
    pub max_range: f32,
    /// Use at most this many beams, thinned evenly (≤ [`MAX_SEARCH_BEAMS`]).
    pub max_beams: u16,
    /// Heading step, radians; 0: derived from the farthest beam used (see the module).
    pub heading_step: f32,
    /// A candidate is a hypothesis only when its score is at least this fraction of the
    /// total weight of the beams used (0..1).
    pub min_score_fraction: f32,
    /// A hypothesis must score at least this fraction of the best one (0..1); the
    /// search prunes with it too.
    pub relative_score: f32,
    /// Minimum score (fraction of the total weight) of the first pass; each pass that
    /// finds nothing is followed by one `pass_step` lower, down to `min_score_fraction`.
    pub first_pass_fraction: f32,
    /// Step between the passes' minimum scores (0..1].
    pub pass_step: f32,
    /// Work after which the search stops: every node evaluation (a bound or a leaf
    /// score) counts the beams it looked at (it stops at the beam that rules the node
    /// out) plus [`NODE_WORK`]. The instructions of a search are about proportional to
    /// it (see [`SearchReport::estimated_instructions`]), whichever way its nodes are
    /// pruned.
    pub work_budget: u32,
    /// Hypotheses closer than this in position (metres) …
    pub separation_m: f32,
    /// … and in heading (radians) are the same hypothesis: the better one is kept.
    pub separation_rad: f32,
    /// Search only the headings around this many peaks of the wall-direction correlation
    /// ([`super::orientation`](crate::pf::orientation)), each taken as `s` and `s + π`;
    /// 0 searches every heading (at most [`MAX_HEADING_PEAKS`]).
    pub heading_peaks: u8,
    /// Half-width of the heading window around each peak, radians.
    pub heading_window: f32,
    /// The search is over when a pass finds a hypothesis scoring at least this fraction
    /// of the total weight; until then the headings outside the windows are searched
    /// too, one minimum score behind the windows (0: never, only the windows). A scan
    /// whose wall directions the correlation does not pick out then still finds its
    /// pose, and a good match in the windows at the first minimums costs no more.
    pub full_turn_below: f32,
}

impl GlobalSearchConfig {
    /// Settings for a lidar indoors on a 5 cm map (see `docs/global-localization.md` for
    /// how they were chosen and what they cost).
    pub const DEFAULT: Self = Self {
        max_range: 8.0,
        max_beams: 30,
        heading_step: 0.0,
        min_score_fraction: 0.5,
        relative_score: 0.8,
        first_pass_fraction: 0.8,
        pass_step: 0.1,
        work_budget: 830_000,
        separation_m: 0.5,
        separation_rad: 0.35,
        heading_peaks: 3,
        heading_window: 0.07,
        full_turn_below: 0.6,
    };

    /// `true` when every setting is finite and in range.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first setting out of range (the field's name and its rule), `None` when every
    /// one is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        // The rules' texts below name these limits.
        const _: () = assert!(MAX_SEARCH_BEAMS == 128 && MAX_HEADING_PEAKS == 4);
        let (non_negative, fraction) = (InvalidSetting::non_negative, InvalidSetting::fraction);
        InvalidSetting::first([
            InvalidSetting::positive("max_range", self.max_range),
            (
                "max_beams",
                "within 1 ..= 128",
                (1..=MAX_SEARCH_BEAMS).contains(&usize::from(self.max_beams)),
            ),
            non_negative("heading_step", self.heading_step),
            fraction("min_score_fraction", self.min_score_fraction),
            fraction("relative_score", self.relative_score),
            fraction("first_pass_fraction", self.first_pass_fraction),
            InvalidSetting::positive_fraction("pass_step", self.pass_step),
            ("work_budget", "1 or more", self.work_budget > 0),
            non_negative("separation_m", self.separation_m),
            non_negative("separation_rad", self.separation_rad),
            (
                "heading_peaks",
                "at most 4",
                usize::from(self.heading_peaks) <= MAX_HEADING_PEAKS,
            ),
            non_negative("heading_window", self.heading_window),
            fraction("full_turn_below", self.full_turn_below),
        ])
    }
}

impl Default for GlobalSearchConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}
