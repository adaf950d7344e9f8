//! From the core's [`Event`] stream to wire messages, for a host that streams a recorded
//! or simulated run to a device.
//!
//! Velocity odometry in an [`Event`] holds until the next odometry sample, while a wire
//! [`Odometry::Velocity`] is a step of known duration. [`EventsToWire`] keeps the last
//! velocity and, before every later event, sends the motion up to that event's stamp:
//! `(v, ω, dt = stamp − stamp of the last motion)`, with `dt` computed in `f64` from the
//! event stamps and then rounded to `f32`. A car's speed and steering angle
//! ([`EventKind::Ackermann`]) are held the same way and sent as
//! [`Odometry::Ackermann`]. Stamps go on the wire as whole microseconds.
//!
//! Sent: velocities and a car's speed and steering (as held motion), increments, yaw
//! rates, and sightings with a unique id. Skipped (counted in [`EventsToWire::skipped`]): sightings without a unique id (the
//! wire carries known-id sightings only) and event kinds the wire does not know.

use heapless::Vec;

use crate::event::{Event, EventKind, Identity};
use crate::scalar::Real;

use super::messages::{Odometry, ToDevice};

/// Converts a time-ordered event stream into wire messages with sequence numbers 1, 2, ….
#[derive(Clone, Debug, Default)]
pub struct EventsToWire {
    seq: u32,
    held: Option<HeldVelocity>,
    skipped: u32,
}

/// The motion held since `since`: what goes on the wire at the next event.
#[derive(Clone, Copy, Debug)]
struct HeldVelocity {
    since: f64,
    motion: HeldMotion,
}

#[derive(Clone, Copy, Debug)]
enum HeldMotion {
    /// Speed and turn rate.
    Velocity { v: f32, omega: f32 },
    /// A car's speed and steering angle.
    Ackermann { v: f32, steering: f32 },
}

/// Whole microseconds of a stamp in seconds (saturating; negative and NaN give 0).
fn micros(stamp: f64) -> u64 {
    let us = libm::round(stamp * 1e6);
    if us.is_finite() && us > 0.0 {
        us as u64
    } else {
        0
    }
}

impl EventsToWire {
    /// A converter that has seen no event.
    pub const fn new() -> Self {
        Self {
            seq: 0,
            held: None,
            skipped: 0,
        }
    }

    /// Events that produced no message.
    pub fn skipped(&self) -> u32 {
        self.skipped
    }

    /// Sequence number of the last message produced.
    pub fn last_seq(&self) -> u32 {
        self.seq
    }

    fn next_seq(&mut self) -> u32 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    /// The messages for one event: the held motion up to its stamp (if a velocity is
    /// held), then the event itself (if the wire carries it).
    pub fn push<T: Real>(&mut self, event: &Event<T>) -> Vec<ToDevice, 2> {
        let mut out = Vec::new();
        let stamp = event.stamp;
        let stamp_us = micros(stamp);
        if let Some(held) = self.held.as_mut() {
            let dt = (stamp - held.since) as f32;
            held.since = stamp;
            let odometry = match held.motion {
                HeldMotion::Velocity { v, omega } => Odometry::Velocity { v, omega, dt },
                HeldMotion::Ackermann { v, steering } => Odometry::Ackermann { v, steering, dt },
            };
            let seq = self.next_seq();
            // Capacity 2, and this is the first push: cannot fail.
            let _ = out.push(ToDevice::Odometry {
                seq,
                stamp_us,
                odometry,
            });
        }
        let f = |x: T| x.to_f64() as f32;
        let msg = match &event.kind {
            EventKind::Velocity { v, omega } => {
                self.held = Some(HeldVelocity {
                    since: stamp,
                    motion: HeldMotion::Velocity {
                        v: f(*v),
                        omega: f(*omega),
                    },
                });
                None
            }
            EventKind::Ackermann { v, steering } => {
                self.held = Some(HeldVelocity {
                    since: stamp,
                    motion: HeldMotion::Ackermann {
                        v: f(*v),
                        steering: f(*steering),
                    },
                });
                None
            }
            EventKind::Increment(inc) => Some(ToDevice::Odometry {
                seq: self.next_seq(),
                stamp_us,
                odometry: Odometry::Increment {
                    dx: f(inc.x),
                    dy: f(inc.y),
                    dtheta: f(inc.theta),
                },
            }),
            EventKind::YawRate(rate) => Some(ToDevice::YawRate {
                seq: self.next_seq(),
                stamp_us,
                yaw_rate: f(*rate),
            }),
            EventKind::Sighting(s) => match s.identity {
                Identity::Unique(id) => Some(ToDevice::Landmark {
                    seq: self.next_seq(),
                    stamp_us,
                    id,
                    range: f(s.z.range),
                    bearing: f(s.z.bearing),
                }),
                Identity::Class(_) | Identity::Unknown => None,
            },
            #[allow(unreachable_patterns)]
            _ => None,
        };
        match msg {
            Some(m) => {
                let _ = out.push(m);
            }
            None if !matches!(
                event.kind,
                EventKind::Velocity { .. } | EventKind::Ackermann { .. }
            ) =>
            {
                self.skipped = self.skipped.saturating_add(1);
            }
            None => {}
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::Sighting;
    use crate::sensors::range_bearing::RangeBearing;

    fn sighting(stamp: f64, identity: Identity) -> Event<f64> {
        Event::new(
            stamp,
            EventKind::Sighting(Sighting {
                identity,
                z: RangeBearing::new(2.0, 0.5),
                covariance: None,
            }),
        )
    }

    #[test]
    fn velocities_become_held_motion_steps_before_each_later_event() {
        let mut w = EventsToWire::new();
        let events = [
            sighting(99.0, Identity::Unique(7)),
            Event::new(100.0, EventKind::Velocity { v: 0.5, omega: 0.1 }),
            sighting(100.25, Identity::Unique(7)),
            Event::new(100.5, EventKind::Velocity { v: 0.2, omega: 0.0 }),
            sighting(100.75, Identity::Class(3)),
        ];
        let msgs: std::vec::Vec<ToDevice> = events.iter().flat_map(|e| w.push(e)).collect();
        let expect = [
            ToDevice::Landmark {
                seq: 1,
                stamp_us: 99_000_000,
                id: 7,
                range: 2.0,
                bearing: 0.5,
            },
            ToDevice::Odometry {
                seq: 2,
                stamp_us: 100_250_000,
                odometry: Odometry::Velocity {
                    v: 0.5,
                    omega: 0.1,
                    dt: 0.25,
                },
            },
            ToDevice::Landmark {
                seq: 3,
                stamp_us: 100_250_000,
                id: 7,
                range: 2.0,
                bearing: 0.5,
            },
            ToDevice::Odometry {
                seq: 4,
                stamp_us: 100_500_000,
                odometry: Odometry::Velocity {
                    v: 0.5,
                    omega: 0.1,
                    dt: 0.25,
                },
            },
            ToDevice::Odometry {
                seq: 5,
                stamp_us: 100_750_000,
                odometry: Odometry::Velocity {
                    v: 0.2,
                    omega: 0.0,
                    dt: 0.25,
                },
            },
        ];
        assert_eq!(msgs, expect);
        assert_eq!(w.skipped(), 1, "the class-only sighting");
        assert_eq!(w.last_seq(), 5);
    }

    #[test]
    fn a_cars_speed_and_steering_are_held_as_velocities_are() {
        let mut w = EventsToWire::new();
        let events = [
            Event::new(
                10.0,
                EventKind::Ackermann {
                    v: 2.0,
                    steering: 0.1,
                },
            ),
            Event::new(10.5, EventKind::Velocity { v: 1.0, omega: 0.0 }),
            sighting(10.75, Identity::Unique(2)),
        ];
        let msgs: std::vec::Vec<ToDevice> = events.iter().flat_map(|e| w.push(e)).collect();
        assert_eq!(msgs.len(), 3);
        assert_eq!(
            msgs[0],
            ToDevice::Odometry {
                seq: 1,
                stamp_us: 10_500_000,
                odometry: Odometry::Ackermann {
                    v: 2.0,
                    steering: 0.1,
                    dt: 0.5,
                },
            }
        );
        assert!(matches!(
            msgs[1],
            ToDevice::Odometry {
                odometry: Odometry::Velocity { dt: 0.25, .. },
                ..
            }
        ));
        assert_eq!(w.skipped(), 0);
    }
}
