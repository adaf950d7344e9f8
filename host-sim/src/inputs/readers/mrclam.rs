//! UTIAS MRCLAM (Leung, Barfoot, Liu 2011): one robot's odometry, sightings and ground
//! truth.
//!
//! Files in the dataset folder (tab-separated, 4 `#` header lines):
//! - `Robot<k>_Odometry.dat`: time (s), v (m/s), ω (rad/s) → [`EventKind::Velocity`];
//! - `Robot<k>_Measurement.dat`: time, **barcode**, range (m), bearing (rad) →
//!   [`EventKind::Sighting`] with [`Identity::Unique`]`(subject)`; the barcode is mapped
//!   to a subject through `Barcodes.dat` (each subject and each barcode listed once).
//!   Subjects 1–5 are the robots: their sightings are
//!   dropped, as are barcodes that `Barcodes.dat` does not list (counted in
//!   [`Recording::dropped_sightings`]);
//! - `Robot<k>_Groundtruth.dat` (optional: dataset 1 has none): time, x, y, θ;
//! - `Landmark_Groundtruth.dat`: subject, x, y, σx, σy; each subject once, a landmark
//!   (not a robot) that `Barcodes.dat` lists.

use super::sort_events;
use super::text::{ReadError, invalid, read_table, read_table_with};
use crate::domain::recording::{Recording, TrueLandmark, TruePose};
use microslam::event::{Event, EventKind, Identity, Sighting};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use std::collections::HashMap;
use std::path::Path;

/// Subjects 1..=5 are robots; landmarks are 6 and up.
pub const LAST_ROBOT_SUBJECT: u32 = 5;

/// Reads robot `robot`'s log from the MRCLAM folder `dir`.
pub fn read(dir: &Path, robot: u8) -> anyhow::Result<Recording> {
    let file = |name: String| dir.join(name);
    let barcodes_path = file("Barcodes.dat".into());
    let barcodes = read_table::<2>(&barcodes_path)?;
    let mut subject_of = HashMap::new();
    // The line of each subject and of each barcode: each is listed once.
    let (mut subject_line, mut barcode_line) = (HashMap::new(), HashMap::new());
    for row in &barcodes {
        let subject = whole(&barcodes_path, row.line, row.values[0], "subject")?;
        let barcode = whole(&barcodes_path, row.line, row.values[1], "barcode")?;
        for (what, value, lines) in [
            ("subject", subject, &mut subject_line),
            ("barcode", barcode, &mut barcode_line),
        ] {
            if let Some(first) = lines.insert(value, row.line) {
                return Err(invalid(
                    &barcodes_path,
                    row.line,
                    format!("{what} {value} is listed twice (first on line {first})"),
                )
                .into());
            }
        }
        subject_of.insert(barcode, subject);
    }

    let odo_path = file(format!("Robot{robot}_Odometry.dat"));
    if !odo_path.exists() {
        let found: Vec<u8> = (1..=9)
            .filter(|k| file(format!("Robot{k}_Odometry.dat")).exists())
            .collect();
        anyhow::bail!(
            "robot {robot} is not in {}: no {} (robots there: {found:?})",
            dir.display(),
            odo_path.display()
        );
    }
    let meas_path = file(format!("Robot{robot}_Measurement.dat"));
    let gt_path = file(format!("Robot{robot}_Groundtruth.dat"));
    // The three large files are parsed in parallel, straight into events and poses.
    let (odometry, measurements, ground_truth) = std::thread::scope(|s| {
        let odometry = s.spawn(|| {
            let mut events = Vec::with_capacity(65_536);
            let mut order = InOrder::new(&odo_path);
            read_table_with::<3>(&odo_path, |row| {
                let [t, v, omega] = row.values;
                order.check(row.line, t);
                events.push(Event::new(t, EventKind::Velocity { v, omega }));
            })?;
            order.result().map(|()| events)
        });
        let truth = s.spawn(|| {
            let mut poses = Vec::with_capacity(65_536);
            let mut far = None;
            let mut order = InOrder::new(&gt_path);
            if gt_path.exists() {
                read_table_with::<4>(&gt_path, |row| {
                    let [stamp, x, y, theta] = row.values;
                    order.check(row.line, stamp);
                    if far.is_none() {
                        far = beyond(&gt_path, row.line, [("x", x), ("y", y)]).err();
                    }
                    poses.push(TruePose {
                        stamp,
                        pose: Pose2::new(x, y, theta),
                    });
                })?;
            }
            order.result()?;
            far.map_or(Ok(poses), Err)
        });
        let measurements = read_table::<4>(&meas_path);
        let panicked = |_| anyhow::anyhow!("reader thread panicked");
        anyhow::Ok((
            odometry.join().map_err(panicked)?,
            measurements,
            truth.join().map_err(panicked)?,
        ))
    })?;
    let (mut events, measurements, mut ground_truth) = (odometry?, measurements?, ground_truth?);
    if events.is_empty() {
        anyhow::bail!(
            "{}: no odometry samples (only comments or nothing): nothing to replay",
            odo_path.display()
        );
    }
    events.reserve(measurements.len());
    // Sightings dropped: of the other robots, and of barcodes Barcodes.dat does not list.
    let (mut of_robots, mut unknown) = (0, 0);
    let mut order = InOrder::new(&meas_path);
    for row in &measurements {
        let [t, code, range, bearing] = row.values;
        order.check(row.line, t);
        order.result()?;
        let code = whole(&meas_path, row.line, code, "barcode")?;
        if range <= 0.0 {
            return Err(invalid(
                &meas_path,
                row.line,
                format!("range {range} is not positive"),
            )
            .into());
        }
        match subject_of.get(&code) {
            Some(&subject) if subject > LAST_ROBOT_SUBJECT => events.push(Event::new(
                t,
                EventKind::Sighting(Sighting {
                    identity: Identity::Unique(subject),
                    z: RangeBearing::new(range, bearing),
                    covariance: None,
                }),
            )),
            Some(_) => of_robots += 1,
            None => unknown += 1,
        }
    }
    sort_events(&mut events)?;
    ground_truth.sort_by(|a, b| a.stamp.total_cmp(&b.stamp));

    let lm_path = file("Landmark_Groundtruth.dat".into());
    let mut landmarks = Vec::new();
    if lm_path.exists() {
        let mut landmark_line = HashMap::new();
        for row in read_table::<5>(&lm_path)? {
            let id = whole(&lm_path, row.line, row.values[0], "subject")?;
            let refuse = |why: String| -> anyhow::Error { invalid(&lm_path, row.line, why).into() };
            if let Some(first) = landmark_line.insert(id, row.line) {
                return Err(refuse(format!(
                    "subject {id} is listed twice (first on line {first})"
                )));
            }
            if id <= LAST_ROBOT_SUBJECT {
                return Err(refuse(format!(
                    "subject {id} is a robot (subjects 1–{LAST_ROBOT_SUBJECT}), not a landmark"
                )));
            }
            if !subject_line.contains_key(&id) {
                return Err(refuse(format!(
                    "subject {id} has no barcode in {}: it could never be sighted",
                    barcodes_path.display()
                )));
            }
            beyond(
                &lm_path,
                row.line,
                [("x", row.values[1]), ("y", row.values[2])],
            )?;
            landmarks.push(TrueLandmark {
                id,
                position: [row.values[1], row.values[2]],
            });
        }
    }

    let first = events.first().map(|e| e.stamp);
    let initial_pose =
        first.and_then(|t| crate::domain::recording::interpolate_pose(&ground_truth, t));
    let name = format!(
        "mrclam/{}/robot{robot}",
        dir.file_name()
            .map(|n| n.to_string_lossy())
            .unwrap_or_default()
    );
    Ok(Recording {
        name,
        events,
        ground_truth,
        landmarks,
        initial_pose,
        dropped_sightings: of_robots + unknown,
        dropped_reason: match (of_robots, unknown) {
            (0, 0) => String::new(),
            (r, 0) => format!("{r} of other robots"),
            (0, u) => format!("{u} of a barcode {} does not list", barcodes_path.display()),
            (r, u) => format!(
                "{r} of other robots, {u} of a barcode {} does not list",
                barcodes_path.display()
            ),
        },
    })
}

/// Refuses a position coordinate beyond 100 km of the origin
/// ([`super::carmen::MAX_COORDINATE_M`]), naming the line and the field.
fn beyond<const N: usize>(
    path: &Path,
    line: usize,
    fields: [(&str, f64); N],
) -> Result<(), ReadError> {
    match fields
        .into_iter()
        .find(|(_, v)| v.abs() > super::carmen::MAX_COORDINATE_M)
    {
        Some((what, v)) => Err(invalid(
            path,
            line,
            format!("{what} = {v} m is beyond 100 km of the origin"),
        )),
        None => Ok(()),
    }
}

/// A field that must hold a non-negative whole number.
fn whole(path: &Path, line: usize, v: f64, what: &str) -> Result<u32, ReadError> {
    if v >= 0.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX) {
        Ok(v as u32)
    } else {
        Err(invalid(
            path,
            line,
            format!("{what} `{v}` is not a whole number"),
        ))
    }
}

/// The time column of one of MRCLAM's files, checked row by row: the files are in time
/// order (every file of the published datasets is), so a stamp that goes back is a
/// damaged or edited file, refused with its line rather than sorted away.
struct InOrder<'a> {
    path: &'a Path,
    /// The line and stamp of the last row.
    last: Option<(usize, f64)>,
    /// The first row whose stamp went back.
    error: Option<super::text::ReadError>,
}

impl<'a> InOrder<'a> {
    fn new(path: &'a Path) -> Self {
        Self {
            path,
            last: None,
            error: None,
        }
    }

    /// Takes the row on `line` stamped `t` (s).
    fn check(&mut self, line: usize, t: f64) {
        if self.error.is_some() {
            return;
        }
        if let Some((before, last)) = self.last
            && t < last
        {
            self.error = Some(invalid(
                self.path,
                line,
                format!(
                    "time {t} s goes back before line {before}'s {last} s: MRCLAM's files are in time order"
                ),
            ));
        }
        self.last = Some((line, t));
    }

    /// The first stamp that went back, as an error.
    fn result(&mut self) -> Result<(), super::text::ReadError> {
        self.error.take().map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-robot MRCLAM folder whose ground truth's second row is `truth_row`.
    fn folder(truth_row: &str, landmark_row: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let head = "# a\n# b\n# c\n# d\n";
        let write = |name: &str, rows: &str| {
            std::fs::write(dir.path().join(name), format!("{head}{rows}")).unwrap();
        };
        write("Barcodes.dat", "6\t72\n");
        write("Robot1_Odometry.dat", "10.0\t0.1\t0.0\n10.1\t0.1\t0.0\n");
        write("Robot1_Measurement.dat", "10.05\t72\t2.0\t0.1\n");
        write(
            "Robot1_Groundtruth.dat",
            &format!("10.0\t1.0\t2.0\t0.0\n{truth_row}\n"),
        );
        write("Landmark_Groundtruth.dat", &format!("{landmark_row}\n"));
        dir
    }

    #[test]
    fn dropped_sightings_are_counted_by_reason() {
        let dir = folder("10.1\t1.01\t2.0\t0.0", "6\t3.0\t4.0\t0.01\t0.01");
        let head = "# a\n# b\n# c\n# d\n";
        std::fs::write(
            dir.path().join("Barcodes.dat"),
            format!("{head}2\t14\n6\t72\n"),
        )
        .unwrap();
        std::fs::write(
            dir.path().join("Robot1_Measurement.dat"),
            format!("{head}10.05\t72\t2.0\t0.1\n10.06\t14\t2.0\t0.1\n10.07\t99\t2.0\t0.1\n10.08\t98\t2.0\t0.1\n"),
        )
        .unwrap();
        let r = read(dir.path(), 1).unwrap();
        assert_eq!(r.dropped_sightings, 3);
        let barcodes = dir.path().join("Barcodes.dat");
        assert_eq!(
            r.dropped_reason,
            format!(
                "1 of other robots, 2 of a barcode {} does not list",
                barcodes.display()
            )
        );
    }

    #[test]
    fn subjects_and_barcodes_listed_twice_and_landmarks_no_barcode_names_are_refused() {
        let head = "# a\n# b\n# c\n# d\n";
        let landmark = "6\t3.0\t4.0\t0.01\t0.01";
        for (file, rows, why) in [
            (
                "Barcodes.dat",
                "6\t72\n6\t73\n",
                "Barcodes.dat:6: subject 6 is listed twice (first on line 5)",
            ),
            (
                "Barcodes.dat",
                "6\t72\n7\t72\n",
                "Barcodes.dat:6: barcode 72 is listed twice (first on line 5)",
            ),
            (
                "Landmark_Groundtruth.dat",
                "6\t3.0\t4.0\t0.01\t0.01\n6\t5.0\t4.0\t0.01\t0.01\n",
                "Landmark_Groundtruth.dat:6: subject 6 is listed twice (first on line 5)",
            ),
            (
                "Landmark_Groundtruth.dat",
                "3\t3.0\t4.0\t0.01\t0.01\n",
                "Landmark_Groundtruth.dat:5: subject 3 is a robot (subjects 1–5), not a landmark",
            ),
            (
                "Landmark_Groundtruth.dat",
                "8\t3.0\t4.0\t0.01\t0.01\n",
                "Landmark_Groundtruth.dat:5: subject 8 has no barcode in",
            ),
        ] {
            let dir = folder("10.1\t1.01\t2.0\t0.0", landmark);
            std::fs::write(dir.path().join(file), format!("{head}{rows}")).unwrap();
            let e = read(dir.path(), 1).unwrap_err().to_string();
            assert!(e.contains(why), "{e}");
        }
    }

    #[test]
    fn a_position_beyond_100_km_is_refused_with_its_line_and_field() {
        let good = folder("10.1\t1.01\t2.0\t0.0", "6\t3.0\t4.0\t0.01\t0.01");
        assert_eq!(read(good.path(), 1).unwrap().landmarks.len(), 1);
        let far = folder("10.1\t1.01\t-2e8\t0.0", "6\t3.0\t4.0\t0.01\t0.01");
        let e = read(far.path(), 1).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "Robot1_Groundtruth.dat:6: y = -200000000 m is beyond 100 km of the origin"
            ),
            "{e}"
        );
        let far = folder("10.1\t1.01\t2.0\t0.0", "6\t3e6\t4.0\t0.01\t0.01");
        let e = read(far.path(), 1).unwrap_err().to_string();
        assert!(
            e.ends_with("Landmark_Groundtruth.dat:5: x = 3000000 m is beyond 100 km of the origin"),
            "{e}"
        );
    }

    #[test]
    fn a_stamp_going_back_in_any_file_is_refused_with_its_line() {
        let landmark = "6\t3.0\t4.0\t0.01\t0.01";
        // Equal stamps are in order.
        let same = folder("10.0\t1.01\t2.0\t0.0", landmark);
        assert_eq!(read(same.path(), 1).unwrap().ground_truth.len(), 2);
        let back = folder("9.5\t1.01\t2.0\t0.0", landmark);
        let e = read(back.path(), 1).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "Robot1_Groundtruth.dat:6: time 9.5 s goes back before line 5's 10 s: MRCLAM's files are in time order"
            ),
            "{e}"
        );
        let good = folder("10.1\t1.01\t2.0\t0.0", landmark);
        let rewrite = |name: &str, rows: &str| {
            std::fs::write(
                good.path().join(name),
                format!("# a\n# b\n# c\n# d\n{rows}"),
            )
            .unwrap();
        };
        rewrite(
            "Robot1_Odometry.dat",
            "10.0\t0.1\t0.0\n10.1\t0.1\t0.0\n10.05\t0.1\t0.0\n",
        );
        let e = read(good.path(), 1).unwrap_err().to_string();
        assert!(
            e.contains("Robot1_Odometry.dat:7: time 10.05 s goes back before line 6's 10.1 s"),
            "{e}"
        );
        rewrite("Robot1_Odometry.dat", "10.0\t0.1\t0.0\n10.1\t0.1\t0.0\n");
        rewrite(
            "Robot1_Measurement.dat",
            "10.05\t72\t2.0\t0.1\n10.01\t72\t2.0\t0.1\n",
        );
        let e = read(good.path(), 1).unwrap_err().to_string();
        assert!(
            e.contains("Robot1_Measurement.dat:6: time 10.01 s goes back before line 5's 10.05 s"),
            "{e}"
        );
    }
}
