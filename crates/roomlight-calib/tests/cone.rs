//! The large aperture's cone mask keeps the target dark; the ring it darkens is handed to the
//! texture projector.

mod common;

use common::{decode_projector, small_scene};
use roomlight_calib::cone::{Sphere, ThinLens, cone_mask, ring_node};
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
    let node = ring_node(&large, &mask, &target, &tex, texture, 0, 2).expect("ring node");
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
}
