//! Property tests: random graphs never give non-finite poses and never panic; refused
//! inputs return their error and leave the graph as it was.

use super::*;
use proptest::collection::vec;
use proptest::prelude::*;

type Graph = PoseGraph<64, 8>;

fn pose() -> impl Strategy<Value = Pose2<f32>> {
    (-50.0_f32..50.0, -50.0_f32..50.0, -PI..PI).prop_map(|(x, y, t)| Pose2::new(x, y, t))
}

fn chain() -> impl Strategy<Value = ChainEdge> {
    (
        -2.0_f32..2.0,
        -2.0_f32..2.0,
        -3.1_f32..3.1,
        1e-3_f32..1.0,
        1e-3_f32..1.0,
    )
        .prop_map(|(x, y, t, sp, st)| chain_edge(x, y, t, sp, st))
}

/// A loop edge with its nodes as fractions of the graph's length (see [`place`]).
fn loop_spec() -> impl Strategy<Value = (f32, f32, LoopEdge)> {
    (
        0.0_f32..1.0,
        0.0_f32..1.0,
        (-20.0_f32..20.0, -20.0_f32..20.0, -PI..PI),
        (0.0_f32..1e6, 0.0_f32..1e6, -1.0_f32..1.0, 0.0_f32..1e6),
    )
        .prop_map(|(a, b, (x, y, t), (xx, yy, corr, w))| {
            let xy = corr * (xx * yy).sqrt() * 0.999;
            (a, b, loop_edge(0, 0, Pose2::new(x, y, t), [xx, xy, yy], w))
        })
}

/// The loop edge between nodes `a` and `b` (fractions) of a graph of `n ≥ 2` nodes.
fn place((a, b, edge): (f32, f32, LoopEdge), n: usize) -> LoopEdge {
    let from = ((a * (n - 1) as f32) as usize).min(n - 2);
    let to = from + 1 + ((b * (n - 1 - from) as f32) as usize).min(n - 2 - from);
    LoopEdge {
        from: from as u16,
        to: to as u16,
        ..edge
    }
}

/// One way to spoil an input, and the error it must get.
type Spoil<'a, T> = (&'a dyn Fn(&mut T), GraphError);

/// A number spread over `10^−exp … 10^exp`, log-uniformly.
fn spread(exp: f32) -> impl Strategy<Value = f32> {
    (-exp..exp).prop_map(|e| 10_f32.powf(e))
}

/// Checks an optimisation's outcome: finite poses in range with node 0 in place, or a
/// numerical failure that left the graph as it was.
fn check_outcome(
    before: &Graph,
    after: &Graph,
    result: Result<SolveReport, GraphError>,
) -> Result<(), TestCaseError> {
    match result {
        Ok(_) => {
            prop_assert_eq!(after.pose(0), before.pose(0));
            prop_assert_eq!(after.len(), before.len());
            for p in after.poses() {
                prop_assert!(p.is_finite(), "{:?}", p);
                prop_assert!(p.theta > -PI && p.theta <= PI, "{:?}", p);
            }
        }
        Err(GraphError::NumericalFailure) => prop_assert!(after == before),
        Err(e) => prop_assert!(false, "unexpected {:?}", e),
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn random_graphs_give_finite_poses(
        start in pose(),
        edges in vec(chain(), 1..63),
        loops in vec(loop_spec(), 0..=8),
        max_iterations in 1_u16..40,
        tolerance in 0.0_f32..1e-2,
    ) {
        let mut graph = Graph::new();
        graph.reset(start).unwrap();
        for e in &edges {
            prop_assert!(graph.add_node(*e).is_ok());
        }
        for l in loops {
            let edge = place(l, graph.len());
            prop_assert_eq!(graph.add_loop(edge), Ok(()));
        }
        let before = graph.clone();
        let mut scratch = vec![f32::NAN; Graph::SCRATCH_LEN];
        let settings = SolverSettings { max_iterations, relative_tolerance: tolerance };
        let result = graph.optimise(&mut scratch, &settings);
        check_outcome(&before, &graph, result)?;
        // A second optimisation from the solution never fails either.
        if result.is_ok() {
            let before = graph.clone();
            let again = graph.optimise(&mut scratch, &settings);
            check_outcome(&before, &graph, again)?;
        }
    }

    #[test]
    fn extreme_noise_and_information_never_panic(
        edges in vec((chain(), spread(20.0), spread(20.0)), 1..63),
        loops in vec((loop_spec(), spread(30.0), spread(30.0)), 0..=8),
    ) {
        let mut graph = Graph::new();
        graph.reset(Pose2::new(0.0, 0.0, 0.0)).unwrap();
        for (e, sp, st) in edges {
            let edge = ChainEdge { position_std: sp, heading_std: st, ..e };
            prop_assert!(graph.add_node(edge).is_ok());
        }
        for (l, scale_position, scale_heading) in loops {
            let mut edge = place(l, graph.len());
            edge.position_information = edge.position_information.map(|v| v * scale_position);
            edge.heading_information *= scale_heading;
            // Scaled past f32's range the check may refuse it; that is the point of it.
            let _ = graph.add_loop(edge);
        }
        let before = graph.clone();
        let mut scratch = vec![0.0; Graph::SCRATCH_LEN];
        let result = graph.optimise(&mut scratch, &SolverSettings::DEFAULT);
        check_outcome(&before, &graph, result)?;
    }

    #[test]
    fn refused_inputs_leave_the_graph_unchanged(
        start in pose(),
        edges in vec(chain(), 1..63),
        loops in vec(loop_spec(), 0..8),
        probe in loop_spec(),
    ) {
        let mut graph = Graph::new();
        graph.reset(start).unwrap();
        for e in &edges {
            graph.add_node(*e).unwrap();
        }
        for l in loops {
            graph.add_loop(place(l, graph.len())).unwrap();
        }
        let before = graph.clone();
        let n = graph.len() as u16;
        let good_chain = chain_edge(0.5, 0.0, 0.1, 0.01, 0.01);
        let good_loop = place(probe, graph.len());

        let bad_chains: [Spoil<ChainEdge>; 7] = [
            (&|e| e.motion.x = f32::NAN, GraphError::NonFiniteInput),
            (&|e| e.motion.y = f32::INFINITY, GraphError::NonFiniteInput),
            (&|e| e.motion.theta = f32::NAN, GraphError::NonFiniteInput),
            (&|e| e.position_std = 0.0, GraphError::InvalidNoise),
            (&|e| e.position_std = -0.1, GraphError::InvalidNoise),
            (&|e| e.heading_std = f32::NAN, GraphError::InvalidNoise),
            (&|e| e.heading_std = f32::INFINITY, GraphError::InvalidNoise),
        ];
        for (spoil, error) in bad_chains {
            let mut edge = good_chain;
            spoil(&mut edge);
            prop_assert_eq!(graph.add_node(edge), Err(error), "{:?}", edge);
            prop_assert!(graph == before);
        }

        let (from, to) = (good_loop.from, good_loop.to);
        let bad_loops: [Spoil<LoopEdge>; 11] = [
            (&|e| (e.from, e.to) = (to, from), GraphError::BackwardLoop),
            (&|e| e.from = to, GraphError::BackwardLoop),
            (&|e| e.to = n, GraphError::UnknownNode),
            (&|e| (e.from, e.to) = (0, u16::MAX), GraphError::UnknownNode),
            (&|e| e.relative.y = f32::NAN, GraphError::NonFiniteInput),
            (&|e| e.position_information = [-1.0, 0.0, 1.0], GraphError::InvalidInformation),
            (&|e| e.position_information = [1.0, 0.0, -1e-9], GraphError::InvalidInformation),
            (&|e| e.position_information = [1.0, 2.0, 1.0], GraphError::InvalidInformation),
            (&|e| e.position_information[1] = f32::NAN, GraphError::InvalidInformation),
            (&|e| e.heading_information = -1.0, GraphError::InvalidInformation),
            (&|e| e.heading_information = f32::INFINITY, GraphError::InvalidInformation),
        ];
        for (spoil, error) in bad_loops {
            let mut edge = good_loop;
            spoil(&mut edge);
            prop_assert_eq!(graph.add_loop(edge), Err(error), "{:?}", edge);
            prop_assert!(graph == before);
        }

        let mut short = vec![0.0; Graph::SCRATCH_LEN - 1];
        let settings = SolverSettings::DEFAULT;
        prop_assert_eq!(graph.optimise(&mut short, &settings), Err(GraphError::ScratchTooShort));
        prop_assert_eq!(graph.optimise(&mut [], &settings), Err(GraphError::ScratchTooShort));
        let mut scratch = vec![0.0; Graph::SCRATCH_LEN];
        let broken = SolverSettings { max_iterations: 0, ..settings };
        prop_assert_eq!(graph.optimise(&mut scratch, &broken), Err(GraphError::InvalidSettings));
        let broken = SolverSettings { relative_tolerance: f32::NAN, ..settings };
        prop_assert_eq!(graph.optimise(&mut scratch, &broken), Err(GraphError::InvalidSettings));
        prop_assert!(graph == before);

        // And the good ones are taken.
        prop_assert_eq!(graph.add_loop(good_loop), Ok(()));
        prop_assert_eq!(graph.add_node(good_chain), Ok(n));
    }
}

#[test]
fn full_and_empty_graphs_refuse() {
    let mut graph = PoseGraph::<3, 1>::new();
    let step = chain_edge(1.0, 0.0, 0.0, 0.1, 0.1);
    assert_eq!(graph.add_node(step), Err(GraphError::Empty));
    let probe = loop_edge(0, 1, Pose2::new(1.0, 0.0, 0.0), [1.0, 0.0, 1.0], 1.0);
    assert_eq!(graph.add_loop(probe), Err(GraphError::UnknownNode));
    let mut scratch = [0.0; PoseGraph::<3, 1>::SCRATCH_LEN];
    assert_eq!(
        graph.optimise(&mut scratch, &SolverSettings::DEFAULT),
        Ok(SolveReport::default())
    );
    assert_eq!(
        graph.reset(Pose2::new(f32::NAN, 0.0, 0.0)),
        Err(GraphError::NonFiniteInput)
    );
    assert!(graph.is_empty());

    graph.reset(Pose2::new(0.0, 0.0, 7.0)).unwrap();
    assert!((graph.pose(0).unwrap().theta - (7.0 - core::f32::consts::TAU)).abs() < 1e-6);
    assert_eq!(graph.add_node(step), Ok(1));
    assert_eq!(graph.add_node(step), Ok(2));
    assert_eq!(graph.chain_edges(), &[step, step]);
    let before = graph.clone();
    assert_eq!(graph.add_node(step), Err(GraphError::Full));
    assert_eq!(graph.add_loop(probe), Ok(()));
    let after_loop = graph.clone();
    assert_eq!(graph.add_loop(probe), Err(GraphError::Full));
    assert_eq!(graph, after_loop);
    assert_ne!(graph, before);

    // Reset empties it in place.
    graph.reset(Pose2::new(1.0, 2.0, 0.5)).unwrap();
    assert_eq!((graph.len(), graph.loop_count()), (1, 0));
    assert_eq!(graph.poses(), &[Pose2::new(1.0, 2.0, 0.5)]);
    assert!(graph.chain_edges().is_empty() && graph.loop_edges().is_empty());
    // Equal to a graph built afresh, whatever the old nodes left in the capacity.
    let mut fresh = PoseGraph::<3, 1>::new();
    fresh.reset(Pose2::new(1.0, 2.0, 0.5)).unwrap();
    assert_eq!(graph, fresh);

    let mut nothing = PoseGraph::<0, 0>::new();
    assert_eq!(
        nothing.reset(Pose2::new(0.0, 0.0, 0.0)),
        Err(GraphError::Full)
    );
}

#[test]
fn a_node_whose_pose_would_overflow_is_refused() {
    let mut graph = PoseGraph::<4, 1>::new();
    graph
        .reset(Pose2::new(0.0, 0.0, core::f32::consts::FRAC_PI_4))
        .unwrap();
    let before = graph.clone();
    let huge = chain_edge(f32::MAX, f32::MAX, 0.0, 0.1, 0.1);
    assert_eq!(graph.add_node(huge), Err(GraphError::NonFiniteInput));
    assert_eq!(graph, before);
}

#[test]
fn overflowing_information_fails_without_touching_the_poses() {
    let mut graph = PoseGraph::<8, 1>::new();
    graph.reset(Pose2::new(0.0, 0.0, 0.0)).unwrap();
    for _ in 0..5 {
        graph
            .add_node(chain_edge(1.0, 0.0, 0.0, 1e-30, 1e-30))
            .unwrap();
    }
    let far = loop_edge(0, 5, Pose2::new(1e30, 0.0, 3.0), [3e38, 0.0, 3e38], 3e38);
    graph.add_loop(far).unwrap();
    let before = graph.clone();
    let mut scratch = [0.0; PoseGraph::<8, 1>::SCRATCH_LEN];
    let result = graph.optimise(&mut scratch, &SolverSettings::DEFAULT);
    assert_eq!(result, Err(GraphError::NumericalFailure));
    assert_eq!(graph, before);
}
