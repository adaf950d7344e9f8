//! What the structure-aware fuzzing tests share (`mutated_input.rs`, `rosbag.rs`): a
//! proptest runner on a fixed seed that checks both outcomes occurred.

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

/// Runs `cases` mutations from a fixed seed through `test`, then checks that both
/// outcomes occurred (some mutated inputs used, some refused): a property that only
/// ever saw one of them would check little.
pub fn run_cases<T: std::fmt::Debug>(
    cases: u32,
    strategy: &impl Strategy<Value = T>,
    test: impl Fn(T) -> Result<Option<i32>, TestCaseError>,
) {
    let outcomes = std::cell::RefCell::new([0u32; 2]);
    runner(cases)
        .run(strategy, |input| {
            let code = test(input)?;
            outcomes.borrow_mut()[usize::from(code == Some(0))] += 1;
            Ok(())
        })
        .unwrap();
    let [refused, used] = *outcomes.borrow();
    assert!(
        refused > 0 && used > 0,
        "{used} inputs used, {refused} refused"
    );
}

/// The runner: `cases` mutations from a fixed seed.
pub fn runner(cases: u32) -> TestRunner {
    TestRunner::new_with_rng(
        Config {
            cases,
            failure_persistence: None,
            ..Config::default()
        },
        TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    )
}
