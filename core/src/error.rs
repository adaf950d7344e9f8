//! Errors of the estimators: small `Copy` values, never panics.
//!
//! Every step function checks its input before it touches the filter: when it returns an
//! error, the state is exactly what it was before the call.

use crate::scalar::Real;
use core::fmt;

/// Why an EKF step was refused. The filter state is unchanged whenever one is returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EkfError {
    /// An input (odometry, measurement, noise) held NaN or ±∞.
    NonFiniteInput,
    /// A velocity step with a negative duration (time stamps out of order).
    NegativeTimeStep,
    /// A measurement with a range outside `MIN_RANGE..=MAX_RANGE` of
    /// `sensors::range_bearing` (5 cm to 1 km).
    InvalidRange,
    /// A noise setting or covariance that is negative or not finite.
    InvalidNoise,
    /// The landmark index does not name an active landmark.
    UnknownLandmark,
    /// The landmark sits on the sensor: its bearing is undefined.
    LandmarkOnSensor,
    /// The landmark table is full: the sighting was not added (it is still the caller's).
    MapFull,
    /// The innovation covariance is not positive definite (a corrupted filter or noise).
    SingularInnovation,
    /// The step would leave a non-finite value in the state; it was not applied.
    NumericalFailure,
    /// A measurement with a bearing beyond one turn (`MAX_BEARING` of
    /// `sensors::range_bearing`): a corrupted reading.
    InvalidBearing,
}

impl fmt::Display for EkfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NonFiniteInput => "input contains NaN or infinity",
            Self::NegativeTimeStep => "negative time step (time stamps out of order)",
            Self::InvalidRange => "measured range is outside 5 cm ..= 1 km",
            Self::InvalidNoise => "noise parameter is negative or not finite",
            Self::UnknownLandmark => "no active landmark has this index",
            Self::LandmarkOnSensor => "landmark coincides with the sensor",
            Self::MapFull => "landmark table is full",
            Self::SingularInnovation => "innovation covariance is not positive definite",
            Self::NumericalFailure => "step would make the state non-finite",
            Self::InvalidBearing => "measured bearing is beyond one turn (±2π)",
        })
    }
}

impl core::error::Error for EkfError {}

/// A fixed-capacity table is full; carries back the item that did not fit, like
/// `heapless::Vec::push`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MapFull<I>(pub I);

impl<I> fmt::Display for MapFull<I> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("table is full")
    }
}

impl<I: fmt::Debug> core::error::Error for MapFull<I> {}

/// A setting out of its range, as a configuration's `invalid_setting` reports it
/// ([`crate::pf::GridPfConfig::invalid_setting`]): the field's name — the key `host-sim`'s
/// settings files use — and the range it must be in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InvalidSetting {
    /// The field, e.g. `"resample_neff_fraction"`.
    pub name: &'static str,
    /// What it must be, e.g. `"within 0 ..= 1"`.
    pub rule: &'static str,
}

/// One check of a configuration for [`InvalidSetting::first`]: the field's name, its
/// rule, and whether the field keeps it.
pub type SettingCheck = (&'static str, &'static str, bool);

impl InvalidSetting {
    /// The rule of noise figures, weights and spreads: `"finite and non-negative"`.
    pub const NON_NEGATIVE: &'static str = "finite and non-negative";
    /// The rule of sizes and scales: `"finite and positive"`.
    pub const POSITIVE: &'static str = "finite and positive";
    /// The rule of shares and fractions: `"within 0 ..= 1"`.
    pub const FRACTION: &'static str = "within 0 ..= 1";
    /// The rule of rates and steps that must not be 0: `"within (0, 1]"`.
    pub const POSITIVE_FRACTION: &'static str = "within (0, 1]";

    /// The first of `checks` that does not hold. Always inlined, so that a caller asking
    /// only whether one fails (`is_valid`) keeps no names.
    #[inline(always)]
    pub fn first<const N: usize>(checks: [SettingCheck; N]) -> Option<Self> {
        checks
            .into_iter()
            .find(|(_, _, holds)| !holds)
            .map(|(name, rule, _)| Self { name, rule })
    }

    /// `name` must be [`InvalidSetting::NON_NEGATIVE`] (NaN and ±∞ are not).
    #[inline(always)]
    pub fn non_negative<T: Real>(name: &'static str, value: T) -> SettingCheck {
        (name, Self::NON_NEGATIVE, value.finite() && value >= T::ZERO)
    }

    /// `name` must be [`InvalidSetting::POSITIVE`].
    #[inline(always)]
    pub fn positive<T: Real>(name: &'static str, value: T) -> SettingCheck {
        (name, Self::POSITIVE, value.finite() && value > T::ZERO)
    }

    /// `name` must be [`InvalidSetting::FRACTION`] (NaN is not).
    #[inline(always)]
    pub fn fraction<T: Real>(name: &'static str, value: T) -> SettingCheck {
        (name, Self::FRACTION, value >= T::ZERO && value <= T::ONE)
    }

    /// `name` must be [`InvalidSetting::POSITIVE_FRACTION`] (NaN is not).
    #[inline(always)]
    pub fn positive_fraction<T: Real>(name: &'static str, value: T) -> SettingCheck {
        (
            name,
            Self::POSITIVE_FRACTION,
            value > T::ZERO && value <= T::ONE,
        )
    }
}

impl fmt::Display for InvalidSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}` must be {}", self.name, self.rule)
    }
}

impl core::error::Error for InvalidSetting {}
