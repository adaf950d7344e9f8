//! The simulator's car (issue 60, item 3): the same landmark field and path as the
//! differential-drive robot, driven by speed and steering angle through the bicycle
//! model with a sensor 0.3 m ahead of the rear axle. Its EKF-SLAM ATE must be within 2×
//! the differential-drive robot's, with known and with hidden ids (JCBB).

use host_sim::domain::config::Settings;
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

/// The settings of `host-sim sim --car`: the built-in car of `configs/sim.toml`
/// (`[vehicle]`: wheelbase 0.3 m, the robot's speed noise, 0.02 rad of steering noise —
/// about the robot's turn-rate noise at the scenario's speed) with its sensor
/// `car_sensor_ahead_m` (0.3 m) ahead of the rear axle.
fn car(mut settings: Settings) -> Settings {
    let vehicle = settings.vehicle.clone().expect("sim.toml has a [vehicle]");
    assert_eq!(vehicle.wheelbase_m, 0.3);
    let ahead = settings
        .scenario
        .as_ref()
        .expect("[scenario]")
        .car_sensor_ahead_m;
    assert_eq!(ahead, 0.3);
    settings.sighting.mount = [ahead, 0.0, 0.0];
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
