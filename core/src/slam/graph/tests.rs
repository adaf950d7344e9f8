//! Tests of the pose graph: known answers (a chain alone, a biased square, a loop across a
//! corridor, a full turn), the dense `f64` reference of [`reference`], convergence on a
//! long chain, sizes; refused inputs and random graphs in [`properties`].

use super::*;
use core::f32::consts::{FRAC_PI_2, PI};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

mod properties;
mod reference;

/// A graph from its start, chain and loops (boxed: the large ones are 18 KB).
fn build<const N: usize, const L: usize>(
    start: Pose2<f32>,
    chain: &[ChainEdge],
    loops: &[LoopEdge],
) -> Box<PoseGraph<N, L>> {
    let mut graph = Box::new(PoseGraph::new());
    graph.reset(start).unwrap();
    for c in chain {
        graph.add_node(*c).unwrap();
    }
    for l in loops {
        graph.add_loop(*l).unwrap();
    }
    graph
}

/// Optimises with the default settings and enough scratch.
fn optimise<const N: usize, const L: usize>(graph: &mut PoseGraph<N, L>) -> SolveReport {
    let mut scratch = vec![f32::NAN; PoseGraph::<N, L>::SCRATCH_LEN];
    graph
        .optimise(&mut scratch, &SolverSettings::DEFAULT)
        .unwrap()
}

/// Largest position and heading differences between `poses` and `expected`.
fn worst(poses: &[Pose2<f32>], expected: &[Pose2<f64>]) -> (f64, f64) {
    assert_eq!(poses.len(), expected.len());
    poses
        .iter()
        .zip(expected)
        .fold((0.0, 0.0), |(dp, dt), (p, e)| {
            let d = (f64::from(p.x) - e.x).hypot(f64::from(p.y) - e.y);
            let t = reference::wrap(f64::from(p.theta) - e.theta).abs();
            (f64::max(dp, d), f64::max(dt, t))
        })
}

fn chain_edge(x: f32, y: f32, theta: f32, position_std: f32, heading_std: f32) -> ChainEdge {
    ChainEdge {
        motion: Pose2::new(x, y, theta),
        position_std,
        heading_std,
    }
}

fn loop_edge(
    from: u16,
    to: u16,
    relative: Pose2<f32>,
    position: [f32; 3],
    heading: f32,
) -> LoopEdge {
    LoopEdge {
        from,
        to,
        relative,
        position_information: position,
        heading_information: heading,
    }
}

/// Poses along `motions` from `start`, composed in `f64`.
fn compose_f64(
    start: Pose2<f64>,
    motions: impl IntoIterator<Item = Pose2<f64>>,
) -> Vec<Pose2<f64>> {
    let mut poses = vec![start];
    for m in motions {
        let last = *poses.last().unwrap();
        let (s, c) = last.theta.sin_cos();
        poses.push(Pose2::new(
            last.x + c * m.x - s * m.y,
            last.y + s * m.x + c * m.y,
            reference::wrap(last.theta + m.theta),
        ));
    }
    poses
}

#[test]
fn chain_without_loops_stays_where_it_is() {
    // Turns enough that the headings cross ±π several times.
    let chain: Vec<_> = (0..150)
        .map(|k| {
            let turn = 0.3 * ((k as f32) * 0.37).sin();
            chain_edge(
                0.4,
                0.02 * (k % 3) as f32,
                turn,
                0.01 + 0.001 * (k % 7) as f32,
                0.02,
            )
        })
        .collect();
    let mut graph = build::<200, 4>(Pose2::new(1.0, -2.0, 3.0), &chain, &[]);
    let before = graph.poses().to_vec();
    let report = optimise(&mut graph);
    assert!(report.converged(), "{report:?}");
    // The chain composed in f64: adding the nodes one by one in f32 rounds each pose,
    // and the solver, fitting every increment exactly, undoes part of that rounding.
    let motions = chain.iter().map(|c| c.motion.cast::<f64>());
    let exact = compose_f64(Pose2::new(1.0, -2.0, 3.0), motions);
    let (dp_before, dt_before) = worst(&before, &exact);
    let (dp_after, dt_after) = worst(graph.poses(), &exact);
    println!(
        "chain: {report:?}; from f64: {dp_before:.1e} m {dt_before:.1e} rad before, \
         {dp_after:.1e} m {dt_after:.1e} rad after"
    );
    for (k, (a, b)) in before.iter().zip(graph.poses()).enumerate() {
        let d = (a.x - b.x).hypot(a.y - b.y);
        let t = wrap_heading(a.theta - b.theta).abs();
        assert!(d < 2e-5 && t < 3e-6, "node {k}: {a:?} → {b:?}");
    }
    assert!(dp_after <= dp_before.max(1e-5) && dt_after <= dt_before.max(1e-6));
    assert_eq!(graph.pose(0), Some(Pose2::new(1.0, -2.0, 3.0)));
}

/// The true motions around a square of `side` metres in steps of `step`, turning left at
/// each corner; the odometry adds `bias` to every heading.
fn square(side: f32, step: f32, bias: f32) -> (Vec<Pose2<f64>>, Vec<ChainEdge>) {
    let per_side = (side / step).round() as usize;
    let mut truth = Vec::new();
    let mut chain = Vec::new();
    for k in 0..4 * per_side {
        let turn = if (k + 1) % per_side == 0 {
            FRAC_PI_2
        } else {
            0.0
        };
        truth.push(Pose2::new(f64::from(step), 0.0, f64::from(turn)));
        chain.push(chain_edge(step, 0.0, turn + bias, 0.02, 0.01));
    }
    let start = Pose2::new(0.0, 0.0, 0.0);
    (compose_f64(start, truth), chain)
}

#[test]
fn biased_square_closes_on_the_truth_and_matches_the_dense_reference() {
    // 80 keyframes around a 10 m square, the odometry turning 0.01 rad too far at each.
    let (truth, chain) = square(10.0, 0.5, 0.01);
    let last = chain.len() as u16;
    let precise = loop_edge(0, last, Pose2::new(0.0, 0.0, 0.0), [1e4, 0.0, 1e4], 1e6);
    let start = Pose2::new(0.0, 0.0, 0.0);
    let mut graph = build::<128, 4>(start, &chain, &[precise]);
    let (drift, _) = worst(graph.poses(), &truth);
    assert!(drift > 2.0, "odometry drift {drift}");

    let report = optimise(&mut graph);
    assert!(report.converged(), "{report:?}");
    let end = graph.pose(chain.len()).unwrap();
    assert!(
        end.x.hypot(end.y) < 0.01 && end.theta.abs() < 1e-3,
        "{end:?}"
    );
    let (to_truth, heading_to_truth) = worst(graph.poses(), &truth);
    assert!(
        to_truth < 0.02 && heading_to_truth < 2e-3,
        "{to_truth} {heading_to_truth}"
    );

    let dense = reference::solve(start, &chain, &[precise]);
    let (dp, dt) = worst(graph.poses(), &dense);
    println!("square: {report:?}, against dense f64: {dp:.2e} m, {dt:.2e} rad");
    assert!(dp < 1e-4 && dt < 1e-5, "{dp} {dt}");
}

#[test]
fn anisotropic_loop_moves_nodes_only_across_the_corridor() {
    // A straight corridor at 0.7 rad; the loop measures the end 0.4 m further along and
    // 0.3 m to the left, but is informative only across.
    let heading = 0.7_f32;
    let start = Pose2::new(1.0, 2.0, heading);
    let chain = vec![chain_edge(0.5, 0.0, 0.0, 0.02, 0.01); 39];
    let across = loop_edge(0, 39, Pose2::new(19.9, 0.3, 0.0), [0.0, 0.0, 1e4], 0.0);
    let mut graph = build::<64, 2>(start, &chain, &[across]);
    let before = graph.poses().to_vec();
    let report = optimise(&mut graph);
    assert!(report.converged(), "{report:?}");

    let (along_x, along_y) = (f64::from(heading).cos(), f64::from(heading).sin());
    let moves: Vec<(f64, f64)> = before
        .iter()
        .zip(graph.poses())
        .map(|(a, b)| {
            let (dx, dy) = (f64::from(b.x - a.x), f64::from(b.y - a.y));
            (dx * along_x + dy * along_y, -dx * along_y + dy * along_x)
        })
        .collect();
    // The chain accumulates 39 · 0.02² = 0.0156 m² across, the loop 10⁻⁴ m²: the end
    // moves 0.3 · 0.0156 / 0.0157 across, the nodes before it in proportion.
    let end = 0.3 * 0.0156 / (0.0156 + 1e-4);
    for (k, &(along, side)) in moves.iter().enumerate() {
        assert!(along.abs() < 2e-5, "node {k} moved {along} along");
        assert!(
            (side - end * k as f64 / 39.0).abs() < 1e-4,
            "node {k}: {side}"
        );
    }
    for (a, b) in before.iter().zip(graph.poses()) {
        assert!((a.theta - b.theta).abs() < 1e-6);
    }
    let (dp, dt) = worst(graph.poses(), &reference::solve(start, &chain, &[across]));
    assert!(dp < 1e-4 && dt < 1e-6, "{dp} {dt}");
}

#[test]
fn loop_around_a_full_turn_is_taken_modulo_two_pi() {
    // 60 keyframes around a circle of 3 m radius starting near the ±π cut, each turning
    // 0.004 rad too far: the chain's headings sum to 2π + 0.24, the loop measures 0.
    let steps = 60;
    let turn = core::f64::consts::TAU / f64::from(steps);
    let chord = 2.0 * 3.0 * (turn / 2.0).sin();
    let motion = Pose2::new(chord, 0.0, turn);
    let start64 = Pose2::new(0.5, 0.5, 3.0);
    let truth = compose_f64(start64, (0..steps).map(|_| motion));
    let chain =
        vec![chain_edge(chord as f32, 0.0, turn as f32 + 0.004, 0.01, 0.01); steps as usize];
    let start = start64.cast::<f32>();
    for measured in [0.0, core::f32::consts::TAU, -core::f32::consts::TAU] {
        let closing = loop_edge(0, 60, Pose2::new(0.0, 0.0, measured), [1e4, 0.0, 1e4], 1e6);
        let mut graph = build::<64, 2>(start, &chain, &[closing]);
        let report = optimise(&mut graph);
        assert!(report.converged(), "{report:?}");
        let (to_truth, heading_to_truth) = worst(graph.poses(), &truth);
        assert!(
            to_truth < 0.01 && heading_to_truth < 1e-3,
            "{measured}: {to_truth} {heading_to_truth}"
        );
        let (dp, dt) = worst(graph.poses(), &reference::solve(start, &chain, &[closing]));
        assert!(dp < 1e-4 && dt < 1e-5, "{dp} {dt}");
    }
}

#[test]
fn uncertain_chain_edge_takes_the_correction() {
    // Ten steps along x; edge 5 is 100 times as uncertain as the others; the loop puts
    // the end 0.5 m further.
    let mut chain = vec![chain_edge(1.0, 0.0, 0.0, 0.01, 0.01); 10];
    chain[4].position_std = 1.0;
    let further = loop_edge(0, 10, Pose2::new(10.5, 0.0, 0.0), [1e6, 0.0, 1e6], 0.0);
    let mut graph = build::<16, 1>(Pose2::new(0.0, 0.0, 0.0), &chain, &[further]);
    optimise(&mut graph);
    // Variances 9 · 10⁻⁴ + 1 (chain) and 10⁻⁶ (loop): edge 5 takes 1 / 1.000901 of it.
    let share = 0.5 / (1.0 + 9e-4 + 1e-6);
    let x: Vec<f32> = graph.poses().iter().map(|p| p.x).collect();
    assert!((x[5] - x[4] - 1.0 - share as f32).abs() < 1e-4, "{x:?}");
    assert!((x[4] - x[3] - 1.0).abs() < 1e-3, "{x:?}");
}

/// A random walk of `n` keyframes, its noisy odometry, and `loops` loop edges between
/// random pairs with noisy relative poses; anisotropic information unless `isotropic`.
fn random_walk(
    seed: u64,
    n: usize,
    loops: usize,
    isotropic: bool,
) -> (Vec<Pose2<f64>>, Vec<ChainEdge>, Vec<LoopEdge>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let unit = Normal::new(0.0, 1.0).unwrap();
    let (position_std, heading_std) = (0.02_f64, 0.005_f64);
    let motions: Vec<Pose2<f64>> = (1..n)
        .map(|_| {
            Pose2::new(
                rng.random_range(0.3..0.7),
                rng.random_range(-0.05..0.05),
                0.3 * unit.sample(&mut rng),
            )
        })
        .collect();
    let truth = compose_f64(Pose2::new(0.0, 0.0, 0.0), motions.iter().copied());
    let chain = motions
        .iter()
        .map(|m| {
            chain_edge(
                (m.x + position_std * unit.sample(&mut rng)) as f32,
                (m.y + position_std * unit.sample(&mut rng)) as f32,
                (m.theta + heading_std * unit.sample(&mut rng)) as f32,
                position_std as f32,
                heading_std as f32,
            )
        })
        .collect();
    let mut edges = Vec::new();
    while edges.len() < loops {
        let i = rng.random_range(0..n - 20);
        let j = rng.random_range(i + 20..n);
        let (a, b) = (truth[i], truth[j]);
        let (s, c) = a.theta.sin_cos();
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let relative = Pose2::new(
            c * dx + s * dy + 0.01 * unit.sample(&mut rng),
            -s * dx + c * dy + 0.01 * unit.sample(&mut rng),
            reference::wrap(b.theta - a.theta + 0.002 * unit.sample(&mut rng)),
        );
        let (sa, sb): (f64, f64) = if isotropic {
            (0.02, 0.02)
        } else {
            (rng.random_range(0.005..0.1), rng.random_range(0.005..0.1))
        };
        let phi: f64 = rng.random_range(0.0..PI as f64);
        let (ps, pc) = phi.sin_cos();
        let (ia, ib) = (1.0 / (sa * sa), 1.0 / (sb * sb));
        let information = [
            pc * pc * ia + ps * ps * ib,
            pc * ps * (ia - ib),
            ps * ps * ia + pc * pc * ib,
        ];
        edges.push(loop_edge(
            i as u16,
            j as u16,
            relative.cast::<f32>(),
            information.map(|v| v as f32),
            1.0 / (0.002 * 0.002),
        ));
    }
    (truth, chain, edges)
}

#[test]
fn long_chain_with_ten_loops_converges_in_about_loops_iterations() {
    for (seed, isotropic) in [(3, false), (4, false), (5, true)] {
        let (truth, chain, loops) = random_walk(seed, 500, 10, isotropic);
        let start = Pose2::new(0.0, 0.0, 0.0);
        let mut graph = build::<512, 64>(start, &chain, &loops);
        let (odometry_error, _) = worst(graph.poses(), &truth);
        let report = optimise(&mut graph);
        let (dp, dt) = worst(graph.poses(), &reference::solve(start, &chain, &loops));
        let (to_truth, _) = worst(graph.poses(), &truth);
        println!(
            "seed {seed} isotropic {isotropic}: {report:?}\n  against dense f64: {dp:.2e} m, \
             {dt:.2e} rad; to the truth {to_truth:.3} m (odometry {odometry_error:.3} m)"
        );
        assert!(report.converged(), "{report:?}");
        // Rank + 1 in exact arithmetic: 11 for the headings, 21 for the positions (11
        // with isotropic loop information). In f32, with loops some 3000 times as stiff as
        // the chain over their ranges, measured: headings 14, 14, 16; positions 33, 38
        // (anisotropic), 19 (isotropic). Far fewer than the 499 and 998 unknowns.
        assert!(report.headings.iterations <= 10 + 6, "{report:?}");
        let rank = if isotropic { 10 } else { 20 };
        assert!(report.positions.iterations <= 2 * (rank + 1), "{report:?}");
        assert!(dp < 1e-4 && dt < 1e-5, "{dp} {dt}");
        assert!(to_truth < odometry_error, "{to_truth} {odometry_error}");
    }
}

#[test]
fn sizes_are_as_documented() {
    assert_eq!(size_of::<PoseGraph<512, 64>>(), graph_bytes(512, 64));
    assert_eq!(graph_bytes(512, 64), 18_440);
    assert_eq!(size_of::<PoseGraph<16, 2>>(), 32 * 16 + 32 * 2 + 8);
    assert_eq!(size_of::<ChainEdge>() + size_of::<Pose2<f32>>(), 32);
    assert_eq!(size_of::<LoopEdge>(), 32);
    assert_eq!(PoseGraph::<512, 64>::SCRATCH_LEN, 4928);
    assert_eq!(scratch_len(512, 64) * size_of::<f32>(), 19_712);
}

#[test]
fn a_graph_is_built_in_a_static() {
    static GRAPH: PoseGraph<8, 2> = PoseGraph::new();
    assert!(GRAPH.is_empty() && GRAPH.loop_count() == 0 && GRAPH.pose(0).is_none());
}

#[test]
fn settings_out_of_range_are_named() {
    use crate::testing::{BrokenSetting, each_broken_setting_is_named};
    let cases: [BrokenSetting<SolverSettings>; 4] = [
        (|s| s.max_iterations = 0, "max_iterations", "1 or more"),
        (
            |s| s.relative_tolerance = -0.1,
            "relative_tolerance",
            InvalidSetting::FRACTION,
        ),
        (
            |s| s.relative_tolerance = 1.5,
            "relative_tolerance",
            InvalidSetting::FRACTION,
        ),
        (
            |s| s.relative_tolerance = f32::NAN,
            "relative_tolerance",
            InvalidSetting::FRACTION,
        ),
    ];
    each_broken_setting_is_named(SolverSettings::DEFAULT, &cases, |s| {
        (s.is_valid(), s.invalid_setting())
    });
}

#[test]
fn headings_wrap_alike_on_both_sides_of_three_turns() {
    for a in [
        -100.0_f32, -9.5, -9.0, -3.5, -PI, 0.0, PI, 3.5, 8.99, 9.5, 1e4,
    ] {
        let w = wrap_heading(a);
        assert!(w > -PI && w <= PI, "{a} → {w}");
        let expected = reference::wrap(f64::from(a));
        let near_cut = (expected.abs() - core::f64::consts::PI).abs() < 1e-6;
        let error = if near_cut {
            f64::from(w).abs() - expected.abs()
        } else {
            f64::from(w) - expected
        };
        assert!(error.abs() < 1e-6, "{a} → {w}, expected {expected}");
    }
    assert!(wrap_heading(f32::NAN).is_nan() && wrap_heading(f32::INFINITY).is_nan());
}
