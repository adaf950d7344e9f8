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
use microslam::sensors::range_bearing::{RangeBearing, RangeBearingSensor};
use nalgebra::Vector2;
use rand_core::SeedableRng;
use rand_distr::{Distribution, Normal, Uniform};
use rand_xoshiro::Xoshiro256PlusPlus;

pub mod lidar_world;

/// Simulates the scenario of `settings` with noise seed `seed`: the differential-drive
/// robot, its odometry reporting velocities.
pub fn simulate(settings: &Settings, seed: u64) -> Result<Recording> {
    simulate_drive(settings, seed, None)
}

/// The same scenario driven by a car (`[vehicle]` of `settings`, required): the same
/// landmark field (the same seed places the same landmarks) and the same path, the car's
/// rear-axle centre on it; its odometry reports the speed and the steering angle
/// `φ = atan(ω L / v)` ([`EventKind::Ackermann`]) with the `[vehicle]` noise, and its
/// sensor sits at `[sighting] mount` (ahead of the rear axle for a forward sensor).
pub fn simulate_car(settings: &Settings, seed: u64) -> Result<Recording> {
    let car = settings
        .vehicle::<f64>()
        .context("the simulated car needs a [vehicle] section")?;
    if let Some(bad) = car.invalid_setting() {
        bail!("[vehicle]: {bad}");
    }
    let mut run = simulate_drive(settings, seed, Some(car))?;
    run.name = format!("sim/car/seed{seed}");
    Ok(run)
}

/// [`simulate`] for the differential-drive robot (`car` `None`) or a car.
fn simulate_drive(
    settings: &Settings,
    seed: u64,
    car: Option<microslam::motion::Ackermann<f64>>,
) -> Result<Recording> {
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
    // Sightings are taken from the sensor's mount, as the filter models them.
    let sensor = RangeBearingSensor::new(Pose2::new(s.mount[0], s.mount[1], s.mount[2]));
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
        let scale = (1.0 / dt).sqrt();
        if let Some(car) = &car {
            // The steering that turns the rear axle at ω, and what the car reports.
            let steering = (omega * car.wheelbase / v).atan();
            let n = &car.noise;
            let sv = n.speed_std + n.speed_std_per_mps * v.abs();
            let sp = n.steering_std + n.steering_std_per_mps * v.abs();
            let v_meas = v + sv * scale * unit.sample(&mut rng);
            let steering_meas = steering + sp * scale * unit.sample(&mut rng);
            events.push(Event::new(
                t,
                EventKind::Ackermann {
                    v: v_meas,
                    steering: steering_meas,
                },
            ));
        } else {
            let sv = o.linear_std + o.linear_std_per_mps * v.abs();
            let sw = o.angular_std
                + o.angular_std_per_radps * omega.abs()
                + o.angular_std_per_mps * v.abs();
            let v_meas = v + sv * scale * unit.sample(&mut rng);
            let w_meas = omega + sw * scale * unit.sample(&mut rng);
            events.push(Event::new(
                t,
                EventKind::Velocity {
                    v: v_meas,
                    omega: w_meas,
                },
            ));
        }
        if k % frame_every == 0 {
            for l in &landmarks {
                let landmark = Vector2::new(l.position[0], l.position[1]);
                let Some(seen) = sensor.predict(&pose, &landmark) else {
                    continue;
                };
                let (range, bearing) = (seen.z.range, seen.z.bearing);
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
        dropped_reason: String::new(),
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

    #[test]
    fn sightings_are_taken_from_the_sensor_mount() {
        let mut s = Settings::load("sim", None).unwrap();
        s.sighting.mount = [0.3, -0.1, 0.25];
        s.sighting.range_std = 0.0;
        s.sighting.bearing_std = 0.0;
        let run = simulate(&s, 3).unwrap();
        let sensor = RangeBearingSensor::new(Pose2::new(0.3, -0.1, 0.25));
        let mut checked = 0;
        for e in &run.events {
            let EventKind::Sighting(sighting) = e.kind else {
                continue;
            };
            let Identity::Unique(id) = sighting.identity else {
                panic!("the simulator gives unique ids");
            };
            let truth = run
                .ground_truth
                .iter()
                .find(|p| p.stamp == e.stamp)
                .expect("a true pose at every sighting stamp");
            let l = run
                .landmarks
                .iter()
                .find(|l| l.id == id)
                .expect("a known landmark");
            let expected = sensor
                .predict(&truth.pose, &Vector2::new(l.position[0], l.position[1]))
                .expect("not at the sensor")
                .z;
            assert!(
                (sighting.z.range - expected.range).abs() < 1e-9,
                "{sighting:?} vs {expected:?}"
            );
            assert!(
                (sighting.z.bearing - expected.bearing).abs() < 1e-9,
                "{sighting:?} vs {expected:?}"
            );
            checked += 1;
        }
        assert!(checked > 1000, "{checked}");
    }
}
