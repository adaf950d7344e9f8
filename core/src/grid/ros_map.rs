//! Reading a ROS `map_server` map (`map.yaml` next to a binary PGM) into log-odds cells
//! (feature `std`): the one reader of the host tools and of the firmware's build script.
//!
//! Grey levels become occupancy probabilities `p = 1 − grey/255` (black occupied, white
//! free, ROS' 205 unknown-grey a weak free), then log-odds in the [`LogOdds`] unit,
//! rounded and clamped to its limits. Rows are flipped: the PGM's first row is the top
//! of the map, the grid's row 0 its bottom.

use super::{GridGeometry, LogOdds};
use std::fmt;
use std::path::{Path, PathBuf};
use std::string::{String, ToString};
use std::vec::Vec;

/// A map read from `map.yaml` + PGM.
#[derive(Clone, Debug, PartialEq)]
pub struct RosMap {
    /// Log-odds cells, row-major, row 0 at the bottom (world y grows with the row).
    pub cells: Vec<i8>,
    /// Size, resolution and origin (the yaml's `origin` x and y; its yaw must be 0).
    pub geometry: GridGeometry,
}

/// Why a map could not be read: the file and what is wrong in it.
#[derive(Debug)]
pub struct RosMapError {
    /// The file at fault.
    pub path: PathBuf,
    /// What is wrong (line and field where there is one).
    pub message: String,
}

impl fmt::Display for RosMapError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for RosMapError {}

fn error(path: &Path, message: impl Into<String>) -> RosMapError {
    RosMapError {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

impl RosMap {
    /// Reads `yaml` (fields `image`, `resolution`, `origin`; `negate: 1` inverts the
    /// grey levels) and the PGM it names (relative to the yaml's folder).
    pub fn read(yaml: &Path, log_odds: &LogOdds) -> Result<Self, RosMapError> {
        let text = std::fs::read_to_string(yaml).map_err(|e| error(yaml, e.to_string()))?;
        let mut image = None;
        let mut resolution = None;
        let mut origin = None;
        let mut negate = false;
        for (n, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("");
            let Some((k, v)) = line.split_once(':') else {
                continue;
            };
            let (k, v) = (k.trim(), v.trim());
            let bad = |what: &str| error(yaml, format!("line {}: field `{k}`: {what}", n + 1));
            match k {
                "image" => image = Some(v.trim_matches(['"', '\'']).to_string()),
                "resolution" => {
                    let r: f32 = v.parse().map_err(|_| bad("not a number"))?;
                    if !(r.is_finite() && r > 0.0) {
                        return Err(bad("must be positive"));
                    }
                    resolution = Some(r);
                }
                "origin" => {
                    let parts: Result<Vec<f32>, _> = v
                        .trim_matches(['[', ']'])
                        .split(',')
                        .map(|s| s.trim().parse::<f32>())
                        .collect();
                    match parts.map_err(|_| bad("expected [x, y, yaw]"))?[..] {
                        [x, y] | [x, y, 0.0] => origin = Some((x, y)),
                        [_, _, _] => return Err(bad("a rotated map (yaw ≠ 0) is not supported")),
                        _ => return Err(bad("expected [x, y, yaw]")),
                    }
                }
                "negate" => negate = v == "1" || v == "true",
                _ => {}
            }
        }
        let missing = |f: &str| error(yaml, format!("field `{f}` is missing"));
        let image = image.ok_or_else(|| missing("image"))?;
        let resolution = resolution.ok_or_else(|| missing("resolution"))?;
        let (origin_x, origin_y) = origin.ok_or_else(|| missing("origin"))?;
        let pgm_path = yaml.parent().unwrap_or(Path::new(".")).join(image);
        let bytes = std::fs::read(&pgm_path).map_err(|e| error(&pgm_path, e.to_string()))?;
        let (width, height, pixels) = parse_pgm(&bytes).map_err(|m| error(&pgm_path, m))?;
        let unit = f64::from(log_odds.nats_per_unit());
        let mut cells = Vec::with_capacity(width * height);
        for row in pixels.chunks_exact(width).rev() {
            for &grey in row {
                let grey = if negate { 255 - grey } else { grey };
                let p = (1.0 - f64::from(grey) / 255.0).clamp(1e-6, 1.0 - 1e-6);
                let l = (p / (1.0 - p)).ln() / unit;
                cells.push(
                    l.round()
                        .clamp(f64::from(log_odds.min), f64::from(log_odds.max))
                        as i8,
                );
            }
        }
        let geometry = GridGeometry {
            width,
            height,
            resolution,
            origin_x,
            origin_y,
        };
        if !geometry.is_valid() {
            return Err(error(
                yaml,
                "geometry is invalid (size, resolution or origin)",
            ));
        }
        Ok(Self { cells, geometry })
    }
}

/// Width, height and the `width × height` pixels of a binary 8-bit PGM (`P5`).
fn parse_pgm(bytes: &[u8]) -> Result<(usize, usize, &[u8]), String> {
    let mut fields: Vec<&[u8]> = Vec::new();
    let mut i = 0;
    while fields.len() < 4 && i < bytes.len() {
        match bytes.get(i) {
            Some(b) if b.is_ascii_whitespace() => i += 1,
            Some(b'#') => {
                while bytes.get(i).is_some_and(|&b| b != b'\n') {
                    i += 1;
                }
            }
            Some(_) => {
                let s = i;
                while bytes.get(i).is_some_and(|b| !b.is_ascii_whitespace()) {
                    i += 1;
                }
                fields.push(bytes.get(s..i).unwrap_or(&[]));
            }
            None => break,
        }
    }
    // Exactly one whitespace byte separates the header from the pixels.
    i += 1;
    let [magic, w, h, max] = fields[..] else {
        return Err("PGM header is incomplete".into());
    };
    if magic != b"P5" {
        return Err("not a binary PGM (P5)".into());
    }
    let number = |f: &[u8], what: &str| -> Result<usize, String> {
        std::str::from_utf8(f)
            .ok()
            .and_then(|s| s.parse().ok())
            .filter(|&n| n > 0)
            .ok_or_else(|| format!("PGM {what} is not a positive number"))
    };
    let (w, h) = (number(w, "width")?, number(h, "height")?);
    if number(max, "maximum grey")? > 255 {
        return Err("16-bit PGM is not supported".into());
    }
    let n = w.checked_mul(h).ok_or("PGM size overflows")?;
    let pixels = i
        .checked_add(n)
        .and_then(|end| bytes.get(i..end))
        .ok_or_else(|| format!("PGM is truncated: {n} pixels expected"))?;
    Ok((w, h, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, yaml: &str, pgm: &[u8]) -> PathBuf {
        std::fs::write(dir.join("m.pgm"), pgm).unwrap();
        let p = dir.join("m.yaml");
        std::fs::write(&p, yaml).unwrap();
        p
    }

    #[test]
    fn reads_a_map_bottom_row_first() {
        let dir = std::env::temp_dir().join(format!("ros_map_ok_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut pgm = b"P5\n# comment\n3 2\n255\n".to_vec();
        pgm.extend_from_slice(&[0, 255, 205, 255, 255, 0]);
        let yaml = "image: m.pgm\nresolution: 0.1\norigin: [-1.0, 2.0, 0.0]\nnegate: 0\n";
        let map = RosMap::read(&write(&dir, yaml, &pgm), &LogOdds::SEED).unwrap();
        assert_eq!(map.geometry.width, 3);
        assert_eq!(map.geometry.origin_y, 2.0);
        // Row 0 is the PGM's last row: white, white, black.
        assert_eq!(map.cells[2], 100);
        assert_eq!(map.cells[0], -100);
        // The top row's black corner.
        assert_eq!(map.cells[3], 100);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn errors_name_the_file_and_field() {
        let dir = std::env::temp_dir().join(format!("ros_map_bad_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let pgm = b"P5\n3 2\n255\n\0\0\0".to_vec();
        let p = write(
            &dir,
            "image: m.pgm\nresolution: x\norigin: [0, 0, 0]\n",
            &pgm,
        );
        let e = RosMap::read(&p, &LogOdds::SEED).unwrap_err().to_string();
        assert!(
            e.contains("m.yaml") && e.contains("line 2") && e.contains("resolution"),
            "{e}"
        );
        let p = write(
            &dir,
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n",
            &pgm,
        );
        let e = RosMap::read(&p, &LogOdds::SEED).unwrap_err().to_string();
        assert!(e.contains("m.pgm") && e.contains("truncated"), "{e}");
        let p = write(&dir, "image: m.pgm\norigin: [0, 0, 0]\n", &pgm);
        let e = RosMap::read(&p, &LogOdds::SEED).unwrap_err().to_string();
        assert!(e.contains("`resolution` is missing"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
