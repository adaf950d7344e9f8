//! Stress recordings made from a shared one: what a robot the settings never saw does
//! differently, applied to a recording that has been replayed before.
//!
//! A variant is named after the recording with `+` suffixes, applied left to right:
//! `mrclam:dataset6/robot3+fast3+8hz+turn1.4` is dataset 6's robot 3 driving three
//! times as fast, its odometry logged at 8 Hz, its turn rates read 40 % too large.
//!
//! | suffix | what the robot does differently | ground truth |
//! | --- | --- | --- |
//! | `8hz` (any `<f>hz`) | odometry logged at `f` Hz: the sample in force at each tick of a `1/f` s clock (the stream is piecewise constant, each sample holding until the next) | unchanged |
//! | `speed<k>` | odometry speeds read `k` times the true ones (`speed1.4`: 40 % fast) | unchanged |
//! | `turn<k>` | odometry turn rates read `k` times the true ones | unchanged |
//! | `drop<p>` | each sighting lost with probability `p` (a fixed-seed generator: the same sightings every time) | unchanged |
//! | `fast<k>` | the same path driven `k` times as fast: stamps divided by `k` (from the first event), speeds and turn rates times `k` (the robot's response to its odometry's readings, 0.2 s late on MRCLAM, then comes `k` times sooner too: add `lag<s>` to keep it) | stamps divided by `k` |
//! | `lag<s>` | the odometry stamped `s` seconds early: a robot whose wheels follow its odometry's readings `s` seconds later than the recording's did | unchanged |
//! | `twice` | a second pass: the run, then the same path driven back to the start (the events in reverse order, velocities negated; the camera sees what it saw at each pose) | the path, then the path in reverse |
//!
//! Variants change the events only as described; the true landmarks stay. The filter
//! never learns which variant it replays.

use crate::domain::recording::{Recording, TruePose};
use anyhow::{Context, Result, bail};
use microslam::event::{Event, EventKind};
use rand_core::SeedableRng;
use rand_distr::{Bernoulli, Distribution};
use rand_xoshiro::Xoshiro256PlusPlus;
use std::fmt;
use std::str::FromStr;

/// One change to a recording.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Variant {
    /// Odometry logged at this rate (Hz).
    OdometryRate(f64),
    /// Odometry speeds read this many times the true ones.
    SpeedScale(f64),
    /// Odometry turn rates read this many times the true ones.
    TurnScale(f64),
    /// Each sighting lost with this probability.
    DropSightings(f64),
    /// The same path driven this many times as fast.
    Faster(f64),
    /// The odometry stamped this many seconds early.
    OdometryLag(f64),
    /// The run, then back along the same path to the start.
    Twice,
}

/// The generator's seed for [`Variant::DropSightings`]: fixed, so a variant is the same
/// recording every time it is made.
const DROP_SEED: u64 = 57;

impl FromStr for Variant {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Self> {
        let number = |text: &str| -> Result<f64> {
            let v: f64 = text
                .parse()
                .with_context(|| format!("stress variant `{s}`: `{text}` is not a number"))?;
            if !(v.is_finite() && v > 0.0) {
                bail!("stress variant `{s}`: {v} must be finite and positive");
            }
            Ok(v)
        };
        let v = if s == "twice" {
            Self::Twice
        } else if let Some(hz) = s.strip_suffix("hz") {
            Self::OdometryRate(number(hz)?)
        } else if let Some(k) = s.strip_prefix("speed") {
            Self::SpeedScale(number(k)?)
        } else if let Some(k) = s.strip_prefix("turn") {
            Self::TurnScale(number(k)?)
        } else if let Some(p) = s.strip_prefix("drop") {
            let p = number(p)?;
            if p >= 1.0 {
                bail!("stress variant `{s}`: a probability below 1 is needed");
            }
            Self::DropSightings(p)
        } else if let Some(k) = s.strip_prefix("fast") {
            Self::Faster(number(k)?)
        } else if let Some(k) = s.strip_prefix("lag") {
            Self::OdometryLag(number(k)?)
        } else {
            bail!(
                "unknown stress variant `{s}`: expected <f>hz, speed<k>, turn<k>, drop<p>, \
                 fast<k>, lag<s> or twice (e.g. mrclam:dataset6/robot3+8hz+turn1.4)"
            );
        };
        Ok(v)
    }
}

impl fmt::Display for Variant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::OdometryRate(hz) => write!(f, "{hz}hz"),
            Self::SpeedScale(k) => write!(f, "speed{k}"),
            Self::TurnScale(k) => write!(f, "turn{k}"),
            Self::DropSightings(p) => write!(f, "drop{p}"),
            Self::Faster(k) => write!(f, "fast{k}"),
            Self::OdometryLag(s) => write!(f, "lag{s}"),
            Self::Twice => write!(f, "twice"),
        }
    }
}

/// Splits `dataset6/robot3+8hz+turn1.4` into the recording (`dataset6/robot3`) and its
/// variants, in order.
pub fn split(spec: &str) -> Result<(&str, Vec<Variant>)> {
    let mut parts = spec.split('+');
    let base = parts.next().unwrap_or_default();
    let variants = parts.map(str::parse).collect::<Result<Vec<_>>>()?;
    Ok((base, variants))
}

/// The recording with `variants` applied in order; its name gains their suffixes.
pub fn apply(mut recording: Recording, variants: &[Variant]) -> Recording {
    for v in variants {
        recording = apply_one(recording, *v);
        recording.name = format!("{}+{v}", recording.name);
    }
    recording
}

fn apply_one(mut r: Recording, variant: Variant) -> Recording {
    match variant {
        Variant::OdometryRate(hz) => r.events = decimate_odometry(&r.events, 1.0 / hz),
        Variant::SpeedScale(k) => scale_velocities(&mut r.events, k, 1.0),
        Variant::TurnScale(k) => scale_velocities(&mut r.events, 1.0, k),
        Variant::DropSightings(p) => r.events = drop_sightings(&r.events, p),
        Variant::Faster(k) => {
            let start = r.events.first().map_or(0.0, |e| e.stamp);
            for e in &mut r.events {
                e.stamp = start + (e.stamp - start) / k;
            }
            scale_velocities(&mut r.events, k, k);
            for p in &mut r.ground_truth {
                p.stamp = start + (p.stamp - start) / k;
            }
        }
        Variant::OdometryLag(s) => {
            for e in &mut r.events {
                if matches!(e.kind, EventKind::Velocity { .. }) {
                    e.stamp -= s;
                }
            }
            r.events.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
        }
        Variant::Twice => {
            let end = r.events.last().map_or(0.0, |e| e.stamp);
            r.events = there_and_back(&r.events, end);
            let back: Vec<TruePose> = r
                .ground_truth
                .iter()
                .rev()
                .filter(|p| p.stamp < end)
                .map(|p| TruePose {
                    stamp: 2.0 * end - p.stamp,
                    pose: p.pose,
                })
                .collect();
            r.ground_truth.retain(|p| p.stamp <= end);
            r.ground_truth.extend(back);
        }
    }
    r
}

fn scale_velocities(events: &mut [Event<f64>], speed: f64, turn: f64) {
    for e in events {
        if let EventKind::Velocity { v, omega } = &mut e.kind {
            *v *= speed;
            *omega *= turn;
        }
    }
}

/// The odometry sample in force at each tick `t₀ + k·period` (the last sample at or
/// before it), stamped at the tick, up to the last event; other events unchanged.
fn decimate_odometry(events: &[Event<f64>], period: f64) -> Vec<Event<f64>> {
    let Some(first) = events
        .iter()
        .find(|e| matches!(e.kind, EventKind::Velocity { .. }))
    else {
        return events.to_vec();
    };
    let start = first.stamp;
    let mut out = Vec::with_capacity(events.len());
    let mut in_force: Option<EventKind<f64>> = None;
    let mut ticks = 0u32;
    let tick = |k: u32| start + f64::from(k) * period;
    for e in events {
        // Ticks passed before this event take the sample in force then.
        while e.stamp > tick(ticks) {
            if let Some(kind) = in_force {
                out.push(Event::new(tick(ticks), kind));
            }
            ticks += 1;
        }
        match e.kind {
            EventKind::Velocity { .. } => in_force = Some(e.kind),
            _ => out.push(*e),
        }
    }
    out
}

fn drop_sightings(events: &[Event<f64>], p: f64) -> Vec<Event<f64>> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(DROP_SEED);
    let coin = Bernoulli::new(p).unwrap_or_else(|_| Bernoulli::new(0.0).expect("0 is valid"));
    events
        .iter()
        .filter(|e| !(matches!(e.kind, EventKind::Sighting(_)) && coin.sample(&mut rng)))
        .copied()
        .collect()
}

/// The events, then the same events mirrored in time about `end` with the velocities
/// negated: the robot drives its path back to the start. A velocity sample holds from its
/// stamp to the next one's, so its mirror is stamped at the mirror of the next one's.
fn there_and_back(events: &[Event<f64>], end: f64) -> Vec<Event<f64>> {
    let mut out = events.to_vec();
    let mut next_odometry = end;
    let mut back = Vec::with_capacity(events.len());
    for e in events.iter().rev() {
        match e.kind {
            EventKind::Velocity { v, omega } => {
                back.push(Event::new(
                    2.0 * end - next_odometry,
                    EventKind::Velocity {
                        v: -v,
                        omega: -omega,
                    },
                ));
                next_odometry = e.stamp;
            }
            kind => back.push(Event::new(2.0 * end - e.stamp, kind)),
        }
    }
    // Mirrored sightings of the last stamp (2·end − end = end) come after the forward
    // pass; a stable sort keeps each pass's order.
    back.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));
    out.extend(back);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::domain::recording::interpolate_pose;
    use microslam::event::{Identity, Sighting};
    use microslam::geometry::Pose2;
    use microslam::motion::integrate_velocity;
    use microslam::sensors::range_bearing::RangeBearing;

    /// 10 s of odometry at 50 Hz on a wobbling arc, a sighting every 0.5 s, and the
    /// truth: the odometry integrated.
    fn drive() -> Recording {
        let mut events = Vec::new();
        let mut truth = Vec::new();
        let mut pose = Pose2::new(1.0, 2.0, 0.3);
        for i in 0..500 {
            let t = 100.0 + f64::from(i) * 0.02;
            let (v, omega) = (0.2 + 0.05 * (t * 0.7).sin(), 0.3 * (t * 0.4).cos());
            truth.push(TruePose { stamp: t, pose });
            events.push(Event::new(t, EventKind::Velocity { v, omega }));
            if i % 25 == 0 {
                events.push(Event::new(
                    t,
                    EventKind::Sighting(Sighting {
                        identity: Identity::Unique(6 + i as u32 / 25),
                        z: RangeBearing::new(2.0, 0.1),
                        covariance: None,
                    }),
                ));
            }
            pose = integrate_velocity(&pose, v, omega, 0.02).pose;
        }
        truth.push(TruePose { stamp: 110.0, pose });
        Recording {
            name: "drive".into(),
            events,
            ground_truth: truth,
            landmarks: Vec::new(),
            initial_pose: Some(Pose2::new(1.0, 2.0, 0.3)),
            dropped_sightings: 0,
            dropped_reason: String::new(),
        }
    }

    /// The odometry integrated from the initial pose to each true pose's stamp, holding
    /// each sample until the next: the largest distance from the truth.
    fn dead_reckoning_error(r: &Recording) -> f64 {
        let mut pose = r.initial_pose.unwrap();
        let mut velocity = (0.0, 0.0);
        let mut last = r.events[0].stamp;
        let mut worst: f64 = 0.0;
        for e in &r.events {
            pose = integrate_velocity(&pose, velocity.0, velocity.1, e.stamp - last).pose;
            last = e.stamp;
            if let EventKind::Velocity { v, omega } = e.kind {
                velocity = (v, omega);
            }
            if let Some(t) = interpolate_pose(&r.ground_truth, e.stamp) {
                worst = worst.max((t.x - pose.x).hypot(t.y - pose.y));
            }
        }
        worst
    }

    fn count(r: &Recording, odometry: bool) -> usize {
        r.events
            .iter()
            .filter(|e| matches!(e.kind, EventKind::Velocity { .. }) == odometry)
            .count()
    }

    #[test]
    fn names_parse_and_print_back() {
        let (base, v) = split("dataset6/robot3+8hz+turn1.4+drop0.5+fast3+twice+lag0.15").unwrap();
        assert_eq!(base, "dataset6/robot3");
        assert_eq!(
            v,
            [
                Variant::OdometryRate(8.0),
                Variant::TurnScale(1.4),
                Variant::DropSightings(0.5),
                Variant::Faster(3.0),
                Variant::Twice,
                Variant::OdometryLag(0.15)
            ]
        );
        let names: Vec<String> = v.iter().map(ToString::to_string).collect();
        assert_eq!(
            names,
            ["8hz", "turn1.4", "drop0.5", "fast3", "twice", "lag0.15"]
        );
        for bad in ["x+slow", "x+drop1", "x+turn-1", "x+speednan", "x+0hz"] {
            assert!(split(bad).is_err(), "{bad}");
        }
        assert_eq!(split("dataset1").unwrap(), ("dataset1", vec![]));
    }

    #[test]
    fn the_truth_still_follows_the_odometry_where_it_should() {
        let r = drive();
        assert!(dead_reckoning_error(&r) < 1e-9);
        let fast = apply(drive(), &[Variant::Faster(3.0)]);
        assert_eq!(fast.name, "drive+fast3");
        assert!(dead_reckoning_error(&fast) < 1e-9);
        let twice = apply(drive(), &[Variant::Twice]);
        assert_eq!(count(&twice, true), 1000);
        assert_eq!(count(&twice, false), 40);
        // Back at the start, along the same path.
        assert!(
            dead_reckoning_error(&twice) < 1e-9,
            "{}",
            dead_reckoning_error(&twice)
        );
        let end = twice.ground_truth.last().unwrap();
        assert_eq!(end.pose, Pose2::new(1.0, 2.0, 0.3));
        assert!((end.stamp - 2.0 * 109.98 + 100.0).abs() < 1e-9);
        // The odometry early: the truth follows it 0.1 s late.
        let lag = apply(drive(), &[Variant::OdometryLag(0.1)]);
        let first_odometry = |r: &Recording| {
            r.events
                .iter()
                .find(|e| matches!(e.kind, EventKind::Velocity { .. }))
                .map(|e| e.stamp)
                .unwrap()
        };
        let (early, late) = (first_odometry(&lag), first_odometry(&drive()));
        assert!((late - early - 0.1).abs() < 1e-12, "{early} {late}");
        assert!(dead_reckoning_error(&lag) > 0.01);
        // Wrong scales: the odometry leaves the truth.
        let turn = apply(drive(), &[Variant::TurnScale(1.4)]);
        assert!(dead_reckoning_error(&turn) > 0.2);
    }

    #[test]
    fn decimated_odometry_ticks_at_the_rate_and_keeps_the_sightings() {
        let r = apply(drive(), &[Variant::OdometryRate(8.0)]);
        assert_eq!(r.name, "drive+8hz");
        // 10 s at 8 Hz: ticks at 100, 100.125, …, 110 (the last sample's).
        assert_eq!(count(&r, true), 80);
        assert_eq!(count(&r, false), 20);
        let stamps: Vec<f64> = r
            .events
            .iter()
            .filter(|e| matches!(e.kind, EventKind::Velocity { .. }))
            .map(|e| e.stamp)
            .collect();
        assert!(
            stamps
                .windows(2)
                .all(|w| (w[1] - w[0] - 0.125).abs() < 1e-9)
        );
        assert!(r.events.windows(2).all(|w| w[0].stamp <= w[1].stamp));
        // Held samples drift a little from the truth; not far.
        let e = dead_reckoning_error(&r);
        assert!(e > 1e-4 && e < 0.05, "{e}");
    }

    #[test]
    fn dropped_sightings_are_the_same_every_time() {
        let a = apply(drive(), &[Variant::DropSightings(0.5)]);
        let b = apply(drive(), &[Variant::DropSightings(0.5)]);
        assert_eq!(a.events, b.events);
        assert_eq!(count(&a, true), 500);
        let kept = count(&a, false);
        assert!((4..=16).contains(&kept), "{kept}");
    }
}
