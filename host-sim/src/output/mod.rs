//! Files written after a run: TUM trajectories, `metrics.json`, PNG pictures.

pub mod grid_map;
