//! `host-sim export-ld06`: the Intel log's front scans written as an LD06 lidar's byte
//! stream come back, through the board's packet decoder and revolution binner
//! (`microslam::sensors::ld06`), as the log's scans: every reading at its angle, to the
//! millimetre.

use host_sim::commands::ld06::export;
use host_sim::inputs::readers::carmen::{front_scans, read_log, resolve_log};
use microslam::sensors::ld06::{EMPTY_BIN, Ld06Decoder, Ld06Setup, RevolutionBinner};
use microslam::sensors::lidar::BeamStatus;

#[test]
fn the_intel_logs_scans_come_back_from_the_lidars_byte_stream() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let out = dir.path().join("intel.ld06");
    let n = 200;
    let e = export("intel/intel-raw-part.clf", &out, Some(n)).expect("export");
    assert_eq!(e.scans, n);
    assert_eq!(e.packets, 30 * n, "360 points a turn for beams 1° apart");
    let bytes = std::fs::read(&out).expect("the stream");
    assert_eq!(bytes.len(), 47 * e.packets);

    let log = read_log(&resolve_log("intel/intel-raw-part.clf").expect("log")).expect("reads");
    let scans = front_scans(&log);
    let lidar = host_sim::domain::grid::carmen_lidar(180);
    let setup = Ld06Setup {
        // The SICK's readings reach 81.8 m (no return); the LD06's 12 m would drop some.
        max_range: 65.0,
        ..Ld06Setup::LD06
    };
    let mut decoder = Ld06Decoder::new();
    let mut binner = RevolutionBinner::<360>::new(setup).expect("valid setup");
    let mut revolution = 0;
    let mut worst = 0.0f32;
    for &b in &bytes {
        let Some(p) = decoder.push(b) else { continue };
        if !binner.push(&p) {
            continue;
        }
        // A revolution ended: it is scan `revolution` of the log.
        let back = binner.scan();
        let laser = &scans[revolution];
        for (i, &r) in laser.ranges.iter().enumerate() {
            // Beam i at −90° + i counter-clockwise: bin (270 + i) mod 360.
            let got = back.ranges[(270 + i) % 360];
            // Usable for the SICK's geometry and within the binner's range.
            if lidar.classify(r) == BeamStatus::Valid && r < 65.0 {
                worst = worst.max((got - r).abs());
            } else {
                assert_eq!(got, EMPTY_BIN, "scan {revolution} beam {i}: {r} m");
            }
        }
        revolution += 1;
    }
    let c = decoder.counters();
    assert_eq!(
        (c.packets as usize, c.skipped_bytes, c.bad_crc),
        (e.packets, 0, 0)
    );
    // The last revolution ends only when a next one begins.
    assert_eq!(revolution, n - 1);
    // Millimetres: half a millimetre of rounding, and f32's steps at 10 m.
    assert!(worst <= 0.000_51, "{worst} m");
}

#[test]
fn a_log_whose_beams_make_no_whole_turn_is_refused_naming_the_scan() {
    let dir = tempfile::tempdir().expect("temporary folder");
    let err = export(
        "mit-csail/csail-raw.log.gz",
        &dir.path().join("mit.ld06"),
        Some(2),
    )
    .expect_err("361 beams over 180° are not a whole number of points a turn");
    let text = format!("{err:#}");
    assert!(
        text.contains("csail-raw.log.gz: scan 0 (361 beams)"),
        "{text}"
    );
}
