//! The one grid run driver: lidar scans with their odometry poses → [`GridSlam`] or
//! [`GridLocalizer`] → the estimate at each scan (and the map). Used by
//! `replay --filter grid-slam`, `localize` and the simulator's lidar world.
//!
//! The filter is predicted with the odometry pose increment between consecutive scans in
//! **input order** (never with stamp differences: the Intel log's stamps go backwards).
//! An odometry pose that is not finite is refused and counted
//! ([`GridRun::refused_odometry`]), and the next good one predicts the whole motion; a step
//! longer than `max_odometry_step_m` is an odometry reset ([`super::scan_odometry`]); a scan
//! with no usable beam is counted ([`GridRun::skipped_scans`]) and the pose held.

use super::graph_slam::run_graph_slam;
use super::grid_run::changes;
pub use super::grid_run::{
    GraphSummary, GridInput, GridRun, GridRunOptions, LocalizerSummary, MapChanges,
};
use super::scan_odometry::{OdometryStep, ScanOdometry};
use crate::domain::grid::{MAX_BEAMS, SUPPORTED_PARTICLES, ScanSpacing};
use crate::inputs::readers::carmen::LaserMessage;
use crate::inputs::sim::lidar_world::LidarRecording;
use anyhow::{Result, anyhow, bail};
use microslam::geometry::Pose2;
use microslam::grid::{GridView, OccupancyGrid};
use microslam::pf::{GridEstimator, GridLocalizer, GridSlam, LocalizerState, StepReport};
use microslam::sensors::lidar::{LidarGeometry, LidarScan, robot_to_world};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

/// What a run looks like after one scan: for recordings of the run (`--mcap`).
#[derive(Clone, Copy, Debug)]
pub struct GridStep<'a> {
    /// Index of the scan in the inputs.
    pub index: usize,
    /// Its stamp, s.
    pub stamp: f64,
    /// Its odometry pose.
    pub odometry: Pose2<f32>,
    /// The estimate after the scan.
    pub pose: Pose2<f32>,
    /// The particles' pose covariance `[xx, xy, xθ, yy, yθ, θθ]`.
    pub covariance: [f32; 6],
    /// The scan's ranges.
    pub ranges: &'a [f32],
    /// The lidar geometry.
    pub lidar: &'a LidarGeometry,
    /// The particles.
    pub particles: &'a [Pose2<f32>],
    /// The map after the scan, when [`GridObserver::wants_map`] asked for it.
    pub map: Option<GridView<'a>>,
}

/// Sees every step of a grid run (e.g. to record it).
pub trait GridObserver: Send {
    /// Whether step `index` should carry the map (copying it costs time).
    fn wants_map(&self, index: usize) -> bool;
    /// Called after each scan.
    fn step(&mut self, step: &GridStep<'_>) -> Result<()>;
}

/// What the drive loop needs of a grid filter besides [`GridEstimator`]: its particles
/// and its map, for the observer and the map snapshots.
trait GridFilter: GridEstimator {
    fn particles(&self) -> &[Pose2<f32>];
    /// The end points of `scan` (every `decimation`-th beam) off the grid after the step
    /// that `report` describes.
    fn off_grid(&self, report: &StepReport, _scan: &LidarScan<'_>, _decimation: usize) -> u32 {
        report.map.off_grid
    }
    fn view(&self) -> GridView<'_>;
    fn cells(&self) -> &[i8] {
        self.view().cells()
    }
}

impl<const W: usize, const H: usize, const P: usize, const B: usize, const BITMAP: usize> GridFilter
    for GridSlam<'_, W, H, P, B, BITMAP>
{
    fn particles(&self) -> &[Pose2<f32>] {
        self.filter().poses()
    }
    fn view(&self) -> GridView<'_> {
        self.map().view()
    }
}

impl<const P: usize, const B: usize> GridFilter for GridLocalizer<'_, P, B> {
    fn particles(&self) -> &[Pose2<f32>] {
        self.filter().poses()
    }
    /// A localizer writes no map: the end points seen from its estimate that fall
    /// outside the map it localizes on.
    fn off_grid(&self, report: &StepReport, scan: &LidarScan<'_>, decimation: usize) -> u32 {
        let geometry = self.map().geometry();
        let outside = scan
            .beams(decimation)
            .map(|beam| robot_to_world(&report.pose, beam.robot_point))
            .filter(|&(x, y)| geometry.world_to_cell(x, y).is_none())
            .count();
        u32::try_from(outside).unwrap_or(u32::MAX)
    }
    fn view(&self) -> GridView<'_> {
        *self.map()
    }
}

/// The drive loop, written once: predict with the odometry increment, observe the scan,
/// record the pose, show the step to `observer`, and every `snapshot_every` scans (when not
/// 0) record the map's changes.
fn drive(
    filter: &mut impl GridFilter,
    inputs: &[GridInput<'_>],
    options: &GridRunOptions,
    run: &mut GridRun,
    progress: &dyn Fn(usize),
    mut observer: Option<&mut dyn GridObserver>,
    snapshot_every: usize,
) -> Result<()> {
    let lidar = &options.lidar;
    let mut odometry = ScanOdometry::new(options.max_odometry_step_m);
    let mut shadow = Vec::new();
    if snapshot_every > 0 {
        shadow = vec![0; filter.cells().len()];
        run.snapshots.push(changes(&mut shadow, filter.cells(), 0));
    }
    run.scan_spacing = ScanSpacing::of(inputs.iter().map(|input| input.odometry));
    for (i, input) in inputs.iter().enumerate() {
        let odom = input.odometry;
        if let OdometryStep::Move(from, to) = odometry.step(odom) {
            filter
                .predict_odometry(&from, &to)
                .map_err(|e| anyhow!("scan {i}: {e}"))?;
        }
        (run.refused_odometry, run.odometry_resets) = (odometry.refused, odometry.resets);
        let scan = LidarScan::new(input.ranges, *lidar);
        run.non_finite_beams += scan.census().1;
        match filter.observe(&scan) {
            Ok(r) => {
                run.trajectory.push((input.stamp, r.pose));
                let off_grid = filter.off_grid(&r, &scan, options.config.beam_decimation);
                run.off_grid_end_points += u64::from(off_grid);
                run.scans_off_grid += usize::from(off_grid > 0);
            }
            Err(_) => {
                run.skipped_scans += 1;
                run.trajectory.push((input.stamp, filter.pose()));
            }
        }
        if let Some(o) = observer.as_deref_mut() {
            let t0 = Instant::now();
            o.step(&GridStep {
                index: i,
                stamp: input.stamp,
                odometry: odom,
                pose: filter.pose(),
                covariance: filter.pose_covariance(),
                ranges: input.ranges,
                lidar,
                particles: filter.particles(),
                map: o.wants_map(i).then(|| filter.view()),
            })?;
            run.observer_time_s += t0.elapsed().as_secs_f64();
        }
        if snapshot_every > 0 && ((i + 1) % snapshot_every == 0 || i + 1 == inputs.len()) {
            run.snapshots
                .push(changes(&mut shadow, filter.cells(), i + 1));
        }
        progress(i);
    }
    Ok(())
}

macro_rules! dispatch_particles {
    ($p:expr, $f:ident, [$($g:tt)*], $($arg:expr),*) => {
        match $p {
            8 => $f::<$($g)* 8>($($arg),*),
            16 => $f::<$($g)* 16>($($arg),*),
            32 => $f::<$($g)* 32>($($arg),*),
            64 => $f::<$($g)* 64>($($arg),*),
            100 => $f::<$($g)* 100>($($arg),*),
            128 => $f::<$($g)* 128>($($arg),*),
            200 => $f::<$($g)* 200>($($arg),*),
            400 => $f::<$($g)* 400>($($arg),*),
            other => bail!("--particles {other} is not compiled in; use one of {SUPPORTED_PARTICLES:?}"),
        }
    };
}

/// Grid SLAM on an `N × N` grid over `inputs`, from `start`: centred on the origin, or
/// where [`GridRunOptions::grid_origin`] puts it.
///
/// Runs on a thread with a 64 MB stack: a large grid is built on the stack before it is
/// boxed in unoptimised builds.
pub fn run_slam<const N: usize, const BITMAP: usize>(
    inputs: &[GridInput<'_>],
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<GridRun> {
    run_slam_observed::<N, BITMAP>(inputs, start, options, progress, None, 0)
}

/// [`run_slam`] with every step shown to `observer` and, when `snapshot_every` is not 0,
/// the map recorded every `snapshot_every` scans and after the last one
/// ([`GridRun::snapshots`]: what `--animate` draws).
///
/// Runs on a rayon pool of its own, whose thread that steps the filter scores particles
/// too (see `on_own_pool`).
pub fn run_slam_observed<const N: usize, const BITMAP: usize>(
    inputs: &[GridInput<'_>],
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
    observer: Option<&mut dyn GridObserver>,
    snapshot_every: usize,
) -> Result<GridRun> {
    if let Some(graph) = &options.loop_closure {
        if observer.is_some() || snapshot_every > 0 {
            bail!(
                "grid SLAM with loop closure keeps only a local map: it cannot be recorded \
                 (--mcap) or animated (--animate) yet"
            );
        }
        return on_own_pool("grid SLAM", || {
            let (mut run, summary) =
                run_graph_slam::<N, BITMAP>(inputs, start, options, graph, progress)?;
            run.loop_closure = Some(summary);
            Ok(run)
        });
    }
    on_own_pool("grid SLAM", || {
        dispatch_particles!(
            options.particles,
            slam_p,
            [N, BITMAP,],
            inputs,
            start,
            options,
            progress,
            observer,
            snapshot_every
        )
    })
}

fn slam_p<const N: usize, const BITMAP: usize, const P: usize>(
    inputs: &[GridInput<'_>],
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &dyn Fn(usize),
    observer: Option<&mut dyn GridObserver>,
    snapshot_every: usize,
) -> Result<GridRun> {
    let c = options.config;
    let mut grid = Box::new(match options.grid_origin {
        Some([x, y]) => OccupancyGrid::<N, N, BITMAP>::new(c.resolution, x, y, c.log_odds),
        None => OccupancyGrid::<N, N, BITMAP>::centred(c.resolution, c.log_odds),
    });
    let mut run = GridRun::empty(Vec::new(), *grid.geometry(), inputs.len());
    let t0 = Instant::now();
    {
        let mut slam = GridSlam::<N, N, P, MAX_BEAMS, BITMAP>::new(&mut grid, c, start)
            .map_err(|e| anyhow!("grid SLAM: {e}"))?;
        drive(
            &mut slam,
            inputs,
            options,
            &mut run,
            progress,
            observer,
            snapshot_every,
        )?;
    }
    run.filter_time_s = t0.elapsed().as_secs_f64() - run.observer_time_s;
    run.cells = grid.cells().to_vec();
    Ok(run)
}

/// Runs `run` on a thread of a rayon pool of its own (as many threads as the global pool,
/// `RAYON_NUM_THREADS`; 64 MB stacks, as a large grid is built on the stack in
/// unoptimised builds), so that the thread that steps the filter also scores particles:
/// it never sleeps waiting for the other workers, as a thread outside the pool would (on
/// the Intel log, 36 000 context switches a run otherwise, and 0.8 s more on one thread;
/// `docs/speed.md`). The other workers are kept awake between scans (`stay_awake`). `what`
/// names the run in the error when the threads cannot start.
fn on_own_pool<R: Send>(what: &str, run: impl FnOnce() -> Result<R> + Send) -> Result<R> {
    on_pool(rayon::current_num_threads(), what, run)
}

/// [`on_own_pool`] with `threads` threads.
fn on_pool<R: Send>(
    threads: usize,
    what: &str,
    run: impl FnOnce() -> Result<R> + Send,
) -> Result<R> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .stack_size(64 << 20)
        .thread_name(|i| format!("grid-{i}"))
        .build()
        .map_err(|e| anyhow!("{what}: cannot start its threads: {e}"))?
        .install(|| {
            let helpers = rayon::current_num_threads().saturating_sub(1);
            if helpers == 0 {
                return run();
            }
            let stepper = rayon::current_thread_index();
            let done = AtomicBool::new(false);
            let awake = AtomicUsize::new(0);
            rayon::scope(|s| {
                for _ in 0..helpers {
                    s.spawn(|_| stay_awake(stepper, &done, &awake));
                }
                // Every helper picked up by another worker before the run starts: the
                // stepping thread then never finds one in its queue while it waits for
                // its particles.
                while awake.load(Ordering::Acquire) < helpers {
                    std::thread::yield_now();
                }
                // The helpers let go when the run ends, also by a panic (which the scope
                // then passes on instead of waiting for them for ever).
                let _release = Release(&done);
                run()
            })
        })
}

/// Sets its flag when dropped.
struct Release<'a>(&'a AtomicBool);

impl Drop for Release<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// Keeps a worker of the run's pool awake until `done`: it takes every job the stepping
/// thread shares (a scan's particles) as soon as there is one, instead of sleeping
/// between scans and being woken for each. Between scans a grid step's serial part (map
/// update, resampling, ≈ 60 µs on the Intel log) outlasts rayon's own spinning, and
/// waking a sleeping thread takes tens of microseconds on a VM: on the Intel log with the
/// settings of `GridPfConfig::UNTUNED` the replay takes 1.14 s instead of 1.46 s on two cores
/// (`docs/speed.md`). When there is no job it yields its core to any other thread that
/// wants it. Same particles scored, same results: only who scores them changes.
fn stay_awake(stepper: Option<usize>, done: &AtomicBool, awake: &AtomicUsize) {
    awake.fetch_add(1, Ordering::AcqRel);
    if rayon::current_thread_index() == stepper {
        // Only if the stepping thread found it in its own queue: never spin there.
        return;
    }
    while !done.load(Ordering::Acquire) {
        if rayon::yield_now() != Some(rayon::Yield::Executed) {
            std::thread::yield_now();
        }
    }
}

/// Localization on the fixed `map` over `inputs`, from `start` (in the map's frame).
pub fn run_localizer(
    inputs: &[GridInput<'_>],
    map: &GridView<'_>,
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<GridRun> {
    run_localizer_observed(inputs, map, start, options, progress, None)
}

/// [`run_localizer`] with every step shown to `observer`; runs on a rayon pool of its
/// own, as [`run_slam_observed`] does.
pub fn run_localizer_observed(
    inputs: &[GridInput<'_>],
    map: &GridView<'_>,
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &(dyn Fn(usize) + Sync),
    observer: Option<&mut dyn GridObserver>,
) -> Result<GridRun> {
    on_own_pool("grid localizer", || {
        dispatch_particles!(
            options.particles,
            localize_p,
            [],
            inputs,
            map,
            start,
            options,
            progress,
            observer
        )
    })
}

fn localize_p<const P: usize>(
    inputs: &[GridInput<'_>],
    map: &GridView<'_>,
    start: Pose2<f32>,
    options: &GridRunOptions,
    progress: &dyn Fn(usize),
    observer: Option<&mut dyn GridObserver>,
) -> Result<GridRun> {
    if options.loop_closure.is_some() {
        bail!("loop closure is for grid SLAM; a localizer's map is fixed");
    }
    let mut run = GridRun::empty(map.cells().to_vec(), *map.geometry(), inputs.len());
    let t0 = Instant::now();
    let mut loc = GridLocalizer::<P, MAX_BEAMS>::new(*map, options.config, start)
        .map_err(|e| anyhow!("grid localizer: {e}"))?;
    drive(&mut loc, inputs, options, &mut run, progress, observer, 0)?;
    run.filter_time_s = t0.elapsed().as_secs_f64() - run.observer_time_s;
    let s = loc.status();
    run.localizer = Some(LocalizerSummary {
        lost_events: s.lost_events,
        relocalizations: s.relocalizations,
        final_state: state_name(s.state),
        final_hit_fraction: s.hit_fraction,
        expected_hit_fraction: s.expected_hit_fraction,
    });
    Ok(run)
}

/// The name of a localizer state in `metrics.json`.
pub fn state_name(state: LocalizerState) -> &'static str {
    match state {
        LocalizerState::Tracking => "tracking",
        LocalizerState::Lost => "lost",
        LocalizerState::Relocalized => "relocalized",
    }
}

/// The driver's inputs from CARMEN laser messages (odometry narrowed to `f32`).
pub fn carmen_inputs<'a>(scans: &[&'a LaserMessage]) -> Vec<GridInput<'a>> {
    scans
        .iter()
        .map(|l| GridInput {
            stamp: l.stamp,
            odometry: Pose2::new(l.odom[0] as f32, l.odom[1] as f32, l.odom[2] as f32),
            ranges: &l.ranges,
        })
        .collect()
}

/// The driver's inputs from the simulator's lidar world.
pub fn sim_inputs(rec: &LidarRecording) -> Vec<GridInput<'_>> {
    rec.scans
        .iter()
        .map(|s| GridInput {
            stamp: s.stamp,
            odometry: f32_pose(&s.odometry),
            ranges: &s.ranges,
        })
        .collect()
}

/// A pose narrowed to `f32`, as the grid filters take it.
pub fn f32_pose(p: &Pose2<f64>) -> Pose2<f32> {
    Pose2::new(p.x as f32, p.y as f32, p.theta as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// A run that shares work with the pool many times, as a grid run shares each scan's
    /// particles, and counts the items done off the stepping thread.
    fn shared_work(rounds: usize) -> Result<(u64, usize)> {
        let mut total = 0u64;
        let mut helped = 0;
        let stepper = rayon::current_thread_index();
        for round in 0..rounds as u64 {
            let (sum, others): (u64, usize) = (0..200u32)
                .into_par_iter()
                .with_min_len(8)
                .map(|i| {
                    let other = usize::from(rayon::current_thread_index() != stepper);
                    (u64::from(i) * round, other)
                })
                .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
            total += sum;
            helped += others;
        }
        Ok((total, helped))
    }

    /// `f`'s result, on a thread of its own, so that a run that never ends (helpers
    /// never let go) fails the test instead of hanging it.
    fn within_a_minute<R: Send + 'static>(what: &str, f: impl FnOnce() -> R + Send + 'static) -> R {
        let (sender, receiver) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = sender.send(f());
        });
        match receiver.recv_timeout(std::time::Duration::from_secs(60)) {
            Ok(r) => r,
            Err(_) => panic!("{what}: the run did not end within 60 s"),
        }
    }

    /// The run ends (the helpers kept awake let go of their threads) with its result,
    /// with and without helpers; with one thread nothing is done off it. How much the
    /// helpers take depends on the machine's load: `docs/speed.md` measures it.
    #[test]
    fn a_run_on_its_pool_ends_with_its_result_on_any_number_of_threads() {
        let expected: u64 = (0..300u64).map(|r| r * (0..200u64).sum::<u64>()).sum();
        for threads in [1, 2, 4] {
            let what = format!("{threads} threads");
            let (total, helped) =
                within_a_minute(&what, move || on_pool(threads, "test", || shared_work(300)))
                    .unwrap();
            assert_eq!(total, expected, "{what}");
            if threads == 1 {
                assert_eq!(helped, 0);
            }
        }
    }

    #[test]
    fn a_panic_of_the_run_is_passed_on() {
        let r = within_a_minute("panic", || {
            std::panic::catch_unwind(|| on_pool(2, "test", || -> Result<()> { panic!("bug") }))
        });
        assert!(r.is_err(), "the panic was not passed on");
    }

    #[test]
    fn an_error_of_the_run_is_returned() {
        let r: Result<()> = within_a_minute("error", || on_pool(2, "test", || bail!("refused")));
        assert_eq!(r.unwrap_err().to_string(), "refused");
    }
}
