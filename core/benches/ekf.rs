//! Time per EKF step with 16, 32 and 64 active landmarks, in f32 and f64.
//! `cargo bench -p microslam --bench ekf`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use microslam::Real;
use microslam::ekf::{EkfConfig, EkfSlam, factor_len, state_dim};
use microslam::sensors::range_bearing::RangeBearing;
use std::hint::black_box;

/// A filter holding `L` landmarks on a circle, correlated by a few predict/update rounds.
fn filled<T: Real, const N: usize, const P: usize>(config: EkfConfig<T>) -> Box<EkfSlam<T, N, P>> {
    let mut slam = Box::new(EkfSlam::<T, N, P>::new(config));
    let l = EkfSlam::<T, N, P>::MAX_LANDMARKS;
    for i in 0..l {
        let b = T::lit(-3.0 + 6.0 * i as f64 / l as f64);
        slam.add_landmark(&RangeBearing::new(T::lit(3.0), b))
            .expect("room for every landmark");
        slam.predict_velocity(T::lit(0.1), T::lit(0.05), T::lit(0.1))
            .expect("finite input");
    }
    slam
}

fn bench_size<T: Real, const N: usize, const P: usize>(c: &mut Criterion, scalar: &str) {
    let l = EkfSlam::<T, N, P>::MAX_LANDMARKS;
    let mut group = c.benchmark_group(format!("ekf_{scalar}"));
    let mut slam = filled::<T, N, P>(EkfConfig::DEFAULT_F64.cast());
    group.bench_function(BenchmarkId::new("predict", l), |b| {
        b.iter(|| {
            slam.predict_velocity(
                black_box(T::lit(0.2)),
                black_box(T::lit(0.01)),
                black_box(T::lit(0.01)),
            )
        })
    });
    {
        let mut slam = filled::<T, N, P>(EkfConfig::DEFAULT_F64.cast());
        // The predicted sightings: updating with them leaves the mean where it is, so every
        // timed update is accepted and costs the same.
        let sightings: Vec<RangeBearing<T>> = (0..l)
            .map(|i| {
                let landmark = slam.landmark(i).expect("filled");
                slam.config()
                    .sensor
                    .predict(&slam.pose(), &landmark)
                    .expect("not on the sensor")
                    .z
            })
            .collect();
        let mut i = 0;
        group.bench_function(BenchmarkId::new("update", l), |b| {
            b.iter(|| {
                i = (i + 1) % l;
                slam.update(i, black_box(&sightings[i]))
            })
        });
    }
    group.finish();
}

fn ekf(c: &mut Criterion) {
    bench_size::<f32, { state_dim(16) }, { factor_len(16) }>(c, "f32");
    bench_size::<f32, { state_dim(32) }, { factor_len(32) }>(c, "f32");
    bench_size::<f32, { state_dim(64) }, { factor_len(64) }>(c, "f32");
    bench_size::<f64, { state_dim(16) }, { factor_len(16) }>(c, "f64");
    bench_size::<f64, { state_dim(32) }, { factor_len(32) }>(c, "f64");
    bench_size::<f64, { state_dim(64) }, { factor_len(64) }>(c, "f64");
}

criterion_group!(benches, ekf);
criterion_main!(benches);
