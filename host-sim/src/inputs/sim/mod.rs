//! The built-in deterministic simulator: a field of landmarks, a robot driving laps of a
//! wobbly circle, noisy velocity odometry and range-bearing sightings, ground truth; and
//! a world of walls with a ray-cast lidar for the grid particle filter
//! ([`lidar_world`]).
//!
//! The noise is drawn from the same figures the filter is configured with (the
//! `[odometry]` and `[sighting]` sections), so the filter's model is exact and its NEES
//! should sit inside the χ² band. The same seed gives the same run on every machine
//! (xoshiro256++ and rand_distr).

use crate::domain::config::Settings;
use crate::domain::recording::{Recording, TrueLandmark, TruePose};
use anyhow::{Context, Result, bail};
use microslam::event::{Event, EventKind, Identity, Sighting};
use microslam::geometry::{Pose2, wrap_angle};
use microslam::motion::integrate_velocity;
use microslam::sensors::range_bearing::RangeBearing;
use rand_core::SeedableRng;
use rand_distr::{Distribution, Normal, Uniform};
use rand_xoshiro::Xoshiro256PlusPlus;

pub mod lidar_world;

/// Simulates the scenario of `settings` with noise seed `seed`.
pub fn simulate(settings: &Settings, seed: u64) -> Result<Recording> {
    let sc = settings
        .scenario
        .as_ref()
        .context("the settings have no [scenario] section")?;
    if !(sc.odometry_rate_hz > 0.0 && sc.sighting_rate_hz > 0.0 && sc.duration_s > 0.0) {
        bail!("scenario rates and duration must be positive");
    }
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0)?;
    let h = sc.field_half_size_m;
    let coord = Uniform::new_inclusive(-h, h)?;
    let mut landmarks: Vec<TrueLandmark> = Vec::new();
    let mut attempts = 0;
    while landmarks.len() < sc.landmarks as usize {
        attempts += 1;
        if attempts > 100_000 {
            bail!(
                "cannot place {} landmarks {} m apart",
                sc.landmarks,
                sc.min_landmark_spacing_m
            );
        }
        let p = [coord.sample(&mut rng), coord.sample(&mut rng)];
        let spaced = landmarks.iter().all(|l| {
            (l.position[0] - p[0]).hypot(l.position[1] - p[1]) >= sc.min_landmark_spacing_m
        });
        if spaced {
            landmarks.push(TrueLandmark {
                id: landmarks.len() as u32 + 1,
                position: p,
            });
        }
    }

    let o = &settings.odometry;
    let s = &settings.sighting;
    let dt = 1.0 / sc.odometry_rate_hz;
    let frame_every = (sc.odometry_rate_hz / sc.sighting_rate_hz).round().max(1.0) as usize;
    let steps = (sc.duration_s * sc.odometry_rate_hz).round() as usize;
    let half_fov = sc.fov_deg.to_radians() / 2.0;
    let mut pose = Pose2::new(sc.loop_radius_m, 0.0, std::f64::consts::FRAC_PI_2);
    let mut events = Vec::with_capacity(steps * 2);
    let mut truth = Vec::with_capacity(steps);
    for k in 0..steps {
        let t = k as f64 * dt;
        truth.push(TruePose { stamp: t, pose });
        // Commanded (true) velocities, and what the wheel odometry reports.
        let v = sc.speed_mps;
        let omega = v / sc.loop_radius_m
            + sc.wobble_radps * (std::f64::consts::TAU * t / sc.wobble_period_s).sin();
        let sv = o.linear_std + o.linear_std_per_mps * v.abs();
        let sw =
            o.angular_std + o.angular_std_per_radps * omega.abs() + o.angular_std_per_mps * v.abs();
        let scale = (1.0 / dt).sqrt();
        let v_meas = v + sv * scale * unit.sample(&mut rng);
        let w_meas = omega + sw * scale * unit.sample(&mut rng);
        events.push(Event::new(
            t,
            EventKind::Velocity {
                v: v_meas,
                omega: w_meas,
            },
        ));
        if k % frame_every == 0 {
            for l in &landmarks {
                let (dx, dy) = (l.position[0] - pose.x, l.position[1] - pose.y);
                let range = dx.hypot(dy);
                let bearing = wrap_angle(dy.atan2(dx) - pose.theta);
                if range > sc.max_range_m || range < s.min_range || bearing.abs() > half_fov {
                    continue;
                }
                let z = RangeBearing::new(
                    (range + s.range_std * unit.sample(&mut rng)).max(1e-3),
                    wrap_angle(bearing + s.bearing_std * unit.sample(&mut rng)),
                );
                events.push(Event::new(
                    t,
                    EventKind::Sighting(Sighting {
                        identity: Identity::Unique(l.id),
                        z,
                        covariance: None,
                    }),
                ));
            }
        }
        pose = integrate_velocity(&pose, v, omega, dt).pose;
    }
    Ok(Recording {
        name: format!("sim/seed{seed}"),
        events,
        ground_truth: truth,
        landmarks,
        initial_pose: Some(Pose2::new(
            sc.loop_radius_m,
            0.0,
            std::f64::consts::FRAC_PI_2,
        )),
        dropped_sightings: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_run_other_seed_other_noise() {
        let s = Settings::load("sim", None).unwrap();
        let a = simulate(&s, 7).unwrap();
        let b = simulate(&s, 7).unwrap();
        let c = simulate(&s, 8).unwrap();
        assert_eq!(a.events, b.events);
        assert_ne!(a.events, c.events);
        let sightings = a
            .events
            .iter()
            .filter(|e| matches!(e.kind, EventKind::Sighting(_)))
            .count();
        assert!(sightings > 1000, "{sightings}");
        assert_eq!(a.landmarks.len(), 24);
    }
}
