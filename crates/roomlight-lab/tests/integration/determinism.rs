//! At a fixed seed a run through the real agents over loopback is the same on every run: the
//! same excess after every capture, to the last bit. What could make it differ is timing —
//! which capture a node agent's first frame lands in, the order in which contributions arrive
//! and are summed, when the driver notices the last capture — and the bench takes every one
//! of them out (`pipeline::gate`, `roomlight_core::round::Controller`).

use roomlight_core::StepRule;
use roomlight_lab::bench::room::synthetic_trace;

/// Eight node agents (80 nodes), momentum, one round per capture: the first capture taken
/// only once all eight are in, the run ending right after its last capture's rounds. (Model
/// rounds are left out: with them the bench still differs in the last bits now and then, from
/// a cause not yet found — docs/results.md.)
fn trace(seed: u64) -> Vec<u64> {
    synthetic_trace(80, (StepRule::Momentum { theta: 1.0 }, 0), 6, seed)
        .expect("a run")
        .into_iter()
        .map(f64::to_bits)
        .collect()
}

#[test]
fn a_run_at_a_fixed_seed_is_the_same_bit_for_bit() {
    let first = trace(7);
    assert_eq!(first.len(), 7, "the start and six captures");
    assert!(
        first.iter().all(|b| f64::from_bits(*b).is_finite()),
        "finite excess"
    );
    for again in 0..2 {
        assert_eq!(trace(7), first, "run {} differs from the first", again + 2);
    }
}
