//! At a fixed seed a run through the real agents over loopback is the same on every run: the
//! same excess after every capture, to the last bit. What could make it differ is timing —
//! which capture a node agent's first frame lands in, the order in which contributions arrive
//! and are summed, when the driver notices the last capture — and the bench takes every one
//! of them out (`pipeline::gate`, `roomlight_core::round::Controller`).

use roomlight_core::StepRule;
use roomlight_lab::bench::room::synthetic_trace;

/// Eight node agents (80 nodes), momentum with model rounds: many contributions to sum in
/// every round, and the first capture taken only once all eight are in.
fn trace(seed: u64) -> Vec<u64> {
    synthetic_trace(80, (StepRule::Momentum { theta: 1.0 }, 5), 4, seed)
        .expect("a run")
        .into_iter()
        .map(f64::to_bits)
        .collect()
}

#[test]
fn a_run_at_a_fixed_seed_is_the_same_bit_for_bit() {
    let first = trace(7);
    assert_eq!(first.len(), 5, "the start and four captures");
    assert!(
        first.iter().all(|b| f64::from_bits(*b).is_finite()),
        "finite excess"
    );
    for again in 0..2 {
        assert_eq!(trace(7), first, "run {} differs from the first", again + 2);
    }
}
