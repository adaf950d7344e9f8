//! The checks run by the fuzz targets in `fuzz/`, shared with `cargo test`, which replays
//! every input kept in `fuzz/regressions/<target>/` through them.
//!
//! Each function takes raw fuzzer bytes, drives one public API with them and panics when an
//! invariant breaks: a panic inside the library, a non-finite or asymmetric covariance, a
//! negative variance, an error that changed the state, or a non-finite input that was
//! accepted.

use microslam::association::{KnownIds, observe_known};
use microslam::ekf::{CovarianceUpdate, EkfConfig, EkfSlam, state_dim};
use microslam::geometry::Pose2;
use microslam::sensors::range_bearing::RangeBearing;
use microslam::wire::{FrameDecoder, MAX_FRAME_LEN, Session, ToDevice, encode_frame};
use nalgebra::{DMatrix, Matrix2};

/// Landmarks of the fuzzed filters: small, so that the table fills up.
const L: usize = 4;
type Slam = EkfSlam<f32, { state_dim(L) }>;

/// Reads little-endian `f32`s off the front of `bytes`.
fn take_f32s<const K: usize>(bytes: &mut &[u8]) -> Option<[f32; K]> {
    let mut out = [0.0; K];
    for v in &mut out {
        let (head, rest) = bytes.split_first_chunk::<4>()?;
        *v = f32::from_le_bytes(*head);
        *bytes = rest;
    }
    Some(out)
}

/// Panics unless the filter's active state is finite, its covariance exactly symmetric
/// with a non-negative diagonal, and (up to rounding) positive semi-definite.
pub fn assert_ekf_healthy<const N: usize>(ekf: &EkfSlam<f32, N>) {
    let p = ekf.active_covariance();
    let k = p.nrows();
    assert!(
        ekf.active_mean().iter().all(|v| v.is_finite()),
        "non-finite mean {:?}",
        ekf.active_mean()
    );
    let mut trace = 0.0f64;
    for i in 0..k {
        assert!(p[(i, i)] >= 0.0, "negative variance {} at {i}", p[(i, i)]);
        trace += f64::from(p[(i, i)]);
        for j in 0..k {
            assert!(p[(i, j)].is_finite(), "non-finite covariance at ({i}, {j})");
            assert_eq!(
                p[(i, j)].to_bits(),
                p[(j, i)].to_bits(),
                "asymmetric at ({i}, {j})"
            );
        }
    }
    let dense = DMatrix::from_fn(k, k, |i, j| f64::from(p[(i, j)]));
    let min_eig = dense.symmetric_eigen().eigenvalues.min();
    // f32 rounding: relative to the largest variance.
    assert!(
        min_eig >= -1e-4 * trace.max(f64::MIN_POSITIVE),
        "not PSD: min eigenvalue {min_eig}, trace {trace}"
    );
}

/// Fuzzes the EKF step API: each op is one selector byte and three `f32`s, arbitrary bit
/// patterns (NaN, ±∞, subnormal, huge). Both covariance update forms are exercised.
pub fn ekf_steps(data: &[u8]) {
    let Some((&form, mut bytes)) = data.split_first() else {
        return;
    };
    let config = EkfConfig {
        covariance_update: if form & 1 == 0 {
            CovarianceUpdate::Joseph
        } else {
            CovarianceUpdate::Symmetric
        },
        ..EkfConfig::DEFAULT_F32
    };
    let mut ekf = Box::new(Slam::new(config));
    let mut ids = KnownIds::<L>::new();
    while let Some((&op, rest)) = bytes.split_first() {
        bytes = rest;
        let Some([a, b, c]) = take_f32s::<3>(&mut bytes) else {
            return;
        };
        let finite = a.is_finite() && b.is_finite() && c.is_finite();
        let before = (
            ekf.active_mean().to_vec(),
            ekf.active_covariance().clone_owned(),
        );
        let index = usize::from(op >> 3);
        // What the EKF accepts as a sighting: finite, range within 1 mm ..= 1 km.
        let valid_z = a.is_finite() && b.is_finite() && (1e-3..=1e3).contains(&a);
        let (refused, must_refuse) = match op % 6 {
            0 => (ekf.predict_velocity(a, b, c).is_err(), !finite || c < 0.0),
            1 => (
                ekf.predict_increment(&Pose2::new(a, b, c)).is_err(),
                !finite,
            ),
            2 => (
                ekf.update(index, &RangeBearing::new(a, b)).is_err(),
                !valid_z,
            ),
            3 => (
                ekf.add_landmark(&RangeBearing::new(a, b)).is_err(),
                !valid_z,
            ),
            4 => {
                let r = Matrix2::new(c.abs(), 0.0, 0.0, c.abs());
                let z = RangeBearing::new(a, b);
                (
                    ekf.update_with_covariance(index, &z, &r).is_err(),
                    !valid_z || !c.is_finite(),
                )
            }
            _ => {
                let z = RangeBearing::new(a, b);
                let out = observe_known(&mut ekf, &mut ids, u32::from(op >> 3), &z);
                (out.is_err(), !valid_z)
            }
        };
        if must_refuse {
            assert!(refused, "op {op}: bad input ({a}, {b}, {c}) accepted");
        }
        if refused {
            assert_eq!(
                ekf.active_mean(),
                &before.0[..],
                "op {op}: a refused step changed the mean"
            );
            assert_eq!(
                ekf.active_covariance().clone_owned(),
                before.1,
                "op {op}: a refused step changed P"
            );
        }
        assert_ekf_healthy(&ekf);
    }
}

/// Fuzzes the device side of the serial protocol: arbitrary bytes into a [`Session`]
/// (decoder + EKF). No panic; the filter stays healthy; every frame is counted once.
pub fn wire_session(data: &[u8]) {
    let mut ekf = Box::new(Slam::new(EkfConfig::DEFAULT_F32));
    let mut session = Session::<_, L>::new(&mut ekf, EkfConfig::DEFAULT_F32);
    for &b in data {
        let _ = session.receive(b);
    }
    let status = session.status();
    let delimiters = data.iter().filter(|&&b| b == 0).count() as u64;
    assert!(
        u64::from(status.frames_ok) + u64::from(status.frames_bad) <= delimiters,
        "{} frames counted for {delimiters} delimiters",
        status.frames_ok + status.frames_bad
    );
    assert_ekf_healthy(session.ekf());
}

/// Fuzzes the frame decoder alone: every message it accepts re-encodes to a frame that
/// decodes to the same message.
pub fn wire_decoder(data: &[u8]) {
    let mut decoder = FrameDecoder::<MAX_FRAME_LEN>::new();
    for &b in data {
        if let Some(Ok(msg)) = decoder.push::<ToDevice>(b) {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let frame = encode_frame(&msg, &mut buf).expect("a decoded message fits a frame");
            let mut again = FrameDecoder::<MAX_FRAME_LEN>::new();
            let mut got = None;
            for &c in frame {
                if let Some(r) = again.push::<ToDevice>(c) {
                    got = Some(r);
                }
            }
            // NaN payloads compare unequal: compare the encodings instead.
            let got = got
                .expect("one frame out")
                .expect("re-encoded frame decodes");
            let mut buf2 = [0u8; MAX_FRAME_LEN];
            assert_eq!(encode_frame(&got, &mut buf2).expect("fits"), frame);
        }
    }
}

/// A fuzz target's check: panics when an invariant breaks.
pub type FuzzCheck = fn(&[u8]);

/// Every fuzz target by name, for the regression replay.
pub const TARGETS: &[(&str, FuzzCheck)] = &[
    ("ekf_steps", ekf_steps),
    ("wire_session", wire_session),
    ("wire_decoder", wire_decoder),
];
