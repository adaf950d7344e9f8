//! The estimator side of the replay, generic over the filter's scalar.

use crate::domain::config::Settings;
use crate::domain::leave_outs::{LeaveOut, leave_out};
use crate::domain::recording::Recording;
use crate::domain::{AssociationMode, Precision};
use crate::drivers::odometry::{VelocityProfile, delay_odometry};
use anyhow::{Result, bail};
use indicatif::ProgressBar;
use microslam::EkfError;
use microslam::association::{Jcbb, KnownIds, Observed, Pairing, icnn, observe_known_supervised};
use microslam::ekf::health::Supervisor;
use microslam::ekf::{EkfSlam, UpdateOutcome, factor_len, state_dim};
use microslam::event::{EventKind, Identity};
use microslam::geometry::Pose2;
use microslam::motion::{Ackermann, compose_increment, integrate_velocity};
use microslam::scalar::Real;
use microslam::sensors::range_bearing::RangeBearing;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Landmark capacity of the host replay's filter.
pub const MAX_LANDMARKS: usize = 64;
/// Largest JCBB batch; larger batches are split.
pub const MAX_BATCH: usize = 8;
/// Candidate landmarks kept per sighting in JCBB.
pub const MAX_CANDIDATES: usize = 8;

type Slam<T> = EkfSlam<T, { state_dim(MAX_LANDMARKS) }, { factor_len(MAX_LANDMARKS) }>;

/// The filter's pose estimate after the prediction to an odometry stamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseSample {
    /// Time, s.
    pub stamp: f64,
    /// Estimated pose.
    pub pose: Pose2<f64>,
    /// Its covariance (x, y, θ).
    pub covariance: [[f64; 3]; 3],
    /// The supervision's lost flag was up ([`microslam::ekf::health::flags::LOST`]).
    pub lost: bool,
}

/// A landmark of the final map.
#[derive(Clone, Debug, PartialEq)]
pub struct MapLandmark {
    /// Estimated position.
    pub position: [f64; 2],
    /// Its 2 × 2 covariance.
    pub covariance: [[f64; 2]; 2],
    /// The id the estimator bound it to (known-id mode only).
    pub id: Option<u32>,
    /// How many of the sightings it absorbed (its creation included) were of each true
    /// landmark: for scoring the association only, never seen by the estimator.
    pub true_ids: BTreeMap<u32, usize>,
}

/// A landmark's estimate at one moment of a replay.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LandmarkEstimate {
    /// Estimated position.
    pub position: [f64; 2],
    /// Its 2 × 2 covariance.
    pub covariance: [[f64; 2]; 2],
    /// The id the estimator bound it to (known-id mode only).
    pub id: Option<u32>,
}

/// The map at one moment of a replay (for recordings such as `--mcap`).
#[derive(Clone, Debug, PartialEq)]
pub struct MapSnapshot {
    /// Time, s.
    pub stamp: f64,
    /// The landmarks then, in the filter's order.
    pub landmarks: Vec<LandmarkEstimate>,
}

/// Snapshots of the map a replay keeps, spread evenly over the recording's time span.
pub const MAP_SNAPSHOTS: usize = 200;

/// What the association did with the sightings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct AssociationCounts {
    /// Sightings that corrected the filter.
    pub updates: usize,
    /// Sightings refused by the update's innovation gate.
    pub gated: usize,
    /// Sightings that created a landmark.
    pub added: usize,
    /// Sightings dropped as ambiguous (near a landmark but not compatible).
    pub ambiguous: usize,
    /// Sightings dropped before association (range limits, invalid values, no id).
    pub dropped: usize,
    /// Sightings refused by the filter (full map, numerical refusal).
    pub refused: usize,
    /// JCBB searches cut at the node bound.
    pub truncated_searches: usize,
    /// Odometry samples with a non-finite or implausible reading (beyond the configured
    /// speed and turn-rate limits): skipped, the previous velocity held.
    pub odometry_refused: usize,
    /// Predictions the filter refused (the filter then stays where it was).
    pub predictions_refused: usize,
    /// Sightings accepted with a Huber down-weighting (`[recovery] huber_sigma`).
    pub downweighted: usize,
    /// Recoveries: the filter was declared lost and its pose covariance inflated.
    pub recoveries: usize,
}

/// Self-calibration the filter estimated as states, at the end of the run (`None` where
/// it was not estimated).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Calibration {
    /// Odometry speed and turn-rate scale factors `[s_v, s_ω]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub odometry_scale: Option<[f64; 2]>,
    /// Range bias `[b₀ (m), b₂ (m/rad²)]`: ranges measured `r + b₀ + b₂ β²`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range_bias: Option<[f64; 2]>,
}

/// Everything a replay produced.
#[derive(Clone, Debug)]
pub struct ReplayRun {
    /// Association mode used.
    pub mode: AssociationMode,
    /// Scalar the filter ran on.
    pub precision: Precision,
    /// Pose estimates, one per odometry sample.
    pub trajectory: Vec<PoseSample>,
    /// Odometry integrated alone (dead reckoning), at the same stamps.
    pub dead_reckoning: Vec<(f64, Pose2<f64>)>,
    /// The final map.
    pub landmarks: Vec<MapLandmark>,
    /// The map as it grew: up to [`MAP_SNAPSHOTS`] snapshots after sighting batches.
    pub map_history: Vec<MapSnapshot>,
    /// NIS of each accepted update.
    pub nis: Vec<f64>,
    /// Odometry steps.
    pub steps: usize,
    /// Landmark sightings offered to the estimator.
    pub sightings: usize,
    /// Association counts.
    pub counts: AssociationCounts,
    /// Self-calibration estimated as states.
    pub calibration: Calibration,
    /// Time of the replay loop: prediction, association and update of every event, and
    /// recording the pose estimates (reading, scoring and writing excluded).
    pub filter_time: Duration,
}

/// Replays the recording's events through the filter in the chosen precision.
pub fn replay(
    recording: &Recording,
    settings: &Settings,
    mode: AssociationMode,
    precision: Precision,
    progress: Option<&ProgressBar>,
) -> Result<ReplayRun> {
    replay_with(recording, settings, mode, precision, progress, &mut |_| {})
}

/// Pose samples handed to a [`replay_with`] observer at a time.
pub const SAMPLE_CHUNK: usize = 4096;

/// [`replay`], handing the pose samples to `on_samples` while the filter runs: each call
/// gets the samples recorded since the previous one, in order, [`SAMPLE_CHUNK`] at a time
/// and the rest at the end. (`host-sim replay` writes `trajectory.tum` from them on
/// another core while the filter goes on.)
pub fn replay_with(
    recording: &Recording,
    settings: &Settings,
    mode: AssociationMode,
    precision: Precision,
    progress: Option<&ProgressBar>,
    on_samples: &mut dyn FnMut(&[PoseSample]),
) -> Result<ReplayRun> {
    // Dead reckoning runs beside the filter (it only needs the events).
    let max_gap = settings.odometry.max_gap_s;
    std::thread::scope(|s| {
        let limits = (
            settings.odometry.max_speed_mps,
            settings.odometry.max_turn_rate_radps,
        );
        let vehicle = settings.vehicle::<f64>();
        let dr = s.spawn(move || dead_reckoning_with(recording, max_gap, limits, vehicle));
        let mut run = match precision {
            Precision::F32 => Replayer::<f32>::new(settings, mode, recording)?
                .run(recording, progress, precision, on_samples),
            Precision::F64 => Replayer::<f64>::new(settings, mode, recording)?
                .run(recording, progress, precision, on_samples),
        }?;
        run.dead_reckoning = dr
            .join()
            .map_err(|_| anyhow::anyhow!("dead-reckoning thread panicked"))?;
        Ok(run)
    })
}

/// Odometry integrated alone from the recording's initial pose, at each odometry stamp
/// (after integrating up to it), with the same motion model and gap rule as the filter.
/// `limits` are the largest plausible speed (m/s) and turn rate (rad/s).
pub fn dead_reckoning(
    recording: &Recording,
    max_gap: f64,
    limits: (f64, f64),
) -> Vec<(f64, Pose2<f64>)> {
    dead_reckoning_with(recording, max_gap, limits, None)
}

/// [`dead_reckoning`] of a recording that may hold a car's samples
/// ([`EventKind::Ackermann`], moved through `vehicle`; skipped without one) and odometry
/// increments (composed at once; the motion held before them stops).
pub fn dead_reckoning_with(
    recording: &Recording,
    max_gap: f64,
    limits: (f64, f64),
    vehicle: Option<Ackermann<f64>>,
) -> Vec<(f64, Pose2<f64>)> {
    let (max_speed, max_turn) = limits;
    let mut out = Vec::with_capacity(recording.events.len());
    let mut pose = recording.initial_pose.unwrap_or(Pose2::IDENTITY);
    let mut velocity = (0.0, 0.0);
    let mut last: Option<f64> = None;
    for e in &recording.events {
        if let Some(prev) = last {
            let dt = (e.stamp - prev).min(max_gap);
            if dt > 0.0 {
                pose = integrate_velocity(&pose, velocity.0, velocity.1, dt).pose;
            }
        }
        last = Some(last.map_or(e.stamp, |p: f64| p.max(e.stamp)));
        match e.kind {
            EventKind::Velocity { v, omega } => {
                // As the filter does: an implausible sample is skipped, the last velocity held.
                if v.abs() <= max_speed && omega.abs() <= max_turn {
                    velocity = (v, omega);
                }
                out.push((e.stamp, pose));
            }
            EventKind::Ackermann { v, steering } => {
                let omega = vehicle.and_then(|car| car.turn_rate(v, steering));
                if let Some(omega) = omega.filter(|w| v.abs() <= max_speed && w.abs() <= max_turn) {
                    velocity = (v, omega);
                }
                out.push((e.stamp, pose));
            }
            EventKind::Increment(inc) => {
                pose = compose_increment(&pose, &inc).pose;
                velocity = (0.0, 0.0);
                out.push((e.stamp, pose));
            }
            _ => {}
        }
    }
    out
}

/// `true` when an odometry sample is finite and within the configured limits.
fn plausible(settings: &Settings, v: f64, omega: f64) -> bool {
    v.abs() <= settings.odometry.max_speed_mps
        && omega.abs() <= settings.odometry.max_turn_rate_radps
}

/// The odometry sample in force between two events.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Held {
    /// Velocities (through the velocity profile: held or interpolated).
    Velocity,
    /// A car's speed and steering angle.
    Ackermann(f64, f64),
    /// Nothing moves (before the first sample, after an increment).
    Still,
}

struct Replayer<T: Real> {
    slam: Box<Slam<T>>,
    /// The car of `[vehicle]`, for [`EventKind::Ackermann`] samples.
    vehicle: Option<Ackermann<T>>,
    ids: KnownIds<MAX_LANDMARKS>,
    jcbb: Jcbb<T, MAX_BATCH, MAX_CANDIDATES>,
    supervisor: Supervisor<T>,
    mode: AssociationMode,
    settings: Settings,
    true_ids: Vec<BTreeMap<u32, usize>>,
    nis: Vec<f64>,
    counts: AssociationCounts,
    filter_time: Duration,
}

fn lit<T: Real>(v: f64) -> T {
    T::lit(v)
}

impl<T: Real> Replayer<T> {
    fn new(settings: &Settings, mode: AssociationMode, recording: &Recording) -> Result<Self> {
        let config = settings.ekf_config::<T>();
        let mut slam = Box::new(Slam::<T>::new(config));
        let start = recording.initial_pose.unwrap_or(Pose2::IDENTITY);
        let start = Pose2::new(lit(start.x), lit(start.y), lit(start.theta));
        if let Err(e) = slam.init(config, start) {
            bail!("filter settings refused: {e}");
        }
        let o = &settings.odometry;
        if o.estimates_scale()
            && let Err(e) =
                slam.estimate_odometry_scale(lit(o.speed_scale_std), lit(o.turn_scale_std))
        {
            bail!("odometry scale estimation refused: {e}");
        }
        let sg = &settings.sighting;
        if sg.estimates_bias()
            && let Err(e) = slam.estimate_range_bias_from(
                (
                    lit(sg.range_bias_offset_mean),
                    lit(sg.range_bias_curvature_mean),
                ),
                lit(sg.range_bias_offset_std),
                lit(sg.range_bias_curvature_std),
            )
        {
            bail!("range bias estimation refused: {e}");
        }
        let vehicle = settings.vehicle::<T>();
        if vehicle.is_none()
            && recording
                .events
                .iter()
                .any(|e| matches!(e.kind, EventKind::Ackermann { .. }))
        {
            bail!(
                "{} has `ackermann` records (a car's speed and steering) but the settings have no [vehicle] (wheelbase_m, max_steering_rad and the noise: configs/landmarks.toml)",
                recording.name
            );
        }
        Ok(Self {
            slam,
            vehicle,
            ids: KnownIds::new(),
            jcbb: Jcbb::new(settings.association_config::<T>()),
            supervisor: Supervisor::new(settings.health_config::<T>()),
            mode,
            settings: settings.clone(),
            true_ids: Vec::new(),
            nis: Vec::new(),
            counts: AssociationCounts::default(),
            filter_time: Duration::ZERO,
        })
    }

    /// The landmarks' estimates now.
    fn landmark_estimates(&self) -> Vec<LandmarkEstimate> {
        (0..self.slam.landmark_count())
            .map(|j| {
                let p = self.slam.landmark(j).unwrap_or_default();
                let c = self.slam.landmark_covariance(j).unwrap_or_default();
                LandmarkEstimate {
                    position: [p[0].to_f64(), p[1].to_f64()],
                    covariance: [
                        [c[(0, 0)].to_f64(), c[(0, 1)].to_f64()],
                        [c[(1, 0)].to_f64(), c[(1, 1)].to_f64()],
                    ],
                    id: self.ids.id_of(j),
                }
            })
            .collect()
    }

    fn run(
        mut self,
        recording: &Recording,
        progress: Option<&ProgressBar>,
        precision: Precision,
        on_samples: &mut dyn FnMut(&[PoseSample]),
    ) -> Result<ReplayRun> {
        let odometry = &self.settings.odometry;
        let delayed = delay_odometry(&recording.events, odometry.latency_s);
        let events = delayed.as_deref().unwrap_or(&recording.events);
        let max_gap = odometry.max_gap_s;
        let settings = &self.settings;
        let mut profile = VelocityProfile::new(
            events,
            |v, omega| plausible(settings, v, omega),
            odometry.interpolate,
            max_gap,
        );
        // The stamp of the sample in force.
        let mut held_stamp = f64::NEG_INFINITY;
        let window = self.settings.association.batch_window_s;
        let mut trajectory = Vec::with_capacity(events.len());
        let mut velocity = (0.0f64, 0.0f64);
        let mut held = Held::Velocity;
        let mut last: Option<f64> = None;
        let mut sightings = 0;
        let mut steps = 0;
        let mut batch: Vec<(RangeBearing<T>, Identity)> = Vec::with_capacity(MAX_BATCH);
        let span = events.last().map_or(0.0, |e| e.stamp) - events.first().map_or(0.0, |e| e.stamp);
        let snapshot_every = span / MAP_SNAPSHOTS as f64;
        let mut next_snapshot = f64::NEG_INFINITY;
        let mut map_history = Vec::new();
        // Samples already handed to `on_samples`.
        let mut handed = 0;
        // One clock around the whole loop: a clock read per step cost as much as a
        // prediction.
        let clock = Instant::now();
        // A leave-out build (feature `leave-outs`) may predict only before sightings, over
        // the time summed since the last batch; `false` in every other build.
        let at_sightings_only = leave_out(LeaveOut::Predictions);
        let mut pending = 0.0f64;
        let mut i = 0;
        while i < events.len() {
            if let Some(p) = progress
                && i % 4096 == 0
            {
                p.set_position(i as u64);
            }
            let Some(event) = events.get(i) else { break };
            let t = event.stamp;
            // Predict to the event's stamp with the velocity held since the last one.
            if let Some(prev) = last {
                let mut dt = (t - prev).min(max_gap);
                if at_sightings_only {
                    if matches!(event.kind, EventKind::Velocity { .. }) {
                        pending += dt.max(0.0);
                        dt = 0.0;
                    } else {
                        dt = dt.max(0.0) + std::mem::take(&mut pending);
                    }
                }
                if dt > 0.0 {
                    let r = match (held, &self.vehicle) {
                        (Held::Velocity, _) => {
                            let (v, omega) = profile.over(velocity, held_stamp, prev, prev + dt);
                            self.slam.predict_velocity(lit(v), lit(omega), lit(dt))
                        }
                        (Held::Ackermann(v, steering), Some(car)) => {
                            self.slam
                                .predict_ackermann(car, lit(v), lit(steering), lit(dt))
                        }
                        _ => Ok(()),
                    };
                    if r.is_err() {
                        self.counts.predictions_refused += 1;
                    }
                }
            }
            last = Some(last.map_or(t, |p: f64| p.max(t)));
            match event.kind {
                EventKind::Velocity { .. }
                | EventKind::Ackermann { .. }
                | EventKind::Increment(_) => {
                    match event.kind {
                        EventKind::Velocity { v, omega } => {
                            if plausible(&self.settings, v, omega) {
                                velocity = (v, omega);
                                held_stamp = t;
                                held = Held::Velocity;
                            } else {
                                self.counts.odometry_refused += 1;
                            }
                        }
                        EventKind::Ackermann { v, steering } => {
                            let turn = self
                                .vehicle
                                .and_then(|car| car.turn_rate(lit::<T>(v), lit(steering)));
                            match turn {
                                Some(omega) if plausible(&self.settings, v, omega.to_f64()) => {
                                    held = Held::Ackermann(v, steering);
                                }
                                _ => self.counts.odometry_refused += 1,
                            }
                        }
                        EventKind::Increment(inc) => {
                            let inc = Pose2::new(lit(inc.x), lit(inc.y), lit(inc.theta));
                            if self.slam.predict_increment(&inc).is_err() {
                                self.counts.predictions_refused += 1;
                            }
                            held = Held::Still;
                        }
                        _ => {}
                    }
                    steps += 1;
                    trajectory.push(self.sample(t));
                    if trajectory.len() - handed >= SAMPLE_CHUNK {
                        on_samples(trajectory.get(handed..).unwrap_or(&[]));
                        handed = trajectory.len();
                    }
                    i += 1;
                }
                EventKind::Sighting(_) => {
                    // Gather the batch: consecutive sightings within the window.
                    batch.clear();
                    let mut j = i;
                    while let Some(e) = events.get(j) {
                        let EventKind::Sighting(s) = e.kind else {
                            break;
                        };
                        if e.stamp > t + window {
                            break;
                        }
                        sightings += 1;
                        let z = RangeBearing::new(lit::<T>(s.z.range), lit::<T>(s.z.bearing));
                        let range = s.z.range;
                        let sg = &self.settings.sighting;
                        if range < sg.min_range || range > sg.max_range || !z.is_valid() {
                            self.counts.dropped += 1;
                        } else {
                            batch.push((z, s.identity));
                        }
                        j += 1;
                    }
                    self.observe_batch(&batch);
                    if t >= next_snapshot {
                        map_history.push(MapSnapshot {
                            stamp: t,
                            landmarks: self.landmark_estimates(),
                        });
                        next_snapshot = t + snapshot_every;
                    }
                    i = j;
                }
                _ => i += 1,
            }
        }
        self.filter_time = clock.elapsed();
        if handed < trajectory.len() {
            on_samples(trajectory.get(handed..).unwrap_or(&[]));
        }
        if let Some(p) = progress {
            p.set_position(events.len() as u64);
        }
        let landmarks = self
            .landmark_estimates()
            .into_iter()
            .enumerate()
            .map(|(j, l)| MapLandmark {
                position: l.position,
                covariance: l.covariance,
                id: l.id,
                true_ids: self.true_ids.get(j).cloned().unwrap_or_default(),
            })
            .collect();
        let health = self.supervisor.status();
        self.counts.downweighted = health.downweighted as usize;
        self.counts.recoveries = usize::from(health.recoveries);
        Ok(ReplayRun {
            mode: self.mode,
            precision,
            trajectory,
            dead_reckoning: Vec::new(),
            landmarks,
            map_history,
            nis: self.nis,
            steps,
            sightings,
            counts: self.counts,
            calibration: Calibration {
                odometry_scale: self
                    .slam
                    .odometry_scale()
                    .map(|(a, b)| [a.to_f64(), b.to_f64()]),
                range_bias: self
                    .slam
                    .range_bias()
                    .map(|(a, b)| [a.to_f64(), b.to_f64()]),
            },
            filter_time: self.filter_time,
        })
    }

    fn sample(&self, stamp: f64) -> PoseSample {
        let p = self.slam.pose();
        let c = self.slam.pose_covariance();
        let mut covariance = [[0.0; 3]; 3];
        for (r, row) in covariance.iter_mut().enumerate() {
            for (k, v) in row.iter_mut().enumerate() {
                *v = c[(r, k)].to_f64();
            }
        }
        PoseSample {
            stamp,
            pose: Pose2::new(p.x.to_f64(), p.y.to_f64(), p.theta.to_f64()),
            covariance,
            lost: self.supervisor.is_lost(),
        }
    }

    fn credit(&mut self, landmark: usize, identity: Identity) {
        if let Identity::Unique(id) | Identity::Class(id) = identity {
            if self.true_ids.len() <= landmark {
                self.true_ids.resize(landmark + 1, BTreeMap::new());
            }
            if let Some(m) = self.true_ids.get_mut(landmark) {
                *m.entry(id).or_default() += 1;
            }
        }
    }

    fn updated(
        &mut self,
        landmark: usize,
        outcome: Result<UpdateOutcome<T>, EkfError>,
        truth: Identity,
    ) {
        match outcome {
            Ok(UpdateOutcome::Accepted { nis }) => {
                self.counts.updates += 1;
                self.nis.push(nis.to_f64());
                self.credit(landmark, truth);
            }
            Ok(UpdateOutcome::Gated { .. }) => self.counts.gated += 1,
            Err(_) => self.counts.refused += 1,
        }
    }

    fn added(&mut self, outcome: Result<usize, EkfError>, truth: Identity) {
        match outcome {
            Ok(j) => {
                self.counts.added += 1;
                self.credit(j, truth);
            }
            Err(_) => self.counts.refused += 1,
        }
    }

    /// Associates and applies one batch. `truth` identities are only used by the known-id
    /// mode (as the front end's answer) and for scoring.
    fn observe_batch(&mut self, batch: &[(RangeBearing<T>, Identity)]) {
        match self.mode {
            AssociationMode::Known => {
                for &(z, identity) in batch {
                    let Identity::Unique(id) = identity else {
                        self.counts.dropped += 1;
                        continue;
                    };
                    let r = observe_known_supervised(
                        &mut self.slam,
                        &mut self.ids,
                        id,
                        &z,
                        &mut self.supervisor,
                    );
                    match r {
                        Ok(Observed::Updated { index, outcome }) => {
                            self.updated(index, Ok(outcome), identity)
                        }
                        Ok(Observed::Added { index }) => self.added(Ok(index), identity),
                        Err(_) => self.counts.refused += 1,
                    }
                }
            }
            AssociationMode::Icnn => {
                // The association reads the covariance many times: apply the deferred
                // predictions once first (the update after it would do it anyway).
                self.slam.flush_predictions();
                let config = *self.jcbb.config();
                for &(z, truth) in batch {
                    let pairing = icnn(&self.slam, &z, &config);
                    self.apply(pairing, &z, truth);
                }
            }
            AssociationMode::Jcbb => {
                self.slam.flush_predictions();
                for chunk in batch.chunks(MAX_BATCH) {
                    let mut zs = [RangeBearing::new(T::ZERO, T::ZERO); MAX_BATCH];
                    for (slot, (z, _)) in zs.iter_mut().zip(chunk) {
                        *slot = *z;
                    }
                    let zs = zs.get(..chunk.len()).unwrap_or(&[]);
                    let mut pairings = [Pairing::Invalid; MAX_BATCH];
                    match self.jcbb.associate(&self.slam, zs, &mut pairings) {
                        Ok(outcome) => {
                            if outcome.truncated {
                                self.counts.truncated_searches += 1;
                            }
                            for (&pairing, &(z, truth)) in pairings.iter().zip(chunk) {
                                self.apply(pairing, &z, truth);
                            }
                        }
                        Err(_) => self.counts.refused += chunk.len(),
                    }
                }
            }
        }
    }

    fn apply(&mut self, pairing: Pairing, z: &RangeBearing<T>, truth: Identity) {
        match pairing {
            Pairing::Landmark(j) => {
                let r = self.supervisor.update(&mut self.slam, j, z);
                self.updated(j, r, truth);
            }
            Pairing::New => {
                self.supervisor.note_new_landmark();
                let r = self.slam.add_landmark(z);
                self.added(r, truth);
            }
            Pairing::Ambiguous => self.counts.ambiguous += 1,
            Pairing::Invalid => self.counts.dropped += 1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use microslam::event::Event;

    /// A drive of `n` odometry samples at 50 Hz on a gentle arc, no sightings.
    fn drive(n: usize) -> Recording {
        let events = (0..n)
            .map(|i| {
                let t = 100.0 + i as f64 * 0.02;
                Event::new(
                    t,
                    EventKind::Velocity {
                        v: 0.2,
                        omega: 0.1 * (t * 0.3).sin(),
                    },
                )
            })
            .collect();
        Recording {
            name: "drive".into(),
            events,
            ground_truth: Vec::new(),
            landmarks: Vec::new(),
            initial_pose: Some(Pose2::new(1.0, -2.0, 0.5)),
            dropped_sightings: 0,
            dropped_reason: String::new(),
        }
    }

    #[test]
    fn samples_are_handed_over_in_order_in_chunks_then_the_rest() {
        let n = 2 * SAMPLE_CHUNK + 1234;
        let recording = drive(n);
        let settings = Settings::load_for("mrclam", None, None).unwrap();
        let mut handed: Vec<PoseSample> = Vec::new();
        let mut sizes = Vec::new();
        let run = replay_with(
            &recording,
            &settings,
            AssociationMode::Known,
            Precision::F64,
            None,
            &mut |samples| {
                sizes.push(samples.len());
                handed.extend_from_slice(samples);
            },
        )
        .unwrap();
        assert_eq!(sizes, [SAMPLE_CHUNK, SAMPLE_CHUNK, 1234]);
        assert_eq!(run.trajectory.len(), n);
        assert_eq!(handed, run.trajectory);
        // The same samples as the replay without an observer.
        let plain = replay(
            &recording,
            &settings,
            AssociationMode::Known,
            Precision::F64,
            None,
        )
        .unwrap();
        assert_eq!(plain.trajectory, run.trajectory);
        assert!(run.trajectory.last().unwrap().pose.x > 1.0);
    }
}
