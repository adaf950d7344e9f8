//! The plain landmark log (`landmarks:<file>`): a user's own landmark recording, one
//! record per line, for the landmark EKF-SLAM (issue 60; the format is documented in
//! docs/guide.md, "Your own landmark recordings").
//!
//! ```text
//! # comments and blank lines are skipped; fields are separated by white space
//! velocity  t v ω          # m/s, rad/s, held until the next motion record
//! increment t dx dy dθ     # odometry increment since the previous motion record (robot frame)
//! ackermann t v φ          # rear-axle speed m/s, front steering angle rad ([vehicle] settings)
//! sighting  t range bearing id   # m, rad; id a whole number, or - for none
//! truth     t x y θ        # optional ground truth (ATE)
//! landmark  id x y         # optional true landmark positions (map error)
//! ```
//!
//! Stamps (s) never decrease within a record type; records of different types may
//! interleave and are merged in stamp order (equal stamps keep file order). Sightings
//! before the first motion record are skipped and counted
//! ([`Recording::dropped_sightings`]). Every bad input is a [`ReadError`] naming the
//! file, the line and the field.

use super::text::{ReadError, invalid};
use crate::domain::recording::{Recording, TrueLandmark, TruePose, interpolate_pose};
use microslam::event::{Event, EventKind, Identity, Sighting};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// The record types and their fields after the type, as the format names them.
pub const RECORDS: [(&str, &[&str]); 6] = [
    ("velocity", &["t", "v", "ω"]),
    ("increment", &["t", "dx", "dy", "dθ"]),
    ("ackermann", &["t", "v", "φ"]),
    ("sighting", &["t", "range", "bearing", "id"]),
    ("truth", &["t", "x", "y", "θ"]),
    ("landmark", &["id", "x", "y"]),
];

/// Largest |x|, |y| of a position, m (as the other readers: beyond it an `f32` filter
/// loses its centimetres).
const MAX_COORDINATE_M: f64 = super::carmen::MAX_COORDINATE_M;

/// Largest |bearing|, rad: one turn (the filter refuses more as corrupt).
const MAX_BEARING: f64 = 2.0 * std::f64::consts::PI;

/// Reads the plain landmark log `path`.
pub fn read(path: &Path) -> Result<Recording, ReadError> {
    let text = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_owned(),
        source,
    })?;
    let text = String::from_utf8(text).map_err(|e| {
        let valid = e.as_bytes().get(..e.utf8_error().valid_up_to());
        let line = 1 + valid.unwrap_or(&[]).iter().filter(|&&b| b == b'\n').count();
        invalid(path, line, "not UTF-8 text".to_owned())
    })?;
    parse(path, &text)
}

/// One line's fields after the record type, with what names them in errors.
struct Fields<'a> {
    path: &'a Path,
    line: usize,
    record: &'static str,
    names: &'static [&'static str],
    values: Vec<&'a str>,
}

impl Fields<'_> {
    fn error(&self, field: usize, why: impl std::fmt::Display) -> ReadError {
        let name = self.names.get(field).copied().unwrap_or("?");
        invalid(
            self.path,
            self.line,
            format!("{} field {} ({name}): {why}", self.record, field + 2),
        )
    }

    /// Field `i` (0-based after the type) as a finite number.
    fn number(&self, i: usize) -> Result<f64, ReadError> {
        let text = self.values.get(i).copied().unwrap_or("");
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(self.error(i, format_args!("`{}` is not finite", shown(text)))),
            Err(_) => Err(self.error(i, format_args!("`{}` is not a number", shown(text)))),
        }
    }

    /// Field `i` as a position coordinate (within 100 km of the origin).
    fn coordinate(&self, i: usize) -> Result<f64, ReadError> {
        let v = self.number(i)?;
        if v.abs() > MAX_COORDINATE_M {
            return Err(self.error(i, format_args!("{v} m is beyond 100 km of the origin")));
        }
        Ok(v)
    }

    /// Field `i` as a landmark id: a whole number `0 ..= u32::MAX`.
    fn id(&self, i: usize) -> Result<u32, ReadError> {
        let text = self.values.get(i).copied().unwrap_or("");
        text.parse::<u32>().map_err(|_| {
            let text = shown(text);
            self.error(
                i,
                format_args!("`{text}` is not a landmark id (a whole number 0 to 4294967295)"),
            )
        })
    }
}

/// At most the first 40 characters of a field, for an error message (a field of a
/// corrupt file may be megabytes long).
fn shown(text: &str) -> &str {
    text.char_indices()
        .nth(40)
        .and_then(|(end, _)| text.get(..end))
        .unwrap_or(text)
}

/// The stamps of one record type, checked line by line.
#[derive(Default)]
struct Order {
    /// The line and stamp of the last record of each type.
    last: HashMap<&'static str, (usize, f64)>,
}

impl Order {
    fn check(&mut self, f: &Fields<'_>, t: f64) -> Result<(), ReadError> {
        if let Some(&(line, last)) = self.last.get(f.record)
            && t < last
        {
            return Err(f.error(
                0,
                format_args!(
                    "time {t} s goes back before line {line}'s {last} s: the stamps of one record type never decrease"
                ),
            ));
        }
        self.last.insert(f.record, (f.line, t));
        Ok(())
    }
}

/// Parses the text of a plain landmark log read from `path` (named in errors).
pub fn parse(path: &Path, text: &str) -> Result<Recording, ReadError> {
    let mut events = Vec::with_capacity(text.len() / 32);
    let mut ground_truth = Vec::new();
    let mut landmarks: Vec<TrueLandmark> = Vec::new();
    let mut landmark_lines: HashMap<u32, usize> = HashMap::new();
    let mut order = Order::default();
    let mut first_motion: Option<f64> = None;
    let mut motions = 0usize;
    let mut sightings = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let content = raw.split_once('#').map_or(raw, |(before, _)| before);
        let mut words = content.split_whitespace();
        let Some(kind) = words.next() else { continue };
        let Some(&(record, names)) = RECORDS.iter().find(|(name, _)| *name == kind) else {
            let known: Vec<&str> = RECORDS.iter().map(|(n, _)| *n).collect();
            let shown: String = kind.chars().take(40).collect();
            return Err(invalid(
                path,
                line,
                format!(
                    "unknown record type `{shown}`: expected one of {}",
                    known.join(", ")
                ),
            ));
        };
        let f = Fields {
            path,
            line,
            record,
            names,
            values: words.collect(),
        };
        if f.values.len() != names.len() {
            return Err(invalid(
                path,
                line,
                format!(
                    "{record} takes {} fields after its type ({}), found {}",
                    names.len(),
                    names.join(" "),
                    f.values.len()
                ),
            ));
        }
        if record == "landmark" {
            let id = f.id(0)?;
            let position = [f.coordinate(1)?, f.coordinate(2)?];
            if let Some(first) = landmark_lines.insert(id, line) {
                return Err(f.error(
                    0,
                    format_args!("landmark {id} is listed twice (first on line {first})"),
                ));
            }
            landmarks.push(TrueLandmark { id, position });
            continue;
        }
        let t = f.number(0)?;
        order.check(&f, t)?;
        let kind = match record {
            "velocity" => EventKind::Velocity {
                v: f.number(1)?,
                omega: f.number(2)?,
            },
            "increment" => {
                EventKind::Increment(Pose2::new(f.number(1)?, f.number(2)?, f.number(3)?))
            }
            "ackermann" => {
                let (v, steering) = (f.number(1)?, f.number(2)?);
                if steering.abs() >= std::f64::consts::FRAC_PI_2 {
                    return Err(f.error(
                        2,
                        format_args!("{steering} rad is not a steering angle (|φ| < π/2)"),
                    ));
                }
                EventKind::Ackermann { v, steering }
            }
            "sighting" => {
                let (range, bearing) = (f.number(1)?, f.number(2)?);
                if range <= 0.0 {
                    return Err(f.error(1, format_args!("{range} m is not a positive range")));
                }
                if bearing.abs() > MAX_BEARING {
                    return Err(f.error(
                        2,
                        format_args!("{bearing} rad is beyond one turn (|bearing| ≤ 2π)"),
                    ));
                }
                let identity = match f.values.get(3) {
                    Some(&"-") => Identity::Unknown,
                    _ => Identity::Unique(f.id(3)?),
                };
                let event = Event::new(
                    t,
                    EventKind::Sighting(Sighting {
                        identity,
                        z: RangeBearing::new(range, bearing),
                        covariance: None,
                    }),
                );
                sightings.push((line, event));
                continue;
            }
            _ => {
                // truth
                let pose = Pose2::new(f.coordinate(1)?, f.coordinate(2)?, f.number(3)?);
                ground_truth.push(TruePose { stamp: t, pose });
                continue;
            }
        };
        motions += 1;
        first_motion = Some(first_motion.map_or(t, |m: f64| m.min(t)));
        events.push((line, Event::new(t, kind)));
    }
    let Some(start) = first_motion else {
        return Err(invalid(
            path,
            text.lines().count().max(1),
            "no motion record (velocity, increment or ackermann): nothing drives the filter"
                .to_owned(),
        ));
    };
    let total = sightings.len();
    sightings.retain(|(_, e)| e.stamp >= start);
    let skipped = total - sightings.len();
    if sightings.is_empty() {
        let mut why = String::from("no sighting to use");
        if skipped > 0 {
            let _ = write!(
                why,
                ": all {skipped} come before the first motion record at {start} s"
            );
        }
        return Err(invalid(path, text.lines().count().max(1), why));
    }
    debug_assert!(motions > 0);
    // One stream in file order, then a stable sort by stamp: records of equal stamps keep
    // their file order.
    let mut merged = events;
    merged.extend(sightings);
    merged.sort_by_key(|(line, _)| *line);
    let mut merged: Vec<Event<f64>> = merged.into_iter().map(|(_, e)| e).collect();
    super::sort_events(&mut merged).map_err(|e| invalid(path, 1, e.to_string()))?;
    let initial_pose = merged
        .first()
        .and_then(|e| interpolate_pose(&ground_truth, e.stamp));
    let name = format!(
        "landmarks/{}",
        path.file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    );
    Ok(Recording {
        name,
        events: merged,
        ground_truth,
        landmarks,
        initial_pose,
        dropped_sightings: skipped,
        dropped_reason: if skipped > 0 {
            format!("{skipped} before the first motion record")
        } else {
            String::new()
        },
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn parsed(text: &str) -> Result<Recording, String> {
        parse(Path::new("log.txt"), text).map_err(|e| e.to_string())
    }

    /// A small log with every record type (used by the writer's test too).
    pub(crate) const GOOD: &str = "# a run\n\
        sighting 0.5 2.0 0.1 7   # before any motion: skipped\n\
        velocity 1.0 0.5 0.0\n\
        truth 1.0 0 0 0\n\
        sighting 1.0 2.0 0.1 7\n\
        ackermann 2.0 1.0 0.1\n\
        sighting 2.5 3.0 -0.2 -\n\
        increment 3.0 0.1 0.0 0.01\n\
        truth 3.0 1 0 0\n\
        landmark 7 2 0.2\n";

    #[test]
    fn a_good_log_reads_in_file_order_with_the_early_sighting_counted() {
        let r = parsed(GOOD).unwrap();
        assert_eq!(r.dropped_sightings, 1);
        let kinds: Vec<&str> = r
            .events
            .iter()
            .map(|e| match e.kind {
                EventKind::Velocity { .. } => "v",
                EventKind::Ackermann { .. } => "a",
                EventKind::Increment(_) => "i",
                EventKind::Sighting(s) if s.identity == Identity::Unknown => "s-",
                EventKind::Sighting(_) => "s",
                _ => "?",
            })
            .collect();
        assert_eq!(kinds, ["v", "s", "a", "s-", "i"]);
        assert_eq!(r.ground_truth.len(), 2);
        assert_eq!(
            r.landmarks,
            vec![TrueLandmark {
                id: 7,
                position: [2.0, 0.2]
            }]
        );
        assert_eq!(r.initial_pose, Some(Pose2::new(0.0, 0.0, 0.0)));
    }

    /// Each bad input is an error naming the file, the line and the field.
    #[test]
    fn bad_input_is_named_by_file_line_and_field() {
        let base = "velocity 1.0 0.5 0.0\nsighting 1.0 2.0 0.1 7\n";
        let cases = [
            ("bogus 1 2\n", "log.txt:3: unknown record type `bogus`"),
            (
                "velocity 2.0 0.5\n",
                "log.txt:3: velocity takes 3 fields after its type (t v ω), found 2",
            ),
            ("velocity 2.0 0.5 0 9\n", "found 4"),
            (
                "velocity 2.0 NaN 0\n",
                "log.txt:3: velocity field 3 (v): `NaN` is not finite",
            ),
            (
                "velocity 2.0 0.1 inf\n",
                "log.txt:3: velocity field 4 (ω): `inf` is not finite",
            ),
            ("velocity 2.0 0.1 x\n", "field 4 (ω): `x` is not a number"),
            (
                "velocity 0.5 0.1 0\n",
                "log.txt:3: velocity field 2 (t): time 0.5 s goes back before line 1's 1 s",
            ),
            (
                "sighting 2.0 -1 0.1 7\n",
                "log.txt:3: sighting field 3 (range): -1 m is not a positive range",
            ),
            ("sighting 2.0 0 0.1 7\n", "0 m is not a positive range"),
            (
                "sighting 2.0 1 9 7\n",
                "sighting field 4 (bearing): 9 rad is beyond one turn",
            ),
            (
                "sighting 2.0 1 0.1 x\n",
                "sighting field 5 (id): `x` is not a landmark id",
            ),
            ("sighting 2.0 1 0.1 -3\n", "`-3` is not a landmark id"),
            ("sighting 2.0 1 0.1 1.5\n", "`1.5` is not a landmark id"),
            (
                "ackermann 2.0 1 1.6\n",
                "ackermann field 4 (φ): 1.6 rad is not a steering angle",
            ),
            (
                "truth 2.0 1e6 0 0\n",
                "truth field 3 (x): 1000000 m is beyond 100 km",
            ),
            (
                "landmark 7 1 1\nlandmark 7 2 2\n",
                "log.txt:4: landmark field 2 (id): landmark 7 is listed twice (first on line 3)",
            ),
            (
                "landmark - 1 1\n",
                "landmark field 2 (id): `-` is not a landmark id",
            ),
            (
                "landmark 3 1 nan\n",
                "landmark field 4 (y): `nan` is not finite",
            ),
        ];
        for (extra, expected) in cases {
            let e = parsed(&format!("{base}{extra}")).unwrap_err();
            assert!(e.contains(expected), "{extra:?}: {e}");
        }
        assert!(parsed(base).is_ok());
    }

    /// A long number is read whole; a long bad field is shown cut to 40 characters.
    #[test]
    fn long_fields_are_read_whole_and_shown_short() {
        let long = format!("1.{}", "0".repeat(60));
        let r = parsed(&format!("velocity {long} 0.5 0\nsighting 1 2 0.1 7\n")).unwrap();
        assert_eq!(r.events[0].stamp, 1.0);
        let junk = "x".repeat(1000);
        let e = parsed(&format!("velocity 1 {junk} 0\n")).unwrap_err();
        assert!(
            e.ends_with(&format!("`{}` is not a number", "x".repeat(40))),
            "{e}"
        );
    }

    #[test]
    fn a_log_without_motion_or_usable_sightings_is_an_error() {
        let e = parsed("# nothing\nsighting 1 2 0.1 7\n").unwrap_err();
        assert!(e.contains("log.txt:2: no motion record"), "{e}");
        let e = parsed("").unwrap_err();
        assert!(e.contains("no motion record"), "{e}");
        let e = parsed("velocity 1 0.5 0\n").unwrap_err();
        assert!(e.contains("no sighting to use"), "{e}");
        let e = parsed("sighting 0.5 2 0.1 7\nvelocity 1 0.5 0\n").unwrap_err();
        assert!(
            e.contains("all 1 come before the first motion record at 1 s"),
            "{e}"
        );
    }
}
