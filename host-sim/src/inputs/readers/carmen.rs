//! CARMEN log reader (`.clf`, `.log`; `.log.gz` through a decompressing reader).
//!
//! One message a line: `FLASER`/`RLASER` (front/rear laser with the pose and odometry of
//! the scan), `ODOM`, `PARAM`; `#` comments, blank lines and every other message are
//! skipped and counted by type ([`CarmenLog::skipped`]): CARMEN's other messages
//! ([`UNREAD_MESSAGES`]: `SYNC`, GMapping's `NEFF`, other lasers, GPS, …) quietly, a type
//! CARMEN does not have (a misspelt or damaged line) with a warning naming its first line
//! ([`CarmenLog::unknown_messages`]). Messages are kept in **file order**: in the Intel log the time stamps go
//! backwards 265 times and some scans are < 10 ms apart, so order and motion must never
//! be derived from stamp differences — use the odometry pose increments between scans.
//! A stamp that is not finite (`nan`, `inf`) is refused with its line number, as are a
//! laser line whose declared beam count is not the count of readings that follow (or 0),
//! a scan of another length than the log's first of that laser, and a position beyond
//! 100 km ([`MAX_COORDINATE_M`]).

use anyhow::{Context, Result, bail};
use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// A laser scan message (`FLASER` front, `RLASER` rear).
#[derive(Clone, Debug, PartialEq)]
pub struct LaserMessage {
    /// `true` for `RLASER`.
    pub rear: bool,
    /// Ranges in metres, beam 0 first.
    pub ranges: Vec<f32>,
    /// Pose of the robot `(x, y, θ)` written with the scan (corrected or raw).
    pub pose: [f64; 3],
    /// Raw odometry pose `(x, y, θ)` at the scan.
    pub odom: [f64; 3],
    /// IPC time stamp, seconds.
    pub stamp: f64,
}

/// An odometry message.
#[derive(Clone, Debug, PartialEq)]
pub struct OdomMessage {
    /// Odometry pose `(x, y, θ)`.
    pub pose: [f64; 3],
    /// Translational velocity, m/s.
    pub tv: f64,
    /// Rotational velocity, rad/s.
    pub rv: f64,
    /// IPC time stamp, seconds.
    pub stamp: f64,
}

/// One message of the log, in file order.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    /// A laser scan.
    Laser(LaserMessage),
    /// An odometry reading.
    Odom(OdomMessage),
}

/// A parsed log.
#[derive(Clone, Debug, Default)]
pub struct CarmenLog {
    /// Laser and odometry messages in file order.
    pub messages: Vec<Message>,
    /// `PARAM name value` lines.
    pub params: BTreeMap<String, String>,
    /// Lines skipped, by message type (`#` for comments): CARMEN's messages this reader
    /// does not use and types CARMEN does not have; blank lines are not counted.
    pub skipped: BTreeMap<String, SkippedLines>,
}

/// The lines of one skipped message type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkippedLines {
    /// How many.
    pub lines: usize,
    /// The first one's line number, 1-based.
    pub first: usize,
}

/// CARMEN messages this reader skips on purpose (it reads `FLASER`, `RLASER`, `ODOM` and
/// `PARAM`): a log's lines of these types are counted, not warned of.
pub const UNREAD_MESSAGES: &[&str] = &[
    "#",
    "SYNC",
    "NEFF",
    "TRUEPOS",
    "ROBOTLASER1",
    "ROBOTLASER2",
    "RAWLASER1",
    "RAWLASER2",
    "RAWLASER3",
    "RAWLASER4",
    "LASER3",
    "LASER4",
    "POSITIONLASER",
    "SCANMARK",
    "GPSNMEA",
    "NMEAGGA",
    "NMEARMC",
    "SONAR",
    "BUMPER",
    "IMU",
    "VECTORMOVE",
    "ROBOTVELOCITY",
    "FOLLOWTRAJECTORY",
    "BASEVELOCITY",
];

impl CarmenLog {
    /// Skipped lines whose type CARMEN does not have (not in [`UNREAD_MESSAGES`]): `(type,
    /// lines, first line)`, e.g. a misspelt `FLASR` or a line broken by a lost newline.
    pub fn unknown_messages(&self) -> impl Iterator<Item = (&str, usize, usize)> {
        self.skipped
            .iter()
            .filter(|(kind, _)| !UNREAD_MESSAGES.contains(&kind.as_str()))
            .map(|(kind, s)| (kind.as_str(), s.lines, s.first))
    }

    /// How many lines of each type were skipped.
    pub fn skipped_counts(&self) -> BTreeMap<&str, usize> {
        self.skipped
            .iter()
            .map(|(kind, s)| (kind.as_str(), s.lines))
            .collect()
    }
}

impl CarmenLog {
    /// The laser messages (front and rear) in file order.
    pub fn lasers(&self) -> impl Iterator<Item = &LaserMessage> {
        self.messages.iter().filter_map(|m| match m {
            Message::Laser(l) => Some(l),
            Message::Odom(_) => None,
        })
    }

    /// The front laser scans, taken out of the log (no copy of their ranges).
    pub fn into_front_scans(self) -> Vec<LaserMessage> {
        self.messages
            .into_iter()
            .filter_map(|m| match m {
                Message::Laser(l) if !l.rear => Some(l),
                _ => None,
            })
            .collect()
    }
}

/// A malformed line that cannot be skipped silently.
#[derive(Debug)]
pub struct CarmenError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub reason: String,
}

impl std::fmt::Display for CarmenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "CARMEN log line {}: {}", self.line, self.reason)
    }
}

impl std::error::Error for CarmenError {}

/// Most beams a laser message may declare.
pub const MAX_BEAMS: u32 = 1 << 16;

fn num(tok: Option<&str>, line: usize, what: &str) -> Result<f64, CarmenError> {
    tok.and_then(|t| t.parse::<f64>().ok())
        .ok_or_else(|| CarmenError {
            line,
            reason: format!("missing or invalid {what}"),
        })
}

/// The fields of a laser message after its readings.
const LASER_TAIL: [&str; 9] = [
    "x",
    "y",
    "theta",
    "odom_x",
    "odom_y",
    "odom_theta",
    "ipc_timestamp",
    "ipc_hostname",
    "logger_timestamp",
];

/// The fields of an `ODOM` message.
const ODOM_FIELDS: [&str; 9] = [
    "x",
    "y",
    "theta",
    "tv",
    "rv",
    "accel",
    "ipc_timestamp",
    "ipc_hostname",
    "logger_timestamp",
];

/// Farthest a pose may lie from the origin of its frame, metres, along either axis: the
/// library refuses steps beyond 100 km (where `f32` coordinates are coarser than 8 mm).
pub const MAX_COORDINATE_M: f64 = microslam::geometry::MAX_COORDINATE_M;

/// A pose coordinate, refused beyond [`MAX_COORDINATE_M`] (a non-finite one is kept: the
/// replay refuses and counts such an odometry pose).
fn coordinate(value: f64, line: usize, what: &str) -> Result<f64, CarmenError> {
    if value.abs() > MAX_COORDINATE_M {
        Err(CarmenError {
            line,
            reason: format!(
                "{what} = {value} m is beyond {} km of the origin",
                MAX_COORDINATE_M / 1e3
            ),
        })
    } else {
        Ok(value)
    }
}

/// A field that must be a finite number ([`num`], then [`finite`]).
fn finite_num(tok: Option<&str>, line: usize, what: &str) -> Result<f64, CarmenError> {
    finite(num(tok, line, what)?, line, what)
}

/// A message's stamp (`ipc_timestamp`, `logger_timestamp`), refused when it is not
/// finite: a NaN or infinite `ipc_timestamp` would reach the trajectory written and the
/// stamp matching of the metrics, and a log whose `logger_timestamp` is not a time is
/// corrupt even where the replay does not use it.
fn finite(value: f64, line: usize, what: &str) -> Result<f64, CarmenError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(CarmenError {
            line,
            reason: format!("{what} {value} is not finite"),
        })
    }
}

/// The most bytes a gzip-compressed CARMEN log (`.log.gz`) may decompress to: 4 GiB
/// (the largest public CARMEN logs are a few hundred MB). More is refused, naming the
/// limit, rather than read into memory: a decompression bomb.
pub const GZ_DECOMPRESSED_LIMIT: u64 = 4 << 30;

/// A reader that fails once more than `limit` bytes have come through it.
struct Limited<R> {
    inner: R,
    limit: u64,
    read: u64,
}

impl<R: std::io::Read> std::io::Read for Limited<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.read += n as u64;
        if self.read > self.limit {
            return Err(std::io::Error::other(format!(
                "the gzip-compressed log decompresses to more than {} bytes, the limit for a CARMEN log (decompress it on disk to read it)",
                self.limit
            )));
        }
        Ok(n)
    }
}

/// Reads a CARMEN log file: `.gz` files are decompressed (flate2), anything else is read
/// as text.
pub fn read(path: &Path) -> Result<CarmenLog> {
    read_with_limit(path, GZ_DECOMPRESSED_LIMIT)
}

/// [`read`], a `.gz` file decompressing to at most `limit` bytes.
fn read_with_limit(path: &Path, limit: u64) -> Result<CarmenLog> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let gz = path.extension().is_some_and(|e| e == "gz");
    let log = if gz {
        // Every member of a multi-member gzip file (`cat a.gz b.gz`, `gzip` of a stream
        // written in parts), not only the first; at most `limit` bytes in all.
        parse(BufReader::new(Limited {
            inner: flate2::read::MultiGzDecoder::new(file),
            limit,
            read: 0,
        }))
    } else {
        parse(BufReader::new(file))
    };
    log.map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Parses a CARMEN log. Laser messages with a wrong field count are errors (they would
/// silently shift poses and stamps); unknown message types are counted and skipped.
pub fn parse<R: BufRead>(
    reader: R,
) -> std::result::Result<CarmenLog, Box<dyn std::error::Error + Send + Sync>> {
    let mut log = CarmenLog::default();
    // (line, readings) of the first front and the first rear scan.
    let mut first_scan: [Option<(usize, usize)>; 2] = [None, None];
    for (i, line) in reader.lines().enumerate() {
        let line = line?;
        let n = i + 1;
        let mut tok = line.split_ascii_whitespace();
        match tok.next() {
            Some(kind @ ("FLASER" | "RLASER")) => {
                let count = num(tok.next(), n, "beam count")?;
                // A whole number of beams no lidar exceeds; anything else is corruption
                // (and must not size an allocation).
                if !(count.fract() == 0.0 && (0.0..=f64::from(MAX_BEAMS)).contains(&count)) {
                    return Err(CarmenError {
                        line: n,
                        reason: format!("invalid beam count {count} (0..={MAX_BEAMS})"),
                    }
                    .into());
                }
                let count = count as usize;
                if count == 0 {
                    return Err(CarmenError {
                        line: n,
                        reason: format!("{kind} declares 0 readings: a scan needs at least one"),
                    }
                    .into());
                }
                // The declared count must be the count of readings that follow: one more
                // or fewer would shift every later field (a reading read as x, a stamp as
                // a pose).
                let fields: Vec<&str> = tok.collect();
                if fields.len() != count + LASER_TAIL.len() {
                    return Err(CarmenError {
                        line: n,
                        reason: format!(
                            "{kind} declares {count} readings but {} fields follow ({count} readings and {} more fields expected: {})",
                            fields.len(),
                            LASER_TAIL.len(),
                            LASER_TAIL.join(" ")
                        ),
                    }
                    .into());
                }
                // Every scan of one laser has one geometry: a scan of another length is
                // refused, naming the line of the first scan of that laser.
                let rear = kind == "RLASER";
                let first = &mut first_scan[usize::from(rear)];
                match *first {
                    None => *first = Some((n, count)),
                    Some((line, beams)) if beams != count => {
                        return Err(CarmenError {
                            line: n,
                            reason: format!(
                                "{kind} declares {count} readings, the log's first {kind} (line {line}) {beams}: scans of different lengths in one log are not read"
                            ),
                        }
                        .into());
                    }
                    Some(_) => {}
                }
                let mut tok = fields.into_iter();
                let mut ranges = Vec::with_capacity(count);
                for _ in 0..count {
                    ranges.push(num(tok.next(), n, "range")? as f32);
                }
                let mut f = [0.0; 7];
                for (k, v) in f.iter_mut().enumerate() {
                    *v = num(tok.next(), n, LASER_TAIL[k])?;
                }
                let _hostname = tok.next();
                finite_num(tok.next(), n, "logger_timestamp")?;
                for (k, name) in [(0, "x"), (1, "y"), (3, "odom_x"), (4, "odom_y")] {
                    coordinate(f[k], n, name)?;
                }
                log.messages.push(Message::Laser(LaserMessage {
                    rear,
                    ranges,
                    pose: [f[0], f[1], f[2]],
                    odom: [f[3], f[4], f[5]],
                    stamp: finite(f[6], n, "ipc_timestamp")?,
                }));
            }
            Some("ODOM") => {
                let fields: Vec<&str> = tok.collect();
                if fields.len() != ODOM_FIELDS.len() {
                    return Err(CarmenError {
                        line: n,
                        reason: format!(
                            "ODOM has {} fields, expected {}: {}",
                            fields.len(),
                            ODOM_FIELDS.len(),
                            ODOM_FIELDS.join(" ")
                        ),
                    }
                    .into());
                }
                let mut tok = fields.into_iter();
                let mut f = [0.0; 7];
                for (k, v) in f.iter_mut().enumerate() {
                    *v = num(tok.next(), n, ODOM_FIELDS[k])?;
                }
                let _hostname = tok.next();
                finite_num(tok.next(), n, "logger_timestamp")?;
                coordinate(f[0], n, "x")?;
                coordinate(f[1], n, "y")?;
                log.messages.push(Message::Odom(OdomMessage {
                    pose: [f[0], f[1], f[2]],
                    tv: f[3],
                    rv: f[4],
                    stamp: finite(f[6], n, "ipc_timestamp")?,
                }));
            }
            Some("PARAM") => {
                let name = tok.next().unwrap_or_default().to_string();
                let value = tok.collect::<Vec<_>>().join(" ");
                log.params.insert(name, value);
            }
            None => {}
            Some(kind) => {
                // A comment is `#` whatever follows it.
                let kind = if kind.starts_with('#') { "#" } else { kind };
                log.skipped
                    .entry(kind.to_string())
                    .or_insert(SkippedLines { lines: 0, first: n })
                    .lines += 1;
            }
        }
    }
    Ok(log)
}

/// The front-laser messages of `log` in file order: what the grid filters process.
pub fn front_scans(log: &CarmenLog) -> Vec<&LaserMessage> {
    log.lasers().filter(|l| !l.rear).collect()
}

/// A `carmen:<file>` or `rosbag:<file or folder>` location: the path itself when it
/// exists, else relative to the datasets folder.
pub fn resolve_log(spec: &str) -> Result<PathBuf> {
    let direct = PathBuf::from(spec);
    if direct.exists() {
        return Ok(direct);
    }
    crate::domain::datasets::dataset_path(spec)
}

/// Reads a CARMEN log for the grid filters: refused without a front laser scan (the rear
/// laser's are not used).
pub fn read_log(path: &Path) -> Result<CarmenLog> {
    let log = read(path)?;
    let rear = log.lasers().filter(|l| l.rear).count();
    if rear == log.lasers().count() {
        if rear == 0 {
            let other: Vec<String> = log
                .skipped
                .iter()
                .filter(|(kind, _)| kind.contains("LASER"))
                .map(|(kind, s)| format!("{} {kind}", s.lines))
                .collect();
            if other.is_empty() {
                bail!(
                    "{}: no laser scans (FLASER or RLASER lines)",
                    path.display()
                );
            }
            bail!(
                "{}: no laser scans this reader takes (FLASER or RLASER lines); it has {}, which it does not read",
                path.display(),
                other.join(", ")
            );
        }
        bail!(
            "{}: no front laser scans (FLASER); its {rear} rear laser scans (RLASER) are not used",
            path.display()
        );
    }
    Ok(log)
}

/// The beam count of a log's first front scan.
pub fn beam_count(log: &CarmenLog) -> usize {
    log.lasers()
        .find(|l| !l.rear)
        .map_or(180, |l| l.ranges.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skipped_lines_are_counted_by_type_and_unknown_types_named_with_their_first_line() {
        let text = "# a log\n\nSYNC a\nNEFF 12.5\nFLASR 1 1.0 0 0 0 0 0 0 1.0 host 1.0\n\
            FLASER 1 1.0 0 0 0 0 0 0 2.0 host 2.0\n1.07 1.08 1.08\nNEFF 11.0\n\
            FLASR 1 1.0 0 0 0 0 0 0 3.0 host 3.0\n";
        let log = parse(text.as_bytes()).unwrap();
        assert_eq!(log.messages.len(), 1);
        let skipped: Vec<(&str, usize)> = log.skipped_counts().into_iter().collect();
        assert_eq!(
            skipped,
            [
                ("#", 1),
                ("1.07", 1),
                ("FLASR", 2),
                ("NEFF", 2),
                ("SYNC", 1)
            ]
        );
        let unknown: Vec<(&str, usize, usize)> = log.unknown_messages().collect();
        assert_eq!(unknown, [("1.07", 1, 7), ("FLASR", 2, 5)]);
    }

    #[test]
    fn parses_messages_in_file_order() {
        let text = "# comment\nPARAM robot_front_laser_max 81.9 x\n\
            FLASER 3 1.0 2.5 81.9 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 7.0\n\
            ODOM 1 2 3 0.5 0.1 0 99.0 host 7.1\nSYNC x\n\
            RLASER 1 4.0 0 0 0 0 0 0 98.0 host 7.2\n";
        let log = parse(text.as_bytes()).unwrap();
        assert_eq!(log.messages.len(), 3);
        assert_eq!(log.skipped_counts().get("#"), Some(&1));
        assert_eq!(log.skipped_counts().get("SYNC"), Some(&1));
        assert_eq!(log.unknown_messages().count(), 0);
        assert_eq!(log.params["robot_front_laser_max"], "81.9 x");
        let lasers: Vec<_> = log.lasers().collect();
        assert_eq!(lasers[0].ranges, vec![1.0, 2.5, 81.9]);
        assert_eq!(lasers[0].odom, [1.1, 1.2, 1.3]);
        assert_eq!(lasers[0].stamp, 100.5);
        assert!(lasers[1].rear && lasers[1].stamp == 98.0); // stamps may go backwards
        assert!(parse("FLASER 3 1.0 2.0\n".as_bytes()).is_err());
    }

    #[test]
    fn a_stamp_that_is_not_finite_is_refused_with_its_line() {
        for (text, line, value) in [
            (
                "FLASER 1 1.0 0 0 0 0 0 0 5.0 h 1\nFLASER 1 1.0 0 0 0 0 0 0 nan h 1\n",
                2,
                "NaN",
            ),
            ("ODOM 0 0 0 0 0 0 inf h 1\n", 1, "inf"),
            ("RLASER 1 1.0 0 0 0 0 0 0 -inf h 1\n", 1, "-inf"),
        ] {
            let e = parse(text.as_bytes()).unwrap_err().to_string();
            assert_eq!(
                e,
                format!("CARMEN log line {line}: ipc_timestamp {value} is not finite")
            );
        }
        for (text, value) in [
            ("FLASER 1 1.0 0 0 0 0 0 0 5.0 h nan\n", "NaN"),
            ("ODOM 0 0 0 0 0 0 5.0 h inf\n", "inf"),
        ] {
            assert_eq!(
                error(text),
                format!("CARMEN log line 1: logger_timestamp {value} is not finite")
            );
        }
    }

    fn error(text: &str) -> String {
        parse(text.as_bytes()).unwrap_err().to_string()
    }

    #[test]
    fn a_declared_beam_count_that_disagrees_with_the_fields_is_refused_with_its_line() {
        let good = "FLASER 3 1 2 3 0 0 0 0 0 0 5.0 h 5.0\n";
        assert!(parse(good.as_bytes()).is_ok());
        // One reading more than declared: it would be read as x, and x as y, …
        let e = error(&format!("{good}FLASER 3 1 2 3 4 0 0 0 0 0 0 5.1 h 5.1\n"));
        assert_eq!(
            e,
            "CARMEN log line 2: FLASER declares 3 readings but 13 fields follow (3 readings and 9 \
             more fields expected: x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname \
             logger_timestamp)"
        );
        // One fewer.
        let e = error("RLASER 3 1 2 0 0 0 0 0 0 5.1 h 5.1\n");
        assert!(
            e.starts_with("CARMEN log line 1: RLASER declares 3 readings but 11 fields follow"),
            "{e}"
        );
        // An ODOM message with a field missing.
        let e = error("ODOM 0 0 0 0 0 5.0 h 5.0\n");
        assert!(
            e.starts_with("CARMEN log line 1: ODOM has 8 fields, expected 9"),
            "{e}"
        );
        // A logger stamp that is not a number.
        let e = error("FLASER 1 1 0 0 0 0 0 0 5.0 h x\n");
        assert_eq!(e, "CARMEN log line 1: missing or invalid logger_timestamp");
    }

    #[test]
    fn scans_of_another_length_are_refused_naming_both_lines() {
        let text = "FLASER 2 1 2 0 0 0 0 0 0 5.0 h 5.0\nRLASER 1 1 0 0 0 0 0 0 5.0 h 5.0\n\
            FLASER 2 1 2 0 0 0 0 0 0 5.1 h 5.1\nFLASER 3 1 2 3 0 0 0 0 0 0 5.2 h 5.2\n";
        assert_eq!(
            error(text),
            "CARMEN log line 4: FLASER declares 3 readings, the log's first FLASER (line 1) 2: \
             scans of different lengths in one log are not read"
        );
        // The rear laser has its own length.
        assert!(parse(&text.as_bytes()[..text.rfind("FLASER 3").unwrap()]).is_ok());
    }

    #[test]
    fn a_scan_of_no_reading_is_refused_as_such() {
        assert_eq!(
            error("FLASER 0 0 0 0 0 0 0 5.0 h 5.0\n"),
            "CARMEN log line 1: FLASER declares 0 readings: a scan needs at least one"
        );
    }

    #[test]
    fn a_pose_beyond_100_km_is_refused_with_its_field() {
        assert_eq!(
            error("FLASER 1 1 0 0 0 0 2e5 0 5.0 h 5.0\n"),
            "CARMEN log line 1: odom_y = 200000 m is beyond 100 km of the origin"
        );
        assert_eq!(
            error("ODOM 0 0 0 0 0 0 5.0 h 5.0\nODOM -1e7 0 0 0 0 0 5.1 h 5.1\n"),
            "CARMEN log line 2: x = -10000000 m is beyond 100 km of the origin"
        );
    }

    #[test]
    fn every_member_of_a_multi_member_gzip_file_is_read() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("two.log.gz");
        let mut bytes = Vec::new();
        for stamp in [5.0, 5.1] {
            let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
            writeln!(gz, "FLASER 1 1 0 0 0 0 0 0 {stamp} h {stamp}").unwrap();
            bytes.extend(gz.finish().unwrap());
        }
        std::fs::write(&path, bytes).unwrap();
        let log = read(&path).unwrap();
        assert_eq!(
            log.lasers().map(|l| l.stamp).collect::<Vec<_>>(),
            [5.0, 5.1]
        );
    }

    #[test]
    fn a_gzip_log_decompressing_past_the_limit_is_refused_naming_it() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bomb.log.gz");
        // 4 MB of one comment line compress to a few KB.
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
        writeln!(gz, "FLASER 1 1 0 0 0 0 0 0 5 h 5").unwrap();
        gz.write_all(&vec![b'#'; 4 << 20]).unwrap();
        let bytes = gz.finish().unwrap();
        assert!(bytes.len() < 16 << 10, "{}", bytes.len());
        std::fs::write(&path, bytes).unwrap();
        assert_eq!(read_with_limit(&path, 8 << 20).unwrap().lasers().count(), 1);
        let e = read_with_limit(&path, 1 << 20).unwrap_err().to_string();
        assert!(
            e.contains("bomb.log.gz") && e.contains("more than 1048576 bytes, the limit"),
            "{e}"
        );
    }

    #[test]
    fn a_log_of_rear_scans_only_has_no_scans_to_use() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("rear.clf");
        std::fs::write(&path, "RLASER 1 1 0 0 0 0 0 0 5.0 h 5.0\n").unwrap();
        let e = read_log(&path).unwrap_err().to_string();
        assert!(
            e.ends_with("rear.clf: no front laser scans (FLASER); its 1 rear laser scans (RLASER) are not used"),
            "{e}"
        );
    }
}
