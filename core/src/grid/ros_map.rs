//! Reading a ROS `map_server` map (`map.yaml` next to a binary PGM) into log-odds cells
//! (feature `std`): the one reader of the host tools and of the firmware's build script.
//!
//! Grey levels become occupancy probabilities `p = 1 − grey/maxval` (black occupied,
//! white free, ROS' 205 unknown-grey a weak free), then log-odds in the [`LogOdds`] unit,
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
    /// The bitmap of the cells above `occupied_above` ([`super::fill_occupancy_bits`]),
    /// for [`super::GridView::with_occupancy_bits`]: a view with it runs the sparse shift
    /// search, the one a map image in flash runs on the device (the same scores as the
    /// byte-wise search over the cells, in fewer instructions).
    pub fn occupancy_bits(&self, occupied_above: i8) -> Vec<u8> {
        let (w, h) = (self.geometry.width, self.geometry.height);
        let mut bits = std::vec![0u8; super::occupancy_bytes(w, h)];
        // `read` made `cells` width × height long; a hand-built map of another length
        // gets an empty bitmap, which `with_occupancy_bits` refuses with a clear error.
        if super::fill_occupancy_bits(&self.cells, w, h, occupied_above, &mut bits).is_err() {
            bits.clear();
        }
        bits
    }

    /// Reads `yaml` (fields `image`, `resolution`, `origin`; `negate: 1` inverts the
    /// grey levels; `mode` `trinary` or `scale`, the thresholds) and the PGM it names
    /// (relative to the yaml's folder). A line that is not `field: value`, a field given
    /// twice, a field map_server does not know and `mode: raw` (grey levels as occupancy
    /// values, which this reader would turn upside down) are refused with their line.
    pub fn read(yaml: &Path, log_odds: &LogOdds) -> Result<Self, RosMapError> {
        let text = std::fs::read_to_string(yaml).map_err(|e| error(yaml, e.to_string()))?;
        let mut image = None;
        let mut resolution = None;
        let mut origin = None;
        let mut negate = false;
        // (value, line) of `occupied_thresh` and `free_thresh`.
        let mut thresholds: [Option<(f64, usize)>; 2] = [None, None];
        // (field, line) of every field read so far.
        let mut seen: Vec<(String, usize)> = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let line = line.split('#').next().unwrap_or("");
            if line.trim().is_empty() {
                continue;
            }
            let Some((k, v)) = line.split_once(':') else {
                return Err(error(
                    yaml,
                    format!(
                        "line {}: expected `field: value`, got `{}`",
                        n + 1,
                        line.trim()
                    ),
                ));
            };
            let (k, v) = (k.trim(), v.trim());
            let bad = |what: &str| error(yaml, format!("line {}: field `{k}`: {what}", n + 1));
            if let Some((_, first)) = seen.iter().find(|(f, _)| f == k) {
                return Err(bad(&format!("given twice (first at line {first})")));
            }
            seen.push((k.to_string(), n + 1));
            match k {
                "image" => {
                    let name = v.trim_matches(['"', '\'']);
                    if name.is_empty() {
                        return Err(bad("names no image file"));
                    }
                    image = Some(name.to_string());
                }
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
                        [x, y] | [x, y, 0.0]
                            if !(x.is_finite()
                                && y.is_finite()
                                && f64::from(x.abs().max(y.abs()))
                                    <= crate::geometry::MAX_COORDINATE_M) =>
                        {
                            return Err(bad(
                                "must be finite and within 100 km of the frame's origin",
                            ));
                        }
                        [x, y] | [x, y, 0.0] => origin = Some((x, y)),
                        [_, _, _] => return Err(bad("a rotated map (yaw ≠ 0) is not supported")),
                        _ => return Err(bad("expected [x, y, yaw]")),
                    }
                }
                "negate" => {
                    negate = match v {
                        "0" | "false" => false,
                        "1" | "true" => true,
                        _ => return Err(bad("must be 0 or 1")),
                    }
                }
                // Read by `map_server` to make a trinary map; not used here, but a value
                // no probability can have is an error in the file.
                "occupied_thresh" | "free_thresh" => {
                    let t: f64 = v.parse().map_err(|_| bad("not a number"))?;
                    if !(0.0..=1.0).contains(&t) {
                        return Err(bad("a probability threshold must be within 0 ..= 1"));
                    }
                    thresholds[usize::from(k == "free_thresh")] = Some((t, n + 1));
                }
                // How map_server turns grey levels into occupancy: `trinary` (its default)
                // and `scale` read a grey level as a probability, as this reader does;
                // `raw` takes it as the occupancy value itself (0 free … 100 occupied).
                "mode" => match v.trim_matches(['"', '\'']) {
                    "trinary" | "scale" => {}
                    "raw" => {
                        return Err(bad(
                            "`raw` (grey levels as occupancy values 0–100) is not read: \
                             save the map in `trinary` or `scale` mode",
                        ));
                    }
                    _ => return Err(bad("must be trinary, scale or raw")),
                },
                _ => {
                    return Err(bad(
                        "not a map_server field (image, mode, resolution, origin, negate, \
                         occupied_thresh, free_thresh)",
                    ));
                }
            }
        }
        if let [Some((occupied, _)), Some((free, line))] = thresholds
            && free > occupied
        {
            return Err(error(
                yaml,
                format!(
                    "line {line}: field `free_thresh`: {free} is above `occupied_thresh` {occupied}"
                ),
            ));
        }
        let missing = |f: &str| error(yaml, format!("field `{f}` is missing"));
        let image = image.ok_or_else(|| missing("image"))?;
        let resolution = resolution.ok_or_else(|| missing("resolution"))?;
        let (origin_x, origin_y) = origin.ok_or_else(|| missing("origin"))?;
        let pgm_path = yaml.parent().unwrap_or(Path::new(".")).join(image);
        let bytes = std::fs::read(&pgm_path).map_err(|e| {
            error(
                &pgm_path,
                format!("{e} (the field `image` of {})", yaml.display()),
            )
        })?;
        let pgm = parse_pgm(&bytes).map_err(|m| error(&pgm_path, m))?;
        let (width, height) = (pgm.width, pgm.height);
        let unit = f64::from(log_odds.nats_per_unit());
        let maxval = f64::from(pgm.maxval);
        let mut cells = Vec::with_capacity(width * height);
        // map_server's trinary reading: occupied above `occupied_thresh`, free below
        // `free_thresh` (its defaults when the file gives none).
        let occupied_above = thresholds[0].map_or(0.65, |(t, _)| t);
        let free_below = thresholds[1].map_or(0.196, |(t, _)| t);
        let (mut occupied, mut free) = (0usize, 0usize);
        for row in pgm.pixels.chunks_exact(width).rev() {
            for &grey in row {
                let white = (f64::from(grey) / maxval).min(1.0);
                let white = if negate { 1.0 - white } else { white };
                let p = (1.0 - white).clamp(1e-6, 1.0 - 1e-6);
                occupied += usize::from(p > occupied_above);
                free += usize::from(p < free_below);
                let l = (p / (1.0 - p)).ln() / unit;
                cells.push(
                    l.round()
                        .clamp(f64::from(log_odds.min), f64::from(log_odds.max))
                        as i8,
                );
            }
        }
        if occupied + free >= MIN_KNOWN_CELLS_TO_JUDGE && occupied > free {
            return Err(error(
                &pgm_path,
                format!(
                    "{occupied} of its {} known cells are occupied and {free} free, read with \
                     `negate: {}` ({}): a map a robot made is mostly free space, so its \
                     grey levels look inverted; check `negate`",
                    occupied + free,
                    u8::from(negate),
                    yaml.display()
                ),
            ));
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

/// A map with at least this many known (occupied or free) cells must have more free cells
/// than occupied ones, or [`RosMap::read`] refuses it as inverted (`negate` set wrongly):
/// a lidar's rays clear far more cells than their end points fill (the maps `host-sim
/// replay` makes of the Intel lab, MIT CSAIL and ACES: 5.7 %, 4.0 % and 0.7 % of their
/// known cells occupied). Smaller maps (hand-made test patterns) are not judged.
pub const MIN_KNOWN_CELLS_TO_JUDGE: usize = 1000;

/// Largest map [`RosMap::read`] accepts, cells (a 16 384 × 16 384 grid: 256 MB of `i8`).
pub const MAX_MAP_CELLS: usize = 1 << 28;

/// A binary 8-bit PGM image.
#[derive(Debug, PartialEq)]
pub struct Pgm<'a> {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// The grey level of white (1 ..= 255).
    pub maxval: u8,
    /// `width · height` grey levels, row by row from the top.
    pub pixels: &'a [u8],
}

/// Parses a binary PGM (`P5`, 8-bit): the header (magic, width, height, maxval, with
/// `#` comments) and exactly `width · height` pixel bytes after it. Refused: another
/// magic, a missing or non-numeric field, a size of zero or above [`MAX_MAP_CELLS`],
/// `maxval` outside 1 ..= 255 (16-bit PGMs are not read), fewer or more pixel bytes.
pub fn parse_pgm(bytes: &[u8]) -> Result<Pgm<'_>, String> {
    let mut fields: Vec<&[u8]> = Vec::with_capacity(4);
    let mut i = 0;
    while fields.len() < 4 {
        match bytes.get(i) {
            None => break,
            Some(b) if b.is_ascii_whitespace() => i += 1,
            Some(b'#') => {
                while bytes.get(i).is_some_and(|&b| b != b'\n') {
                    i += 1;
                }
            }
            Some(_) => {
                let start = i;
                while bytes.get(i).is_some_and(|b| !b.is_ascii_whitespace()) {
                    i += 1;
                }
                fields.push(bytes.get(start..i).unwrap_or_default());
            }
        }
    }
    let [magic, width, height, maxval] = fields[..] else {
        return Err(if fields.first() == Some(&b"P5".as_slice()) {
            "PGM header ends early: needs width, height and maxval".into()
        } else {
            "not a binary PGM (no P5 magic)".into()
        });
    };
    if magic != b"P5" {
        return Err("not a binary PGM (no P5 magic)".into());
    }
    let number = |field: &[u8], what: &str| -> Result<usize, String> {
        std::str::from_utf8(field)
            .ok()
            .and_then(|s| s.parse::<usize>().ok())
            .ok_or_else(|| {
                format!(
                    "PGM {what} `{}` is not a whole number",
                    String::from_utf8_lossy(field)
                )
            })
    };
    let (width, height) = (number(width, "width")?, number(height, "height")?);
    let maxval = number(maxval, "maxval")?;
    let cells = width
        .checked_mul(height)
        .filter(|&n| n > 0 && n <= MAX_MAP_CELLS)
        .ok_or_else(|| {
            format!("PGM size {width} × {height} is empty or larger than {MAX_MAP_CELLS} cells")
        })?;
    let maxval = u8::try_from(maxval)
        .ok()
        .filter(|&m| m > 0)
        .ok_or_else(|| format!("PGM maxval {maxval} is not in 1 ..= 255 (8-bit PGMs only)"))?;
    // One whitespace byte separates the header from the pixels, which must be exactly
    // as many as the header says: fewer is a truncated file, more a header that does
    // not describe the data (or a second image, which a map does not have).
    let start = i + 1;
    let data = bytes.len().saturating_sub(start);
    if data < cells {
        return Err(format!(
            "PGM is truncated: {data} pixel bytes for {width} × {height}"
        ));
    }
    if data > cells {
        return Err(format!(
            "PGM has {data} pixel bytes, {} more than its header's {width} × {height}",
            data - cells
        ));
    }
    let pixels = bytes.get(start..).unwrap_or_default();
    Ok(Pgm {
        width,
        height,
        maxval,
        pixels,
    })
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
        let map = RosMap::read(&write(&dir, yaml, &pgm), &LogOdds::SYMMETRIC).unwrap();
        assert_eq!(map.geometry.width, 3);
        assert_eq!(map.geometry.origin_y, 2.0);
        // Row 0 is the PGM's last row: white, white, black.
        assert_eq!(map.cells[2], 100);
        assert_eq!(map.cells[0], -100);
        // The top row's black corner.
        assert_eq!(map.cells[3], 100);
        // The bitmap: one byte per 3-cell row, the black cells (2, 0) and (0, 1) set.
        assert_eq!(map.occupancy_bits(0), [0b100, 0b001]);
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
        let e = RosMap::read(&p, &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("m.yaml") && e.contains("line 2") && e.contains("resolution"),
            "{e}"
        );
        let p = write(
            &dir,
            "image: m.pgm\nresolution: 0.05\norigin: [0, 0, 0]\n",
            &pgm,
        );
        let e = RosMap::read(&p, &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.pgm") && e.contains("truncated"), "{e}");
        let p = write(&dir, "image: m.pgm\norigin: [0, 0, 0]\n", &pgm);
        let e = RosMap::read(&p, &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(e.contains("`resolution` is missing"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `m.yaml` + `m.pgm` in a fresh temporary folder named after `tag`.
    fn files(tag: &str, yaml: &str, pgm: &[u8]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("ros_map_{tag}_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        write(&dir, yaml, pgm)
    }

    const YAML: &str = "image: m.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\n";

    /// Asserts that [`YAML`] followed by `extra` (its lines from line 4), with `pgm`, is
    /// refused naming `m.yaml`, the message ending in `why`.
    fn refused_with(tag: &str, extra: &str, pgm: &[u8], why: &str) {
        let yaml = files(tag, &format!("{YAML}{extra}"), pgm);
        let error = RosMap::read(&yaml, &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(error.contains("m.yaml") && error.ends_with(why), "{error}");
    }

    #[test]
    fn maxval_is_white() {
        // maxval 100: grey 100 is white (free), 0 black (occupied), 50 unknown.
        let mut pgm = b"P5\n3 1\n100\n".to_vec();
        pgm.extend_from_slice(&[100, 0, 50]);
        let map = RosMap::read(&files("maxval", YAML, &pgm), &LogOdds::SYMMETRIC).unwrap();
        assert_eq!((map.geometry.width, map.geometry.height), (3, 1));
        assert_eq!((map.geometry.origin_x, map.geometry.origin_y), (-1.0, -2.0));
        assert_eq!(
            map.cells,
            [LogOdds::SYMMETRIC.min, LogOdds::SYMMETRIC.max, 0]
        );
        // Negated: 100 is black.
        let yaml = format!("{YAML}negate: 1\n");
        let map = RosMap::read(&files("negate", &yaml, &pgm), &LogOdds::SYMMETRIC).unwrap();
        assert_eq!(
            map.cells,
            [LogOdds::SYMMETRIC.max, LogOdds::SYMMETRIC.min, 0]
        );
    }

    #[test]
    fn a_map_read_inverted_is_refused_naming_negate() {
        // A 40 x 40 room: walls (black) around free space (white), unknown outside.
        let mut pgm = b"P5\n40 40\n255\n".to_vec();
        for y in 0..40 {
            for x in 0..40 {
                let wall = x == 0 || y == 0 || x == 39 || y == 39;
                pgm.push(if wall { 0 } else { 254 });
            }
        }
        RosMap::read(&files("room", YAML, &pgm), &LogOdds::SYMMETRIC).unwrap();
        let yaml = format!("{YAML}negate: 1\n");
        let error = RosMap::read(&files("room-negated", &yaml, &pgm), &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(error.contains("m.pgm"), "{error}");
        assert!(
            error.contains(
                "1444 of its 1600 known cells are occupied and 156 free, read with `negate: 1`"
            ),
            "{error}"
        );
    }

    #[test]
    fn an_origin_not_finite_or_beyond_100_km_is_refused_with_its_line() {
        let pgm = b"P5\n1 1\n255\n\0";
        for origin in ["[nan, 0, 0]", "[0, 1e30, 0]", "[-2e5, 0]"] {
            let yaml = format!("image: m.pgm\nresolution: 0.05\norigin: {origin}\n");
            let error = RosMap::read(&files("origin", &yaml, pgm), &LogOdds::SYMMETRIC)
                .unwrap_err()
                .to_string();
            assert!(
                error.contains("line 3: field `origin`: must be finite and within 100 km"),
                "{origin}: {error}"
            );
        }
    }

    #[test]
    fn an_image_field_naming_no_file_is_refused_with_its_line() {
        let pgm = b"P5\n1 1\n255\n\0";
        let yaml = "image:\nresolution: 0.05\norigin: [0, 0, 0]\n";
        let error = RosMap::read(&files("no-image", yaml, pgm), &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("m.yaml: line 1: field `image`: names no image file"),
            "{error}"
        );
        let yaml = "image: .\nresolution: 0.05\norigin: [0, 0, 0]\n";
        let error = RosMap::read(&files("image-folder", yaml, pgm), &LogOdds::SYMMETRIC)
            .unwrap_err()
            .to_string();
        assert!(error.contains("(the field `image` of "), "{error}");
    }

    #[test]
    fn bad_headers_are_refused_with_the_file_name() {
        let cases: [(&[u8], &str); 9] = [
            (b"P2\n1 1\n255\n\0", "no P5"),
            (b"", "no P5"),
            (b"P5\n1 1\n", "ends early"),
            (b"P5\n18446744073709551615 2\n255\n", "larger than"),
            (b"P5\n0 5\n255\n", "empty"),
            (b"P5\n2 2\n65535\n\0\0\0\0\0\0\0\0", "maxval 65535"),
            (b"P5\n2 2\n0\n\0\0\0\0", "maxval 0"),
            (b"P5\n4 4\n255\n\0\0\0", "truncated"),
            (
                b"P5\n2 1\n255\n\0\0\0",
                "PGM has 3 pixel bytes, 1 more than its header's 2 × 1",
            ),
        ];
        for (n, (bytes, why)) in cases.into_iter().enumerate() {
            let yaml = files(&format!("header{n}"), YAML, bytes);
            let error = RosMap::read(&yaml, &LogOdds::SYMMETRIC)
                .unwrap_err()
                .to_string();
            assert!(error.contains("m.pgm"), "{why}: {error}");
            assert!(error.contains(why), "{why}: {error}");
        }
    }

    #[test]
    fn thresholds_and_negate_out_of_range_are_refused_with_their_line() {
        let pgm = b"P5\n1 1\n255\n\0";
        for (n, (extra, why)) in [
            (
                "occupied_thresh: 1.5\n",
                "line 4: field `occupied_thresh`: a probability threshold must be within 0 ..= 1",
            ),
            (
                "free_thresh: -0.2\n",
                "line 4: field `free_thresh`: a probability threshold must be within 0 ..= 1",
            ),
            (
                "occupied_thresh: 0.2\nfree_thresh: 0.65\n",
                "line 5: field `free_thresh`: 0.65 is above `occupied_thresh` 0.2",
            ),
            ("negate: 2\n", "line 4: field `negate`: must be 0 or 1"),
        ]
        .into_iter()
        .enumerate()
        {
            refused_with(&format!("thresh{n}"), extra, pgm, why);
        }
        let ok = format!("{YAML}occupied_thresh: 0.65\nfree_thresh: 0.196\nnegate: 0\n");
        assert!(RosMap::read(&files("thresh-ok", &ok, pgm), &LogOdds::SYMMETRIC).is_ok());
    }

    #[test]
    fn unknown_repeated_or_malformed_fields_and_raw_mode_are_refused_with_their_line() {
        let pgm = b"P5\n1 1\n255\n\xff";
        for (n, (extra, why)) in [
            (
                "resolutoin: 0.1\n",
                "line 4: field `resolutoin`: not a map_server field (image, mode, resolution, \
                 origin, negate, occupied_thresh, free_thresh)",
            ),
            (
                "resolution: 0.1\n",
                "line 4: field `resolution`: given twice (first at line 2)",
            ),
            (
                "negate 1\n",
                "line 4: expected `field: value`, got `negate 1`",
            ),
            (
                "mode: raw\n",
                "line 4: field `mode`: `raw` (grey levels as occupancy values 0–100) is not \
                 read: save the map in `trinary` or `scale` mode",
            ),
            (
                "mode: bitmap\n",
                "line 4: field `mode`: must be trinary, scale or raw",
            ),
        ]
        .into_iter()
        .enumerate()
        {
            refused_with(&format!("fields{n}"), extra, pgm, why);
        }
        // What map_server writes, comments and blank lines included, is read.
        for (n, mode) in ["trinary", "scale"].into_iter().enumerate() {
            let ok = format!("# a map\n\n{YAML}mode: {mode}\nnegate: 0  # white free\n");
            let map = RosMap::read(&files(&format!("mode{n}"), &ok, pgm), &LogOdds::SYMMETRIC);
            assert!(map.is_ok(), "{mode}: {map:?}");
        }
    }
}
