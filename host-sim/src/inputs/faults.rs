//! Fault injection for event streams and lidar logs, in the spirit of smoltcp's
//! `FaultInjector`: drops, duplicates, reordering, corrupted readings, a stuck lidar and
//! time stamps going backwards, each at a configurable rate, from a seeded generator so
//! that a run can be repeated exactly. [`inject`] works on landmark event streams,
//! [`inject_scans`] on the laser messages of a CARMEN log.
//!
//! ```
//! use host_sim::inputs::faults::{inject, FaultRates};
//! use microslam::event::{Event, EventKind};
//!
//! let events: Vec<Event<f64>> =
//!     (0..1000).map(|i| Event::new(f64::from(i) * 0.1, EventKind::Velocity { v: 0.2, omega: 0.0 })).collect();
//! let rates: FaultRates = "drop=0.05,nan=0.01".parse()?;
//! let (faulty, counts) = inject(&events, &rates, 7);
//! assert_eq!(faulty.len(), 1000 - counts.dropped);
//! # Ok::<(), anyhow::Error>(())
//! ```

use crate::inputs::readers::carmen::LaserMessage;
use anyhow::{Context, Result, bail};
use microslam::event::{Event, EventKind};
use rand_core::SeedableRng;
use rand_distr::{Bernoulli, Distribution, Uniform};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;
use std::str::FromStr;

/// Probability of each fault per event, in `[0, 1]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FaultRates {
    /// The event is lost.
    pub drop: f64,
    /// The event arrives twice.
    pub duplicate: f64,
    /// The event swaps places with the next one (its stamp then goes backwards).
    pub reorder: f64,
    /// One reading of the event becomes NaN.
    pub nan: f64,
    /// A reading becomes an outlier: a sighting's range ×3, a velocity ×10.
    pub spike: f64,
    /// The stamp jumps one second back (a clock glitch), the content unchanged.
    pub backwards: f64,
    /// The lidar is stuck: the scan repeats the previous scan's ranges (lidar logs only;
    /// event streams have no scans and ignore it).
    pub stuck: f64,
}

impl FaultRates {
    /// Names accepted by [`FromStr`], in order.
    pub const NAMES: [&'static str; 7] = [
        "drop",
        "duplicate",
        "reorder",
        "nan",
        "spike",
        "backwards",
        "stuck",
    ];

    /// Every fault at the same rate.
    pub fn all(rate: f64) -> Self {
        Self {
            drop: rate,
            duplicate: rate,
            reorder: rate,
            nan: rate,
            spike: rate,
            backwards: rate,
            stuck: rate,
        }
    }

    /// `true` when no fault is enabled.
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    fn slot(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "drop" => &mut self.drop,
            "duplicate" | "dup" => &mut self.duplicate,
            "reorder" => &mut self.reorder,
            "nan" => &mut self.nan,
            "spike" => &mut self.spike,
            "backwards" => &mut self.backwards,
            "stuck" => &mut self.stuck,
            _ => return None,
        })
    }
}

/// Parses `name=rate` pairs separated by commas, e.g. `drop=0.01,nan=0.005`, or
/// `all=RATE` for every fault at once.
impl FromStr for FaultRates {
    type Err = anyhow::Error;

    fn from_str(s: &str) -> Result<Self> {
        let mut rates = Self::default();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (name, value) = part
                .split_once('=')
                .with_context(|| format!("fault `{part}`: expected name=rate"))?;
            let rate: f64 = value
                .trim()
                .parse()
                .with_context(|| format!("fault `{part}`: rate is not a number"))?;
            if !(0.0..=1.0).contains(&rate) {
                bail!("fault `{part}`: rate must be within 0..=1");
            }
            if name.trim() == "all" {
                rates = Self::all(rate);
                continue;
            }
            *rates.slot(name.trim()).with_context(|| {
                format!(
                    "unknown fault `{name}`: expected one of {} or all",
                    Self::NAMES.join(", ")
                )
            })? = rate;
        }
        Ok(rates)
    }
}

/// What was injected, by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FaultCounts {
    /// Events removed.
    pub dropped: usize,
    /// Events delivered twice.
    pub duplicated: usize,
    /// Adjacent pairs swapped.
    pub reordered: usize,
    /// Events with a NaN reading.
    pub nan: usize,
    /// Lidar messages delivered with a NaN odometry pose (one delivered twice counts
    /// twice).
    pub nan_odometry: usize,
    /// NaN ranges delivered in lidar messages that were not NaN in the log (copies made
    /// by `stuck` and by duplication count again).
    pub nan_ranges: usize,
    /// Events with an outlier reading.
    pub spiked: usize,
    /// Events whose stamp jumped back.
    pub backwards: usize,
    /// Scans that repeat the previous scan's ranges.
    pub stuck: usize,
}

impl FaultCounts {
    /// Total number of faults.
    pub fn total(&self) -> usize {
        self.dropped
            + self.duplicated
            + self.reordered
            + self.nan
            + self.spiked
            + self.backwards
            + self.stuck
    }
}

/// The faults of a run, as reported in `metrics.json`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FaultReport {
    /// Rates asked for.
    pub rates: FaultRates,
    /// Seed of the fault generator.
    pub seed: u64,
    /// What was injected.
    pub injected: FaultCounts,
}

/// One coin per fault, each falling with its rate.
struct Coins {
    drop: Bernoulli,
    duplicate: Bernoulli,
    reorder: Bernoulli,
    nan: Bernoulli,
    spike: Bernoulli,
    backwards: Bernoulli,
    stuck: Bernoulli,
}

impl Coins {
    fn new(rates: &FaultRates) -> Self {
        Self {
            drop: coin(rates.drop),
            duplicate: coin(rates.duplicate),
            reorder: coin(rates.reorder),
            nan: coin(rates.nan),
            spike: coin(rates.spike),
            backwards: coin(rates.backwards),
            stuck: coin(rates.stuck),
        }
    }
}

fn coin(p: f64) -> Bernoulli {
    // Rates are validated to 0..=1 when parsed; clamp for rates built in code.
    Bernoulli::new(p.clamp(0.0, 1.0))
        .unwrap_or_else(|_| Bernoulli::new(0.0).expect("0 is a valid probability"))
}

/// Corrupts one reading of `kind` with NaN; `false` when the event has no reading.
fn poison(kind: &mut EventKind<f64>) -> bool {
    match kind {
        EventKind::Velocity { v, .. } => *v = f64::NAN,
        EventKind::Increment(p) => p.theta = f64::NAN,
        EventKind::YawRate(w) => *w = f64::NAN,
        EventKind::Sighting(s) => s.z.range = f64::NAN,
        _ => return false,
    }
    true
}

/// Turns one reading of `kind` into an outlier; `false` when the event has no reading.
fn spike(kind: &mut EventKind<f64>) -> bool {
    match kind {
        EventKind::Velocity { v, omega } => {
            *v *= 10.0;
            *omega *= 10.0;
        }
        EventKind::Increment(p) => {
            p.x *= 10.0;
            p.y *= 10.0;
        }
        EventKind::YawRate(w) => *w *= 10.0,
        EventKind::Sighting(s) => s.z.range *= 3.0,
        _ => return false,
    }
    true
}

/// Delivers `item`: swapped with the one before it when the previous draw asked for a
/// swap (`swap_next`), otherwise a draw decides whether it will swap with the next one.
/// A fault injection under way: the coins, the generator they draw from, whether the next
/// item swaps places with the one before, and the counts so far.
struct Injection {
    coins: Coins,
    rng: Xoshiro256PlusPlus,
    swap_next: bool,
    counts: FaultCounts,
}

impl Injection {
    fn new(rates: &FaultRates, seed: u64) -> Self {
        Self {
            coins: Coins::new(rates),
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            swap_next: false,
            counts: FaultCounts::default(),
        }
    }

    /// Whether `coin` falls this time.
    fn falls(&mut self, coin: fn(&Coins) -> &Bernoulli) -> bool {
        coin(&self.coins).sample(&mut self.rng)
    }

    /// Delivers `item`: after the one before it when that one drew a swap (then counted),
    /// and draws whether the next one swaps with it.
    fn deliver<T>(&mut self, out: &mut Vec<T>, item: T) {
        out.push(item);
        let n = out.len();
        if self.swap_next && n >= 2 {
            out.swap(n - 2, n - 1);
            self.counts.reordered += 1;
            self.swap_next = false;
        } else if self.coins.reorder.sample(&mut self.rng) {
            self.swap_next = true;
        }
    }
}

/// Applies the faults to a copy of `events`, drawing from a generator seeded by `seed`.
/// Each event is considered once for each fault, in the order of [`FaultRates::NAMES`];
/// a dropped event gets no other fault.
pub fn inject(
    events: &[Event<f64>],
    rates: &FaultRates,
    seed: u64,
) -> (Vec<Event<f64>>, FaultCounts) {
    let mut f = Injection::new(rates, seed);
    let mut out = Vec::with_capacity(events.len() + events.len() / 8);
    for event in events {
        if f.falls(|c| &c.drop) {
            f.counts.dropped += 1;
            continue;
        }
        let mut e = *event;
        if f.falls(|c| &c.nan) && poison(&mut e.kind) {
            f.counts.nan += 1;
        }
        if f.falls(|c| &c.spike) && spike(&mut e.kind) {
            f.counts.spiked += 1;
        }
        if f.falls(|c| &c.backwards) {
            e.stamp -= 1.0;
            f.counts.backwards += 1;
        }
        f.deliver(&mut out, e);
        if f.falls(|c| &c.duplicate) {
            out.push(e);
            f.counts.duplicated += 1;
        }
    }
    (out, f.counts)
}

/// Beams a range spike covers (a reflection burst): that many consecutive ranges ×3.
pub const SPIKE_BEAMS: usize = 10;

/// Applies the faults to a copy of the laser messages `scans` (file order), drawing from a
/// generator seeded by `seed`. Per message, in this order: dropped (no other fault);
/// stuck (its ranges become the previous delivered scan's); NaN (a coin chooses: one
/// range, or the odometry pose's x); spiked (a run of [`SPIKE_BEAMS`] ranges ×3); stamp
/// one second back; swapped with the next message; delivered twice. Besides the faults
/// drawn, the counts say how many NaN odometry poses and NaN ranges were delivered in
/// all (`nan_odometry`, `nan_ranges`): what a replay must refuse.
pub fn inject_scans(
    scans: &[&LaserMessage],
    rates: &FaultRates,
    seed: u64,
) -> (Vec<LaserMessage>, FaultCounts) {
    let mut f = Injection::new(rates, seed);
    let half = coin(0.5);
    let mut out: Vec<LaserMessage> = Vec::with_capacity(scans.len() + scans.len() / 8);
    // The previous delivered scan's ranges and how many NaNs were injected into them.
    let mut previous: Option<(Vec<f32>, usize)> = None;
    for scan in scans {
        if f.falls(|c| &c.drop) {
            f.counts.dropped += 1;
            continue;
        }
        let mut m = (*scan).clone();
        let mut nan_ranges = 0;
        if f.falls(|c| &c.stuck)
            && let Some((r, injected)) = &previous
        {
            m.ranges.clone_from(r);
            nan_ranges = *injected;
            f.counts.stuck += 1;
        }
        let n = m.ranges.len();
        if f.falls(|c| &c.nan) {
            let beam = Uniform::new(0, n).map_or(0, |u| u.sample(&mut f.rng));
            if half.sample(&mut f.rng) || n == 0 {
                m.odom[0] = f64::NAN;
            } else if let Some(r) = m.ranges.get_mut(beam)
                && !r.is_nan()
            {
                *r = f32::NAN;
                nan_ranges += 1;
            }
            f.counts.nan += 1;
        }
        if f.falls(|c| &c.spike) && n > 0 {
            let start = Uniform::new(0, n).map_or(0, |u| u.sample(&mut f.rng));
            for r in m.ranges.iter_mut().skip(start).take(SPIKE_BEAMS) {
                *r *= 3.0;
            }
            f.counts.spiked += 1;
        }
        if f.falls(|c| &c.backwards) {
            m.stamp -= 1.0;
            f.counts.backwards += 1;
        }
        previous = Some((m.ranges.clone(), nan_ranges));
        let nan_odometry = usize::from(m.odom.iter().any(|v| v.is_nan()));
        let twice = f.falls(|c| &c.duplicate).then(|| m.clone());
        f.counts.nan_odometry += nan_odometry;
        f.counts.nan_ranges += nan_ranges;
        f.deliver(&mut out, m);
        if let Some(t) = twice {
            out.push(t);
            f.counts.duplicated += 1;
            f.counts.nan_odometry += nan_odometry;
            f.counts.nan_ranges += nan_ranges;
        }
    }
    (out, f.counts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use microslam::event::{Identity, Sighting};
    use microslam::sensors::range_bearing::RangeBearing;

    fn stream(n: usize) -> Vec<Event<f64>> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 0.01;
                if i % 4 == 0 {
                    let s = Sighting {
                        identity: Identity::Unique(7),
                        z: RangeBearing::new(2.0, 0.1),
                        covariance: None,
                    };
                    Event::new(t, EventKind::Sighting(s))
                } else {
                    Event::new(t, EventKind::Velocity { v: 0.3, omega: 0.1 })
                }
            })
            .collect()
    }

    #[test]
    fn parses_rates_and_refuses_nonsense() {
        let r: FaultRates = "drop=0.1, nan=0.02,dup=0.5".parse().unwrap();
        assert_eq!((r.drop, r.nan, r.duplicate, r.spike), (0.1, 0.02, 0.5, 0.0));
        assert_eq!(
            "all=0.01".parse::<FaultRates>().unwrap(),
            FaultRates::all(0.01)
        );
        assert!("drop=2".parse::<FaultRates>().is_err());
        assert!(
            "jitter=0.1"
                .parse::<FaultRates>()
                .unwrap_err()
                .to_string()
                .contains("unknown fault")
        );
        assert!("drop".parse::<FaultRates>().is_err());
        assert!("".parse::<FaultRates>().unwrap().is_none());
    }

    /// Each fault alone: the stream shows exactly what the counts say.
    #[test]
    fn counts_match_what_is_in_the_stream() {
        let events = stream(20_000);
        let n = events.len();
        let only = |name: &str| inject(&events, &format!("{name}=0.02").parse().unwrap(), 42);

        let (out, c) = only("drop");
        assert_eq!(out.len(), n - c.dropped);
        let (out, c) = only("duplicate");
        assert_eq!(out.len(), n + c.duplicated);
        assert_eq!(
            out.windows(2).filter(|w| w[0] == w[1]).count(),
            c.duplicated
        );
        let (out, c) = only("nan");
        let nans = out.iter().filter(|e| match e.kind {
            EventKind::Velocity { v, .. } => v.is_nan(),
            EventKind::Sighting(s) => s.z.range.is_nan(),
            _ => false,
        });
        assert_eq!(nans.count(), c.nan);
        let (out, c) = only("spike");
        let spikes = out.iter().filter(|e| match e.kind {
            EventKind::Velocity { v, .. } => v > 1.0,
            EventKind::Sighting(s) => s.z.range > 5.0,
            _ => false,
        });
        assert_eq!(spikes.count(), c.spiked);
        let (out, c) = only("backwards");
        assert_eq!(
            out.iter()
                .zip(&events)
                .filter(|(a, b)| a.stamp != b.stamp)
                .count(),
            c.backwards
        );
        let (out, c) = only("reorder");
        assert_eq!(
            out.windows(2).filter(|w| w[1].stamp < w[0].stamp).count(),
            c.reordered
        );

        // All at once, each near its rate (binomial, n = 20 000, p = 0.02: σ ≈ 20).
        let (_, c) = inject(&events, &FaultRates::all(0.02), 42);
        for (name, k) in [
            ("drop", c.dropped),
            ("dup", c.duplicated),
            ("reorder", c.reordered),
            ("nan", c.nan),
            ("spike", c.spiked),
            ("back", c.backwards),
        ] {
            assert!((300..=500).contains(&k), "{name}: {k}");
        }
    }

    #[test]
    fn same_seed_same_faults_and_zero_rates_change_nothing() {
        let events = stream(5_000);
        let a = inject(&events, &FaultRates::all(0.05), 9);
        let b = inject(&events, &FaultRates::all(0.05), 9);
        assert_eq!(a.1, b.1);
        assert_eq!(format!("{:?}", a.0), format!("{:?}", b.0));
        let (same, none) = inject(&events, &FaultRates::default(), 9);
        assert_eq!(none.total(), 0);
        assert_eq!(same, events);
    }

    fn scans(n: usize) -> Vec<LaserMessage> {
        (0..n)
            .map(|i| LaserMessage {
                rear: false,
                ranges: (0..30).map(|b| 1.0 + (i * 31 + b) as f32 * 0.001).collect(),
                pose: [0.0; 3],
                odom: [i as f64 * 0.01, 0.0, 0.0],
                stamp: i as f64 * 0.1,
            })
            .collect()
    }

    #[test]
    fn scan_faults_are_counted_and_repeatable() {
        let log = scans(3_000);
        let refs: Vec<&LaserMessage> = log.iter().collect();
        let (same, none) = inject_scans(&refs, &FaultRates::default(), 3);
        assert_eq!(none.total(), 0);
        assert_eq!(same, log);
        let rates = FaultRates::all(0.03);
        let (a, ca) = inject_scans(&refs, &rates, 3);
        let (b, cb) = inject_scans(&refs, &rates, 3);
        assert_eq!(ca, cb);
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert_eq!(a.len(), log.len() - ca.dropped + ca.duplicated);
        // What a replay must refuse is exactly what was delivered.
        let nan_odometry = a
            .iter()
            .filter(|m| m.odom.iter().any(|v| v.is_nan()))
            .count();
        let nan_ranges: usize = a
            .iter()
            .map(|m| m.ranges.iter().filter(|r| r.is_nan()).count())
            .sum();
        assert_eq!((ca.nan_odometry, ca.nan_ranges), (nan_odometry, nan_ranges));
        assert!(ca.nan_odometry > 0 && ca.nan_ranges > 0, "{ca:?}");
        // A stuck lidar repeats earlier ranges: some delivered scans are equal to others.
        let repeats = a.windows(2).filter(|w| w[0].ranges == w[1].ranges).count();
        assert!(repeats > 0, "{ca:?}");
        assert!(
            ca.stuck > 50 && ca.spiked > 50 && ca.backwards > 50,
            "{ca:?}"
        );
    }
}
