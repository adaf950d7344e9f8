//! The simulator's camera world: the room (procedural floor texture, walls, sign plates),
//! the camera and the ray caster that renders RGB-D frames. The camera geometry itself
//! (pinhole, mount, sighting conversion and covariance) is `microslam::sensors::camera`.

pub mod world;
