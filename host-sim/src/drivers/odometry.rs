//! How the replay turns odometry samples into the motion between them: each sample held
//! until the next or the two interpolated, and the samples moved by the odometry's
//! latency (`[odometry] latency_s`, `interpolate` of the settings).

use microslam::event::{Event, EventKind};

/// The events with each odometry sample moved `latency` seconds later (the motion a
/// sample reports starts then), in stamp order (stable: equal stamps keep their order);
/// `None` without a latency.
pub fn delay_odometry(events: &[Event<f64>], latency: f64) -> Option<Vec<Event<f64>>> {
    if latency == 0.0 {
        return None;
    }
    let mut out = events.to_vec();
    for e in &mut out {
        if matches!(e.kind, EventKind::Velocity { .. }) {
            e.stamp += latency;
        }
    }
    out.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
    Some(out)
}

/// One odometry sample: stamp (s), speed (m/s), turn rate (rad/s).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Sample {
    stamp: f64,
    v: f64,
    omega: f64,
}

/// The velocity the filter predicts with between two events.
///
/// Held: the last sample's, until the next sample (what a robot that reports its
/// commands does). Interpolated: the velocity goes linearly from one sample to the next
/// (what the wheels of a robot whose odometry is sampled slowly do between samples); the
/// mean over an interval is the interpolated velocity at its middle. Samples further
/// apart than `max_gap` are not interpolated.
pub struct VelocityProfile {
    /// The usable samples in stamp order.
    samples: Vec<Sample>,
    /// Index of the first sample after the one in force.
    next: usize,
    interpolate: bool,
    max_gap: f64,
}

impl VelocityProfile {
    /// The profile of `events`' odometry samples that `usable(v, ω)` accepts (the others
    /// are skipped, the previous velocity held).
    pub fn new(
        events: &[Event<f64>],
        usable: impl Fn(f64, f64) -> bool,
        interpolate: bool,
        max_gap: f64,
    ) -> Self {
        let samples = if interpolate {
            events
                .iter()
                .filter_map(|e| match e.kind {
                    EventKind::Velocity { v, omega } if usable(v, omega) => Some(Sample {
                        stamp: e.stamp,
                        v,
                        omega,
                    }),
                    _ => None,
                })
                .collect()
        } else {
            Vec::new()
        };
        Self {
            samples,
            next: 0,
            interpolate,
            max_gap,
        }
    }

    /// The velocity `(v, ω)` to predict with from `from` to `to` (s), given the sample in
    /// force, `held`, taken at `held_stamp`.
    pub fn over(&mut self, held: (f64, f64), held_stamp: f64, from: f64, to: f64) -> (f64, f64) {
        if !self.interpolate {
            return held;
        }
        while self
            .samples
            .get(self.next)
            .is_some_and(|s| s.stamp <= held_stamp)
        {
            self.next += 1;
        }
        let Some(next) = self.samples.get(self.next) else {
            return held;
        };
        let span = next.stamp - held_stamp;
        if !(span > 0.0 && span <= self.max_gap) {
            return held;
        }
        let middle = 0.5 * (from + to);
        let s = ((middle - held_stamp) / span).clamp(0.0, 1.0);
        (
            held.0 + s * (next.v - held.0),
            held.1 + s * (next.omega - held.1),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn odometry(samples: &[(f64, f64, f64)]) -> Vec<Event<f64>> {
        samples
            .iter()
            .map(|&(t, v, omega)| Event::new(t, EventKind::Velocity { v, omega }))
            .collect()
    }

    #[test]
    fn held_or_interpolated_between_samples() {
        let events = odometry(&[(0.0, 0.0, 0.0), (1.0, 1.0, -2.0), (5.0, 9.0, 9.0)]);
        let mut held = VelocityProfile::new(&events, |_, _| true, false, 1.0);
        assert_eq!(held.over((0.0, 0.0), 0.0, 0.2, 0.4), (0.0, 0.0));
        let mut p = VelocityProfile::new(&events, |_, _| true, true, 1.0);
        // From 0 to 1 s the velocity goes from (0, 0) to (1, −2): at 0.3 s, (0.3, −0.6).
        let (v, w) = p.over((0.0, 0.0), 0.0, 0.2, 0.4);
        assert!((v - 0.3).abs() < 1e-12 && (w + 0.6).abs() < 1e-12);
        // After the last sample but one, the next is 4 s away: beyond the gap, held.
        assert_eq!(p.over((1.0, -2.0), 1.0, 1.5, 2.0), (1.0, -2.0));
        // A refused sample is not interpolated towards.
        let mut q = VelocityProfile::new(&events, |v, _| v < 0.5, true, 10.0);
        assert_eq!(q.over((0.0, 0.0), 0.0, 0.0, 1.0), (0.0, 0.0));
    }

    #[test]
    fn latency_moves_the_odometry_only() {
        let mut events = odometry(&[(0.0, 1.0, 0.0), (0.2, 2.0, 0.0)]);
        events.push(Event::new(0.1, EventKind::YawRate(0.5)));
        assert!(delay_odometry(&events, 0.0).is_none());
        let late = delay_odometry(&events, 0.25).unwrap();
        let stamps: Vec<f64> = late.iter().map(|e| e.stamp).collect();
        assert_eq!(stamps, [0.1, 0.25, 0.45]);
    }
}
