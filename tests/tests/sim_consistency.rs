//! The simulator draws its noise from the filter's own noise model, so the filter must be
//! consistent: the pose NEES averaged over runs must sit inside the 95 % χ² band.

use host_sim::domain::config::Settings;
use host_sim::domain::{AssociationMode, Precision};
use host_sim::metrics::evaluate;
use microslam::gate::chi_square_quantile;

const RUNS: u64 = 12;

#[test]
fn pose_nees_inside_the_chi_square_band() {
    let mut settings = Settings::load("sim", None).unwrap();
    if let Some(s) = settings.scenario.as_mut() {
        s.duration_s = 120.0;
    }
    let mut sum = 0.0;
    for seed in 1..=RUNS {
        let rec = host_sim::inputs::sim::simulate(&settings, seed).unwrap();
        let run = host_sim::drivers::ekf::replay(
            &rec,
            &settings,
            AssociationMode::Known,
            Precision::F64,
            None,
        )
        .unwrap();
        let m = evaluate(&rec, &run);
        sum += m.nees_pose_mean.unwrap();
        // Every run maps well: the landmarks within a few centimetres.
        assert!(m.landmark_rmse_m.se2.unwrap() < 0.05, "seed {seed}: {m:?}");
    }
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
    let run = host_sim::drivers::ekf::replay(
        &rec,
        &settings,
        AssociationMode::Jcbb,
        Precision::F32,
        None,
    )
    .unwrap();
    let m = evaluate(&rec, &run);
    assert!(m.association_purity.unwrap() > 0.99, "{m:?}");
    assert!(m.ate_rmse_m.se2.unwrap() < 0.1, "{m:?}");
}
