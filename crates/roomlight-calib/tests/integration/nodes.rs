//! Nodes and feathering on the small simulated room, decoded from its own structured light.

use crate::common;

use common::{chart_corners, decode_projector, small_scene};
use roomlight_calib::graycode::{Coding, Correspondence, DecodeConfig};
use roomlight_calib::nodes::{
    Node, NodeConfig, Partition, partition_of_unity, projector_weights, segment, segment_beside,
};
use roomlight_sim::{Frame, ProjectorImage, Room};

/// The projector images that show every node at full light.
fn full_frames(room: &Room, nodes: &[Node]) -> Vec<Frame> {
    room.projectors()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (w, h) = (p.pinhole.width, p.pinhole.height);
            let mut pixels = vec![[0.0f32; 3]; (w * h) as usize];
            for n in nodes.iter().filter(|n| n.projector == k) {
                for (px, wgt) in pixels.iter_mut().zip(&n.weights) {
                    for c in px.iter_mut() {
                        *c += wgt;
                    }
                }
            }
            Frame::Linear(ProjectorImage {
                width: w,
                height: h,
                pixels,
            })
        })
        .collect()
}

/// The partition of unity of per-projector weights and dark pixels, through the true
/// correspondence, away from the target (its margin is black).
fn partition(
    room: &Room,
    mask: &[bool],
    truth: &[Vec<Option<u32>>],
    weights: impl Fn(usize) -> (Vec<f32>, Vec<bool>),
) -> Partition {
    let near_target = roomlight_calib::nodes::dilate(
        mask,
        room.camera().width as usize,
        room.camera().height as usize,
        8,
    );
    let (w, dark): (Vec<Vec<f32>>, Vec<Vec<bool>>) = (0..truth.len()).map(weights).unzip();
    partition_of_unity(truth, &w, &dark, &near_target)
}

/// The small room's two standard luminaires decoded from its own structured light (the large
/// aperture is handled by its cone mask).
fn luminaires(room: &Room) -> Vec<Correspondence> {
    (0..2)
        .map(|k| {
            decode_projector(
                room,
                k,
                Coding::Xor04,
                &DecodeConfig::default(),
                40 + k as u64,
            )
        })
        .collect()
}

#[test]
fn nodes_partition_the_light_feather_smoothly_and_keep_the_target_dark() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let corr = luminaires(&room);
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let config = NodeConfig::default();
    let seg = segment(&corr, &charts, Some(&mask), &config).expect("nodes");
    let nodes = &seg.nodes;
    assert!(nodes.len() >= 3, "{} nodes", nodes.len());
    for n in nodes {
        assert!(n.weights.iter().all(|w| (0.0..=1.0).contains(w)));
    }
    // Weights sum to one on every surface point a projector reaches (outside the target's
    // margin): within each projector exactly, across overlaps to the feathering's accuracy.
    let truth: Vec<Vec<Option<u32>>> = (0..2).map(|k| room.true_correspondence(k)).collect();
    let joint = partition(&room, &mask, &truth, |k| {
        (projector_weights(&seg.nodes, k), seg.excluded[k].clone())
    });
    println!("segmented together: {joint}");
    assert!(joint.points > 1000 && joint.overlap > 200, "{joint}");
    // Exact inside one projector; across overlaps the pixel grids of two projectors never line
    // up, so a ramp misses where they disagree. Measured 98.76% within 1e-3 with the projectors
    // compensating each other's pixel steps, 97.80% without (each blend from the camera-space
    // ramps alone).
    assert!(
        joint.within_1e3 > 0.98 && joint.within_0_05 > 0.99,
        "segmented together: {joint}"
    );
    // A claim is the light the projector's nodes give the camera pixel.
    for (k, claims) in seg.claims.iter().enumerate() {
        let w = projector_weights(&seg.nodes, k);
        let pw = corr[k].projector_width as usize;
        for (i, m) in corr[k].map.iter().enumerate() {
            if let Some((x, y)) = m {
                let p = *y as usize * pw + *x as usize;
                let given = if seg.excluded[k][p] { 0.0 } else { w[p] };
                assert!((claims[i] - given).abs() < 1e-5, "projector {k}, pixel {i}");
            }
        }
    }
    // The same projectors one after the other, as over the wire: the first keeps the weights it
    // was segmented with alone, the second takes what the first leaves.
    let first = segment(&corr[..1], &charts, Some(&mask), &config).expect("first alone");
    let second = segment_beside(
        &corr[1..],
        &charts,
        Some(&mask),
        &config,
        Some(&first.claims[0]),
    )
    .expect("second beside the first");
    let one_by_one = partition(&room, &mask, &truth, |k| {
        let s = if k == 0 { &first } else { &second };
        (projector_weights(&s.nodes, 0), s.excluded[0].clone())
    });
    println!("segmented one after the other: {one_by_one}");
    assert!(
        one_by_one.within_1e3 > 0.95 && one_by_one.within_0_05 > 0.99,
        "segmented one after the other: {one_by_one}"
    );
    // Each alone (what calibration over the wire did before): overlaps get the light twice.
    let alone = segment(&corr[1..], &charts, Some(&mask), &config).expect("second alone");
    let twice = partition(&room, &mask, &truth, |k| {
        let s = if k == 0 { &first } else { &alone };
        (projector_weights(&s.nodes, 0), s.excluded[0].clone())
    });
    println!("each segmented alone: {twice}");
    assert!(twice.within_1e3 < 0.95, "each alone: {twice}");
    // Claims outside [0, 1] or of another size are refused by name.
    let mut bad = first.claims[0].clone();
    bad[7] = f32::NAN;
    let err = segment_beside(&corr[1..], &charts, Some(&mask), &config, Some(&bad))
        .expect_err("NaN claim");
    assert!(err.to_string().contains("claimed shares"), "{err}");
    let err = segment_beside(&corr[1..], &charts, Some(&mask), &config, Some(&bad[1..]))
        .expect_err("short claims");
    assert!(err.to_string().contains("claimed shares"), "{err}");
    // Smooth on the surfaces: between neighbouring camera pixels on the same face, a node's
    // weight changes no faster than the feathering ramps allow over the projector pixels
    // between them (depth edges and the target's black margin are not "neighbours").
    let slope = 1.0 / config.node_feather_px + 1.0 / config.edge_feather_px;
    let cam_w = room.camera().width as usize;
    let info = room.pixels();
    let mut steepest = 0.0f32;
    for n in nodes {
        let pw = room.projectors()[n.projector].pinhole.width as i64;
        let t = &truth[n.projector];
        for i in 0..mask.len() - 1 {
            let j = i + 1;
            if (i + 1) % cam_w == 0 || info[i].face != info[j].face || info[i].face.is_none() {
                continue;
            }
            let (Some(a), Some(b)) = (t[i], t[j]) else {
                continue;
            };
            if seg.excluded[n.projector][a as usize] || seg.excluded[n.projector][b as usize] {
                continue;
            }
            let dist = ((i64::from(a) % pw - i64::from(b) % pw)
                .abs()
                .max((i64::from(a) / pw - i64::from(b) / pw).abs()) as f32)
                .max(1.0);
            let step = (n.weights[a as usize] - n.weights[b as usize]).abs() / dist;
            steepest = steepest.max(step / slope);
        }
    }
    println!("steepest node weight change on a surface: {steepest:.2} × the feathering slope");
    // Measured 8.5: where the decoded map has gaps, the inverse map borrows a neighbour's surface
    // point and the overlap share jumps there (known limitation, see the closing note).
    assert!(
        steepest <= 15.0,
        "a node weight jumps: {steepest} × the ramp slope"
    );
    // The target stays dark: luminaire light on it is at most 1% of what the table beside it gets.
    let frames = full_frames(&room, nodes);
    for (k, frame) in frames.iter().enumerate().take(2) {
        let on_target = room.target_irradiance(k, frame).expect("target")[1];
        let table = room
            .direct_irradiance_at(k, frame, [0.75, 0.62, 0.32], [0.0, 0.0, 1.0])
            .expect("table")[1];
        assert!(table > 0.0, "projector {k} must light the table");
        assert!(
            on_target <= 0.01 * table,
            "projector {k}: target {on_target} vs table {table}"
        );
    }
}

#[test]
fn a_projector_that_lights_no_chart_is_refused() {
    let room = Room::build(small_scene()).expect("room");
    let mut c = decode_projector(&room, 0, Coding::Xor04, &DecodeConfig::default(), 40);
    c.map.iter_mut().for_each(|m| *m = None);
    let err =
        segment(&[c], &chart_corners(&room), None, &NodeConfig::default()).expect_err("no chart");
    assert!(err.to_string().contains("lights no chart"), "{err}");
}

/// A decode speckled with small gaps of unknown pixels (a noisier one, such as groups coded in
/// their primaries) is blended as if it were whole: the gaps are closed before the footprint's
/// edges are ramped (`NodeConfig::gap_close_px`). Left open, each gap was an edge the
/// projector's share ramped down around, and the weights were speckled with it.
#[test]
fn gaps_in_a_decode_are_not_footprint_edges() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    let corr = luminaires(&room);
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let truth: Vec<Vec<Option<u32>>> = (0..2).map(|k| room.true_correspondence(k)).collect();
    // Gaps of 6 × 6 camera pixels every 16 in both decodes.
    let w = corr[0].width as usize;
    let speckled: Vec<Correspondence> = corr
        .iter()
        .map(|c| {
            let mut c = c.clone();
            for (i, m) in c.map.iter_mut().enumerate() {
                if (i % w) % 16 < 6 && (i / w) % 16 < 6 {
                    *m = None;
                }
            }
            c
        })
        .collect();
    let joint = |corr: &[Correspondence], config: &NodeConfig| {
        let seg = segment(corr, &charts, Some(&mask), config).expect("nodes");
        partition(&room, &mask, &truth, |k| {
            (projector_weights(&seg.nodes, k), seg.excluded[k].clone())
        })
    };
    let config = NodeConfig::default();
    let whole = joint(&corr, &config);
    let closed = joint(&speckled, &config);
    let open = joint(
        &speckled,
        &NodeConfig {
            gap_close_px: 2,
            ..config
        },
    );
    println!("whole: {whole}\nspeckled, gaps closed: {closed}\nspeckled, closed over 2 px: {open}");
    assert!(config.gap_close_px >= 3, "a 6-pixel gap must close");
    // Measured (2026-12-07), overlap points within 1e-3 / 0.05: whole 96.10% / 98.74%; gaps
    // closed 92.63% / 96.82% (a gap is still a gap in the inverse map, 14% of the camera's
    // pixels here); closed over 2 pixels only 87.29% / 87.71%.
    assert!(
        closed.overlap_within_0_05 > whole.overlap_within_0_05 - 0.03,
        "whole {whole}, speckled {closed}"
    );
    assert!(
        open.overlap_within_0_05 < closed.overlap_within_0_05 - 0.05
            && open.overlap_within_1e3 < closed.overlap_within_1e3 - 0.03,
        "open gaps {open}, closed {closed}"
    );
}
