//! MRCLAM dataset 6, robot 1 (known ids, f64) with faults injected into the event stream
//! (`host-sim replay --faults`): the replay completes, the counters account for every
//! corrupted reading, and the accuracy degrades gracefully. Bounds are the measured
//! figures (docs/reliability.md) plus a small margin.

use host_sim::domain::AssociationMode;
use host_sim::domain::config::Settings;
use host_sim::domain::recording::Recording;
use host_sim::inputs::faults::{FaultRates, inject};
use host_sim::inputs::readers::{self, DatasetSpec};
use host_sim::metrics::{Metrics, evaluate};

fn run_with(rates: &str) -> (Metrics, host_sim::inputs::faults::FaultCounts) {
    let mut rec: Recording =
        readers::read(&DatasetSpec::Mrclam("dataset6".into()), 1).expect("MRCLAM dataset 6");
    let rates: FaultRates = rates.parse().expect("fault spec");
    let (events, injected) = inject(&rec.events, &rates, 1);
    rec.events = events;
    let settings =
        Settings::load_for("mrclam", None, Some(AssociationMode::Known)).expect("settings");
    let run = microslam_replay_tests::replay_known_f64(&rec, &settings);
    (evaluate(&rec, &run), injected)
}

#[test]
fn every_nan_reading_is_refused_and_counted() {
    let (m, injected) = run_with("nan=0.01");
    assert!(injected.nan > 500, "{injected:?}");
    // NaN odometry is skipped (the last velocity held), NaN sightings are dropped.
    assert_eq!(
        m.counts.odometry_refused + m.counts.dropped,
        injected.nan,
        "{:?}",
        m.counts
    );
    assert_eq!(m.counts.predictions_refused, 0);
    // Measured 0.1892 m, as without faults (0.1888 m).
    assert!(m.ate_rmse_m.se2.expect("se2") < 0.1892 * 1.05);
}

#[test]
fn one_percent_of_every_fault_costs_little() {
    let (m, injected) = run_with("all=0.01");
    assert!(injected.total() > 3000, "{injected:?}");
    assert_eq!(m.landmarks_created, 15);
    // Measured 0.195 m (0.189 m without faults).
    let ate = m.ate_rmse_m.se2.expect("se2");
    assert!(ate < 0.1950 * 1.05, "ATE {ate}");
}

#[test]
fn five_percent_of_every_fault_still_tracks() {
    let (m, _) = run_with("all=0.05");
    // Measured 0.270 m; dead reckoning alone is 2.1 m.
    let ate = m.ate_rmse_m.se2.expect("se2");
    assert!(ate < 0.2699 * 1.05, "ATE {ate}");
}
