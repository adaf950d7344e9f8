//! What a landmark EKF replay read, used and lost of each input stream, with the reasons
//! (`metrics.json`'s `inputs`), and the refusal of a run that used none of an input it
//! needs.
//!
//! Every odometry record and every sighting of the recording is accounted for: `read` is
//! `used` plus each way of losing one. A sighting is *used* when it corrected the filter
//! or created a landmark; one the association turned down (outside the gate, ambiguous)
//! was read and weighed but not used, which is the filter working, not lost input.

use crate::domain::recording::Recording;
use crate::drivers::ekf::ReplayRun;
use crate::drivers::grid_run::GridRun;
use crate::inputs::readers::carmen::CarmenLog;
use anyhow::{Result, bail};
use serde::Serialize;

/// The odometry stream of a replay.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct OdometryUse {
    /// Odometry records in the replayed stream.
    pub read: usize,
    /// Records that moved the filter.
    pub used: usize,
    /// Records refused: a non-finite or implausible reading (beyond the settings'
    /// `max_speed_mps`, `max_turn_rate_radps`), the previous one held.
    pub refused_implausible: usize,
    /// Predictions the filter refused (a step it could not take: the robot would leave
    /// the 100 km the filter holds, a non-finite result); the filter stayed where it was.
    pub refused_by_filter: usize,
}

/// The sightings of a replay.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SightingUse {
    /// Sightings in the recording's files (those the reader dropped included).
    pub read: usize,
    /// Dropped by the reader (`reader_dropped_because` says why).
    pub reader_dropped: usize,
    /// The reader's reasons, with counts (left out when it dropped none).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub reader_dropped_because: String,
    /// Outside the settings' `min_range ..= max_range`, or not a valid reading.
    pub out_of_range: usize,
    /// Turned down by the association: outside the innovation gate.
    pub gated: usize,
    /// Turned down by the association: near a landmark but compatible with none.
    pub ambiguous: usize,
    /// Refused by the filter (a full landmark table, a numerical refusal).
    pub refused: usize,
    /// Corrected the filter or created a landmark.
    pub used: usize,
    /// With a list of the true landmarks: the sighted ids it does not list (their
    /// landmarks are mapped, not scored; left out when there are none).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unlisted_ids: Vec<u32>,
}

/// `metrics.json`'s `inputs`: every record of each stream accounted for.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EkfInputs {
    /// The odometry.
    pub odometry: OdometryUse,
    /// The landmark sightings.
    pub sightings: SightingUse,
    /// A line for each stream that lost more than the settings' `loss_warning_fraction`
    /// ([`EkfInputs::warn_above`]; left out when none did).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

impl EkfInputs {
    /// The streams of `run`, a replay of `recording`.
    pub fn of(recording: &Recording, run: &ReplayRun) -> Self {
        let c = &run.counts;
        let refused_odometry = c.odometry_refused + c.predictions_refused;
        let used = c.updates + c.added;
        Self {
            odometry: OdometryUse {
                read: run.steps,
                used: run.steps.saturating_sub(refused_odometry),
                refused_implausible: c.odometry_refused,
                refused_by_filter: c.predictions_refused,
            },
            sightings: SightingUse {
                read: run.sightings + recording.dropped_sightings,
                reader_dropped: recording.dropped_sightings,
                reader_dropped_because: recording.dropped_reason.clone(),
                out_of_range: c.dropped,
                gated: c.gated,
                ambiguous: c.ambiguous,
                // Whatever reached the filter and was neither used nor turned down.
                refused: run
                    .sightings
                    .saturating_sub(used + c.dropped + c.gated + c.ambiguous),
                used,
                unlisted_ids: unlisted_ids(recording),
            },
            warnings: Vec::new(),
        }
    }

    /// Fills [`EkfInputs::warnings`]: the odometry records refused (implausible, or by the
    /// filter) and the sightings that reached the filter but were refused or out of range,
    /// each against `fraction` of its stream. Sightings the reader dropped by design (of the
    /// other robots) and those the association turned down are not losses.
    pub fn warn_above(&mut self, fraction: f64) {
        let o = &self.odometry;
        let s = &self.sightings;
        let offered = s.read.saturating_sub(s.reader_dropped);
        for (lost, of, what) in [
            (
                o.refused_implausible + o.refused_by_filter,
                o.read,
                "odometry records refused (not finite, implausible, or by the filter)",
            ),
            (
                s.out_of_range + s.refused,
                offered,
                "sightings out of range or refused by the filter",
            ),
        ] {
            let share = lost as f64 / of.max(1) as f64;
            if share > fraction {
                self.warnings.push(format!(
                    "{lost} of {of} {what} ({:.1} %), more than the settings' loss_warning_fraction {fraction}",
                    100.0 * share
                ));
            }
        }
        if !s.unlisted_ids.is_empty() {
            let ids: Vec<String> = s.unlisted_ids.iter().map(u32::to_string).collect();
            self.warnings.push(format!(
                "sighted landmark ids that the recording's true landmarks do not list: {} (mapped, not scored)",
                ids.join(", ")
            ));
        }
    }

    /// Refuses a run that used none of an input it needs, naming the recording and the
    /// counts: no odometry record, every one refused, no sighting, or none used. Checked
    /// before anything is written, so such a run never exits 0.
    pub fn check_used(&self, dataset: &str) -> Result<()> {
        let o = &self.odometry;
        if o.read == 0 {
            bail!("{dataset}: no odometry record: nothing drives the filter");
        }
        if o.used == 0 {
            bail!(
                "{dataset}: none of the {} odometry records could be used ({} refused as \
                 not finite or beyond the settings' max_speed_mps / max_turn_rate_radps, \
                 {} refused by the filter)",
                o.read,
                o.refused_implausible,
                o.refused_by_filter
            );
        }
        let s = &self.sightings;
        if s.read == 0 {
            bail!("{dataset}: no landmark sighting: nothing to map");
        }
        if s.used == 0 {
            let mut why = Vec::new();
            if s.reader_dropped > 0 {
                why.push(format!(
                    "{} dropped by the reader: {}",
                    s.reader_dropped, s.reader_dropped_because
                ));
            }
            for (n, what) in [
                (
                    s.out_of_range,
                    "outside the settings' min_range ..= max_range",
                ),
                (s.gated, "outside the innovation gate"),
                (s.ambiguous, "ambiguous"),
                (s.refused, "refused by the filter"),
            ] {
                if n > 0 {
                    why.push(format!("{n} {what}"));
                }
            }
            bail!(
                "{dataset}: none of the {} landmark sightings could be used ({})",
                s.read,
                why.join("; ")
            );
        }
        Ok(())
    }
}

/// The sighted ids (known-id sightings) that `recording`'s true landmarks do not list, in
/// increasing order; none when it lists no landmark.
fn unlisted_ids(recording: &Recording) -> Vec<u32> {
    if recording.landmarks.is_empty() {
        return Vec::new();
    }
    let listed: std::collections::BTreeSet<u32> =
        recording.landmarks.iter().map(|l| l.id).collect();
    let unlisted: std::collections::BTreeSet<u32> = recording
        .sighted_ids()
        .filter(|id| !listed.contains(id))
        .collect();
    unlisted.into_iter().collect()
}

/// Refuses a landmark replay that used none of an input it needs
/// ([`crate::metrics::inputs::EkfInputs::check_used`]) or whose ground truth it could not
/// be scored against (robot ground truth that overlaps no estimate, true landmarks none
/// of whose ids was sighted).
pub fn check_scored(recording: &Recording, metrics: &super::Metrics) -> Result<()> {
    metrics.inputs.check_used(&recording.name)?;
    // True landmarks none of whose ids was sighted: the map cannot be scored.
    let sighted: std::collections::BTreeSet<u32> = recording.sighted_ids().collect();
    let unlisted = &metrics.inputs.sightings.unlisted_ids;
    if !recording.landmarks.is_empty() && !sighted.is_empty() && unlisted.len() == sighted.len() {
        let listed: Vec<String> = recording
            .landmarks
            .iter()
            .map(|l| l.id.to_string())
            .collect();
        let seen: Vec<String> = sighted.iter().map(u32::to_string).collect();
        bail!(
            "{}: none of the sighted landmark ids ({}) is among the true landmarks' ({}): the map cannot be scored",
            recording.name,
            seen.join(", "),
            listed.join(", ")
        );
    }
    if !recording.ground_truth.is_empty() && metrics.evaluated_poses == 0 {
        let (first, last) = (
            recording.ground_truth.first().map_or(0.0, |g| g.stamp),
            recording.ground_truth.last().map_or(0.0, |g| g.stamp),
        );
        bail!(
            "{}: the ground truth ({} poses, {first} s ..= {last} s) overlaps none of the              {} estimates' stamps: no ATE can be computed",
            recording.name,
            recording.ground_truth.len(),
            metrics.steps
        );
    }
    Ok(())
}

/// What a grid run over `log` read, used and lost of each input stream, with the reason,
/// and a warning for each stream whose lost share is above `threshold` (`metrics.json`'s
/// `input_loss`): how many of the front scans' stamps went back before the previous
/// scan's (taken in file order, as the format plays them: `scans.stamps_going_back`), the
/// lines the reader skipped by type (`skipped_lines`), with a warning for each type CARMEN
/// does not have ([`CarmenLog::unknown_messages`]).
pub fn input_loss(run: &GridRun, threshold: f64, log: &CarmenLog) -> serde_json::Value {
    let read = run.trajectory.len();
    let stamps_back = stamps_going_back(log.lasers().filter(|l| !l.rear).map(|l| l.stamp));
    let mut warnings = Vec::new();
    // Lines the reader skipped: every type counted; a type CARMEN does not have (a
    // misspelt or damaged line, whose scan or odometry is lost) warned of.
    for (kind, lines, first) in log.unknown_messages() {
        warnings.push(format!(
            "{lines} line{} of a message type CARMEN does not have skipped: `{kind}` (first at line {first})",
            if lines == 1 { "" } else { "s" }
        ));
    }
    let mut stream = |name: &str, lost: usize, verb: &str, reason: &str| {
        let share = lost as f64 / read.max(1) as f64;
        if share > threshold {
            warnings.push(format!(
                "{lost} of {read} {name} ({:.1} %) {verb}: {reason}; more than the settings' loss_warning_fraction {threshold}",
                100.0 * share
            ));
        }
        serde_json::json!({
            "read": read,
            "used": read - lost.min(read),
            verb: lost,
            "reason": reason,
            "share": share,
        })
    };
    let mut scans = stream("scans", run.skipped_scans, "skipped", "no usable beam");
    scans["stamps_going_back"] = stamps_back.into();
    let mut odometry = stream(
        "odometry poses",
        run.refused_odometry,
        "refused",
        "not finite",
    );
    // A reset is not lost input (the scan is used), but every one is reported: the
    // odometry jumped further than any robot moves between two scans.
    odometry["resets"] = run.odometry_resets.into();
    if run.odometry_resets > 0 {
        warnings.push(format!(
            "{} odometry steps longer than the settings' max_odometry_step_m, taken as odometry resets (the filter re-anchored, not moved)",
            run.odometry_resets
        ));
    }
    serde_json::json!({
        "warning_fraction": threshold,
        "scans": scans,
        "odometry": odometry,
        "skipped_lines": log.skipped_counts(),
        "warnings": warnings,
    })
}

/// How many of `stamps` go back before the one before them (equal stamps are in order).
pub fn stamps_going_back(stamps: impl IntoIterator<Item = f64>) -> usize {
    let mut previous = f64::NEG_INFINITY;
    stamps
        .into_iter()
        .filter(|&t| {
            let back = t < previous;
            previous = t;
            back
        })
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::ekf::AssociationCounts;

    fn inputs(steps: usize, sightings: usize, counts: AssociationCounts) -> EkfInputs {
        EkfInputs {
            odometry: OdometryUse {
                read: steps,
                used: steps - counts.odometry_refused - counts.predictions_refused,
                refused_implausible: counts.odometry_refused,
                refused_by_filter: counts.predictions_refused,
            },
            sightings: SightingUse {
                read: sightings,
                used: counts.updates + counts.added,
                gated: counts.gated,
                ..SightingUse::default()
            },
            warnings: Vec::new(),
        }
    }

    #[test]
    fn a_large_loss_is_a_warning_and_a_small_one_is_not() {
        let mut lossy = inputs(
            10,
            20,
            AssociationCounts {
                odometry_refused: 2,
                updates: 20,
                ..AssociationCounts::default()
            },
        );
        lossy.warn_above(0.1);
        assert_eq!(
            lossy.warnings,
            [
                "2 of 10 odometry records refused (not finite, implausible, or by the filter) (20.0 %), more than the settings' loss_warning_fraction 0.1"
            ]
        );
        lossy.warnings.clear();
        lossy.warn_above(0.2);
        assert!(lossy.warnings.is_empty());
    }

    #[test]
    fn stamps_going_back_are_counted_once_each() {
        assert_eq!(stamps_going_back([1.0, 2.0, 2.0, 1.5, 3.0, 2.9, 2.95]), 2);
        assert_eq!(stamps_going_back([]), 0);
    }

    #[test]
    fn a_run_without_a_used_sighting_or_odometry_record_is_refused_with_the_counts() {
        let gated = AssociationCounts {
            gated: 7,
            ..AssociationCounts::default()
        };
        let err = inputs(10, 7, gated)
            .check_used("run.txt")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "run.txt: none of the 7 landmark sightings could be used (7 outside the innovation gate)"
        );
        let refused = AssociationCounts {
            odometry_refused: 4,
            updates: 3,
            ..AssociationCounts::default()
        };
        let err = inputs(4, 3, refused)
            .check_used("r")
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("r: none of the 4 odometry records could be used (4 refused"),
            "{err}"
        );
        let none = AssociationCounts::default();
        let err = inputs(5, 0, none).check_used("r").unwrap_err().to_string();
        assert_eq!(err, "r: no landmark sighting: nothing to map");
        let used = AssociationCounts {
            updates: 1,
            gated: 6,
            ..AssociationCounts::default()
        };
        inputs(5, 7, used).check_used("r").unwrap();
    }
}
