//! [`WithKeyframes`]: a [`GraphSlam`] together with the storage its keyframes go to, as
//! one [`GridEstimator`], so that a drive loop that knows only the trait (the wire
//! session of a firmware, the host's replay) runs the building-scale SLAM.

use super::{GraphSlam, SlamError};
use crate::geometry::Pose2;
use crate::pf::{GridEstimator, PfError, StepReport};
use crate::sensors::lidar::{LidarGeometry, LidarScan};
use crate::slam::keyframes::{KeyframeStorage, KeyframeStore, StoreError};

/// Where the keyframes stand: storage waiting for the first scan of a run (which fixes
/// the store's geometry), an open store, or storage lost to a failed `create`.
#[derive(Debug)]
enum Keyframes<S> {
    Waiting(S),
    Open {
        store: KeyframeStore<S>,
        /// The lidar geometry of the run's first scan: every later scan must share it.
        lidar: LidarGeometry,
        /// Ranges per scan of the run.
        scan_len: usize,
    },
    Lost(StoreError),
}

/// A [`GraphSlam`] (borrowed: it lives in a `static` on a microcontroller) and the
/// [`KeyframeStorage`] its keyframes go to (flash on a board), driven as a
/// [`GridEstimator`].
///
/// A run's keyframe store is created on its first scan, with that scan's geometry and
/// length (every `decimation`-th range kept, the decimation the filter thins the scan
/// with: the configured `beam_decimation`, raised until at most `B` beams remain); creating
/// it erases the storage. [`GridEstimator::reset`] restarts the SLAM in place with its
/// settings and puts the storage back to wait for the next run's first scan. A scan whose
/// geometry or length differs from the run's first is refused with
/// [`PfError::InvalidScan`] before the filter sees it; a failure of the store, the graph
/// or the local map comes back as [`PfError::Slam`], the [`SlamError`] itself in
/// [`WithKeyframes::last_error`].
///
/// The estimate ([`GridEstimator::pose`]) is the graph's ([`GraphSlam::pose`]); the
/// covariance and the resample count are the particle filter's (its covariance in the
/// filter's frame).
#[derive(Debug)]
pub struct WithKeyframes<
    'a,
    S,
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> {
    slam: &'a mut GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>,
    keyframes: Keyframes<S>,
    last_error: Option<SlamError>,
    /// Where the run's map image goes ([`WithKeyframes::with_map_storage`]).
    map: Option<S>,
    /// The image last written there, when it is whole (feature `map-image`).
    #[cfg_attr(not(feature = "map-image"), allow(dead_code))]
    saved: Option<crate::pf::SavedMap>,
}

impl<
    'a,
    S: KeyframeStorage,
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> WithKeyframes<'a, S, P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>
{
    /// `slam` with its keyframes in `storage`, started ([`GraphSlam::init`]) with
    /// `config` at `start`. The storage is erased on the first scan.
    pub fn new(
        slam: &'a mut GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>,
        storage: S,
        config: crate::slam::GraphSlamConfig,
        start: Pose2<f32>,
    ) -> Result<Self, SlamError> {
        slam.init(config, start)?;
        Ok(Self {
            slam,
            keyframes: Keyframes::Waiting(storage),
            last_error: None,
            map: None,
            saved: None,
        })
    }

    /// The same estimator with `storage` for the map image
    /// [`GridEstimator::save_map`] writes at the end of a run (a flash region of its own:
    /// `GraphSlam::map_image_size` bytes, feature `map-image`; 102 456 for the Intel lab).
    pub fn with_map_storage(self, storage: S) -> Self {
        Self {
            map: Some(storage),
            saved: None,
            ..self
        }
    }

    /// The storage of the map image, when one was given.
    pub fn map_storage(&self) -> Option<&S> {
        self.map.as_ref()
    }

    /// The SLAM.
    pub fn slam(&self) -> &GraphSlam<P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH> {
        self.slam
    }

    /// The run's keyframe store (`None` before its first scan, or when creating it
    /// failed).
    pub fn store(&self) -> Option<&KeyframeStore<S>> {
        match &self.keyframes {
            Keyframes::Open { store, .. } => Some(store),
            _ => None,
        }
    }

    /// Why the last refused step was refused, when it was the store, the graph or the
    /// local map ([`PfError::Slam`]); cleared by every step that succeeds.
    pub fn last_error(&self) -> Option<SlamError> {
        self.last_error
    }

    fn done(&mut self, r: Result<(), SlamError>) -> Result<(), PfError> {
        match r {
            Ok(()) => {
                self.last_error = None;
                Ok(())
            }
            Err(SlamError::Filter(e)) => Err(e),
            Err(e) => {
                self.last_error = Some(e);
                Err(PfError::Slam)
            }
        }
    }
}

/// The open store for `scan`: created on the run's first scan (every `decimation`-th
/// range of at most `beams` kept: see [`WithKeyframes`]); `InvalidScan` when the scan does
/// not share the run's geometry and length.
fn store_for<'k, S: KeyframeStorage>(
    keyframes: &'k mut Keyframes<S>,
    scan: &LidarScan<'_>,
    beam_decimation: usize,
    beams: usize,
) -> Result<&'k mut KeyframeStore<S>, SlamError> {
    if let Keyframes::Waiting(_) = keyframes {
        if !scan.geometry.is_valid() || scan.ranges.is_empty() {
            return Err(SlamError::Filter(PfError::InvalidScan));
        }
        let len = scan.ranges.len();
        let decimation = beam_decimation.max(1).max(len.div_ceil(beams.max(1)));
        if let Keyframes::Waiting(storage) =
            core::mem::replace(keyframes, Keyframes::Lost(StoreError::Storage))
        {
            *keyframes = match KeyframeStore::create(
                storage,
                &scan.geometry,
                decimation,
                len.div_ceil(decimation),
            ) {
                Ok(store) => Keyframes::Open {
                    store,
                    lidar: scan.geometry,
                    scan_len: len,
                },
                Err(e) => Keyframes::Lost(e),
            };
        }
    }
    match keyframes {
        Keyframes::Open {
            store,
            lidar,
            scan_len,
        } => {
            if *lidar != scan.geometry || *scan_len != scan.ranges.len() {
                return Err(SlamError::Filter(PfError::InvalidScan));
            }
            Ok(store)
        }
        Keyframes::Lost(e) => Err(SlamError::Store(*e)),
        Keyframes::Waiting(_) => Err(SlamError::Store(StoreError::Storage)),
    }
}

impl<
    S: KeyframeStorage,
    const P: usize,
    const B: usize,
    const NEAR: usize,
    const NEAR_BITS: usize,
    const FAR: usize,
    const FAR_BITS: usize,
    const NODES: usize,
    const LOOPS: usize,
    const SCRATCH: usize,
> GridEstimator
    for WithKeyframes<'_, S, P, B, NEAR, NEAR_BITS, FAR, FAR_BITS, NODES, LOOPS, SCRATCH>
{
    fn reset(&mut self, start: Pose2<f32>) -> Result<(), PfError> {
        let config = *self.slam.config();
        let r = self.slam.init(config, start);
        if r.is_ok() {
            let keyframes =
                core::mem::replace(&mut self.keyframes, Keyframes::Lost(StoreError::Storage));
            self.keyframes = match keyframes {
                Keyframes::Open { store, .. } => Keyframes::Waiting(store.into_storage()),
                other => other,
            };
        }
        self.done(r)
    }

    fn predict_odometry(&mut self, from: &Pose2<f32>, to: &Pose2<f32>) -> Result<(), PfError> {
        let r = self.slam.predict_odometry(from, to);
        self.done(r)
    }

    fn predict_increment(&mut self, increment: &Pose2<f32>) -> Result<(), PfError> {
        let r = self
            .slam
            .predict_odometry(&Pose2::new(0.0, 0.0, 0.0), increment);
        self.done(r)
    }

    fn predict_arc(&mut self, distance: f32, heading_change: f32) -> Result<(), PfError> {
        let r = self.slam.predict(distance, heading_change);
        self.done(r)
    }

    fn predict_velocity(&mut self, v: f32, omega: f32, dt: f32) -> Result<(), PfError> {
        let r = self.slam.predict_velocity(v, omega, dt);
        self.done(r)
    }

    fn observe(&mut self, scan: &LidarScan<'_>) -> Result<StepReport, PfError> {
        let resamples = self.resamples();
        let decimation = self.slam.config().grid.beam_decimation;
        let step = store_for(&mut self.keyframes, scan, decimation, B)
            .and_then(|store| self.slam.observe(scan, store));
        match step {
            Ok(step) => {
                self.last_error = None;
                Ok(StepReport {
                    pose: step.pose,
                    n_eff: step.n_eff,
                    resampled: self.resamples() != resamples,
                    beams: step.beams,
                    // GraphSlam does not report the correlation score.
                    score: 0,
                    map: step.map,
                })
            }
            Err(e) => Err(self.done(Err(e)).err().unwrap_or(PfError::Slam)),
        }
    }

    fn pose(&self) -> Pose2<f32> {
        self.slam.pose()
    }

    fn resamples(&self) -> u32 {
        self.slam.filter().map_or(0, |f| f.resample_count())
    }

    fn pose_covariance(&self) -> [f32; 6] {
        self.slam.filter().map_or([0.0; 6], |f| f.pose_covariance())
    }

    /// [`GraphSlam::write_map_image`] of the run into the map storage, with the
    /// localizer's free threshold ([`crate::grid::LogOdds::free_below`] of the settings);
    /// `None` without a map storage. Refused with [`PfError::Slam`] (the cause in
    /// [`WithKeyframes::last_error`]) before the first scan or when the write fails; the
    /// run is over either way once the drawing started ([`GraphSlam::write_map_image`]).
    #[cfg(feature = "map-image")]
    fn save_map(&mut self) -> Option<Result<crate::pf::SavedMap, PfError>> {
        let out = self.map.as_mut()?;
        self.saved = None;
        let Keyframes::Open { store, .. } = &self.keyframes else {
            self.last_error = Some(SlamError::NoKeyframes);
            return Some(Err(PfError::Slam));
        };
        let free_below = self.slam.config().grid.log_odds.free_below;
        // Where the robot is in the map drawn (the graph's frame, which the drawing
        // does not move).
        let pose = self.slam.pose();
        let written = self
            .slam
            .write_map_image(store, out, free_below)
            .and_then(|summary| {
                let mut header = [0u8; crate::grid::map_image::MAP_IMAGE_HEADER_LEN];
                out.read(0, &mut header)?;
                let checksum = u32::from_le_bytes([header[36], header[37], header[38], header[39]]);
                Ok(crate::pf::SavedMap {
                    bytes: u32::try_from(summary.bytes).unwrap_or(u32::MAX),
                    checksum,
                    pose,
                })
            });
        Some(match written {
            Ok(saved) => {
                self.last_error = None;
                self.saved = Some(saved);
                Ok(saved)
            }
            Err(e) => {
                self.last_error = Some(e);
                Err(PfError::Slam)
            }
        })
    }

    #[cfg(feature = "map-image")]
    fn read_map(&self, offset: u32, out: &mut [u8]) -> Option<usize> {
        let saved = self.saved?;
        let storage = self.map.as_ref()?;
        let len = (saved.bytes.saturating_sub(offset) as usize).min(out.len());
        let part = out.get_mut(..len)?;
        storage.read(offset as usize, part).ok()?;
        Some(len)
    }
}
