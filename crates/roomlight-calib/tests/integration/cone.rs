//! The large aperture's cone mask keeps the target dark; the ring it darkens is handed to the
//! texture projector.

use crate::common;

use common::{decode_projector, small_scene};
use roomlight_calib::cone::{Sphere, ThinLens, cone_mask, ring_node, shape_ring};
use roomlight_calib::graycode::{Coding, DecodeConfig};
use roomlight_sim::{Frame, ProjectorImage, Room};

#[test]
fn the_cone_mask_keeps_the_target_dark_and_the_ring_goes_to_the_texture_projector() {
    let scene = small_scene();
    let room = Room::build(scene.clone()).expect("room");
    let area = room.projector("area").expect("area");
    let texture = room.projector("texture").expect("texture");
    let spec = &scene.projectors[area];
    let lens = ThinLens {
        position_mm: spec.position_mm,
        look_at_mm: spec.look_at_mm,
        up: spec.up,
        fov_deg: spec.fov_deg,
        resolution: spec.resolution,
        aperture_mm: spec.aperture_mm.expect("aperture"),
        focus_mm: spec.focus_mm.expect("focus"),
    };
    // The target's bounding sphere, from the room config.
    let t = scene.objects.iter().find(|o| o.target).expect("a target");
    let sphere = Sphere {
        center_mm: t.center_mm,
        radius_mm: t.radius_mm.expect("radius"),
    };
    let mask = cone_mask(&lens, &sphere, 10.0).expect("mask");
    // A pinhole mask (chief rays only) would miss the rim of the cones: the cone mask is larger.
    let chief = cone_mask(
        &ThinLens {
            aperture_mm: 0.0,
            ..lens.clone()
        },
        &sphere,
        10.0,
    )
    .expect("mask");
    let (n_cone, n_chief) = (
        mask.iter().filter(|m| **m).count(),
        chief.iter().filter(|m| **m).count(),
    );
    assert!(
        chief.iter().zip(&mask).all(|(c, m)| !c || *m),
        "the cone mask contains the chief-ray mask"
    );
    assert!(
        n_chief > 0 && n_cone > n_chief + n_chief / 10,
        "cone {n_cone} vs chief rays {n_chief}"
    );
    // Light on the target: with the chief-ray mask some still reaches it through the lens rim;
    // with the cone mask at most 1% of what the table next to it gets.
    let (w, h) = (spec.resolution[0], spec.resolution[1]);
    let frame = |m: &[bool]| {
        Frame::Linear(ProjectorImage {
            width: w,
            height: h,
            pixels: m
                .iter()
                .map(|&off| if off { [0.0; 3] } else { [1.0; 3] })
                .collect(),
        })
    };
    let table = room
        .direct_irradiance_at(area, &frame(&mask), [0.75, 0.62, 0.32], [0.0, 0.0, 1.0])
        .expect("table")[1];
    let on_target = room.target_irradiance(area, &frame(&mask)).expect("target")[1];
    let leak = room
        .target_irradiance(area, &frame(&chief))
        .expect("target")[1];
    println!(
        "large aperture on the target: {on_target:.2e} with the cone mask, {leak:.2e} with chief rays only, table {table:.2e}"
    );
    assert!(
        on_target <= 0.01 * table,
        "target {on_target} vs table {table}"
    );
    assert!(
        leak > on_target,
        "the chief-ray mask should leak more than the cone mask"
    );
    // The ring: camera pixels the area projector lights through masked pixels, off the target.
    let large = decode_projector(&room, area, Coding::Gray, &DecodeConfig::strict(), 70);
    let tex = decode_projector(&room, texture, Coding::Xor04, &DecodeConfig::default(), 71);
    let target: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let mut node = ring_node(&large, &mask, &target, &tex, texture, 0, 2).expect("ring node");
    let truth = room.true_correspondence(texture);
    let (mut ring, mut covered) = (0, 0);
    for i in 0..target.len() {
        if let (Some((x, y)), false) = (large.map[i], target[i])
            && mask[(y * w + x) as usize]
            && let Some(p) = truth[i]
        {
            ring += 1;
            covered += usize::from(node.weights[p as usize] > 0.0);
        }
    }
    println!(
        "ring: {ring} camera pixels the texture projector reaches, {covered} covered by its ring node"
    );
    assert!(
        ring > 20 && covered as f64 >= 0.9 * ring as f64,
        "ring {ring}, covered {covered}"
    );
    // The ring is lit again: the area projector without the cone mask is the reference level
    // there; with the mask, the texture projector's ring node at one level x fills it in.
    // x is fitted on the ring's mean; the check is that the whole ring comes back evenly.
    let (tw, th) = (
        room.projectors()[texture].pinhole.width,
        room.projectors()[texture].pinhole.height,
    );
    let n = room.projectors().len();
    let unmasked = vec![false; mask.len()];
    // The area projector (cone-masked or not) and the texture projector's ring node at level x.
    let render = |masked: bool, weights: &[f32], x: f32| {
        let mut frames = vec![Frame::Black; n];
        frames[area] = frame(if masked { &mask } else { &unmasked });
        frames[texture] = Frame::Linear(ProjectorImage {
            width: tw,
            height: th,
            pixels: weights.iter().map(|&w| [w * x; 3]).collect(),
        });
        room.render(&frames, None).expect("render")
    };
    let ring_pixels: Vec<usize> = (0..target.len())
        .filter(|&i| {
            large.map[i].is_some_and(|(x, y)| mask[(y * w + x) as usize])
                && !target[i]
                && truth[i].is_some_and(|p| node.weights[p as usize] > 0.0)
        })
        .collect();
    let mean = |c: &roomlight_sim::Capture| {
        ring_pixels
            .iter()
            .map(|&i| f64::from(c.pixels[i][1]))
            .sum::<f64>()
            / ring_pixels.len() as f64
    };
    let reference = render(false, &node.weights, 0.0);
    let dark = render(true, &node.weights, 0.0);
    // Shape the ring node from two measurements: the light the mask removed, and the texture
    // projector's own light (its ring node at white over black).
    let missing: Vec<f32> = reference
        .pixels
        .iter()
        .zip(&dark.pixels)
        .map(|(a, b)| a[1] - b[1])
        .collect();
    let full_binary = render(true, &node.weights, 1.0);
    let gain: Vec<f32> = full_binary
        .pixels
        .iter()
        .zip(&dark.pixels)
        .map(|(a, b)| a[1] - b[1])
        .collect();
    shape_ring(&mut node, &tex, &missing, &gain).expect("shaped");
    let full = render(true, &node.weights, 1.0);
    let (want, base, gain) = (mean(&reference), mean(&dark), mean(&full) - mean(&dark));
    assert!(
        base < 0.9 * want,
        "the cone mask must darken the ring: {base} vs {want}"
    );
    let x = ((want - base) / gain).clamp(0.0, 1.0) as f32;
    let relit = render(true, &node.weights, x);
    let within = ring_pixels
        .iter()
        .filter(|&&i| {
            (f64::from(relit.pixels[i][1]) / f64::from(reference.pixels[i][1]) - 1.0).abs() <= 0.1
        })
        .count();
    let share = within as f64 / ring_pixels.len() as f64;
    println!(
        "ring relit with x = {x:.3}: {:.0}% of its pixels within 10% of the unmasked light (mean {:.4} vs {:.4})",
        100.0 * share,
        mean(&relit),
        want
    );
    assert!(
        (mean(&relit) / want - 1.0).abs() <= 0.1,
        "ring mean {} vs {want}",
        mean(&relit)
    );
    assert!(share >= 0.8, "only {share} of the ring within 10%");
}
