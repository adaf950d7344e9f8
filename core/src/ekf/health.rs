//! Supervision of the landmark EKF's updates: robust weighting of large innovations,
//! detection of a filter that has lost itself, and recovery instead of lock-out.
//!
//! An overconfident filter refuses true sightings at its χ² gate; each refusal keeps it
//! overconfident, and it never comes back. Written down as PX4's EKF2 does it:
//! - **Robust weighting** (Huber): an innovation farther than `huber_sigma` standard
//!   deviations from the prediction is not refused but down-weighted — its innovation
//!   covariance is scaled by `c = d / huber_sigma` (`d = √NIS`), which gives it the Huber
//!   weight `1/c`. The gate then sees `NIS / c = huber_sigma · d`: large innovations
//!   from the heavy tails of a camera's sightings move the state a little instead of not
//!   at all, and only gross outliers are refused.
//! - **Lost detection**: consecutive gate refusals are counted; an accepted sighting
//!   clears the count. When `lost_after` sightings in a row are refused the filter is
//!   evidently lost.
//! - **Recovery**: the pose covariance is then inflated by
//!   `diag(σ_p², σ_p², σ_θ²)` ([`EkfSlam::inflate_pose_covariance`]), so that the next
//!   sightings pass the gate and pull the robot back onto its map.
//!
//! - **Lost flag**: every sighting the map does not explain — refused by the gate,
//!   down-weighted, or (reported by the association, [`Supervisor::note_new_landmark`])
//!   made a new landmark — counts as a surprise. Their rate over the last `lost_memory`
//!   sightings (an exponentially weighted mean) above `lost_rate` raises
//!   [`flags::LOST`]: the filter's pose no longer matches its map. A filter that keeps
//!   its map is surprised now and then (an outlier, a landmark seen for the first time);
//!   one that has lost it meets surprise after surprise, with known ids (innovations
//!   beyond the noise) and with hidden ids alike (sightings that pair with nothing and
//!   become landmarks where the map already has them). The first `2 · lost_memory`
//!   sightings after a reset never raise it: a map being started is all new landmarks.
//!
//! What happened is reported in [`HealthStatus`]: a bit field of the last sighting's fate
//! and the lost flag, plus counters, small enough for the wire protocol's estimates. Fixed
//! memory, no allocation; per sighting the cost is one extra 2 × 2 innovation.

use super::{EkfSlam, UpdateOutcome};
use crate::error::{EkfError, InvalidSetting};
use crate::scalar::Real;
use crate::sensors::range_bearing::RangeBearing;
use nalgebra::Matrix3;

/// Settings of [`Supervisor`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HealthConfig<T> {
    /// Innovations beyond this many standard deviations (Mahalanobis distance) are
    /// down-weighted (Huber); `0` or less disables the weighting.
    pub huber_sigma: T,
    /// Consecutive gate refusals after which the filter is declared lost and recovered;
    /// `0` disables recovery.
    pub lost_after: u16,
    /// Standard deviation added to the robot's x and y at a recovery, m.
    pub recovery_position_std: T,
    /// Standard deviation added to the robot's heading at a recovery, rad.
    pub recovery_heading_std: T,
    /// Sightings the surprise rate of the lost flag averages over (the memory of its
    /// exponentially weighted mean); `0` disables the flag.
    pub lost_memory: u16,
    /// Surprise rate (share of the recent sightings the map did not explain) above which
    /// [`flags::LOST`] is raised.
    pub lost_rate: T,
}

impl HealthConfig<f32> {
    /// No weighting, no recovery: the bare filter.
    pub const OFF_F32: Self = Self {
        huber_sigma: 0.0,
        lost_after: 0,
        recovery_position_std: 0.0,
        recovery_heading_std: 0.0,
        lost_memory: 0,
        lost_rate: 1.0,
    };
    /// The defaults chosen on UTIAS MRCLAM (see `host-sim/configs/mrclam.toml`, whose
    /// `[recovery]` holds the same figures): Huber beyond 2 σ, recovery after 10 refusals
    /// in a row with 0.3 m and 0.2 rad added, the lost flag above a surprise rate of
    /// 0.1 over the last 20 sightings.
    pub const DEFAULT_F32: Self = Self {
        huber_sigma: 2.0,
        lost_after: 10,
        recovery_position_std: 0.3,
        recovery_heading_std: 0.2,
        lost_memory: 20,
        lost_rate: 0.1,
    };
}

impl<T: Real> HealthConfig<T> {
    /// `true` when every figure is finite and the recovery figures non-negative.
    pub fn is_valid(&self) -> bool {
        self.invalid_setting().is_none()
    }

    /// The first figure out of range (the field's name and its rule), `None` when every one
    /// is valid.
    #[inline]
    pub fn invalid_setting(&self) -> Option<InvalidSetting> {
        InvalidSetting::first([
            ("huber_sigma", "finite", self.huber_sigma.finite()),
            InvalidSetting::non_negative("recovery_position_std", self.recovery_position_std),
            InvalidSetting::non_negative("recovery_heading_std", self.recovery_heading_std),
            InvalidSetting::non_negative("lost_rate", self.lost_rate),
        ])
    }

    /// The same settings in another scalar type.
    pub fn cast<U: Real>(&self) -> HealthConfig<U> {
        HealthConfig {
            huber_sigma: U::lit(self.huber_sigma.to_f64()),
            lost_after: self.lost_after,
            recovery_position_std: U::lit(self.recovery_position_std.to_f64()),
            recovery_heading_std: U::lit(self.recovery_heading_std.to_f64()),
            lost_memory: self.lost_memory,
            lost_rate: U::lit(self.lost_rate.to_f64()),
        }
    }
}

/// Bits of [`HealthStatus::flags`].
pub mod flags {
    /// The last sighting was refused by the innovation gate.
    pub const GATED: u8 = 1 << 0;
    /// The last sighting was accepted with a Huber down-weighting.
    pub const DOWNWEIGHTED: u8 = 1 << 1;
    /// The refusals in a row have reached half of `lost_after`: the filter may be lost.
    pub const SUSPECT: u8 = 1 << 2;
    /// The last sighting triggered a recovery (pose covariance inflated).
    pub const RECOVERED: u8 = 1 << 3;
    /// The last recovery was refused by the filter (numerical limits).
    pub const RECOVERY_FAILED: u8 = 1 << 4;
    /// The filter is lost: most recent sightings were not explained by its map (see the
    /// [module](super) docs). Unlike the bits above it describes the filter, not the last
    /// sighting.
    pub const LOST: u8 = 1 << 5;
}

/// What the supervision saw: the last sighting's fate as bit [`flags`], and counters since
/// the last reset (saturating).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "wire", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HealthStatus {
    /// Bits of [`flags`] for the last sighting.
    pub flags: u8,
    /// Gate refusals in a row now.
    pub refused_in_row: u16,
    /// Recoveries (pose covariance inflations).
    pub recoveries: u16,
    /// Sightings accepted with a Huber down-weighting.
    pub downweighted: u32,
    /// Sightings refused by the gate.
    pub gated: u32,
}

impl HealthStatus {
    /// `true` when bit `flag` (one of [`flags`]) is set.
    pub fn has(&self, flag: u8) -> bool {
        self.flags & flag != 0
    }
}

/// Runs the EKF's landmark updates with robust weighting, lost detection and recovery.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervisor<T> {
    config: HealthConfig<T>,
    status: HealthStatus,
    /// The surprise rate: the weighted mean of 1 (not explained) and 0 (explained).
    surprise: T,
    /// Sightings since the last reset (saturating), for the lost flag's warm-up.
    sightings: u16,
}

impl<T: Real> Supervisor<T> {
    /// A supervisor with `config`, nothing seen yet.
    pub const fn new(config: HealthConfig<T>) -> Self {
        Self {
            config,
            status: HealthStatus {
                flags: 0,
                refused_in_row: 0,
                recoveries: 0,
                downweighted: 0,
                gated: 0,
            },
            surprise: T::ZERO,
            sightings: 0,
        }
    }

    /// The settings.
    pub fn config(&self) -> &HealthConfig<T> {
        &self.config
    }

    /// Replaces the settings; an invalid configuration is refused
    /// ([`EkfError::InvalidNoise`]) and the old one kept.
    pub fn set_config(&mut self, config: HealthConfig<T>) -> Result<(), EkfError> {
        if !config.is_valid() {
            return Err(EkfError::InvalidNoise);
        }
        self.config = config;
        Ok(())
    }

    /// The status after the last sighting.
    pub fn status(&self) -> HealthStatus {
        self.status
    }

    /// Clears the status (with the filter's re-initialisation).
    pub fn reset(&mut self) {
        self.status = HealthStatus::default();
        self.surprise = T::ZERO;
        self.sightings = 0;
    }

    /// `true` while [`flags::LOST`] is raised.
    pub fn is_lost(&self) -> bool {
        self.status.has(flags::LOST)
    }

    /// The share of the recent sightings the map did not explain (the lost flag's
    /// surprise rate, over the last `lost_memory` sightings).
    pub fn surprise_rate(&self) -> T {
        self.surprise
    }

    /// Tells the lost flag that a sighting paired with no landmark and became a new one
    /// (the association's decision, which [`Supervisor::update`] does not see): a
    /// surprise, as a refusal is.
    pub fn note_new_landmark(&mut self) {
        self.count_sighting(true);
    }

    /// Counts one sighting, `surprising` or not, in the surprise rate, and sets
    /// [`flags::LOST`] from it.
    fn count_sighting(&mut self, surprising: bool) {
        let memory = self.config.lost_memory;
        if memory == 0 {
            self.status.flags &= !flags::LOST;
            return;
        }
        let x = if surprising { T::ONE } else { T::ZERO };
        self.surprise += (x - self.surprise) / T::lit(f64::from(memory));
        self.sightings = self.sightings.saturating_add(1);
        let warm = self.sightings > memory.saturating_mul(2);
        if warm && self.surprise > self.config.lost_rate {
            self.status.flags |= flags::LOST;
        } else {
            self.status.flags &= !flags::LOST;
        }
    }

    /// Corrects `slam` with sighting `z` of landmark `index` (configured measurement
    /// noise), weighting a large innovation down and recovering a lost filter.
    ///
    /// The outcome's NIS is the innovation's before any weighting. Errors are the
    /// filter's ([`EkfSlam::update`]); the status is then unchanged.
    pub fn update<const N: usize, const P: usize>(
        &mut self,
        slam: &mut EkfSlam<T, N, P>,
        index: usize,
        z: &RangeBearing<T>,
    ) -> Result<UpdateOutcome<T>, EkfError> {
        let inn = slam.innovation(index, z)?;
        let nis = inn.mahalanobis_squared;
        let k = self.config.huber_sigma;
        let scale = if k > T::ZERO && nis > k * k {
            nis.sqrt() / k
        } else {
            T::ONE
        };
        let outcome = if scale > T::ONE {
            // R' = R + (c − 1) S makes the innovation covariance c S.
            let r = slam.config().measurement_covariance() + inn.s * (scale - T::ONE);
            slam.update_with_covariance(index, z, &r)?
        } else {
            slam.update(index, z)?
        };
        let s = &mut self.status;
        s.flags &= flags::LOST;
        let result = match outcome {
            UpdateOutcome::Accepted { .. } => {
                s.refused_in_row = 0;
                if scale > T::ONE {
                    s.flags |= flags::DOWNWEIGHTED;
                    s.downweighted = s.downweighted.saturating_add(1);
                }
                Ok(UpdateOutcome::Accepted { nis })
            }
            UpdateOutcome::Gated { .. } => {
                s.flags |= flags::GATED;
                s.gated = s.gated.saturating_add(1);
                s.refused_in_row = s.refused_in_row.saturating_add(1);
                let lost_after = self.config.lost_after;
                if lost_after > 0 && s.refused_in_row >= lost_after.div_ceil(2) {
                    s.flags |= flags::SUSPECT;
                }
                if lost_after > 0 && s.refused_in_row >= lost_after {
                    let p = self.config.recovery_position_std;
                    let h = self.config.recovery_heading_std;
                    let added =
                        Matrix3::from_diagonal(&nalgebra::Vector3::new(p * p, p * p, h * h));
                    if slam.inflate_pose_covariance(&added).is_ok() {
                        s.flags |= flags::RECOVERED;
                        s.recoveries = s.recoveries.saturating_add(1);
                    } else {
                        s.flags |= flags::RECOVERY_FAILED;
                    }
                    s.refused_in_row = 0;
                }
                Ok(UpdateOutcome::Gated { nis })
            }
        };
        self.count_sighting(scale > T::ONE || matches!(outcome, UpdateOutcome::Gated { .. }));
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::{EkfConfig, factor_len, state_dim};
    use crate::geometry::Pose2;

    type Slam = EkfSlam<f64, { state_dim(4) }, { factor_len(4) }>;

    fn config() -> HealthConfig<f64> {
        HealthConfig::DEFAULT_F32.cast()
    }

    /// A filter sure of its pose, with one landmark 2 m ahead known to a few cm.
    fn confident() -> Slam {
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        slam.add_landmark(&RangeBearing::new(2.0, 0.0)).unwrap();
        for _ in 0..20 {
            slam.predict_velocity(0.0, 0.0, 0.5).unwrap();
            slam.update(0, &RangeBearing::new(2.0, 0.0)).unwrap();
        }
        slam
    }

    #[test]
    fn inflation_adds_to_the_pose_block_and_refuses_bad_input() {
        let mut slam = confident();
        let before = slam.pose_covariance();
        let added = Matrix3::from_diagonal(&nalgebra::Vector3::new(0.04, 0.09, 0.01));
        slam.inflate_pose_covariance(&added).unwrap();
        let after = slam.pose_covariance();
        assert!((after - before - added).abs().max() < 1e-15);
        let mut nan = added;
        nan[(1, 1)] = f64::NAN;
        assert_eq!(
            slam.inflate_pose_covariance(&nan),
            Err(EkfError::NonFiniteInput)
        );
        let mut negative = added;
        negative[(2, 2)] = -0.01;
        assert_eq!(
            slam.inflate_pose_covariance(&negative),
            Err(EkfError::InvalidNoise)
        );
        let mut indefinite = added;
        indefinite[(0, 1)] = 1.0;
        indefinite[(1, 0)] = 1.0;
        assert_eq!(
            slam.inflate_pose_covariance(&indefinite),
            Err(EkfError::InvalidNoise)
        );
        assert_eq!(slam.pose_covariance(), after, "refusals change nothing");
    }

    #[test]
    fn large_innovation_is_downweighted_not_refused() {
        // 4 σ off: the bare filter (gate 13.8 = 3.7 σ) refuses it, the supervisor
        // accepts it with weight 2/4 (its gate sees 2 · 4 = 8).
        let mut bare = confident();
        let mut robust = confident();
        let s = bare.innovation(0, &RangeBearing::new(2.0, 0.0)).unwrap().s;
        let z = RangeBearing::new(2.0 + 4.0 * s[(0, 0)].sqrt(), 0.0);
        let nis = bare.innovation(0, &z).unwrap().mahalanobis_squared;
        assert!((nis - 16.0).abs() < 0.5, "{nis}");
        assert!(matches!(
            bare.update(0, &z),
            Ok(UpdateOutcome::Gated { .. })
        ));
        let mut sup = Supervisor::new(config());
        let out = sup.update(&mut robust, 0, &z).unwrap();
        assert_eq!(out, UpdateOutcome::Accepted { nis });
        assert!(sup.status().has(flags::DOWNWEIGHTED));
        assert_eq!(sup.status().downweighted, 1);
        // It moved the robot, by less than a full-weight update would.
        let mut full = confident();
        let r = EkfConfig::DEFAULT_F64.measurement_covariance();
        full.update_with_covariance(0, &z, &r).unwrap();
        let moved = (robust.pose().x).abs();
        assert!(moved > 0.0);
        let open = {
            let mut c = EkfConfig::DEFAULT_F64;
            c.gate = crate::gate::ChiSquareGate::open();
            let mut f = confident();
            f.set_config(c).unwrap();
            f.update(0, &z).unwrap();
            f.pose().x.abs()
        };
        assert!(moved < open, "{moved} !< {open}");
    }

    #[test]
    fn refusals_in_a_row_trigger_a_recovery_that_reacquires() {
        let mut slam = confident();
        let mut sup = Supervisor::new(config());
        // The robot was kidnapped 1 m back: every sighting reads 3 m.
        let z = RangeBearing::new(3.0, 0.0);
        for i in 1..config().lost_after {
            assert!(matches!(
                sup.update(&mut slam, 0, &z),
                Ok(UpdateOutcome::Gated { .. })
            ));
            assert_eq!(sup.status().refused_in_row, i);
        }
        assert!(sup.status().has(flags::SUSPECT));
        let before = slam.pose_covariance();
        assert!(matches!(
            sup.update(&mut slam, 0, &z),
            Ok(UpdateOutcome::Gated { .. })
        ));
        let st = sup.status();
        assert!(st.has(flags::RECOVERED) && st.has(flags::GATED));
        assert_eq!((st.recoveries, st.refused_in_row), (1, 0));
        let grown = slam.pose_covariance() - before;
        assert!((grown[(0, 0)] - 0.09).abs() < 1e-6, "{grown}");
        // Re-acquired: the next sightings are accepted and pull the robot back.
        for _ in 0..5 {
            sup.update(&mut slam, 0, &z).unwrap();
        }
        assert_eq!(sup.status().refused_in_row, 0);
        assert!(slam.pose().x < -0.5, "robot at {}", slam.pose().x);
    }

    #[test]
    fn recovery_off_means_lock_out() {
        let mut slam = confident();
        let mut sup = Supervisor::new(HealthConfig::OFF_F32.cast::<f64>());
        let z = RangeBearing::new(3.0, 0.0);
        for _ in 0..50 {
            assert!(matches!(
                sup.update(&mut slam, 0, &z),
                Ok(UpdateOutcome::Gated { .. })
            ));
        }
        assert_eq!(sup.status().recoveries, 0);
        assert_eq!(sup.status().gated, 50);
        assert_eq!(slam.pose(), Pose2::new(0.0, 0.0, 0.0));
    }

    #[test]
    fn errors_leave_the_status_alone() {
        let mut slam = confident();
        let mut sup = Supervisor::new(config());
        assert_eq!(
            sup.update(&mut slam, 3, &RangeBearing::new(2.0, 0.0)),
            Err(EkfError::UnknownLandmark)
        );
        assert_eq!(sup.status(), HealthStatus::default());
        assert!(
            sup.set_config(HealthConfig {
                huber_sigma: f64::NAN,
                ..config()
            })
            .is_err()
        );
    }

    #[test]
    fn the_lost_flag_follows_the_share_of_unexplained_sightings() {
        let mut slam = confident();
        let mut sup = Supervisor::new(config());
        let memory = config().lost_memory;
        let (true_z, kidnapped) = (RangeBearing::new(2.0, 0.0), RangeBearing::new(3.0, 0.0));
        // Explained sightings keep it down; past the warm-up, a few refusals in a row
        // raise it, before the recovery that comes after ten.
        for _ in 0..3 * memory {
            sup.update(&mut slam, 0, &true_z).unwrap();
        }
        assert!(!sup.is_lost() && sup.surprise_rate() == 0.0);
        for _ in 0..3 {
            sup.update(&mut slam, 0, &kidnapped).unwrap();
        }
        assert!(sup.is_lost() && sup.status().has(flags::GATED));
        assert_eq!(sup.status().recoveries, 0);
        // Explained again: it falls back below the rate and clears.
        let mut cleared = 0;
        for i in 0..3 * memory {
            sup.update(&mut slam, 0, &true_z).unwrap();
            if !sup.is_lost() {
                cleared = i;
                break;
            }
        }
        assert!(cleared > 0 && !sup.is_lost(), "{cleared}");
        // New landmarks count as refusals do; off with lost_memory = 0.
        for _ in 0..3 {
            sup.note_new_landmark();
        }
        assert!(sup.is_lost() && sup.status().has(flags::LOST));
        sup.set_config(HealthConfig {
            lost_memory: 0,
            ..config()
        })
        .unwrap();
        sup.note_new_landmark();
        assert!(!sup.is_lost());
        // Nothing before the warm-up: a map being started is all new landmarks.
        let mut fresh = Supervisor::new(config());
        for _ in 0..2 * memory {
            fresh.note_new_landmark();
        }
        assert!(!fresh.is_lost() && fresh.surprise_rate() > 0.5);
        fresh.note_new_landmark();
        assert!(fresh.is_lost());
        fresh.reset();
        assert!(!fresh.is_lost() && fresh.surprise_rate() == 0.0);
    }

    #[test]
    fn an_invalid_setting_is_named_with_its_rule() {
        use crate::testing::{BrokenSetting, each_broken_setting_is_named};
        assert_eq!(HealthConfig::DEFAULT_F32.invalid_setting(), None);
        assert_eq!(HealthConfig::OFF_F32.invalid_setting(), None);
        let cases: [BrokenSetting<HealthConfig<f64>>; 4] = [
            (|c| c.huber_sigma = f64::NAN, "huber_sigma", "finite"),
            (
                |c| c.lost_rate = -0.1,
                "lost_rate",
                "finite and non-negative",
            ),
            (
                |c| c.recovery_position_std = -0.3,
                "recovery_position_std",
                "finite and non-negative",
            ),
            (
                |c| c.recovery_heading_std = f64::INFINITY,
                "recovery_heading_std",
                "finite and non-negative",
            ),
        ];
        each_broken_setting_is_named(config(), &cases, |c| (c.is_valid(), c.invalid_setting()));
    }
}
