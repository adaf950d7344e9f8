//! The plain landmark log (docs/guide.md; read by
//! [`crate::inputs::readers::landmarks`]), written from any landmark recording
//! (`host-sim export-landmarks`).

use crate::domain::recording::Recording;
use microslam::event::{EventKind, Identity};

/// Writes `recording` in the plain landmark log format: its motion records and
/// sightings in event order, then its ground truth and true landmarks. Numbers are
/// written in Rust's shortest round-trip form, so reading the file back gives the same
/// `f64`s. Yaw rates (which the format has no record for) are left out; sightings by
/// class are written with `-` (the format carries unique ids only). Returns how many
/// events were left out.
pub fn write(recording: &Recording, out: &mut impl std::io::Write) -> std::io::Result<usize> {
    writeln!(
        out,
        "# plain landmark log (docs/guide.md), exported by host-sim from {}",
        recording.name
    )?;
    let mut left_out = 0;
    for e in &recording.events {
        let t = e.stamp;
        match e.kind {
            EventKind::Velocity { v, omega } => writeln!(out, "velocity {t} {v} {omega}")?,
            EventKind::Increment(p) => {
                writeln!(out, "increment {t} {} {} {}", p.x, p.y, p.theta)?;
            }
            EventKind::Ackermann { v, steering } => {
                writeln!(out, "ackermann {t} {v} {steering}")?;
            }
            EventKind::Sighting(s) => {
                let (r, b) = (s.z.range, s.z.bearing);
                match s.identity {
                    Identity::Unique(id) => writeln!(out, "sighting {t} {r} {b} {id}")?,
                    _ => writeln!(out, "sighting {t} {r} {b} -")?,
                }
            }
            _ => left_out += 1,
        }
    }
    for p in &recording.ground_truth {
        let q = p.pose;
        writeln!(out, "truth {} {} {} {}", p.stamp, q.x, q.y, q.theta)?;
    }
    for l in &recording.landmarks {
        writeln!(out, "landmark {} {} {}", l.id, l.position[0], l.position[1])?;
    }
    Ok(left_out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inputs::readers::landmarks::{parse, tests::GOOD};
    use std::path::Path;

    #[test]
    fn written_and_read_back_is_the_same_recording() {
        let r = parse(Path::new("log.txt"), GOOD).unwrap();
        let mut text = Vec::new();
        assert_eq!(write(&r, &mut text).unwrap(), 0);
        let back = parse(Path::new("back.txt"), std::str::from_utf8(&text).unwrap()).unwrap();
        assert_eq!(back.events, r.events);
        assert_eq!(back.ground_truth, r.ground_truth);
        assert_eq!(back.landmarks, r.landmarks);
    }
}
