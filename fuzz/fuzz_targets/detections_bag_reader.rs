#![no_main]
//! See `microslam_replay_tests::fuzzing::detections_bag_reader` for what is checked.
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    microslam_replay_tests::fuzzing::detections_bag_reader(data)
});
