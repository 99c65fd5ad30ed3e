//! Light adds: the node-basis fast path equals a full render; captures write and read back.

use roomlight_core::LinearRgb;
use roomlight_sim::room::PngEncoding;
use roomlight_sim::{Frame, NodeBasis, NodeRegion, ProjectorImage, Room, scenes};

/// Two feathered nodes per projector: left and right halves with a linear ramp between them.
fn halves(room: &Room) -> Vec<NodeRegion> {
    let mut nodes = Vec::new();
    for (k, p) in room.projectors().iter().enumerate() {
        let (w, h) = (p.pinhole.width, p.pinhole.height);
        let ramp = |x: u32| ((x as f32 - 0.4 * w as f32) / (0.2 * w as f32)).clamp(0.0, 1.0);
        let right: Vec<f32> = (0..w * h).map(|i| ramp(i % w)).collect();
        let left: Vec<f32> = right.iter().map(|v| 1.0 - v).collect();
        nodes.push(NodeRegion {
            projector: k,
            weights: left,
        });
        nodes.push(NodeRegion {
            projector: k,
            weights: right,
        });
    }
    nodes
}

#[test]
fn node_basis_matches_a_full_render_of_the_same_light() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let preset = Some(room.preset("on").expect("preset"));
    let nodes = halves(&room);
    let basis = NodeBasis::new(&room, &nodes, preset).expect("basis");
    let x: Vec<LinearRgb> = (0..nodes.len())
        .map(|n| LinearRgb([0.2 + 0.1 * n as f64, 0.7, 0.45 - 0.05 * n as f64]))
        .collect();
    // The same light as projector images of linear shares.
    let frames: Vec<Frame> = room
        .projectors()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let pixels = (0..(p.pinhole.width * p.pinhole.height) as usize)
                .map(|i| {
                    let mut v = [0.0f32; 3];
                    for (node, xn) in nodes.iter().zip(&x).filter(|(n, _)| n.projector == k) {
                        for c in 0..3 {
                            v[c] += node.weights[i] * xn[c] as f32;
                        }
                    }
                    v
                })
                .collect();
            Frame::Linear(ProjectorImage {
                width: p.pinhole.width,
                height: p.pinhole.height,
                pixels,
            })
        })
        .collect();
    let full = room.patch_values(&frames, preset).expect("patches");
    let fast = basis.patch_values(&x);
    // Equal up to the radiosity solve's tolerance and its f32 sums (about 1e-5 relative).
    for (a, b) in full.iter().zip(&fast) {
        assert!(
            (*a - *b).max_abs() <= 1e-4 * a.max_abs().max(1e-3),
            "{a:?} vs {b:?}"
        );
    }
    let cap_full = room.render(&frames, preset).expect("render");
    let cap_fast = basis.capture(&x);
    let worst = cap_full
        .pixels
        .iter()
        .zip(&cap_fast.pixels)
        .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "largest pixel difference {worst}");
}

#[test]
fn the_hidden_gamma_shapes_codes_but_not_linear_frames() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let p = &room.projectors()[1]; // gamma [2.0, 2.2, 2.4]
    let half_code = p.light([0.5; 3]);
    let white = p.light([1.0; 3]);
    let black = p.light([0.0; 3]);
    for (c, g) in [2.0, 2.2, 2.4].into_iter().enumerate() {
        let share = (half_code[c] - black[c]) / (white[c] - black[c]);
        assert!(
            (share - 0.5f64.powf(g)).abs() < 1e-6,
            "channel {c}: {share}"
        );
    }
    let linear = p.light_linear([0.5; 3]);
    assert!(((linear[1] - black[1]) / (white[1] - black[1]) - 0.5).abs() < 1e-6);
}

#[test]
fn captures_write_png_in_each_encoding() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let cap = room
        .render(
            &vec![Frame::Uniform([1.0; 3]); room.projectors().len()],
            None,
        )
        .expect("render");
    let dir = tempfile::tempdir().expect("temp dir");
    for enc in [
        PngEncoding::Srgb8,
        PngEncoding::Srgb16,
        PngEncoding::Linear16,
    ] {
        let path = dir.path().join(format!("capture-{}.png", enc.suffix()));
        cap.save_png(&path, enc, 1.0).expect("png written");
        let img = image::open(&path).expect("png reads back");
        assert_eq!((img.width(), img.height()), (cap.width, cap.height));
        if enc == PngEncoding::Linear16 {
            let back = img.to_rgb16();
            let (k, p) = cap
                .pixels
                .iter()
                .enumerate()
                .find(|(_, p)| p[1] > 0.1 && p[1] < 0.9)
                .expect("a mid-grey pixel");
            let v = f32::from(back.as_raw()[3 * k + 1]) / 65535.0;
            assert!((v - p[1]).abs() < 2e-5, "{v} vs {}", p[1]);
        }
    }
}

/// The node captures visited one at a time are those of the stored basis, to the bit.
#[test]
fn visited_node_captures_equal_the_basis_captures() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let nodes = halves(&room);
    let basis = NodeBasis::new(&room, &nodes, None).expect("basis");
    let mut seen = Vec::new();
    NodeBasis::visit_node_captures(&room, &nodes, None, |node, capture| {
        seen.push((node, capture));
        Ok(())
    })
    .expect("visit");
    assert_eq!(seen.len(), nodes.len() + 1);
    for (node, capture) in seen {
        let mut x = vec![LinearRgb::ZERO; nodes.len()];
        if let Some(n) = node {
            x[n] = LinearRgb::ONE;
        }
        assert_eq!(capture, basis.capture(&x), "node {node:?}");
    }
}

/// A render sums every probe's light in one order: one thread and every core give the same
/// capture to the bit, with images on the projectors (their own light tables), the LEDs on and
/// inter-reflection.
#[test]
fn a_render_is_the_same_on_one_thread_and_on_all() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let preset = Some(room.preset("on").expect("preset"));
    let frames = textured(&room);
    let all = room.render(&frames, preset).expect("render");
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("pool")
        .install(|| room.render(&frames, preset))
        .expect("render");
    assert_eq!(all, one);
    assert!(all.pixels.iter().any(|p| p[0] > 0.0));
}

/// A textured image on every projector (its own light table per code).
fn textured(room: &Room) -> Vec<Frame> {
    room.projectors()
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let (w, h) = (p.pinhole.width, p.pinhole.height);
            Frame::Image(ProjectorImage {
                width: w,
                height: h,
                pixels: (0..w * h)
                    .map(|i| {
                        let s = ((i % w) / 8 + (i / w) / 8 + k as u32) % 5;
                        [0.2 * s as f32, 0.5, 1.0 - 0.2 * s as f32]
                    })
                    .collect(),
            })
        })
        .collect()
}

/// Rendering only the chart pixels (and a scattered few) gives each of them the full render's
/// value to the bit, and zero elsewhere; a pixel outside the camera is refused.
#[test]
fn a_subset_render_equals_the_full_render_on_its_pixels() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let preset = Some(room.preset("on").expect("preset"));
    let frames = textured(&room);
    let full = room.render(&frames, preset).expect("render");
    let n = room.pixels().len() as u32;
    let charts = (0..n).filter(|&i| room.pixels()[i as usize].chart.is_some());
    // Repeats and any order are accepted.
    let picked: Vec<u32> = charts.chain((0..n).step_by(97)).chain([5, 5, 0]).collect();
    let subset = room.pixel_subset(picked.iter().copied()).expect("subset");
    assert!(subset.pixels().len() < n as usize / 2, "a real subset");
    let part = room
        .render_subset(&subset, &frames, preset)
        .expect("subset render");
    assert_eq!((part.width, part.height), (full.width, full.height));
    let mut inside = vec![false; n as usize];
    for &p in &picked {
        inside[p as usize] = true;
    }
    let mut lit = 0;
    for (i, (a, b)) in part.pixels.iter().zip(&full.pixels).enumerate() {
        if inside[i] {
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "pixel {i}");
            lit += usize::from(b[1] > 0.0);
        } else {
            assert_eq!(
                a.map(f32::to_bits),
                [0; 3],
                "pixel {i} is not in the subset"
            );
        }
    }
    assert!(lit > 100, "the charts are lit ({lit} pixels)");
    let err = room.pixel_subset([n]).expect_err("outside the camera");
    assert!(err.to_string().contains("camera pixel"), "{err}");
}
