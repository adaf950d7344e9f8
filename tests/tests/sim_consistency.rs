//! The simulator draws its noise from the filter's own noise model, so the filter must be
//! consistent: the pose NEES averaged over runs must sit inside the 95 % χ² band.

use host_sim::domain::config::Settings;
use host_sim::domain::{AssociationMode, Precision};
use host_sim::metrics::evaluate;
use microslam::gate::chi_square_quantile;
use std::collections::BTreeSet;

const RUNS: u64 = 12;

#[test]
fn pose_nees_inside_the_chi_square_band() {
    let mut settings = Settings::load("sim", None).unwrap();
    if let Some(s) = settings.scenario.as_mut() {
        s.duration_s = 120.0;
    }
    let mut sum = 0.0;
    let mut worst_landmarks = 0.0f64;
    for seed in 1..=RUNS {
        let rec = host_sim::inputs::sim::simulate(&settings, seed).unwrap();
        let run = microslam_replay_tests::replay_known_f64(&rec, &settings);
        let m = evaluate(&rec, &run);
        sum += m.nees_pose_mean.unwrap();
        let landmarks = m.landmark_rmse_m.se2.unwrap();
        println!(
            "seed {seed}: NEES {:.3}, landmarks {landmarks:.4} m",
            m.nees_pose_mean.unwrap()
        );
        worst_landmarks = worst_landmarks.max(landmarks);
    }
    // Every run maps well: the worst seed's landmark error (seed 10), measured 0.0350 m.
    assert!(
        worst_landmarks < 0.0365,
        "worst landmark error {worst_landmarks} m"
    );
    let mean = sum / RUNS as f64;
    // Each run's time-averaged NEES counts as one 3-dof draw (its samples are correlated).
    let dof = 3 * RUNS as u32;
    let lo = chi_square_quantile(0.025, dof) / RUNS as f64;
    let hi = chi_square_quantile(0.975, dof) / RUNS as f64;
    assert!(
        lo <= mean && mean <= hi,
        "mean NEES {mean} outside [{lo}, {hi}]"
    );
}

#[test]
fn jcbb_on_the_simulator_finds_every_landmark() {
    let mut settings = Settings::load_for("sim", None, Some(AssociationMode::Jcbb)).unwrap();
    if let Some(s) = settings.scenario.as_mut() {
        s.duration_s = 120.0;
    }
    let rec = host_sim::inputs::sim::simulate(&settings, 1).unwrap();
    // The landmarks the robot saw: the simulator's ids, which JCBB does not get to use.
    let seen: BTreeSet<u32> = rec.sighted_ids().collect();
    assert!(seen.len() > 5, "{seen:?}");
    let run = host_sim::drivers::ekf::replay(
        &rec,
        &settings,
        AssociationMode::Jcbb,
        Precision::F32,
        None,
    )
    .unwrap();
    let m = evaluate(&rec, &run);
    println!("JCBB, f32, seed 1: {m:?}");
    // One landmark per landmark seen, none twice, none missed.
    assert_eq!(m.landmarks_created, seen.len(), "{m:?}");
    assert_eq!(m.association_purity, Some(1.0), "{m:?}");
    // Measured 0.0422 m (seed 1, 120 s).
    assert!(m.ate_rmse_m.se2.unwrap() < 0.044, "{m:?}");
}
