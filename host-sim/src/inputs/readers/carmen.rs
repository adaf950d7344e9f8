//! CARMEN log reader (`.clf`, `.log`; `.log.gz` through a decompressing reader).
//!
//! One message a line: `FLASER`/`RLASER` (front/rear laser with the pose and odometry of
//! the scan), `ODOM`, `PARAM`; `SYNC`, `NEFF`, `#` comments and unknown messages are
//! skipped. Messages are kept in **file order**: in the Intel log the time stamps go
//! backwards 265 times and some scans are < 10 ms apart, so order and motion must never
//! be derived from stamp differences — use the odometry pose increments between scans.
//! A stamp that is not finite (`nan`, `inf`) is refused with its line number.

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
    /// Lines skipped (comments, unknown or malformed messages).
    pub skipped_lines: usize,
}

impl CarmenLog {
    /// The laser messages (front and rear) in file order.
    pub fn lasers(&self) -> impl Iterator<Item = &LaserMessage> {
        self.messages.iter().filter_map(|m| match m {
            Message::Laser(l) => Some(l),
            Message::Odom(_) => None,
        })
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

/// A message's `ipc_timestamp`, refused when it is not finite: a NaN or infinite stamp
/// would reach the trajectory written and the stamp matching of the metrics.
fn stamp(value: f64, line: usize) -> Result<f64, CarmenError> {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(CarmenError {
            line,
            reason: format!("ipc_timestamp {value} is not finite"),
        })
    }
}

/// Reads a CARMEN log file: `.gz` files are decompressed (flate2), anything else is read
/// as text.
pub fn read(path: &Path) -> Result<CarmenLog> {
    let file = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let gz = path.extension().is_some_and(|e| e == "gz");
    let log = if gz {
        parse(BufReader::new(flate2::read::GzDecoder::new(file)))
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
                let mut ranges = Vec::with_capacity(count);
                for _ in 0..count {
                    ranges.push(num(tok.next(), n, "range")? as f32);
                }
                let mut f = [0.0; 7];
                for (k, v) in f.iter_mut().enumerate() {
                    *v = num(
                        tok.next(),
                        n,
                        [
                            "x",
                            "y",
                            "theta",
                            "odom_x",
                            "odom_y",
                            "odom_theta",
                            "ipc_timestamp",
                        ][k],
                    )?;
                }
                log.messages.push(Message::Laser(LaserMessage {
                    rear: kind == "RLASER",
                    ranges,
                    pose: [f[0], f[1], f[2]],
                    odom: [f[3], f[4], f[5]],
                    stamp: stamp(f[6], n)?,
                }));
            }
            Some("ODOM") => {
                let mut f = [0.0; 7];
                for (k, v) in f.iter_mut().enumerate() {
                    *v = num(
                        tok.next(),
                        n,
                        ["x", "y", "theta", "tv", "rv", "accel", "ipc_timestamp"][k],
                    )?;
                }
                log.messages.push(Message::Odom(OdomMessage {
                    pose: [f[0], f[1], f[2]],
                    tv: f[3],
                    rv: f[4],
                    stamp: stamp(f[6], n)?,
                }));
            }
            Some("PARAM") => {
                let name = tok.next().unwrap_or_default().to_string();
                let value = tok.collect::<Vec<_>>().join(" ");
                log.params.insert(name, value);
            }
            _ => log.skipped_lines += 1,
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

/// Reads a CARMEN log.
pub fn read_log(path: &Path) -> Result<CarmenLog> {
    let log = read(path)?;
    if log.lasers().next().is_none() {
        bail!("{}: no laser scans", path.display());
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
    fn parses_messages_in_file_order() {
        let text = "# comment\nPARAM robot_front_laser_max 81.9 x\n\
            FLASER 3 1.0 2.5 81.9 0.1 0.2 0.3 1.1 1.2 1.3 100.5 host 7.0\n\
            ODOM 1 2 3 0.5 0.1 0 99.0 host 7.1\nSYNC x\n\
            RLASER 1 4.0 0 0 0 0 0 0 98.0 host 7.2\n";
        let log = parse(text.as_bytes()).unwrap();
        assert_eq!(log.messages.len(), 3);
        assert_eq!(log.skipped_lines, 2);
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
    }
}
