//! Fuzzing of the node agent's own decoders of a camera agent's messages — Assign weights, Show
//! patterns and their masks, Shade ratios and light, as `wire` checks them and a display then draws them
//! (a shading step keeps every gain finite and bounded, the codes within [0, 1]) — and of its
//! state file (JSON), as `state` reads it. Inputs are valid messages and files changed by
//! bolero-generated edits (`roomlight_proto::mutate`); zero panics, and what passes the checks
//! is drawable. The protobuf messages' common checks are fuzzed in roomlight-proto.
//!
//! `cargo test -p roomlight-agent fuzz` runs each target for a second of random inputs;
//! `BOLERO_RANDOM_ITERATIONS=10000000 cargo test --release -p roomlight-agent fuzz` a long run,
//! `cargo bolero test` the same targets under libFuzzer. Test-only.

use super::state::{Memory, SavedState};
use super::wire::{Wire, assignment_from_wire, pattern_from_wire, shade_from_wire};
use crate::hardware::Display;
use prost::Message;
use roomlight_core::{AttenuationColumn, LinearRgb};
use roomlight_proto::convert::to_rgb;
use roomlight_proto::mutate::{Edits, mutate};
use roomlight_proto::v1;

fn seeds() -> Vec<Vec<u8>> {
    let bodies = [
        v1::room_message::Body::Assign(v1::Assign {
            nodes: vec![v1::NodeAssignment {
                node: 3,
                chart: 3,
                pixels: vec![0, 5, 9],
                weights: vec![1.0, 0.5, 0.25],
            }],
            width: 5,
            height: 2,
            gamma: vec![2.2, 2.2, 2.2],
        }),
        v1::room_message::Body::Show(v1::Show {
            seq: 4,
            pattern: Some(v1::show::Pattern::Gray(v1::GrayBit {
                axis: v1::Axis::Column as i32,
                bit: 1,
                inverse: true,
                coding: v1::Coding::Xor04 as i32,
                cell: 2,
                primary: v1::Primary::Green as i32,
            })),
            mask: vec![0b0000_1001, 0b0000_0010],
        }),
        v1::room_message::Body::Show(v1::Show {
            seq: 5,
            pattern: Some(v1::show::Pattern::Uniform(v1::Uniform {
                code: Some(to_rgb(LinearRgb::splat(0.5))),
            })),
            mask: Vec::new(),
        }),
        v1::room_message::Body::Shade(v1::Shade {
            seq: 6,
            block: roomlight_calib::shading::BLOCK,
            across: 1,
            down: 1,
            ratios: [2.0f32, 1.0, 0.5]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
            rate: 0.8,
            reset: false,
            light: [0.36f32, 0.14, 0.03, 0.18, 0.105, 0.03]
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect(),
        }),
    ];
    bodies
        .into_iter()
        .map(|b| v1::RoomMessage { body: Some(b) }.encode_to_vec())
        .collect()
}

/// A node agent of a 5×2 projector reading a camera agent's message: what its checks accept,
/// its display can draw.
fn node_reads(bytes: &[u8]) {
    let Ok(message) = v1::RoomMessage::decode(bytes) else {
        return;
    };
    match message.body {
        Some(v1::room_message::Body::Assign(a)) => {
            if let Ok(assignment) = assignment_from_wire(&a) {
                assert!(u64::from(assignment.width) * u64::from(assignment.height) <= 1 << 26);
            }
        }
        Some(v1::room_message::Body::Show(s)) => {
            if let Some(Ok(Wire::Frame(pattern))) = s
                .pattern
                .map(|p| pattern_from_wire(p, &s.mask, Some((5, 2))))
            {
                let codes = pattern.codes(5, 2).expect("an accepted pattern draws");
                assert!(codes.iter().flatten().all(|c| (0.0..=1.0).contains(c)));
            }
        }
        Some(v1::room_message::Body::Shade(s)) => {
            use roomlight_calib::shading::{Gains, MAX_GAIN, MIN_GAIN};
            let Ok(step) = shade_from_wire(&s, (5, 2)) else {
                return;
            };
            let mut gains = Gains::flat(5, 2).expect("a 5×2 projector");
            let assignment = crate::hardware::Assignment {
                width: 5,
                height: 2,
                response: roomlight_calib::response::Response::linear(),
                nodes: vec![(1, (0..10).map(|i| (i, 0.5)).collect())],
            };
            // A node at full red: a block asked for more steps to the closest colour.
            let full = [(1, LinearRgb([2.0, 0.8, 0.2]))];
            let light: Vec<[f64; 3]> = assignment
                .light_shaded(&full, Some(&gains))
                .into_iter()
                .map(|l| l.0)
                .collect();
            let headroom = roomlight_calib::shading::headroom(&light, 5, 2);
            if let Some(ratios) = &step.ratios {
                gains
                    .step_within(ratios, step.rate, headroom.as_deref())
                    .expect("accepted ratios step");
            }
            for (x, y) in [(0, 0), (4, 1), (2, 1)] {
                let g = gains.at(x, y);
                assert!(g.iter().all(|v| (MIN_GAIN..=MAX_GAIN).contains(v)), "{g:?}");
            }
            let codes = assignment.draw_shaded(&[(1, LinearRgb::splat(0.3))], Some(&gains));
            assert!(codes.iter().flatten().all(|c| (0.0..=1.0).contains(c)));
        }
        _ => {}
    }
}

#[test]
fn fuzz_the_node_agents_wire_checks() {
    let seeds = seeds();
    bolero::check!()
        .with_type::<Edits>()
        .for_each(|edits| node_reads(&mutate(&seeds, edits)));
}

/// A display that only counts what it is told.
struct Count(usize);

impl Display for Count {
    fn show(&mut self, _: u32, _: LinearRgb) {
        self.0 += 1;
    }
}

/// State files mutated: read, or refused naming the file; a node relit from any of them never
/// panics and shows only finite values.
#[test]
fn fuzz_state_files() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("f.state.json");
    let column =
        AttenuationColumn::new(vec![1, 4], vec![LinearRgb::splat(0.5); 2]).expect("column");
    let valid = SavedState {
        calibration_epoch: 2,
        values: vec![(3, LinearRgb::splat(0.4)), (4, LinearRgb([0.1, 0.2, 0.3]))],
        assignment: None,
        attenuation: vec![(3, column)],
        projector: Some("f".into()),
        gains: None,
    };
    let seeds = vec![serde_json::to_vec(&valid).expect("json")];
    bolero::check!().with_type::<Edits>().for_each(|edits| {
        std::fs::write(&path, mutate(&seeds, edits)).expect("write");
        match SavedState::load(&path) {
            Ok(Some(state)) => assert!(
                state
                    .values
                    .iter()
                    .all(|(_, v)| v.0.iter().all(|c| c.is_finite()))
            ),
            Ok(None) => {}
            Err(e) => assert!(e.to_string().contains("f.state.json"), "{e}"),
        }
        let memory = Memory::relight(Some(path.clone()), &mut Count(0), "f");
        assert!(
            memory
                .values
                .values()
                .all(|v| v.0.iter().all(|c| c.is_finite()))
        );
    });
}
