//! Estimator settings from TOML files, with documented per-dataset defaults in
//! `host-sim/configs/`.
