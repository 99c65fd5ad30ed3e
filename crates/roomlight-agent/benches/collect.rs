//! The camera agent's side of a round alone, at 100, 1 000 and 10 000 nodes (ten per projector,
//! supports of 16 patches), without the network:
//! - `collect`: each node agent's one batched `Contribution` message as it arrives (protobuf
//!   bytes) decoded, its entries checked at the boundary (owned by the sender through the node →
//!   projector index, named once, a finite change of value), each node counted once in the
//!   round's outstanding set, and its contribution `p_n Δx_n` formed from its column and
//!   subtracted from the predicted errors by the round controller (protocol version 3);
//! - `fan_out`: the errors of a round gathered on every node's support, one `Errors` message
//!   per node agent, encoded.
//!
//! Before issue 16 the collection re-checked every outstanding node against every peer's node
//! list and a round grew as nodes^1.9; it must grow linearly. Run with `cargo bench -p
//! roomlight-agent --bench collect`.

use prost::Message;
use roomlight_core::LinearRgb;
use roomlight_core::round::{Collection, Controller, Projectors, Received};
use roomlight_proto::convert::{from_node_changes, node_change, node_errors};
use roomlight_proto::v1;
use std::time::Duration;

/// Nodes per projector, as `roomlight bench net` runs them.
const PER_PROJECTOR: usize = 10;
/// Patches each node's support holds.
const SUPPORT: usize = 16;

fn main() {
    divan::main();
}

/// A node and its support.
type Node = (u32, Vec<u32>);

/// A room: its live projectors, each projector's nodes, and its patches.
struct Room {
    projectors: Projectors,
    nodes: Vec<(String, Vec<Node>)>,
    patches: usize,
}

fn room(nodes: usize) -> Room {
    let patches = 2 * nodes;
    let mut projectors = Projectors::default();
    let mut owned = Vec::new();
    for p in 0..nodes.div_ceil(PER_PROJECTOR) {
        let id = format!("p{p}");
        let first = p * PER_PROJECTOR;
        let ids: Vec<u32> = (first..(first + PER_PROJECTOR).min(nodes))
            .map(|n| n as u32)
            .collect();
        projectors.join(&id, ids.clone(), true);
        projectors.shown(&id, 0);
        let supports = ids
            .into_iter()
            .map(|n| {
                let mut support: Vec<u32> = (0..SUPPORT)
                    .map(|k| ((n as usize * 2 + k * 7) % patches) as u32)
                    .collect();
                support.sort_unstable();
                support.dedup();
                (n, support)
            })
            .collect();
        owned.push((id, supports));
    }
    Room {
        projectors,
        nodes: owned,
        patches,
    }
}

/// One round's contributions as they arrive: per projector its id and its message's bytes.
fn contributions(room: &Room, round: u64) -> Vec<(String, Vec<u8>)> {
    room.nodes
        .iter()
        .map(|(id, nodes)| {
            let nodes = nodes
                .iter()
                .map(|(n, _)| node_change(*n, LinearRgb::splat(1e-3)))
                .collect();
            let message = v1::Contribution { round, nodes };
            (id.clone(), message.encode_to_vec())
        })
        .collect()
}

#[divan::bench(args = [100, 1000, 10000])]
fn collect(bencher: divan::Bencher, nodes: usize) {
    let room = room(nodes);
    let arrived = contributions(&room, 1);
    // Each node's column, as the camera agent's model holds it (indexed by node).
    let columns: Vec<(Vec<u32>, Vec<LinearRgb>)> = room
        .nodes
        .iter()
        .flat_map(|(_, nodes)| nodes.iter())
        .map(|(_, support)| (support.clone(), vec![LinearRgb::splat(0.1); support.len()]))
        .collect();
    bencher
        .with_inputs(|| {
            let mut controller = Controller::new(vec![LinearRgb::ZERO; room.patches], 1);
            controller
                .measured(vec![LinearRgb::splat(0.5); room.patches])
                .expect("valid errors");
            (room.projectors.clone(), controller)
        })
        .bench_local_values(|(mut projectors, mut controller)| {
            let (sent, _late) = projectors.start_round(1);
            let awaited = sent
                .iter()
                .filter_map(|id| projectors.get(id))
                .flat_map(|p| p.nodes().to_vec());
            let mut round = Collection::new(1, awaited, Duration::ZERO, Duration::from_secs(5));
            for (projector, bytes) in &arrived {
                let message = v1::Contribution::decode(bytes.as_slice()).expect("decodes");
                let owns = |n: u32| projectors.owner(n) == Some(projector.as_str());
                let batch = from_node_changes(message.nodes, owns).expect("bounded");
                assert!(batch.refused.is_empty());
                for (node, change) in batch.entries {
                    if round.receive(message.round, node) == Received::Counted {
                        let (support, p) = &columns[node as usize];
                        let delta = p.iter().map(|p| p.hadamard(change));
                        let delta = support.iter().copied().zip(delta);
                        controller
                            .contribution(delta)
                            .expect("a valid contribution");
                    }
                }
            }
            assert!(round.done());
            controller
        });
}

#[divan::bench(args = [100, 1000, 10000])]
fn fan_out(bencher: divan::Bencher, nodes: usize) {
    let room = room(nodes);
    let errors = vec![LinearRgb::splat(0.25); room.patches];
    bencher.bench_local(|| {
        let mut bytes = 0;
        for (_, nodes) in &room.nodes {
            let entries = nodes
                .iter()
                .map(|(n, support)| {
                    let values = support.iter().map(|&i| errors[i as usize]);
                    node_errors(*n, support.len(), values)
                })
                .collect();
            let message = v1::Errors {
                round: 1,
                kind: v1::ErrorKind::Predicted as i32,
                objective: 1.0,
                restart: false,
                nodes: entries,
            };
            bytes += message.encode_to_vec().len();
        }
        bytes
    });
}
