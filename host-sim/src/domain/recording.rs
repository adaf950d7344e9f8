//! A dataset in memory: events in time order and what is known to be true (robot poses,
//! landmarks), and the interpolation of the true poses at any stamp.

use microslam::event::{Event, EventKind, Identity};
use microslam::geometry::{Pose2, wrap_near};

/// A time-stamped ground-truth robot pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruePose {
    /// Time, seconds.
    pub stamp: f64,
    /// Pose in the world frame.
    pub pose: Pose2<f64>,
}

/// A ground-truth landmark.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrueLandmark {
    /// Identity (MRCLAM subject number).
    pub id: u32,
    /// Position in the world frame, metres.
    pub position: [f64; 2],
}

/// A dataset read into memory: events in time order and what is known to be true.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// Short name for reports (e.g. `mrclam/dataset6/robot1`).
    pub name: String,
    /// Sensor events, sorted by stamp (stable: equal stamps keep file order).
    pub events: Vec<Event<f64>>,
    /// Ground-truth robot poses, sorted by stamp (may be empty or end early).
    pub ground_truth: Vec<TruePose>,
    /// Ground-truth landmarks (may be empty).
    pub landmarks: Vec<TrueLandmark>,
    /// The robot's pose at the first event when known (the filter starts there), else
    /// the origin.
    pub initial_pose: Option<Pose2<f64>>,
    /// Sightings the reader dropped (of other robots, unknown barcodes).
    pub dropped_sightings: usize,
    /// Why the reader dropped them, with counts by reason (`metrics.json`'s
    /// `inputs.sightings.reader_dropped_because`; empty when none were dropped).
    pub dropped_reason: String,
}

impl Recording {
    /// The landmark ids of the sightings that carry one ([`Identity::Unique`]), in event
    /// order (with repeats).
    pub fn sighted_ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.events.iter().filter_map(|e| match e.kind {
            EventKind::Sighting(s) => match s.identity {
                Identity::Unique(id) => Some(id),
                _ => None,
            },
            _ => None,
        })
    }
}

/// Ground truth linearly interpolated at `stamp` (heading along the shorter arc), or
/// `None` outside its time span.
pub fn interpolate_pose(truth: &[TruePose], stamp: f64) -> Option<Pose2<f64>> {
    let first = truth.first()?;
    let last = truth.last()?;
    if !(stamp >= first.stamp && stamp <= last.stamp) {
        return None;
    }
    let i = truth.partition_point(|p| p.stamp <= stamp);
    if i == 0 {
        return Some(first.pose);
    }
    let a = truth.get(i - 1)?;
    let Some(b) = truth.get(i) else {
        return Some(a.pose);
    };
    Some(between(a, b, stamp))
}

/// The pose at `stamp` on the straight segment from `a` to `b`, the heading along the
/// shorter arc (`a` when the two share a stamp).
fn between(a: &TruePose, b: &TruePose, stamp: f64) -> Pose2<f64> {
    let span = b.stamp - a.stamp;
    let s = if span > 0.0 {
        (stamp - a.stamp) / span
    } else {
        0.0
    };
    Pose2::new(
        a.pose.x + s * (b.pose.x - a.pose.x),
        a.pose.y + s * (b.pose.y - a.pose.y),
        wrap_near(a.pose.theta + s * wrap_near(b.pose.theta - a.pose.theta)),
    )
}

/// Interpolates ground truth at non-decreasing stamps by walking forward (no search):
/// the same results as [`interpolate_pose`].
pub struct TruthCursor<'a> {
    truth: &'a [TruePose],
    next: usize,
}

impl<'a> TruthCursor<'a> {
    /// A cursor at the start of `truth`.
    pub fn new(truth: &'a [TruePose]) -> Self {
        Self { truth, next: 0 }
    }

    /// Ground truth at `stamp`; stamps must not decrease between calls (a smaller one
    /// falls back to a search).
    pub fn at(&mut self, stamp: f64) -> Option<Pose2<f64>> {
        let t = self.truth;
        if self.next > 0 && t.get(self.next - 1).is_some_and(|p| p.stamp > stamp) {
            return interpolate_pose(t, stamp);
        }
        while t.get(self.next).is_some_and(|p| p.stamp <= stamp) {
            self.next += 1;
        }
        let first = t.first()?;
        let last = t.last()?;
        if !(stamp >= first.stamp && stamp <= last.stamp) {
            return None;
        }
        let a = t.get(self.next.checked_sub(1)?)?;
        let Some(b) = t.get(self.next) else {
            return Some(a.pose);
        };
        Some(between(a, b, stamp))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cursor_matches_search_and_stays_inside_the_span() {
        let truth: Vec<TruePose> = (0..50)
            .map(|i| TruePose {
                stamp: f64::from(i) * 0.1,
                pose: Pose2::new(f64::from(i), -f64::from(i), wrap_near(f64::from(i) * 0.4)),
            })
            .collect();
        let mut c = TruthCursor::new(&truth);
        for k in -5..560 {
            let t = f64::from(k) * 0.00913;
            assert_eq!(c.at(t), interpolate_pose(&truth, t), "t = {t}");
        }
        assert_eq!(c.at(0.05), interpolate_pose(&truth, 0.05), "backwards");
        // Half-way between samples 3 and 4, heading across the ±π cut handled.
        let p = interpolate_pose(&truth, 0.35).unwrap();
        assert!((p.x - 3.5).abs() < 1e-12 && (p.y + 3.5).abs() < 1e-12);
        assert_eq!(interpolate_pose(&truth, 4.95), None);
        assert_eq!(interpolate_pose(&truth, -0.01), None);
    }
}
