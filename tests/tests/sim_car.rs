//! The simulator's car (issue 60, item 3): the same landmark field and path as the
//! differential-drive robot, driven by speed and steering angle through the bicycle
//! model with a sensor 0.3 m ahead of the rear axle. Its EKF-SLAM ATE must be within 2×
//! the differential-drive robot's, with known and with hidden ids (JCBB).

use host_sim::domain::config::{Settings, VehicleSettings};
use host_sim::domain::{AssociationMode, Precision};
use host_sim::inputs::sim::{simulate, simulate_car};
use host_sim::metrics::evaluate;

fn ate(
    recording: &host_sim::domain::recording::Recording,
    settings: &Settings,
    mode: AssociationMode,
) -> f64 {
    let run =
        host_sim::drivers::ekf::replay(recording, settings, mode, Precision::F64, None).unwrap();
    evaluate(recording, &run).ate_rmse_m.se2.expect("ATE(se2)")
}

/// An RC-car-sized vehicle: wheelbase 0.3 m; its speed noise the robot's
/// (`configs/sim.toml`: 0.01 + 0.05 |v| m/s) and a steering noise of 0.02 rad, which at
/// the scenario's 0.4 m/s is a turn-rate noise of 0.4 · 0.02 / 0.3 = 0.027 rad/s, about
/// the robot's (0.01 + 0.05 |ω| + 0.02 |v| ≈ 0.025 rad/s).
fn car(mut settings: Settings) -> Settings {
    settings.vehicle = Some(VehicleSettings {
        wheelbase_m: 0.3,
        max_steering_rad: 0.6,
        speed_std: 0.01,
        speed_std_per_mps: 0.05,
        steering_std: 0.02,
        steering_std_per_mps: 0.0,
    });
    settings.sighting.mount = [0.3, 0.0, 0.0];
    settings
}

#[test]
fn the_car_is_within_twice_the_robots_ate_on_the_same_field() {
    for mode in [AssociationMode::Known, AssociationMode::Jcbb] {
        let robot_settings = Settings::load_for("sim", None, Some(mode)).unwrap();
        let car_settings = car(robot_settings.clone());
        car_settings.validate().unwrap();
        for seed in 1..=4 {
            let robot = simulate(&robot_settings, seed).unwrap();
            let driven = simulate_car(&car_settings, seed).unwrap();
            assert_eq!(robot.landmarks, driven.landmarks, "the same field");
            assert_eq!(robot.ground_truth, driven.ground_truth, "the same path");
            let (a, b) = (
                ate(&robot, &robot_settings, mode),
                ate(&driven, &car_settings, mode),
            );
            println!(
                "{mode:?} seed {seed}: ATE(se2) robot {a:.4} m, car {b:.4} m ({:.2}×)",
                b / a
            );
            assert!(b <= 2.0 * a, "{mode:?} seed {seed}: car {b} robot {a}");
        }
    }
}
