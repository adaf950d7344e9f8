//! The particle filter over robot poses: predict with noisy inputs, weight by map
//! correlation with the shift search, move each particle to its best shift, resample.

use super::correlation::{
    MAX_SHIFTS, ScanPoint, ShiftScore, WEIGHT_ONE, best_shift_with_prior, search_window,
};

/// A heading search before the particles are scored (`slam::score_scan`): offsets up to
/// `span` radians either way in steps of `step` ([`ParticleFilter::search_heading`]),
/// kept when the best scores more than `1 + min_gain` times no offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct HeadingSearch {
    pub(crate) span: f32,
    pub(crate) step: f32,
    /// Every `coarse`-th offset first, then the ones around the best.
    pub(crate) coarse: u8,
    pub(crate) min_gain: f32,
}

/// A shift search: [`search_window`] or one of its variants.
pub(crate) type ShiftSearch =
    fn(&GridView<'_>, &Pose2<f32>, &[ScanPoint], u8, &mut [u32; MAX_SHIFTS]) -> ShiftScore;
use super::prediction::{arc_between, drive_arc};
use super::resampling::resample;
use super::rng::Xoshiro128PlusPlus;
use super::{FilterConfig, PfError};
use crate::geometry::Pose2;
use crate::grid::GridView;
use rand_core::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

/// `P` weighted pose hypotheses with their own random number generator.
///
/// RAM: `28·P + 40` bytes (P = 32: 936 bytes; P = 200: 5.6 KB) plus the config.
#[derive(Clone, Debug)]
pub struct ParticleFilter<const P: usize> {
    poses: [Pose2<f32>; P],
    log_weights: [f32; P],
    scratch: [Pose2<f32>; P],
    rng: Xoshiro128PlusPlus,
    config: FilterConfig,
    last_neff: f32,
    resamples: u32,
    updates: u32,
}

/// What one correlation update did.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UpdateReport {
    /// Index of the heaviest particle (before resampling).
    pub best: usize,
    /// Pose of the heaviest particle, after its shift.
    pub best_pose: Pose2<f32>,
    /// Its shift search result.
    pub best_shift: ShiftScore,
    /// Effective number of particles `1 / Σ w²` after the update, before resampling.
    pub n_eff: f32,
    /// `true` when the particles were resampled.
    pub resampled: bool,
    /// Particles scored (identical neighbours are scored once).
    pub scored: usize,
}

impl<const P: usize> ParticleFilter<P> {
    /// A filter of zero bytes, for a `static` (`.bss`): not a filter yet (zero settings,
    /// zero weights, an unseeded generator); [`ParticleFilter::new`] builds one to replace it.
    pub(crate) const fn zeroed() -> Self {
        const ORIGIN: Pose2<f32> = Pose2::new(0.0, 0.0, 0.0);
        Self {
            poses: [ORIGIN; P],
            log_weights: [0.0; P],
            scratch: [ORIGIN; P],
            rng: Xoshiro128PlusPlus::ZEROED,
            config: FilterConfig::ZEROED,
            last_neff: 0.0,
            resamples: 0,
            updates: 0,
        }
    }

    /// `P` particles at `start` with equal weights, the generator seeded from `config.seed`.
    pub fn new(config: FilterConfig, start: Pose2<f32>) -> Result<Self, PfError> {
        if !config.is_valid() {
            return Err(PfError::InvalidConfig);
        }
        if P == 0 {
            return Err(PfError::NoParticles);
        }
        if !start.is_finite() {
            return Err(PfError::NonFiniteInput);
        }
        let w = -libm::logf(P as f32);
        Ok(Self {
            poses: [start; P],
            log_weights: [w; P],
            scratch: [start; P],
            rng: Xoshiro128PlusPlus::seed_from_u64(config.seed),
            config,
            last_neff: P as f32,
            resamples: 0,
            updates: 0,
        })
    }

    /// Puts all particles at `pose`, spread by Gaussian noise of `std_xy` metres and
    /// `std_theta` radians, with equal weights (the generator continues).
    pub fn reset_around(
        &mut self,
        pose: Pose2<f32>,
        std_xy: f32,
        std_theta: f32,
    ) -> Result<(), PfError> {
        self.reset_among(core::slice::from_ref(&pose), std_xy, std_theta)
    }

    /// Spreads the particles over several poses: particle `i` around `centres[i % n]`
    /// (Gaussian, `std_xy` m, `std_theta` rad), equal weights. Nothing changes when
    /// `centres` is empty or an input is not finite.
    pub fn reset_among(
        &mut self,
        centres: &[Pose2<f32>],
        std_xy: f32,
        std_theta: f32,
    ) -> Result<(), PfError> {
        if centres.is_empty()
            || !(centres.iter().all(Pose2::is_finite)
                && std_xy.is_finite()
                && std_theta.is_finite())
        {
            return Err(PfError::NonFiniteInput);
        }
        let w = -libm::logf(P as f32);
        for ((p, lw), c) in self
            .poses
            .iter_mut()
            .zip(self.log_weights.iter_mut())
            .zip(centres.iter().cycle())
        {
            let nx: f32 = StandardNormal.sample(&mut self.rng);
            let ny: f32 = StandardNormal.sample(&mut self.rng);
            let nt: f32 = StandardNormal.sample(&mut self.rng);
            *p = Pose2::new(
                c.x + std_xy.abs() * nx,
                c.y + std_xy.abs() * ny,
                super::prediction::wrap(c.theta + std_theta.abs() * nt),
            );
            *lw = w;
        }
        self.last_neff = P as f32;
        Ok(())
    }

    /// The settings.
    pub fn config(&self) -> &FilterConfig {
        &self.config
    }

    /// Particle poses.
    pub fn poses(&self) -> &[Pose2<f32>; P] {
        &self.poses
    }

    /// Moves every particle by the rigid motion `correction` of the world frame
    /// (`pose ← correction ⊕ pose`), weights unchanged: what a loop closure does to a
    /// particle set whose map it has moved. A non-finite result is refused
    /// ([`PfError::NonFiniteInput`]) and nothing changes.
    pub fn transform(&mut self, correction: &Pose2<f32>) -> Result<(), PfError> {
        let mut moved = self.poses;
        for p in moved.iter_mut() {
            *p = correction.compose(p);
        }
        if !moved.iter().all(|p| p.is_finite()) {
            return Err(PfError::NonFiniteInput);
        }
        self.poses = moved;
        Ok(())
    }

    /// Turns every particle by `delta` radians about its own position (headings wrapped),
    /// weights unchanged: what a heading search (building-scale SLAM, [`crate::slam`]) found
    /// the odometry's turn to be missing. A non-finite `delta` is refused and nothing
    /// changes.
    pub fn turn(&mut self, delta: f32) -> Result<(), PfError> {
        if !delta.is_finite() {
            return Err(PfError::NonFiniteInput);
        }
        for p in self.poses.iter_mut() {
            p.theta = super::prediction::wrap(p.theta + delta);
        }
        Ok(())
    }

    /// The weighted mean pose of all particles (headings averaged as their differences to
    /// the first particle's, so that a cloud across ±π is not torn apart); the first
    /// particle's pose when the weights or sums are not finite.
    pub fn mean_pose(&self) -> Pose2<f32> {
        let first = self.poses.first().copied().unwrap_or_default();
        self.local_mean(&first, f32::INFINITY, f32::INFINITY)
    }

    /// Which heading offset makes the scan fit the map best around `around`, coarse to
    /// fine: each offset `c·j · step` with `|c·j · step| ≤ span` (`c` = `heading.coarse`, at
    /// least 1; tried 0, −c step, +c step, …) is scored by the shift search at `around`
    /// turned by it, then the `c − 1` offsets either side of the best of them (within
    /// `span`). With `c` = 2 half the shift searches of trying every `step`, the answer
    /// on the same lattice; with `c` = 1 every `step`.
    /// Returns the offset whose best shift scores highest and that score, and the score
    /// of no offset; `(0, s, s)` when none scores more than no offset. For a robot that
    /// turns faster than its odometry follows: the particles' heading noise covers the
    /// odometry's usual errors, not a turn off by ten degrees.
    pub(crate) fn search_heading(
        map: &GridView<'_>,
        around: &Pose2<f32>,
        points: &[ScanPoint],
        half_width: u8,
        search: ShiftSearch,
        heading: &HeadingSearch,
    ) -> (f32, u32, u32) {
        let HeadingSearch {
            span, step, coarse, ..
        } = *heading;
        let mut scores = [0u32; MAX_SHIFTS];
        let none = search(map, around, points, half_width, &mut scores).score;
        if !(span.is_finite() && step.is_finite() && step > 0.0) {
            return (0.0, none, none);
        }
        let mut best = (0i32, none);
        let mut score = |j: i32, best: &mut (i32, u32)| {
            let delta = j as f32 * step;
            let turned = Pose2::new(around.x, around.y, around.theta + delta);
            let s = search(map, &turned, points, half_width, &mut scores).score;
            if s > best.1 {
                *best = (j, s);
            }
        };
        let steps = libm::floorf(span / step) as i32;
        // Every `coarse`-th offset, then those between it and its neighbours around the
        // best.
        let coarse = i32::from(coarse.max(1));
        for k in 1..=2 * (steps / coarse) {
            let j = if k % 2 == 1 { -(k + 1) / 2 } else { k / 2 };
            score(coarse * j, &mut best);
        }
        let centre = best.0;
        for d in 1..coarse {
            for j in [centre - d, centre + d] {
                if j.abs() <= steps {
                    score(j, &mut best);
                }
            }
        }
        (best.0 as f32 * step, best.1, none)
    }

    /// Normalised log-weights (`log Σ exp = 0` after every update).
    pub fn log_weights(&self) -> &[f32; P] {
        &self.log_weights
    }

    /// Index of the heaviest particle (the first of equals).
    pub fn best_index(&self) -> usize {
        let mut best = 0;
        for (i, w) in self.log_weights.iter().enumerate() {
            if *w
                > self
                    .log_weights
                    .get(best)
                    .copied()
                    .unwrap_or(f32::NEG_INFINITY)
            {
                best = i;
            }
        }
        best
    }

    /// Pose of the heaviest particle: the estimate (as in Du n.d., §III-C).
    pub fn best_pose(&self) -> Pose2<f32> {
        self.poses
            .get(self.best_index())
            .copied()
            .unwrap_or_default()
    }

    /// The weighted mean of the particles within `radius_m` (along x and along y) and
    /// `radius_rad` (in heading) of `around` (usually the heaviest particle), headings
    /// averaged as their differences to `around`'s: an estimate that does not jump with
    /// the heaviest particle from scan to scan. `around` itself when no particle is that
    /// close, the weights vanish or a sum is not finite.
    pub fn local_mean(&self, around: &Pose2<f32>, radius_m: f32, radius_rad: f32) -> Pose2<f32> {
        let (mut sw, mut sx, mut sy, mut st) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for (p, lw) in self.poses.iter().zip(&self.log_weights) {
            let (dx, dy) = (p.x - around.x, p.y - around.y);
            let dt = crate::geometry::wrap_near(p.theta - around.theta);
            if dx.abs() <= radius_m && dy.abs() <= radius_m && dt.abs() <= radius_rad {
                let w = libm::expf(*lw);
                sw += w;
                sx += w * dx;
                sy += w * dy;
                st += w * dt;
            }
        }
        if sw <= 0.0 || !sw.is_finite() {
            return *around;
        }
        let mean = Pose2::new(
            around.x + sx / sw,
            around.y + sy / sw,
            crate::geometry::wrap_near(around.theta + st / sw),
        );
        if mean.is_finite() { mean } else { *around }
    }

    /// Weighted covariance of the particle poses about their weighted mean, its upper
    /// triangle row by row: `[xx, xy, xθ, yy, yθ, θθ]` (m², m·rad, rad²; what an estimate
    /// on the wire carries). Headings enter as their difference to the heaviest particle's,
    /// wrapped to (−π, π], so that a cloud across ±π is not torn apart. All zero when the
    /// particles coincide; never NaN (non-finite sums give zeros).
    pub fn pose_covariance(&self) -> [f32; 6] {
        let reference = self.best_pose().theta;
        let mut weights = [0.0f32; P];
        let mut total = 0.0f32;
        let mut mean = [0.0f32; 3];
        for ((w, lw), p) in weights.iter_mut().zip(&self.log_weights).zip(&self.poses) {
            *w = libm::expf(*lw);
            total += *w;
            let d = crate::geometry::wrap_near(p.theta - reference);
            mean[0] += *w * p.x;
            mean[1] += *w * p.y;
            mean[2] += *w * d;
        }
        if !(total > 0.0 && total.is_finite()) {
            return [0.0; 6];
        }
        let mean = mean.map(|m| m / total);
        let mut c = [0.0f32; 6];
        for (w, p) in weights.iter().zip(&self.poses) {
            let e = [
                p.x - mean[0],
                p.y - mean[1],
                crate::geometry::wrap_near(p.theta - reference) - mean[2],
            ];
            let w = *w / total;
            c[0] += w * e[0] * e[0];
            c[1] += w * e[0] * e[1];
            c[2] += w * e[0] * e[2];
            c[3] += w * e[1] * e[1];
            c[4] += w * e[1] * e[2];
            c[5] += w * e[2] * e[2];
        }
        if c.iter().all(|v| v.is_finite()) {
            c
        } else {
            [0.0; 6]
        }
    }

    /// Effective number of particles after the last update.
    pub fn n_eff(&self) -> f32 {
        self.last_neff
    }

    /// How often the particles were resampled.
    pub fn resample_count(&self) -> u32 {
        self.resamples
    }

    /// How many updates were applied.
    pub fn update_count(&self) -> u32 {
        self.updates
    }

    /// Moves every particle along the arc `(distance, heading_change)` with its own noisy
    /// copy of the input ([`super::MotionNoise`]). A non-finite input is refused and
    /// nothing moves.
    pub fn predict(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
        if !(distance.is_finite() && heading_change.is_finite()) {
            return Err(PfError::NonFiniteInput);
        }
        let (sd, st, ss) = self.config.motion_noise.std_devs(distance, heading_change);
        for p in self.poses.iter_mut() {
            let n1: f32 = StandardNormal.sample(&mut self.rng);
            let n2: f32 = StandardNormal.sample(&mut self.rng);
            let n3: f32 = StandardNormal.sample(&mut self.rng);
            let moved = drive_arc(p, distance + sd * n1, heading_change + st * n2, ss * n3);
            if moved.is_finite() {
                *p = moved;
            }
        }
        Ok(())
    }

    /// Velocity form: `(v, ω)` held for `dt` seconds (`dt ≥ 0`). A zero-length step is a
    /// no-op (the per-step noise floor is not applied), so that repeated stamps do not
    /// spread the particles.
    pub fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        if !(v.is_finite() && omega.is_finite() && dt.is_finite()) {
            return Err(PfError::NonFiniteInput);
        }
        if dt < 0.0 {
            return Err(PfError::NegativeTimeStep);
        }
        if dt == 0.0 {
            return Ok(());
        }
        self.predict(v * dt, omega * dt)
    }

    /// Odometry form: the arc between the odometry poses before and after the step (only
    /// their difference is used, so the odometry frame does not matter). A non-finite
    /// pose is refused and nothing moves.
    ///
    /// The arc leaves out the step's sideways part ([`super::prediction::arc_between`]):
    /// 0.26 mm median for the Intel log's scans 5.6 cm apart, 36 mm for the ACES log's a
    /// metre apart. Predict at every scan, a few centimetres a step: the filter loses the
    /// map on scans a metre apart (`docs/results-grid.md`).
    pub fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
        if !(from.is_finite() && to.is_finite()) {
            return Err(PfError::NonFiniteInput);
        }
        let (d, t) = arc_between(from, to);
        self.predict(d, t)
    }

    /// Weights the particles by the correlation of `points` with `map`: each particle is
    /// scored over the shift window, moved to its best shift, and its log-weight grows by
    /// `log_likelihood_per_unit · corr`. Then resamples when `N_eff ≤ fraction · P`.
    ///
    /// With no points the filter is unchanged and [`PfError::EmptyScan`] is returned.
    pub fn update(
        &mut self,
        map: &GridView<'_>,
        points: &[ScanPoint],
    ) -> Result<UpdateReport, PfError> {
        self.update_with(map, points, search_window)
    }

    /// [`ParticleFilter::update`] with the given shift search (all give the same scores;
    /// the choice decides which code a build carries).
    pub(crate) fn update_with(
        &mut self,
        map: &GridView<'_>,
        points: &[ScanPoint],
        search: ShiftSearch,
    ) -> Result<UpdateReport, PfError> {
        self.update_with_prior(map, points, search, 0.0)
    }

    /// [`ParticleFilter::update_with`] with a Gaussian prior on the shifts: each particle
    /// moves to the shift that maximises `corr − shift_penalty · (dx² + dy²)`
    /// ([`best_shift_with_prior`]; 0: no prior) and is weighted by the correlation there.
    pub(crate) fn update_with_prior(
        &mut self,
        map: &GridView<'_>,
        points: &[ScanPoint],
        search: ShiftSearch,
        shift_penalty: f32,
    ) -> Result<UpdateReport, PfError> {
        let k = self.config.shift_window_cells;
        self.update_in_window(map, points, (search, shift_penalty), k)
    }

    /// [`ParticleFilter::update_with_prior`] over a shift window of half-width `k`
    /// instead of the configured one (clamped to [`super::correlation::MAX_SHIFT_WINDOW`]
    /// by the search).
    pub(crate) fn update_in_window(
        &mut self,
        map: &GridView<'_>,
        points: &[ScanPoint],
        search: PriorSearch,
        k: u8,
    ) -> Result<UpdateReport, PfError> {
        let (search, shift_penalty) = search;
        if points.is_empty() {
            return Err(PfError::EmptyScan);
        }
        let res = map.geometry().resolution;
        let scale = self.config.log_likelihood_per_unit / WEIGHT_ONE as f32;
        let mut shifts = [ShiftScore {
            dx: 0,
            dy: 0,
            score: 0,
        }; P];
        let scored = score_particles(
            map,
            &self.poses,
            points,
            k,
            (search, shift_penalty),
            &mut shifts,
        );
        for (p, s) in self.poses.iter_mut().zip(shifts.iter()) {
            p.x += s.dx as f32 * res;
            p.y += s.dy as f32 * res;
        }
        for (lw, s) in self.log_weights.iter_mut().zip(shifts.iter()) {
            *lw += scale * s.score as f32;
        }
        self.normalise();
        self.updates = self.updates.wrapping_add(1);
        let best = self.best_index();
        let report = UpdateReport {
            best,
            best_pose: self.poses.get(best).copied().unwrap_or_default(),
            best_shift: shifts.get(best).copied().unwrap_or(ShiftScore {
                dx: 0,
                dy: 0,
                score: 0,
            }),
            n_eff: self.last_neff,
            resampled: self.last_neff <= self.config.resample_neff_fraction * P as f32,
            scored,
        };
        if report.resampled {
            self.resample();
        }
        Ok(report)
    }

    /// Subtracts the log of the total weight and computes `N_eff`.
    fn normalise(&mut self) {
        let max = self
            .log_weights
            .iter()
            .copied()
            .fold(f32::NEG_INFINITY, f32::max);
        if !max.is_finite() {
            let w = -libm::logf(P as f32);
            self.log_weights.fill(w);
            self.last_neff = P as f32;
            return;
        }
        let mut sum = 0.0f32;
        for lw in self.log_weights.iter_mut() {
            *lw = (*lw - max).max(-1.0e4);
            sum += libm::expf(*lw);
        }
        let log_sum = libm::logf(sum);
        let mut sum_sq = 0.0f32;
        for lw in self.log_weights.iter_mut() {
            *lw -= log_sum;
            let w = libm::expf(*lw);
            sum_sq += w * w;
        }
        self.last_neff = if sum_sq > 0.0 { 1.0 / sum_sq } else { P as f32 };
    }

    /// Draws `P` particles by the configured scheme; weights become equal.
    pub fn resample(&mut self) {
        let mut weights = [0.0f32; P];
        for (w, lw) in weights.iter_mut().zip(self.log_weights.iter()) {
            *w = libm::expf(*lw);
        }
        let poses = &self.poses;
        let scratch = &mut self.scratch;
        resample(&weights, self.config.resampling, &mut self.rng, |k, j| {
            if let (Some(dst), Some(src)) = (scratch.get_mut(k), poses.get(j)) {
                *dst = *src;
            }
        });
        self.poses.copy_from_slice(&self.scratch);
        self.log_weights.fill(-libm::logf(P as f32));
        self.resamples = self.resamples.wrapping_add(1);
    }
}

/// A shift search with the penalty of [`best_shift_with_prior`] (0: none).
type PriorSearch = (ShiftSearch, f32);

/// One particle's shift search, the best shift picked with the prior.
fn search_with_prior(
    map: &GridView<'_>,
    pose: &Pose2<f32>,
    points: &[ScanPoint],
    half_width: u8,
    search: PriorSearch,
    scores: &mut [u32; MAX_SHIFTS],
) -> ShiftScore {
    let s = (search.0)(map, pose, points, half_width, scores);
    if search.1 > 0.0 {
        let n = 2 * usize::from(half_width.min(super::correlation::MAX_SHIFT_WINDOW)) + 1;
        best_shift_with_prior(scores.get(..n * n).unwrap_or(&[]), half_width, search.1)
    } else {
        s
    }
}

/// Best shift of every particle; a particle equal to its predecessor (copies after
/// resampling that did not move) reuses its result. Returns how many were scored.
#[cfg(not(feature = "parallel"))]
fn score_particles<const P: usize>(
    map: &GridView<'_>,
    poses: &[Pose2<f32>; P],
    points: &[ScanPoint],
    half_width: u8,
    search: PriorSearch,
    shifts: &mut [ShiftScore; P],
) -> usize {
    let mut scores = [0u32; MAX_SHIFTS];
    let mut scored = 0;
    let mut previous: Option<(&Pose2<f32>, ShiftScore)> = None;
    for (p, shift) in poses.iter().zip(shifts.iter_mut()) {
        *shift = match previous {
            Some((q, s)) if q == p => s,
            _ => {
                scored += 1;
                search_with_prior(map, p, points, half_width, search, &mut scores)
            }
        };
        previous = Some((p, *shift));
    }
    scored
}

/// [`score_particles`] on all cores (feature `parallel`): every particle is scored
/// independently, so the result is the same as on one core.
#[cfg(feature = "parallel")]
fn score_particles<const P: usize>(
    map: &GridView<'_>,
    poses: &[Pose2<f32>; P],
    points: &[ScanPoint],
    half_width: u8,
    search: PriorSearch,
    shifts: &mut [ShiftScore; P],
) -> usize {
    use rayon::prelude::*;
    let repeats = |i: usize| i > 0 && poses.get(i) == poses.get(i - 1);
    shifts
        .par_iter_mut()
        .enumerate()
        .with_min_len(8)
        .for_each(|(i, shift)| {
            if !repeats(i) {
                let mut scores = [0u32; MAX_SHIFTS];
                if let Some(p) = poses.get(i) {
                    *shift = search_with_prior(map, p, points, half_width, search, &mut scores);
                }
            }
        });
    let mut scored = 0;
    for i in 0..P {
        if repeats(i) {
            if let Some(prev) = shifts.get(i - 1).copied()
                && let Some(s) = shifts.get_mut(i)
            {
                *s = prev;
            }
        } else {
            scored += 1;
        }
    }
    scored
}
