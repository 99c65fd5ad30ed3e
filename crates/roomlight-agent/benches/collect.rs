//! The camera agent's contribution collection alone, at 100, 1 000 and 10 000 nodes (ten per
//! projector, supports of 16 patches): per contribution, the ownership check through the node →
//! projector index, the round's outstanding set, and the update of the predicted errors. Before
//! issue 16 this re-checked every outstanding node against every peer's node list, and a round
//! grew as nodes^1.9; it must now grow linearly. Run with `cargo bench -p roomlight-agent
//! --bench collect`.

use roomlight_core::LinearRgb;
use roomlight_core::aggregator::ErrorAggregator;
use roomlight_core::round::{Collection, Projectors, Received};
use std::time::Duration;

/// Nodes per projector, as `roomlight bench net` runs them.
const PER_PROJECTOR: usize = 10;
/// Patches each node's contribution touches.
const SUPPORT: usize = 16;

fn main() {
    divan::main();
}

/// One round's contributions: (projector, node, its delta).
type Contributions = Vec<(String, u32, Vec<(u32, LinearRgb)>)>;

fn room(nodes: usize) -> (Projectors, Contributions, usize) {
    let patches = 2 * nodes;
    let mut projectors = Projectors::default();
    let mut contributions = Vec::with_capacity(nodes);
    for p in 0..nodes.div_ceil(PER_PROJECTOR) {
        let id = format!("p{p}");
        let first = p * PER_PROJECTOR;
        let ids: Vec<u32> = (first..(first + PER_PROJECTOR).min(nodes))
            .map(|n| n as u32)
            .collect();
        projectors.join(&id, ids.clone(), true);
        projectors.shown(&id, 0);
        for n in ids {
            let delta = (0..SUPPORT)
                .map(|k| {
                    let patch = (n as usize * 2 + k * 7) % patches;
                    (patch as u32, LinearRgb::splat(1e-3))
                })
                .collect();
            contributions.push((id.clone(), n, delta));
        }
    }
    (projectors, contributions, patches)
}

#[divan::bench(args = [100, 1000, 10000])]
fn collect(bencher: divan::Bencher, nodes: usize) {
    let (projectors, contributions, patches) = room(nodes);
    bencher
        .with_inputs(|| {
            (
                projectors.clone(),
                ErrorAggregator::new(patches),
                contributions.clone(),
            )
        })
        .bench_local_values(|(mut projectors, mut aggregator, contributions)| {
            let (sent, _late) = projectors.start_round(1);
            let awaited = sent
                .iter()
                .filter_map(|id| projectors.get(id))
                .flat_map(|p| p.nodes().to_vec());
            let mut round = Collection::new(1, awaited, Duration::ZERO, Duration::from_secs(5));
            for (projector, node, delta) in contributions {
                if projectors.owner(node) != Some(projector.as_str()) {
                    continue;
                }
                if round.receive(1, node) == Received::Counted {
                    aggregator
                        .add_contribution(delta)
                        .expect("a valid contribution");
                }
            }
            assert!(round.done());
            aggregator
        });
}
