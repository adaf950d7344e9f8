//! IMU yaw rate: a 10 Hz low-pass filter and the alignment of the IMU stream to the
//! encoder clock, as in Du (n.d., §III-B and §III-C).
//!
//! - [`YawRateLowPass`]: a first-order (single-pole RC) low-pass filter
//!   `y_k = y_{k−1} + α (x_k − y_{k−1})` with `α = dt / (RC + dt)`, `RC = 1 / (2π f_c)`,
//!   where `dt` is the stamp difference of consecutive samples (so an irregular IMU rate is
//!   handled). The first sample initialises the output. One scalar of state.
//! - [`ImuAligner`]: keeps the last `N` (filtered) samples in a fixed ring; the encoder
//!   clock is the main clock, and for an encoder stamp `t` it returns the nearest IMU sample
//!   or the mean of the two nearest ones (the choice of Du n.d. for its noisy gyro).
//!   Push every IMU sample with a stamp up to the encoder stamp plus half the IMU period
//!   before asking, so that the nearest sample after `t` is already in the ring.
//!
//! # References
//!
//! - Du, C. (n.d.). *ECE 276 Project: Particle Filter SLAM*. Undated report, University of
//!   California, San Diego. The low-pass filter and the alignment to the encoder clock,
//!   §III-B and §III-C.

use crate::scalar::Real;
use core::fmt;

/// Why an IMU sample or a query was refused (the filter or ring is unchanged).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImuError {
    /// The stamp or the rate is NaN or ±∞.
    NonFinite,
    /// The stamp is older than the previous sample's.
    OutOfOrder,
    /// No sample has been pushed yet.
    Empty,
}

impl fmt::Display for ImuError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NonFinite => "IMU stamp or rate is not finite",
            Self::OutOfOrder => "IMU stamp is older than the previous one",
            Self::Empty => "no IMU sample yet",
        })
    }
}

impl core::error::Error for ImuError {}

/// First-order low-pass filter of the yaw rate, cut-off `cutoff_hz` (Du n.d.: 10 Hz).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct YawRateLowPass<T> {
    rc: T,
    state: Option<(T, T)>,
}

impl<T: Real> YawRateLowPass<T> {
    /// A filter with the given cut-off frequency in hertz (must be positive; a
    /// non-positive or non-finite value disables filtering: the output is the input).
    pub fn new(cutoff_hz: T) -> Self {
        let rc = if cutoff_hz.finite() && cutoff_hz > T::ZERO {
            T::ONE / (T::two_pi() * cutoff_hz)
        } else {
            T::ZERO
        };
        Self { rc, state: None }
    }

    /// Filters one sample taken at `stamp` seconds; returns the filtered rate.
    pub fn update(&mut self, stamp: T, rate: T) -> Result<T, ImuError> {
        if !stamp.finite() || !rate.finite() {
            return Err(ImuError::NonFinite);
        }
        let y = match self.state {
            None => rate,
            Some((t0, y0)) => {
                let dt = stamp - t0;
                if dt < T::ZERO {
                    return Err(ImuError::OutOfOrder);
                }
                let denom = self.rc + dt;
                if denom <= T::ZERO {
                    y0
                } else {
                    y0 + dt / denom * (rate - y0)
                }
            }
        };
        self.state = Some((stamp, y));
        Ok(y)
    }

    /// The last output, if any.
    pub fn output(&self) -> Option<T> {
        self.state.map(|s| s.1)
    }
}

/// How an IMU rate is picked for an encoder stamp.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Alignment {
    /// The sample with the closest stamp (ties: the earlier one).
    Nearest,
    /// The mean of the two samples with the closest stamps (Du n.d., §III-C).
    MeanOfTwoNearest,
}

/// The last `N` IMU samples `(stamp, rate)` in a fixed ring (`N ≥ 2` for two-sample
/// alignment).
#[derive(Clone, Copy, Debug)]
pub struct ImuAligner<T, const N: usize> {
    samples: [(T, T); N],
    next: usize,
    len: usize,
}

impl<T: Real, const N: usize> Default for ImuAligner<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T: Real, const N: usize> ImuAligner<T, N> {
    /// An empty ring.
    pub const fn new() -> Self {
        Self {
            samples: [(T::ZERO, T::ZERO); N],
            next: 0,
            len: 0,
        }
    }

    /// Number of samples held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// `true` when no sample is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Stores a sample; the oldest one is dropped when the ring is full.
    pub fn push(&mut self, stamp: T, rate: T) -> Result<(), ImuError> {
        if !stamp.finite() || !rate.finite() {
            return Err(ImuError::NonFinite);
        }
        if N == 0 {
            return Ok(());
        }
        if self.len > 0 {
            let last = (self.next + N - 1) % N;
            if let Some(s) = self.samples.get(last)
                && stamp < s.0
            {
                return Err(ImuError::OutOfOrder);
            }
        }
        if let Some(slot) = self.samples.get_mut(self.next) {
            *slot = (stamp, rate);
        }
        self.next = (self.next + 1) % N;
        self.len = (self.len + 1).min(N);
        Ok(())
    }

    /// The yaw rate for the encoder stamp `stamp`.
    pub fn rate_at(&self, stamp: T, mode: Alignment) -> Result<T, ImuError> {
        if !stamp.finite() {
            return Err(ImuError::NonFinite);
        }
        let mut best: Option<(T, T)> = None; // (distance, rate)
        let mut second: Option<(T, T)> = None;
        for k in 0..self.len {
            let idx = (self.next + N - self.len + k) % N;
            let Some(&(t, r)) = self.samples.get(idx) else {
                continue;
            };
            let d = (t - stamp).abs();
            match best {
                Some((bd, _)) if d >= bd => {
                    if second.is_none_or(|(sd, _)| d < sd) {
                        second = Some((d, r));
                    }
                }
                _ => {
                    second = best;
                    best = Some((d, r));
                }
            }
        }
        match (mode, best, second) {
            (_, None, _) => Err(ImuError::Empty),
            (Alignment::Nearest, Some((_, r)), _) | (_, Some((_, r)), None) => Ok(r),
            (Alignment::MeanOfTwoNearest, Some((_, a)), Some((_, b))) => Ok((a + b) * T::lit(0.5)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn low_pass_step_response_is_first_order() {
        // 10 Hz cut-off sampled at 1 kHz: after one time constant RC = 15.9 ms the step
        // response is 1 − e^{-1} ≈ 0.632 (discretisation error ≈ 3 % at this rate).
        let mut f = YawRateLowPass::new(10.0f64);
        f.update(0.0, 0.0).unwrap();
        let rc = 1.0 / (2.0 * core::f64::consts::PI * 10.0);
        let mut t = 0.0;
        let mut y = 0.0;
        while t < rc - 1e-12 {
            t += 0.001;
            y = f.update(t, 1.0).unwrap();
        }
        assert!((y - (1.0 - (-t / rc).exp())).abs() < 0.02, "{y}");
        // A fast oscillation (200 Hz) is attenuated by ≈ 20×.
        let mut f = YawRateLowPass::new(10.0f64);
        let mut peak = 0.0f64;
        for k in 0..2000 {
            let t = k as f64 * 1e-4;
            let y = f
                .update(t, (2.0 * core::f64::consts::PI * 200.0 * t).sin())
                .unwrap();
            if k > 1000 {
                peak = peak.max(y.abs());
            }
        }
        assert!(peak < 0.08, "{peak}");
    }

    #[test]
    fn low_pass_rejects_bad_samples_and_keeps_state() {
        let mut f = YawRateLowPass::new(10.0f32);
        f.update(1.0, 0.5).unwrap();
        assert_eq!(f.update(0.5, 1.0), Err(ImuError::OutOfOrder));
        assert_eq!(f.update(f32::NAN, 1.0), Err(ImuError::NonFinite));
        assert_eq!(f.update(2.0, f32::INFINITY), Err(ImuError::NonFinite));
        assert_eq!(f.output(), Some(0.5));
    }

    #[test]
    fn alignment_nearest_and_two_nearest() {
        let mut a = ImuAligner::<f64, 4>::new();
        assert_eq!(a.rate_at(0.0, Alignment::Nearest), Err(ImuError::Empty));
        for (t, r) in [
            (0.00, 1.0),
            (0.01, 2.0),
            (0.02, 3.0),
            (0.03, 4.0),
            (0.04, 5.0),
        ] {
            a.push(t, r).unwrap();
        }
        assert_eq!(a.len(), 4); // the first sample was dropped
        assert_eq!(a.rate_at(0.0121, Alignment::Nearest), Ok(2.0));
        assert_eq!(a.rate_at(0.0121, Alignment::MeanOfTwoNearest), Ok(2.5));
        assert_eq!(a.rate_at(0.1, Alignment::MeanOfTwoNearest), Ok(4.5));
        assert_eq!(a.rate_at(-5.0, Alignment::Nearest), Ok(2.0));
        assert_eq!(a.push(0.035, 9.0), Err(ImuError::OutOfOrder));
        assert_eq!(a.rate_at(0.04, Alignment::Nearest), Ok(5.0));
        let mut one = ImuAligner::<f32, 2>::new();
        one.push(1.0, 7.0).unwrap();
        assert_eq!(one.rate_at(3.0, Alignment::MeanOfTwoNearest), Ok(7.0));
    }
}
