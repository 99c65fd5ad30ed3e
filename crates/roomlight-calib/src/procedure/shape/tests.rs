//! Shaping against scenes whose answer is known: the camera sees the projector pixel for pixel,
//! so a node shaped to a reference must follow the reference's ratio to the white exactly.

use super::*;
use crate::charts::SampleConfig;
use crate::procedure::PlacedNode;
use crate::response::Response;
use crate::rig::{Projector, ProjectorKind, ProjectorRole};

const W: u32 = 64;
const H: u32 = 48;
const DARK: f32 = 0.01;

fn setup() -> Setup {
    Setup {
        corners: Vec::new(),
        sample: SampleConfig::default(),
        target_mask: vec![false; (W * H) as usize],
        target_patches: Vec::new(),
        wall_patches: Vec::new(),
        reference: None,
    }
}

fn image(f: impl Fn(u32, u32) -> f32) -> LinearImage {
    LinearImage {
        width: W,
        height: H,
        pixels: (0..W * H).map(|i| [f(i % W, i / W); 3]).collect(),
    }
}

/// The camera sees projector pixel `(x, y)` at camera pixel `(x, y)`.
fn identity() -> Correspondence {
    Correspondence {
        reach: 0.1,
        ..Correspondence::identity(W, H)
    }
}

/// One charted projector with `nodes` nodes, each of full weight on its share of the columns.
fn placed(nodes: usize) -> Placed {
    let per = W as usize / nodes;
    Placed {
        projector: Projector {
            id: "wall".into(),
            width: W,
            height: H,
            kind: ProjectorKind::Standard,
            role: ProjectorRole::Luminaire,
        },
        layout: Layout::Charted,
        nodes: (0..nodes)
            .map(|k| PlacedNode {
                id: k as u32,
                chart: Some(k),
                weights: (0..W * H)
                    .map(|i| f32::from((i % W) as usize / per == k))
                    .collect(),
            })
            .collect(),
        claim: None,
        excluded: Vec::new(),
        response: Response::linear(),
        shape: None,
    }
}

/// A reference brighter to the right, 4× across the frame, over a flat white.
fn gradient(x: u32, _: u32) -> f32 {
    DARK + 0.1 + 0.3 * x as f32 / (W - 1) as f32
}

fn shaped(reference: &LinearImage, white: &LinearImage, nodes: usize) -> (Placed, Vec<Shaped>) {
    let (setup, dark, corr) = (setup(), image(|_, _| DARK), identity());
    let mut p = [placed(nodes)];
    let lit = [Some(Lit { white, corr: &corr })];
    let out = shape(&setup, reference, &dark, &mut p, &lit).expect("shaped");
    let [p] = p;
    (p, out)
}

#[test]
fn a_node_follows_the_reference_where_it_is_dimmer_than_typical_and_keeps_full_weight_elsewhere() {
    let white = image(|_, _| DARK + 0.5);
    let (p, out) = shaped(&image(gradient), &white, 1);
    let w = &p.nodes[0].weights;
    assert!(w.iter().all(|w| w.is_finite() && (0.0..=1.0).contains(w)));
    // Between the first and last block centres the ratio is linear, so read exactly: the
    // weight is the reference's light over that at the median column (the nearest-rank
    // median of 64 equal columns is column 31's), as the white is flat.
    let light = |x: u32| f64::from(gradient(x, 0) - DARK);
    let typical = light(31);
    for y in 0..H {
        for x in 8..31 {
            let got = f64::from(w[(y * W + x) as usize]);
            let want = light(x) / typical;
            assert!(
                (got - want).abs() < 2e-3,
                "({x}, {y}): weight {got}, the reference's ratio {want}"
            );
        }
        for x in 32..W {
            let got = w[(y * W + x) as usize];
            assert!(
                (got - 1.0).abs() < 1e-6,
                "({x}, {y}) is brighter than typical: {got}"
            );
        }
    }
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].nodes, 1);
    assert!(
        out[0].spread.0 < 0.6 && out[0].spread.1 > 1.3,
        "{:?}",
        out[0].spread
    );
}

#[test]
fn a_reference_shaped_like_the_white_leaves_the_nodes_flat() {
    // The projector's own white falls off; the reference falls off the same way, brighter:
    // each node's ratio is the same everywhere, so nothing changes.
    let white = image(|x, y| DARK + 0.2 + 0.005 * (x + y) as f32);
    let reference = image(|x, y| DARK + 1.5 * (0.2 + 0.005 * (x + y) as f32));
    let (p, _) = shaped(&reference, &white, 2);
    for (n, flat) in p.nodes.iter().zip(placed(2).nodes) {
        for (a, b) in n.weights.iter().zip(&flat.weights) {
            assert!((a - b).abs() < 1e-5, "{a} against {b}");
        }
    }
}

#[test]
fn shaped_again_from_its_shape_a_placement_gets_the_same_weights() {
    let white = image(|_, _| DARK + 0.5);
    let (p, _) = shaped(&image(gradient), &white, 2);
    let mut again = placed(2);
    p.shape
        .as_ref()
        .expect("kept")
        .apply(&mut again)
        .expect("applied");
    assert_eq!(again.nodes, p.nodes);
    // A placement with other nodes is refused, named.
    let err = p
        .shape
        .as_ref()
        .expect("kept")
        .apply(&mut placed(4))
        .expect_err("other nodes");
    assert!(
        err.to_string().contains("wall: 4 nodes placed, 2 shaped"),
        "{err}"
    );
}

#[test]
fn pixels_that_cannot_be_read_do_not_shape_and_bad_images_are_refused() {
    let white = image(|_, _| DARK + 0.5);
    // Every pixel of the reference saturated or not finite: no block reads, the node stays
    // flat and nothing is reported.
    let blind = image(|x, _| if x % 2 == 0 { f32::NAN } else { 5.0 });
    let (p, out) = shaped(&blind, &white, 1);
    assert!(out.is_empty());
    assert_eq!(p.nodes, placed(1).nodes);
    assert!(p.shape.is_none());
    // A projector the camera does not see (its white no brighter than dark) stays flat too.
    let (p, out) = shaped(&image(gradient), &image(|_, _| DARK), 1);
    assert!(out.is_empty() && p.shape.is_none());
    // A few NaN pixels in a readable reference are skipped: the weights stay finite.
    let spotted = image(|x, y| {
        if (x + y) % 7 == 0 {
            f32::NAN
        } else {
            gradient(x, y)
        }
    });
    let (p, _) = shaped(&spotted, &white, 1);
    assert!(p.nodes[0].weights.iter().all(|w| w.is_finite()));
    // A reference of another size than the camera's is refused, naming it.
    let small = LinearImage {
        width: 2,
        height: 2,
        pixels: vec![[0.5; 3]; 4],
    };
    let (setup, dark, corr) = (setup(), image(|_, _| DARK), identity());
    let mut ps = [placed(1)];
    let lit = [Some(Lit {
        white: &white,
        corr: &corr,
    })];
    let err = shape(&setup, &small, &dark, &mut ps, &lit).expect_err("a small reference");
    assert!(
        err.to_string()
            .contains("reference: the reference image has 4 pixels, the camera 3072"),
        "{err}"
    );
}
