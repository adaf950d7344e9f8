//! Measurement switches of `scripts/mrclam-leave-outs`, which times the MRCLAM replay
//! without parts of its work beside MRPT `kf-slam` (docs/speed.md, "Why 20× is out of
//! reach"). They exist only in a build with the feature `leave-outs`, where each is read
//! from the environment once a run; in every other build [`leave_out`] is the constant
//! `false` and the code behind it is compiled (so it cannot rot) and optimised away.

/// A part of the work a leave-out build can skip.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeaveOut {
    /// `LEAVE_OUT_TUM`: neither TUM file is written (the poses are still scored).
    TumFiles,
    /// `LEAVE_OUT_PREDICTIONS`: one EKF prediction over the summed time before each batch
    /// of sightings instead of one per odometry sample.
    Predictions,
}

impl LeaveOut {
    /// The environment variable that switches it on.
    pub const fn variable(self) -> &'static str {
        match self {
            Self::TumFiles => "LEAVE_OUT_TUM",
            Self::Predictions => "LEAVE_OUT_PREDICTIONS",
        }
    }
}

/// `true` when this build leaves `part` out: a `leave-outs` build whose environment sets
/// its variable. Always `false` without the feature.
#[cfg(feature = "leave-outs")]
pub fn leave_out(part: LeaveOut) -> bool {
    std::env::var_os(part.variable()).is_some()
}

/// `true` when this build leaves `part` out: a `leave-outs` build whose environment sets
/// its variable. Always `false` without the feature.
#[cfg(not(feature = "leave-outs"))]
pub const fn leave_out(part: LeaveOut) -> bool {
    let _ = part;
    false
}
