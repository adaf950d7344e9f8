//! Readers on real and damaged files.

use host_sim::readers::{self, DatasetSpec};

#[test]
fn mrclam_dataset6_reads_in_time_order() {
    let rec = readers::read(&DatasetSpec::Mrclam("dataset6".into()), 1).expect("dataset6");
    assert!(rec.events.windows(2).all(|w| w[0].stamp <= w[1].stamp));
    assert_eq!(rec.landmarks.len(), 15);
}
