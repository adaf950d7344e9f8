//! The hypotheses of a search: candidate poses with their scores ([`Hypothesis`]), the
//! `N` best of them pairwise apart by the configured separation ([`Hypotheses`]), and
//! the relative score that keeps them.

use super::GlobalSearchConfig;
use crate::geometry::{Pose2, wrap_near};

/// A candidate pose of the robot with its correlation score.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Hypothesis {
    /// Robot pose in the map frame (at a cell centre, at a candidate heading).
    pub pose: Pose2<f32>,
    /// Correlation (fixed point,
    /// [`super::correlation::WEIGHT_ONE`](crate::pf::correlation::WEIGHT_ONE) = 1.0).
    pub score: u32,
}

/// Up to `N` hypotheses, best first.
#[derive(Clone, Copy, Debug)]
pub struct Hypotheses<const N: usize> {
    items: [Hypothesis; N],
    len: usize,
}

impl<const N: usize> Default for Hypotheses<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Hypotheses<N> {
    /// None.
    pub const fn new() -> Self {
        Self {
            items: [Hypothesis {
                pose: Pose2::new(0.0, 0.0, 0.0),
                score: 0,
            }; N],
            len: 0,
        }
    }

    /// The hypotheses, best first.
    pub fn as_slice(&self) -> &[Hypothesis] {
        self.items.get(..self.len).unwrap_or(&[])
    }

    /// The best one.
    pub fn best(&self) -> Option<&Hypothesis> {
        self.as_slice().first()
    }

    /// Number held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` when none is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Drops all.
    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// Moves every hypothesis by `motion` (a pose in the frame of the hypothesis: the
    /// robot's motion since the scan the hypotheses are for).
    pub fn move_by(&mut self, motion: &Pose2<f32>) {
        let len = self.len;
        for h in self.items.iter_mut().take(len) {
            h.pose = h.pose.compose(motion);
        }
    }

    /// Lowest score that still enters: the `N`-th best when full, else 0.
    pub(super) fn floor(&self) -> u32 {
        if self.len >= N {
            self.items
                .get(N.wrapping_sub(1))
                .map_or(u32::MAX, |h| h.score)
        } else {
            0
        }
    }

    /// Drops the hypotheses scoring `threshold` or less.
    pub(super) fn keep_above(&mut self, threshold: u32) {
        self.len = self
            .as_slice()
            .iter()
            .take_while(|h| h.score > threshold)
            .count();
    }

    /// Offers a candidate: kept when it beats every held hypothesis within the
    /// separation (those are dropped) and the `N`-th best.
    pub(super) fn offer(&mut self, h: Hypothesis, sep_m: f32, sep_rad: f32) {
        if N == 0 || (self.len >= N && h.score <= self.floor()) {
            return;
        }
        // No trigonometry and no square root: a search that holds many candidates
        // above its threshold offers one per leaf, and libm's `sincosf`, `atan2f` and
        // `hypotf` cost thousands of Cortex-M4F instructions each (headings are in
        // (−π, π], so their difference is within `wrap_near`'s one turn).
        let near = |o: &Hypothesis| {
            let (dx, dy) = (o.pose.x - h.pose.x, o.pose.y - h.pose.y);
            dx * dx + dy * dy < sep_m * sep_m
                && libm::fabsf(wrap_near(o.pose.theta - h.pose.theta)) < sep_rad
        };
        if self
            .as_slice()
            .iter()
            .any(|o| near(o) && o.score >= h.score)
        {
            return;
        }
        // Drop the worse ones nearby, then insert in order.
        let mut kept = 0;
        for i in 0..self.len {
            if let Some(o) = self.items.get(i).copied()
                && !near(&o)
            {
                if let Some(slot) = self.items.get_mut(kept) {
                    *slot = o;
                }
                kept += 1;
            }
        }
        self.len = kept;
        let at = self
            .as_slice()
            .iter()
            .position(|o| o.score < h.score)
            .unwrap_or(self.len);
        if at >= N {
            return;
        }
        let last = self.len.min(N - 1);
        let mut i = last;
        while i > at {
            if let Some(prev) = self.items.get(i - 1).copied()
                && let Some(slot) = self.items.get_mut(i)
            {
                *slot = prev;
            }
            i -= 1;
        }
        if let Some(slot) = self.items.get_mut(at) {
            *slot = h;
        }
        self.len = (self.len + 1).min(N);
    }
}

/// The highest score below [`GlobalSearchConfig::relative_score`] × the best score.
pub(super) fn below_relative(config: &GlobalSearchConfig, best: Option<&Hypothesis>) -> u32 {
    let best = best.map_or(0, |b| b.score);
    (libm::ceilf(config.relative_score * best as f32) as u32).saturating_sub(1)
}
