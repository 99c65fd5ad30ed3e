//! Nodes and feathering on the small simulated room, decoded from its own structured light.

mod common;

use common::{chart_corners, decode_projector, small_scene};
use roomlight_calib::graycode::{Coding, Correspondence, DecodeConfig};
use roomlight_calib::nodes::{Node, NodeConfig, segment};
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

#[test]
fn nodes_partition_the_light_feather_smoothly_and_keep_the_target_dark() {
    let room = Room::build(small_scene()).expect("room");
    let charts = chart_corners(&room);
    // The two standard luminaires (the large aperture is handled by its cone mask).
    let corr: Vec<Correspondence> = (0..2)
        .map(|k| {
            decode_projector(
                &room,
                k,
                Coding::Xor04,
                &DecodeConfig::default(),
                40 + k as u64,
            )
        })
        .collect();
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
    let near_target = roomlight_calib::nodes::dilate(
        &mask,
        room.camera().width as usize,
        room.camera().height as usize,
        8,
    );
    let (mut checked, mut worst_single, mut worst_overlap) = (0, 0.0f32, 0.0f32);
    let (mut within_tight, mut within_loose) = (0usize, 0usize);
    for i in 0..mask.len() {
        if near_target[i] {
            continue;
        }
        let reaching: Vec<(usize, u32)> =
            (0..2).filter_map(|k| truth[k][i].map(|p| (k, p))).collect();
        // Points behind the target's silhouette, lit through the excluded margin, stay dark.
        if reaching.is_empty() || reaching.iter().any(|&(k, p)| seg.excluded[k][p as usize]) {
            continue;
        }
        let sum: f32 = reaching
            .iter()
            .map(|&(k, p)| {
                nodes
                    .iter()
                    .filter(|n| n.projector == k)
                    .map(|n| n.weights[p as usize])
                    .sum::<f32>()
            })
            .sum();
        within_tight += usize::from((sum - 1.0).abs() <= 1e-3);
        within_loose += usize::from((sum - 1.0).abs() <= 0.05);
        if reaching.len() == 1 {
            worst_single = worst_single.max((sum - 1.0).abs());
        } else {
            worst_overlap = worst_overlap.max((sum - 1.0).abs());
        }
        checked += 1;
    }
    let (tight, loose) = (
        within_tight as f64 / checked as f64,
        within_loose as f64 / checked as f64,
    );
    println!(
        "partition of unity on {checked} surface points: {:.2}% within 1e-3, {:.2}% within 0.05; worst {worst_single:.3} where one projector reaches, {worst_overlap:.3} in overlaps",
        100.0 * tight,
        100.0 * loose
    );
    assert!(checked > 1000);
    // Exact inside one projector; across overlaps the shares come from decoded maps, whose gaps
    // (unknown pixels) leave a few points off.
    assert!(
        tight > 0.95 && loose > 0.99,
        "within 1e-3: {tight}, within 0.05: {loose}"
    );
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
