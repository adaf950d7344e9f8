//! Feeding a time-ordered stream of [`Event`]s to an estimator.
//!
//! An [`Event`] says what a sensor measured and when; an estimator step says how far to
//! move or what was seen. [`EventFeed`] turns the first into the second for every
//! estimator that moves with odometry ([`Predictor`]: [`EkfSlam`], [`GridSlam`],
//! [`GridLocalizer`]):
//!
//! - before every event, the estimator is predicted up to the event's stamp with the
//!   velocity held since the last [`EventKind::Velocity`] sample (`dt` computed in `f64`
//!   from the stamps, capped at `max_gap` seconds so that a pause in a recording does not
//!   become one long drive);
//! - [`EventKind::Velocity`] is held (it describes the motion *after* its stamp), and so is
//!   a car's [`EventKind::Ackermann`] (speed and steering, moved through the feed's
//!   vehicle, [`EventFeed::with_vehicle`]); each replaces the other;
//!   [`EventKind::Increment`] is applied at once;
//! - a sighting is handed back as [`Fed::Sighting`] for the caller's data association
//!   ([`observe_known_sighting`] for known ids, or ICNN / JCBB from
//!   [`crate::association`]); a yaw rate comes back as [`Fed::YawRate`].
//!
//! A stamp earlier than one already seen moves nothing (time never runs backwards) but
//! the event itself is still used. A non-finite stamp or odometry sample is refused with
//! a [`FeedError`] and changes nothing, in the feed and in the estimator.
//!
//! Lidar scans are not events (see [`crate::event`]): call [`EventFeed::advance`] to the
//! scan's stamp, then the grid filter's `observe`.
//!
//! ```
//! use microslam::association::KnownIds;
//! use microslam::ekf::{factor_len, state_dim, EkfConfig, EkfSlam};
//! use microslam::event::{Event, EventKind, Identity, Sighting};
//! use microslam::feed::{observe_known_sighting, EventFeed, Fed};
//! use microslam::sensors::range_bearing::RangeBearing;
//!
//! let mut slam = EkfSlam::<f32, { state_dim(8) }, { factor_len(8) }>::new(EkfConfig::DEFAULT_F32);
//! let mut ids = KnownIds::<8>::new();
//! let mut feed = EventFeed::<f32>::new(1.0);
//! let sighting = Sighting {
//!     identity: Identity::Unique(7),
//!     z: RangeBearing::new(2.0, 0.1),
//!     covariance: None,
//! };
//! let events = [
//!     Event::new(10.0, EventKind::Velocity { v: 0.5, omega: 0.0 }),
//!     Event::new(10.5, EventKind::Sighting(sighting)), // first predicts 0.5 s at 0.5 m/s
//! ];
//! for event in &events {
//!     if let Fed::Sighting(s) = feed.feed(&mut slam, event)? {
//!         observe_known_sighting(&mut slam, &mut ids, &s)?;
//!     }
//! }
//! assert!((slam.pose().x - 0.25).abs() < 1e-6);
//! assert_eq!(slam.landmark_count(), 1);
//! # Ok::<(), microslam::feed::FeedError<microslam::EkfError>>(())
//! ```
//!
//! # References
//!
//! - El Masri El Chaarani, A., Ashraf, J., and Abu Hara, R. (n.d.). *EKF-SLAM with
//!   Traffic sign images*. Undated report. The known-id step, §II-A.

use core::fmt;

use crate::association::{KnownIds, Observed, observe_known};
use crate::ekf::EkfSlam;
use crate::error::EkfError;
use crate::event::{Event, EventKind, Identity, Sighting};
use crate::geometry::Pose2;
use crate::motion::Ackermann;
use crate::pf::{GridLocalizer, GridSlam, PfError};
use crate::scalar::Real;

/// An estimator that moves with wheel odometry: the prediction half of a filter.
pub trait Predictor<T: Real> {
    /// What a refused step returns.
    type Error;

    /// Moves with `(v, ω)` held for `dt` seconds.
    fn predict_velocity(&mut self, v: T, omega: T, dt: T) -> Result<(), Self::Error>;

    /// Moves by `(dx, dy, dθ)` in the previous robot frame.
    fn predict_increment(&mut self, increment: &Pose2<T>) -> Result<(), Self::Error>;

    /// Moves a car with speed `v` and steering angle `steering` held for `dt` seconds.
    /// By default the same arc as velocities `(v, v tan φ / L)`; the EKF overrides it with
    /// the steering's own noise ([`EkfSlam::predict_ackermann`]). [`EventFeed`] checks the
    /// steering against `car.max_steering` before calling.
    fn predict_ackermann(
        &mut self,
        car: &Ackermann<T>,
        v: T,
        steering: T,
        dt: T,
    ) -> Result<(), Self::Error> {
        let omega = car.turn_rate(v, steering).unwrap_or(T::ZERO);
        self.predict_velocity(v, omega, dt)
    }
}

impl<T: Real, const N: usize, const P: usize> Predictor<T> for EkfSlam<T, N, P> {
    type Error = EkfError;

    fn predict_velocity(&mut self, v: T, omega: T, dt: T) -> Result<(), EkfError> {
        EkfSlam::predict_velocity(self, v, omega, dt)
    }

    fn predict_increment(&mut self, increment: &Pose2<T>) -> Result<(), EkfError> {
        EkfSlam::predict_increment(self, increment)
    }

    fn predict_ackermann(
        &mut self,
        car: &Ackermann<T>,
        v: T,
        steering: T,
        dt: T,
    ) -> Result<(), EkfError> {
        EkfSlam::predict_ackermann(self, car, v, steering, dt)
    }
}

impl<const W: usize, const H: usize, const P: usize, const B: usize, const BITMAP: usize>
    Predictor<f32> for GridSlam<'_, W, H, P, B, BITMAP>
{
    type Error = PfError;

    fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        GridSlam::predict_velocity(self, v, omega, dt)
    }

    fn predict_increment(&mut self, increment: &Pose2<f32>) -> Result<(), PfError> {
        GridSlam::predict_odometry(self, &Pose2::IDENTITY, increment)
    }
}

impl<const P: usize, const B: usize> Predictor<f32> for GridLocalizer<'_, P, B> {
    type Error = PfError;

    fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        GridLocalizer::predict_velocity(self, v, omega, dt)
    }

    fn predict_increment(&mut self, increment: &Pose2<f32>) -> Result<(), PfError> {
        GridLocalizer::predict_odometry(self, &Pose2::IDENTITY, increment)
    }
}

/// Why [`EventFeed`] refused an event (nothing changed).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FeedError<E> {
    /// The event's stamp is NaN or infinite.
    NonFiniteStamp,
    /// A velocity, increment or car sample with a NaN or infinite component, or a car's
    /// steering angle beyond its vehicle's `max_steering`.
    NonFiniteOdometry,
    /// A car's sample ([`EventKind::Ackermann`]) reached a feed without a vehicle
    /// ([`EventFeed::with_vehicle`]).
    NoVehicle,
    /// The estimator refused the step.
    Estimator(E),
}

impl<E> From<E> for FeedError<E> {
    fn from(e: E) -> Self {
        Self::Estimator(e)
    }
}

impl<E: fmt::Display> fmt::Display for FeedError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NonFiniteStamp => f.write_str("event stamp is not finite"),
            Self::NonFiniteOdometry => f.write_str("odometry sample is not finite"),
            Self::NoVehicle => f.write_str("a car's odometry sample, but the feed has no vehicle"),
            Self::Estimator(e) => write!(f, "estimator refused the step: {e}"),
        }
    }
}

impl<E: fmt::Debug + fmt::Display> core::error::Error for FeedError<E> {}

/// What [`EventFeed::feed`] did with an event (after predicting up to its stamp).
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum Fed<T: nalgebra::Scalar> {
    /// A velocity sample: held for the motion until the next event.
    VelocityHeld,
    /// A car's speed and steering: held for the motion until the next event.
    AckermannHeld,
    /// An odometry increment: applied.
    IncrementApplied,
    /// A sighting, for the caller's data association.
    Sighting(Sighting<T>),
    /// A yaw rate (rad/s): the estimators here do not use it; an IMU filter may.
    YawRate(T),
}

/// Turns a time-ordered [`Event`] stream into estimator steps (see the module docs).
///
/// Small and `const`-constructible: it can sit in a `static` next to the estimator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventFeed<T> {
    max_gap: f64,
    last: Option<f64>,
    held: Held<T>,
    car: Option<Ackermann<T>>,
}

/// The odometry sample in force.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Held<T> {
    Nothing,
    Velocity(T, T),
    Ackermann(T, T),
}

impl<T: Real> EventFeed<T> {
    /// A feed that has seen no event; predictions span at most `max_gap_s` seconds
    /// (a NaN or negative cap means no motion is ever predicted from held velocities).
    pub const fn new(max_gap_s: f64) -> Self {
        Self {
            max_gap: max_gap_s,
            last: None,
            held: Held::Nothing,
            car: None,
        }
    }

    /// A feed for a car: as [`EventFeed::new`], and [`EventKind::Ackermann`] samples move
    /// the estimator through `car` (without one they are refused,
    /// [`FeedError::NoVehicle`]).
    pub const fn with_vehicle(max_gap_s: f64, car: Ackermann<T>) -> Self {
        Self {
            max_gap: max_gap_s,
            last: None,
            held: Held::Nothing,
            car: Some(car),
        }
    }

    /// The latest stamp seen, seconds.
    pub fn last_stamp(&self) -> Option<f64> {
        self.last
    }

    /// The velocity `(v, ω)` held since the last velocity sample (for a car's sample,
    /// its speed and turn rate `v tan φ / L`).
    pub fn held_velocity(&self) -> Option<(T, T)> {
        match self.held {
            Held::Nothing => None,
            Held::Velocity(v, omega) => Some((v, omega)),
            Held::Ackermann(v, steering) => {
                let omega = self.car.and_then(|car| car.turn_rate(v, steering))?;
                Some((v, omega))
            }
        }
    }

    /// Predicts `estimator` up to `stamp` with the held velocity (nothing when no
    /// velocity is held, or when `stamp` is not later than the latest stamp seen).
    pub fn advance<E: Predictor<T> + ?Sized>(
        &mut self,
        estimator: &mut E,
        stamp: f64,
    ) -> Result<(), FeedError<E::Error>> {
        if !stamp.is_finite() {
            return Err(FeedError::NonFiniteStamp);
        }
        if let Some(last) = self.last {
            let dt = (stamp - last).min(self.max_gap);
            if dt > 0.0 {
                match (self.held, &self.car) {
                    (Held::Velocity(v, omega), _) => {
                        estimator.predict_velocity(v, omega, T::lit(dt))?;
                    }
                    (Held::Ackermann(v, steering), Some(car)) => {
                        estimator.predict_ackermann(car, v, steering, T::lit(dt))?;
                    }
                    _ => {}
                }
            }
        }
        self.last = Some(self.last.map_or(stamp, |last| last.max(stamp)));
        Ok(())
    }

    /// Advances to the event's stamp, then applies the event's odometry or hands back
    /// what the caller must handle. A refused event changes nothing.
    pub fn feed<E: Predictor<T> + ?Sized>(
        &mut self,
        estimator: &mut E,
        event: &Event<T>,
    ) -> Result<Fed<T>, FeedError<E::Error>> {
        // Check the event before anything moves, so that a refusal changes nothing.
        let odometry_ok = match &event.kind {
            EventKind::Velocity { v, omega } => v.finite() && omega.finite(),
            EventKind::Increment(inc) => inc.x.finite() && inc.y.finite() && inc.theta.finite(),
            EventKind::Ackermann { v, steering } => match &self.car {
                Some(car) => car.turn_rate(*v, *steering).is_some(),
                None => return Err(FeedError::NoVehicle),
            },
            _ => true,
        };
        if !event.stamp.is_finite() {
            return Err(FeedError::NonFiniteStamp);
        }
        if !odometry_ok {
            return Err(FeedError::NonFiniteOdometry);
        }
        self.advance(estimator, event.stamp)?;
        Ok(match event.kind {
            EventKind::Velocity { v, omega } => {
                self.held = Held::Velocity(v, omega);
                Fed::VelocityHeld
            }
            EventKind::Ackermann { v, steering } => {
                self.held = Held::Ackermann(v, steering);
                Fed::AckermannHeld
            }
            EventKind::Increment(inc) => {
                estimator.predict_increment(&inc)?;
                Fed::IncrementApplied
            }
            EventKind::Sighting(s) => Fed::Sighting(s),
            EventKind::YawRate(rate) => Fed::YawRate(rate),
        })
    }
}

/// The known-id step of El Masri El Chaarani et al. (n.d., §II-A) for a sighting from an
/// event: [`observe_known`] (with the sighting's own covariance when it carries one) for
/// [`Identity::Unique`] ids; `Ok(None)` for a class or an unknown identity, which need
/// ICNN or JCBB.
pub fn observe_known_sighting<T: Real, const N: usize, const P: usize, const L: usize>(
    slam: &mut EkfSlam<T, N, P>,
    ids: &mut KnownIds<L>,
    sighting: &Sighting<T>,
) -> Result<Option<Observed<T>>, EkfError> {
    let Identity::Unique(id) = sighting.identity else {
        return Ok(None);
    };
    let Some(r) = sighting.covariance else {
        return observe_known(slam, ids, id, &sighting.z).map(Some);
    };
    if let Some(index) = ids.get(id) {
        let outcome = slam.update_with_covariance(index, &sighting.z, &r)?;
        return Ok(Some(Observed::Updated { index, outcome }));
    }
    if ids.len() >= L {
        return Err(EkfError::MapFull);
    }
    let index = slam.add_landmark_with_covariance(&sighting.z, &r)?;
    ids.insert(id, index).map_err(|_| EkfError::MapFull)?;
    Ok(Some(Observed::Added { index }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ekf::{EkfConfig, factor_len, state_dim};
    use crate::sensors::range_bearing::RangeBearing;
    use nalgebra::Matrix2;

    type Slam = EkfSlam<f64, { state_dim(4) }, { factor_len(4) }>;

    fn velocity(t: f64, v: f64, omega: f64) -> Event<f64> {
        Event::new(t, EventKind::Velocity { v, omega })
    }

    fn sighting(t: f64, identity: Identity) -> Event<f64> {
        Event::new(
            t,
            EventKind::Sighting(Sighting {
                identity,
                z: RangeBearing::new(2.0, 0.0),
                covariance: None,
            }),
        )
    }

    /// Records every prediction, to check what the feed asks of an estimator.
    #[derive(Default)]
    struct Recorder {
        velocity: heapless::Vec<(f64, f64, f64), 8>,
        increments: heapless::Vec<Pose2<f64>, 8>,
    }

    impl Predictor<f64> for Recorder {
        type Error = ();
        fn predict_velocity(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), ()> {
            self.velocity.push((v, omega, dt)).map_err(|_| ())
        }
        fn predict_increment(&mut self, increment: &Pose2<f64>) -> Result<(), ()> {
            self.increments.push(*increment).map_err(|_| ())
        }
    }

    #[test]
    fn held_velocity_moves_up_to_each_stamp_capped_at_the_gap() {
        let mut feed = EventFeed::new(1.0);
        let mut r = Recorder::default();
        assert_eq!(
            feed.feed(&mut r, &velocity(5.0, 0.5, 0.1)),
            Ok(Fed::VelocityHeld)
        );
        assert!(
            r.velocity.is_empty(),
            "nothing held before the first sample"
        );
        assert!(matches!(
            feed.feed(&mut r, &sighting(5.25, Identity::Unknown)),
            Ok(Fed::Sighting(_))
        ));
        assert_eq!(
            feed.feed(&mut r, &velocity(8.0, 0.2, 0.0)),
            Ok(Fed::VelocityHeld)
        );
        assert_eq!(
            feed.feed(&mut r, &Event::new(8.5, EventKind::YawRate(0.3))),
            Ok(Fed::YawRate(0.3))
        );
        assert_eq!(
            r.velocity.as_slice(),
            &[(0.5, 0.1, 0.25), (0.5, 0.1, 1.0), (0.2, 0.0, 0.5)],
            "0.25 s, then 2.75 s capped at 1 s, then 0.5 s at the new velocity"
        );
    }

    #[test]
    fn increments_are_applied_and_late_stamps_move_nothing() {
        let mut feed = EventFeed::new(10.0);
        let mut r = Recorder::default();
        let inc = Pose2::new(0.1, 0.0, 0.02);
        feed.feed(&mut r, &velocity(2.0, 1.0, 0.0)).unwrap();
        assert_eq!(
            feed.feed(&mut r, &Event::new(1.0, EventKind::Increment(inc))),
            Ok(Fed::IncrementApplied)
        );
        assert_eq!(r.increments.as_slice(), &[inc]);
        assert!(r.velocity.is_empty(), "an earlier stamp predicts nothing");
        assert_eq!(feed.last_stamp(), Some(2.0), "time does not run backwards");
        feed.advance(&mut r, 2.5).unwrap();
        assert_eq!(r.velocity.as_slice(), &[(1.0, 0.0, 0.5)]);
    }

    #[test]
    fn non_finite_events_are_refused_and_change_nothing() {
        let mut feed = EventFeed::new(1.0);
        let mut r = Recorder::default();
        feed.feed(&mut r, &velocity(1.0, 0.5, 0.0)).unwrap();
        let before = feed;
        assert_eq!(
            feed.feed(&mut r, &velocity(1.5, f64::NAN, 0.0)),
            Err(FeedError::NonFiniteOdometry)
        );
        let bad_inc = Event::new(
            1.5,
            EventKind::Increment(Pose2::new(0.0, f64::INFINITY, 0.0)),
        );
        assert_eq!(
            feed.feed(&mut r, &bad_inc),
            Err(FeedError::NonFiniteOdometry)
        );
        assert_eq!(
            feed.feed(&mut r, &sighting(f64::NAN, Identity::Unknown)),
            Err(FeedError::NonFiniteStamp)
        );
        assert_eq!(feed, before);
        assert!(r.velocity.is_empty() && r.increments.is_empty());
    }

    #[test]
    fn estimator_refusals_come_back_wrapped() {
        let mut feed = EventFeed::new(1.0);
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        feed.feed(&mut slam, &velocity(0.0, 1.0, 0.0)).unwrap();
        // A plain drive is predicted...
        feed.feed(&mut slam, &velocity(1.0, 1.0, 0.0)).unwrap();
        assert!((slam.pose().x - 1.0).abs() < 1e-12);
        // ...but a step the filter refuses (beyond 100 km of the origin) is its error.
        let far = Event::new(2.0, EventKind::Increment(Pose2::new(2.0e5, 0.0, 0.0)));
        assert!(matches!(
            feed.feed(&mut slam, &far),
            Err(FeedError::Estimator(_))
        ));
    }

    #[test]
    fn known_sightings_add_then_update_and_others_are_left_to_the_caller() {
        let mut slam = Slam::new(EkfConfig::DEFAULT_F64);
        let mut ids = KnownIds::<4>::new();
        let s = |identity, covariance| Sighting {
            identity,
            z: RangeBearing::new(2.0, 0.0),
            covariance,
        };
        assert_eq!(
            observe_known_sighting(&mut slam, &mut ids, &s(Identity::Unique(9), None)),
            Ok(Some(Observed::Added { index: 0 }))
        );
        let r = Matrix2::new(0.01, 0.0, 0.0, 0.001);
        assert!(matches!(
            observe_known_sighting(&mut slam, &mut ids, &s(Identity::Unique(9), Some(r))),
            Ok(Some(Observed::Updated { index: 0, .. }))
        ));
        assert_eq!(
            observe_known_sighting(&mut slam, &mut ids, &s(Identity::Unique(4), Some(r))),
            Ok(Some(Observed::Added { index: 1 }))
        );
        assert_eq!(
            observe_known_sighting(&mut slam, &mut ids, &s(Identity::Class(3), None)),
            Ok(None)
        );
        assert_eq!(
            observe_known_sighting(&mut slam, &mut ids, &s(Identity::Unknown, None)),
            Ok(None)
        );
        assert_eq!(slam.landmark_count(), 2);
        assert_eq!(ids.get(4), Some(1));
    }

    /// A car's samples are held and drive the EKF through the feed's vehicle exactly as
    /// `predict_ackermann` called by hand; a feed without a vehicle, or a steering angle
    /// beyond the vehicle's limit, is refused and changes nothing.
    #[test]
    fn a_car_is_held_and_moved_through_the_vehicle() {
        use crate::motion::{Ackermann, AckermannNoise};
        let car = Ackermann {
            wheelbase: 2.5,
            max_steering: 0.6,
            noise: AckermannNoise {
                speed_std: 0.1,
                speed_std_per_mps: 0.0,
                steering_std: 0.02,
                steering_std_per_mps: 0.0,
            },
        };
        let drive = |v, steering| EventKind::Ackermann { v, steering };
        let mut fed = Slam::new(EkfConfig::DEFAULT_F64);
        let mut feed = EventFeed::with_vehicle(1.0, car);
        assert_eq!(
            feed.feed(&mut fed, &Event::new(1.0, drive(2.0, 0.2))),
            Ok(Fed::AckermannHeld)
        );
        feed.feed(&mut fed, &Event::new(1.5, drive(2.0, -0.1)))
            .unwrap();
        assert!(matches!(
            feed.feed(&mut fed, &sighting(1.75, Identity::Unknown)),
            Ok(Fed::Sighting(_))
        ));
        let mut by_hand = Slam::new(EkfConfig::DEFAULT_F64);
        by_hand.predict_ackermann(&car, 2.0, 0.2, 0.5).unwrap();
        by_hand.predict_ackermann(&car, 2.0, -0.1, 0.25).unwrap();
        assert_eq!(fed.pose(), by_hand.pose());
        assert_eq!(fed.pose_covariance(), by_hand.pose_covariance());
        assert_eq!(
            feed.feed(&mut fed, &Event::new(2.0, drive(2.0, 0.7))),
            Err(FeedError::NonFiniteOdometry)
        );
        assert_eq!(fed.pose(), by_hand.pose());
        let mut plain = EventFeed::new(1.0);
        assert_eq!(
            plain.feed(&mut fed, &Event::new(2.0, drive(2.0, 0.1))),
            Err(FeedError::NoVehicle)
        );
        assert_eq!(plain.last_stamp(), None);
    }
}
