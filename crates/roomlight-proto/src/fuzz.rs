//! Fuzzing of every decoder of a peer's bytes, as the agents use them: protobuf messages both
//! ways, then the boundary checks of this crate on what decoded. Inputs are valid messages
//! mutated (bytes flipped, cut, spliced, repeated) and plain random bytes, from a seeded
//! generator, so a failure reproduces from its seed and iteration. Zero panics; what passes the
//! checks is finite and in range.
//!
//! `cargo test -p roomlight-proto fuzz` runs 20 000 inputs per target (well under a second);
//! `ROOMLIGHT_FUZZ_ITERS=10000000 cargo test --release -p roomlight-proto fuzz` the long run.
//! Test-only: it owns no code the agents run.

use crate::bounds::{check_projector_id, cut, escaped, token_matches};
use crate::convert::{
    check_display_status, from_node_changes, from_node_errors, from_rgb, from_sparse, node_change,
    node_errors, to_rgb, to_sparse,
};
use crate::v1;
use prost::Message;
use roomlight_core::LinearRgb;

/// A seeded generator (SplitMix64) and a byte mutator, shared by this crate's fuzz targets.
pub(crate) struct Mutator(u64);

impl Mutator {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed)
    }

    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `0..n` (`n = 0`: 0).
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }

    /// One of `seeds` mutated a few times, or (one time in eight) random bytes.
    pub(crate) fn input(&mut self, seeds: &[Vec<u8>]) -> Vec<u8> {
        if seeds.is_empty() || self.below(8) == 0 {
            let len = self.below(256);
            return (0..len).map(|_| self.next() as u8).collect();
        }
        let mut bytes = seeds[self.below(seeds.len())].clone();
        for _ in 0..=self.below(4) {
            let at = self.below(bytes.len() + 1);
            match self.below(5) {
                0 if at < bytes.len() => bytes[at] ^= 1 << self.below(8),
                1 if at < bytes.len() => bytes[at] = self.next() as u8,
                2 => bytes.truncate(at),
                3 => {
                    let extra: Vec<u8> = (0..self.below(16)).map(|_| self.next() as u8).collect();
                    bytes.splice(at..at, extra);
                }
                _ => {
                    let end = (at + self.below(32)).min(bytes.len());
                    let repeated = bytes[at..end].to_vec();
                    bytes.splice(at..at, repeated);
                }
            }
        }
        bytes
    }
}

/// Inputs per target: `ROOMLIGHT_FUZZ_ITERS`, else 3 000.
pub(crate) fn iterations() -> usize {
    std::env::var("ROOMLIGHT_FUZZ_ITERS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(20_000)
}

fn node_seeds() -> Vec<Vec<u8>> {
    let values = [LinearRgb([0.1, 0.2, 0.3]), LinearRgb::splat(0.5)];
    let bodies = [
        v1::node_message::Body::Hello(v1::Hello {
            protocol_version: 3,
            room: "lab".into(),
            token: "s3cret".into(),
            projector_id: "p0".into(),
            width: 4,
            height: 2,
            state: Some(v1::PersistedState {
                calibration_epoch: 1,
                nodes: vec![v1::NodeState {
                    node: 3,
                    x: Some(to_rgb(values[0])),
                    attenuation: Some(to_sparse(&[1, 4], &values)),
                }],
            }),
            ..Default::default()
        }),
        v1::node_message::Body::Contribution(v1::Contribution {
            round: 7,
            nodes: vec![
                node_change(3, values[0]),
                node_change(4, LinearRgb([-0.5, 0.0, 1.0])),
            ],
        }),
        v1::node_message::Body::DisplayStatus(v1::DisplayStatus {
            state: v1::DisplayState::Lost as i32,
            output: "HDMI-1".into(),
            reason: "gone".into(),
        }),
        v1::node_message::Body::Goodbye(v1::Goodbye {
            reason: "bye".into(),
        }),
    ];
    bodies
        .into_iter()
        .map(|b| v1::NodeMessage { body: Some(b) }.encode_to_vec())
        .collect()
}

fn room_seeds() -> Vec<Vec<u8>> {
    let values = [LinearRgb([0.1, 0.2, 0.3]), LinearRgb::splat(0.5)];
    let bodies = [
        v1::room_message::Body::Errors(v1::Errors {
            round: 2,
            kind: v1::ErrorKind::Measured as i32,
            objective: 0.5,
            restart: false,
            nodes: vec![node_errors(3, 2, values), node_errors(4, 1, [values[0]])],
        }),
        v1::room_message::Body::Attenuation(v1::Attenuation {
            node: 3,
            p: Some(to_sparse(&[1, 4], &values)),
            s: Some(to_sparse(&[1, 4], &values)),
            start: Some(to_rgb(values[1])),
        }),
        v1::room_message::Body::Show(v1::Show {
            seq: 9,
            pattern: Some(v1::show::Pattern::Nodes(v1::NodeValues {
                values: vec![v1::NodeState {
                    node: 3,
                    x: Some(to_rgb(values[1])),
                    attenuation: None,
                }],
            })),
            mask: Vec::new(),
        }),
    ];
    bodies
        .into_iter()
        .map(|b| v1::RoomMessage { body: Some(b) }.encode_to_vec())
        .collect()
}

fn finite(v: &LinearRgb) -> bool {
    v.0.iter().all(|c| c.is_finite())
}

/// What a camera agent does with a node's message, checked: decoded, then the Hello's checks
/// and each body's boundary check.
fn camera_reads(bytes: &[u8]) {
    let Ok(message) = v1::NodeMessage::decode(bytes) else {
        return;
    };
    match message.body {
        Some(v1::node_message::Body::Hello(h)) => {
            let _ = token_matches(&h.token, "s3cret");
            if check_projector_id(&h.projector_id).is_ok() {
                assert!(!h.projector_id.chars().any(char::is_control));
            }
            let logged = escaped(&h.projector_id);
            assert!(!logged.chars().any(char::is_control), "{logged:?}");
            assert!(cut(&h.room, 128).len() <= 128);
            for n in h.state.into_iter().flat_map(|s| s.nodes) {
                if let Some(Ok((_, values))) = n.attenuation.as_ref().map(|a| from_sparse("a", a)) {
                    assert!(values.iter().all(finite));
                }
            }
        }
        Some(v1::node_message::Body::Contribution(c)) => {
            if let Ok(batch) = from_node_changes(c.nodes, |n| n < 100) {
                for (node, change) in &batch.entries {
                    assert!(*node < 100);
                    assert!(finite(change) && change.0.iter().all(|c| c.abs() <= 1.0));
                }
            }
        }
        Some(v1::node_message::Body::DisplayStatus(d)) if check_display_status(&d).is_ok() => {
            assert!(d.output.len() <= crate::convert::MAX_DISPLAY_TEXT);
        }
        Some(v1::node_message::Body::Goodbye(g)) => {
            assert!(!escaped(&g.reason).chars().any(char::is_control));
        }
        _ => {}
    }
}

/// What a node agent does with the camera agent's message (beyond its own wire module's
/// checks, fuzzed in roomlight-agent).
fn node_reads(bytes: &[u8]) {
    let Ok(message) = v1::RoomMessage::decode(bytes) else {
        return;
    };
    match message.body {
        Some(v1::room_message::Body::Errors(e)) => {
            if let Ok(batch) = from_node_errors(e.nodes, |n| n < 100) {
                assert!(batch.entries.iter().all(|(_, v)| v.iter().all(finite)));
            }
        }
        Some(v1::room_message::Body::Attenuation(a)) => {
            for sparse in [a.p, a.s].iter().flatten() {
                if let Ok((patches, values)) = from_sparse("a", sparse) {
                    assert_eq!(patches.len(), values.len());
                    assert!(patches.windows(2).all(|w| w[0] < w[1]));
                }
            }
            if let Ok(v) = from_rgb("start", a.start.as_ref()) {
                assert!(finite(&v));
            }
        }
        Some(v1::room_message::Body::Show(s)) => {
            if let Some(v1::show::Pattern::Nodes(values)) = s.pattern {
                for v in values.values {
                    if let Ok(x) = from_rgb("show", v.x.as_ref()) {
                        assert!(finite(&x));
                    }
                }
            }
        }
        _ => {}
    }
}

#[test]
fn fuzz_what_a_camera_agent_reads_from_node_agents() {
    let seeds = node_seeds();
    let mut m = Mutator::new(0x5EED_0001);
    for _ in 0..iterations() {
        camera_reads(&m.input(&seeds));
    }
}

#[test]
fn fuzz_what_a_node_agent_reads_from_the_camera_agent() {
    let seeds = room_seeds();
    let mut m = Mutator::new(0x5EED_0002);
    for _ in 0..iterations() {
        node_reads(&m.input(&seeds));
    }
}
