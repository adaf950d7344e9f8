//! Where the shared datasets live: the one helper every reader and test goes through.
//!
//! The folder is `$SLAM_DATASETS` when that variable is set, otherwise
//! `<workspace root>/../shared/datasets` (the workspace root is known at compile time).
//! The datasets are never copied into the repository.

use anyhow::{Result, bail};
use std::path::{Path, PathBuf};

/// The environment variable naming the datasets folder.
pub const DATASETS_ENV: &str = "SLAM_DATASETS";

/// The default datasets folder: `<workspace root>/../shared/datasets`.
pub fn default_dir() -> PathBuf {
    // CARGO_MANIFEST_DIR is `<workspace>/host-sim`.
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/datasets")
}

/// The datasets folder, checked to exist.
///
/// Fails with a message that names the path it tried and the variable to set.
pub fn datasets_dir() -> Result<PathBuf> {
    let (dir, from_env) = match std::env::var_os(DATASETS_ENV) {
        Some(v) if !v.is_empty() => (PathBuf::from(v), true),
        _ => (default_dir(), false),
    };
    if !dir.is_dir() {
        let origin = if from_env {
            format!("from ${DATASETS_ENV}")
        } else {
            format!("the default; set ${DATASETS_ENV} to the datasets folder to change it")
        };
        bail!("datasets folder not found: {} ({origin})", dir.display());
    }
    Ok(dir.canonicalize().unwrap_or(dir))
}

/// A dataset path: `spec` itself when it names an existing folder, otherwise
/// `<datasets>/<family>/<spec>` (e.g. `mrclam` + `dataset6`).
pub fn resolve(family: &str, spec: &str) -> Result<PathBuf> {
    let direct = PathBuf::from(spec);
    if direct.is_dir() {
        return Ok(direct);
    }
    let dir = datasets_dir()?.join(family).join(spec);
    if !dir.is_dir() {
        bail!(
            "{family} dataset not found: {} (nor {})",
            dir.display(),
            direct.display()
        );
    }
    Ok(dir)
}

/// Like [`datasets_dir`] but joined with `relative`, checked to exist.
pub fn dataset_path(relative: impl AsRef<Path>) -> Result<PathBuf> {
    let p = datasets_dir()?.join(relative.as_ref());
    if !p.exists() {
        bail!("dataset file not found: {}", p.display());
    }
    Ok(p)
}
