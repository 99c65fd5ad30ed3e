//! The simulator's physics against closed forms: radiosity furnace and reciprocity, inverse
//! square and cosine, inter-reflection, thin-lens blur and penumbra, fisheye, noise, colour.

use roomlight_core::LinearRgb;
use roomlight_sim::optics::cct_to_linear_rgb;
use roomlight_sim::room::{CameraNoise, Capture};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole, ProjectorSpec};
use roomlight_sim::{Frame, ProjectorImage, Room, Scene, scenes};

/// An empty closed room with one projector on the ceiling looking straight down.
fn empty_room(albedo: f64, interreflection: bool) -> Scene {
    let mut scene = scenes::small().expect("small scene");
    scene.objects.clear();
    scene.charts.clear();
    scene.lights.clear();
    scene.presets.clear();
    scene.room.wall_albedo = [albedo; 3];
    scene.room.floor_albedo = [albedo; 3];
    scene.room.ceiling_albedo = [albedo; 3];
    scene.room.interreflection = interreflection;
    scene.camera.resolution = [64, 48];
    scene.projectors = vec![ProjectorSpec {
        name: "down".into(),
        kind: ProjectorKind::Standard,
        role: ProjectorRole::Luminaire,
        position_mm: [800.0, 600.0, 1100.0],
        look_at_mm: [800.0, 600.0, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_deg: 40.0,
        resolution: [200, 200],
        black_level: 0.0,
        peak: [1.0; 3],
        gamma: [1.0; 3],
        mixing: None,
        aperture_mm: None,
        focus_mm: None,
        lens_samples: None,
    }];
    scene
}

#[test]
fn furnace_closed_white_box_reaches_rho_e_over_one_minus_rho() {
    let room = Room::build(empty_room(0.8, true)).expect("room");
    let r = room.radiosity().expect("radiosity on");
    let e = 0.3;
    let direct = vec![LinearRgb::splat(e); r.len()];
    let solution = r.solve(&direct, 1e-7);
    let expected = 0.8 * e / (1.0 - 0.8);
    for b in &solution.radiosity {
        assert!(
            (b[0] - expected).abs() < 2e-3 * expected,
            "B = {}, expected {expected}",
            b[0]
        );
    }
}

#[test]
fn form_factors_are_reciprocal_and_closed() {
    let room = Room::build(empty_room(0.5, true)).expect("room");
    let r = room.radiosity().expect("radiosity on");
    let a = r.areas();
    for i in 0..r.len() {
        let row: f32 = (0..r.len()).map(|j| r.form_factor(i, j)).sum();
        assert!((row - 1.0).abs() < 1e-3, "row {i} sums to {row}");
        for j in 0..r.len() {
            let (x, y) = (a[i] * r.form_factor(i, j), a[j] * r.form_factor(j, i));
            assert!(
                (x - y).abs() <= 1e-5 * x.max(y) + 1e-9,
                "A_i F_ij = {x}, A_j F_ji = {y}"
            );
        }
    }
}

#[test]
fn projector_light_follows_inverse_square_and_cosine() {
    let room = Room::build(empty_room(0.5, false)).expect("room");
    let white = Frame::Uniform([1.0; 3]);
    let up = [0.0, 0.0, 1.0];
    // On the floor, 1.1 m below the lens, facing it: peak / D², uniformly across the frame
    // (the pixel solid angle shrinks off-axis as cos³ α).
    let on_axis = room
        .direct_irradiance_at(0, &white, [0.8, 0.6, 0.0], up)
        .expect("irradiance")[0];
    assert!((on_axis - 1.0 / 1.1f64.powi(2)).abs() < 1e-4, "{on_axis}");
    let off_axis = room
        .direct_irradiance_at(0, &white, [0.95, 0.7, 0.0], up)
        .expect("irradiance")[0];
    assert!(
        (off_axis - on_axis).abs() < 1e-4 * on_axis,
        "{off_axis} vs {on_axis}"
    );
    // Twice as far along the same ray (a plane 2.2 m away would be outside the room, so compare
    // a point halfway up): four times brighter.
    let half = room
        .direct_irradiance_at(0, &white, [0.8, 0.6, 0.55], up)
        .expect("irradiance")[0];
    assert!((half / on_axis - 4.0).abs() < 1e-3, "{}", half / on_axis);
    // A surface tilted by 60° gets cos 60° = half.
    let tilted = [0.0, (60f32).to_radians().sin(), (60f32).to_radians().cos()];
    let e = room
        .direct_irradiance_at(0, &white, [0.8, 0.6, 0.0], tilted)
        .expect("irradiance")[0];
    assert!((e / on_axis - 0.5).abs() < 1e-3, "{}", e / on_axis);
    // Outside the frustum: nothing.
    let outside = room
        .direct_irradiance_at(0, &white, [0.1, 0.1, 0.0], up)
        .expect("irradiance")[0];
    assert!(outside.abs() < 1e-12);
}

#[test]
fn interreflection_reaches_outside_the_frustum_and_switching_it_off_removes_exactly_that() {
    let on = Room::build(scenes::small().expect("scene")).expect("room");
    let mut scene = scenes::small().expect("scene");
    scene.room.interreflection = false;
    let off = Room::build(scene).expect("room");
    let n = on.projectors().len();
    let mut frames = vec![Frame::Black; n];
    frames[0] = Frame::Uniform([1.0; 3]);
    let with = on.patch_values(&frames, None).expect("patches");
    let without = off.patch_values(&frames, None).expect("patches");
    let black = on
        .patch_values(&vec![Frame::Black; n], None)
        .expect("patches");
    let black_off = off
        .patch_values(&vec![Frame::Black; n], None)
        .expect("patches");
    let mut outside_seen = 0;
    for (k, ((w, wo), (b, bo))) in with
        .iter()
        .zip(&without)
        .zip(black.iter().zip(&black_off))
        .enumerate()
    {
        // Direct light is the same with and without inter-reflection; indirect only adds.
        assert!(w[1] >= wo[1] - 1e-12, "patch {k}");
        let lit_directly = (*wo - *bo).max_abs() > 1e-9;
        if !lit_directly {
            outside_seen += 1;
            assert!(
                (*w - *b).max_abs() > 1e-6,
                "patch {k} outside the frustum gets no indirect light"
            );
        }
    }
    assert!(
        outside_seen > 0,
        "some patch must lie outside the projector's frustum"
    );
    // Rendered captures agree: off equals on minus the indirect part, which is nonnegative.
    let cap_on = on.render(&frames, None).expect("render");
    let cap_off = off.render(&frames, None).expect("render");
    assert!(
        cap_on
            .pixels
            .iter()
            .zip(&cap_off.pixels)
            .all(|(a, b)| a[0] >= b[0] - 1e-6)
    );
    assert!(
        cap_on
            .pixels
            .iter()
            .zip(&cap_off.pixels)
            .any(|(a, b)| a[0] > b[0] + 1e-4)
    );
}

/// A room with a large-aperture projector 1.5 m above the floor, focused at `focus_mm`.
fn lens_room(aperture_mm: f64, focus_mm: f64, kind: ProjectorKind) -> Room {
    let mut scene = empty_room(0.5, false);
    scene.room.size_mm = [3000.0, 3000.0, 2000.0];
    scene.camera.position_mm = [1500.0, 30.0, 1500.0];
    scene.camera.look_at_mm = [1500.0, 3000.0, 500.0];
    let p = &mut scene.projectors[0];
    p.kind = kind;
    p.position_mm = [1500.0, 1500.0, 1500.0];
    p.look_at_mm = [1500.0, 1500.0, 0.0];
    p.fov_deg = 30.0;
    p.resolution = [400, 400];
    p.aperture_mm = Some(aperture_mm);
    p.focus_mm = Some(focus_mm);
    p.lens_samples = Some(256);
    Room::build(scene).expect("room")
}

/// The 10–90% width (m) of the edge of a half-white image along x on the floor.
fn edge_width(room: &Room) -> f64 {
    let pixels = (0..400 * 400)
        .map(|i| if i % 400 < 200 { [1.0f32; 3] } else { [0.0; 3] })
        .collect();
    let frame = Frame::Image(ProjectorImage {
        width: 400,
        height: 400,
        pixels,
    });
    let xs: Vec<f64> = (0..600).map(|k| 1.3 + 0.4 * k as f64 / 599.0).collect();
    let e: Vec<f64> = xs
        .iter()
        .map(|&x| {
            room.direct_irradiance_at(0, &frame, [x as f32, 1.5, 0.0], [0.0, 0.0, 1.0])
                .expect("irradiance")[0]
        })
        .collect();
    let max = e.iter().copied().fold(0.0, f64::max);
    let at = |level: f64| xs[e.iter().rposition(|&v| v >= level * max).unwrap_or(0)];
    (at(0.1) - at(0.9)).abs()
}

/// 10–90% width of the edge response of a uniform disk of diameter `c`.
fn disk_edge_width(c: f64) -> f64 {
    // Share of a unit-radius disk beyond a chord at distance x from the centre.
    let beyond = |x: f64| {
        ((x.clamp(-1.0, 1.0)).acos() - x * (1.0 - x * x).max(0.0).sqrt()) / std::f64::consts::PI
    };
    let solve = |level: f64| {
        let (mut lo, mut hi) = (-1.0, 1.0);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if beyond(mid) > level {
                lo = mid
            } else {
                hi = mid
            }
        }
        0.5 * (lo + hi)
    };
    (solve(0.1) - solve(0.9)).abs() * c / 2.0
}

#[test]
fn defocus_blur_grows_with_aperture_and_distance_as_thin_lens_geometry_predicts() {
    // Focused at 1.0 m; the floor is at 1.5 m: blur circle c = A·|z − F|/F on the focus plane,
    // magnified by z/F onto the floor: c_floor = A·(z − F)/F · (z/F)... measured along the floor
    // the blur is the lens disk seen through the focus point: A·(z − F)/F.
    for (aperture, focus) in [(100.0, 1000.0), (200.0, 1000.0), (200.0, 1250.0)] {
        let room = lens_room(aperture, focus, ProjectorKind::LargeAperture);
        let (a, f, z) = (aperture / 1000.0, focus / 1000.0, 1.5);
        let predicted = disk_edge_width(a * (z - f) / f);
        let measured = edge_width(&room);
        assert!(
            (measured / predicted - 1.0).abs() < 0.15,
            "A={aperture} F={focus}: measured {measured}, predicted {predicted}"
        );
    }
    // In focus, and for a standard projector, the edge is sharp: about a pixel's footprint.
    let pixel = 2.0 * 1.5 * (15f64).to_radians().tan() / 400.0;
    assert!(edge_width(&lens_room(200.0, 1500.0, ProjectorKind::LargeAperture)) < 3.0 * pixel);
    assert!(edge_width(&lens_room(200.0, 1000.0, ProjectorKind::Standard)) < 3.0 * pixel);
}

#[test]
fn occluder_penumbra_grows_with_the_aperture_and_a_standard_projector_casts_a_hard_shadow() {
    // A 200 mm board 0.5 m above the floor under the lens (1.5 m up): a disk source of diameter A
    // at 1.0 m from the board casts a penumbra of width A·(1.5 − 1.0)/1.0 on the floor.
    let shadow = |aperture: f64, kind: ProjectorKind| {
        let mut scene = empty_room(0.5, false);
        scene.room.size_mm = [3000.0, 3000.0, 2000.0];
        scene.camera.position_mm = [1500.0, 30.0, 1500.0];
        scene.camera.look_at_mm = [1500.0, 3000.0, 500.0];
        let p = &mut scene.projectors[0];
        p.kind = kind;
        p.position_mm = [1500.0, 1500.0, 1500.0];
        p.look_at_mm = [1500.0, 1500.0, 0.0];
        p.fov_deg = 40.0;
        p.aperture_mm = Some(aperture);
        p.focus_mm = Some(1500.0);
        p.lens_samples = Some(256);
        scene.objects.push(roomlight_sim::scene::ObjectSpec {
            name: "board".into(),
            shape: roomlight_sim::scene::ShapeKind::Box,
            center_mm: [1400.0, 1500.0, 500.0],
            size_mm: Some([200.0, 600.0, 10.0]),
            radius_mm: None,
            height_mm: None,
            yaw_deg: 0.0,
            albedo: [0.5; 3],
            target: false,
        });
        let room = Room::build(scene).expect("room");
        let xs: Vec<f64> = (0..500).map(|k| 1.35 + 0.3 * k as f64 / 499.0).collect();
        let e: Vec<f64> = xs
            .iter()
            .map(|&x| {
                room.direct_irradiance_at(
                    0,
                    &Frame::Uniform([1.0; 3]),
                    [x as f32, 1.5, 0.0],
                    [0.0, 0.0, 1.0],
                )
                .expect("irradiance")[0]
            })
            .collect();
        let max = e.iter().copied().fold(0.0, f64::max);
        // The board's right edge is at x = 1.5; its shadow edge on the floor runs from umbra to
        // full light: 10–90% width.
        let first = |level: f64| xs[e.iter().position(|&v| v >= level * max).unwrap_or(0)];
        first(0.9) - first(0.1)
    };
    let narrow = shadow(100.0, ProjectorKind::LargeAperture);
    let wide = shadow(300.0, ProjectorKind::LargeAperture);
    let hard = shadow(300.0, ProjectorKind::Standard);
    for (a, w) in [(0.1, narrow), (0.3, wide)] {
        let predicted = disk_edge_width(a * 0.5 / 1.0);
        assert!(
            (w / predicted - 1.0).abs() < 0.2,
            "aperture {a}: penumbra {w}, predicted {predicted}"
        );
    }
    assert!(hard < 0.005, "standard projector penumbra {hard}");
}

#[test]
fn fisheye_projection_round_trips() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let cam = room.camera();
    let mut checked = 0;
    for v in (0..cam.height).step_by(7) {
        for u in (0..cam.width).step_by(7) {
            let (fu, fv) = (u as f32 + 0.5, v as f32 + 0.5);
            if let Some(d) = cam.ray(fu, fv) {
                let (pu, pv) = cam.project(cam.position + d * 2.0).expect("in view");
                assert!(
                    (pu - fu).abs() < 2e-3 && (pv - fv).abs() < 2e-3,
                    "({fu},{fv}) -> ({pu},{pv})"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 500);
}

#[test]
fn camera_noise_has_the_configured_statistics_and_saturation_clips() {
    let mut scene = scenes::small().expect("scene");
    scene.camera.read_noise = 0.01;
    scene.camera.shot_noise = 0.05;
    scene.camera.saturation = 0.9;
    let room = Room::build(scene).expect("room");
    let mut noise = CameraNoise::new(&room);
    let n = 200_000;
    let level = 0.4f32;
    let flat = Capture {
        width: n as u32,
        height: 1,
        pixels: vec![[level; 3]; n],
    };
    let noisy = noise.expose(&flat);
    let values: Vec<f64> = noisy.pixels.iter().map(|p| f64::from(p[1])).collect();
    let mean = values.iter().sum::<f64>() / n as f64;
    let sd = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let expected = (0.05f64.powi(2) * 0.4 + 0.01f64.powi(2)).sqrt();
    assert!(
        (mean - 0.4).abs() < 3.0 * expected / (n as f64).sqrt() + 1e-6,
        "mean {mean}"
    );
    assert!(
        (sd / expected - 1.0).abs() < 0.01,
        "sd {sd}, expected {expected}"
    );
    let bright = Capture {
        width: 4,
        height: 1,
        pixels: vec![[2.0; 3]; 4],
    };
    assert!(
        noise
            .expose(&bright)
            .pixels
            .iter()
            .flatten()
            .all(|&v| (v - 0.9).abs() < 1e-6)
    );
    // Same seed, same noise.
    let again = CameraNoise::new(&room).expose(&flat);
    assert_eq!(again.pixels[..100], noisy.pixels[..100]);
}

#[test]
fn colour_temperatures_give_the_expected_whites() {
    // A 6504 K blackbody is near D65 (sRGB white), which lies slightly off the Planckian locus
    // (Δuv ≈ 0.003): within 8% per channel.
    let d65 = cct_to_linear_rgb(6504.0);
    assert!(
        (d65[0] / d65[1] - 1.0).abs() < 0.08 && (d65[2] / d65[1] - 1.0).abs() < 0.08,
        "{d65:?}"
    );
    let luminance = 0.2126 * d65[0] + 0.7152 * d65[1] + 0.0722 * d65[2];
    assert!((luminance - 1.0).abs() < 0.01, "luminance {luminance}");
    let warm = cct_to_linear_rgb(2700.0);
    assert!(warm[0] > warm[1] && warm[1] > warm[2], "{warm:?}");
    let cool = cct_to_linear_rgb(10000.0);
    assert!(cool[2] > cool[1] && cool[1] > cool[0], "{cool:?}");
}

#[test]
fn the_true_correspondence_points_at_the_pixels_that_light_the_camera_pixel() {
    let room = Room::build(scenes::small().expect("scene")).expect("room");
    let n = room.projectors().len();
    let corr = room.true_correspondence(0);
    let (w, h) = (320u32, 240u32);
    // Light one block of the projector and check that camera pixels mapped into it are bright.
    let inside = |px: u32| (100..140).contains(&(px % w)) && (80..120).contains(&(px / w));
    let pixels = (0..w * h)
        .map(|px| if inside(px) { [1.0; 3] } else { [0.0; 3] })
        .collect();
    let mut frames = vec![Frame::Black; n];
    frames[0] = Frame::Image(ProjectorImage {
        width: w,
        height: h,
        pixels,
    });
    let mut scene = scenes::small().expect("scene");
    scene.room.interreflection = false;
    let direct_only = Room::build(scene).expect("room");
    let cap = direct_only.render(&frames, None).expect("render");
    let black = direct_only
        .render(&vec![Frame::Black; n], None)
        .expect("render");
    let (mut lit, mut dark) = (0, 0);
    for ((c, p), b) in corr.iter().zip(&cap.pixels).zip(&black.pixels) {
        let Some(px) = c else { continue };
        let gain = p[1] - b[1];
        // Skip the block's border, where a camera pixel straddles lit and unlit projector pixels.
        let deep = (102..138).contains(&(px % w)) && (82..118).contains(&(px / w));
        let far = !((95..145).contains(&(px % w)) && (75..125).contains(&(px / w)));
        if deep {
            assert!(gain > 1e-3, "pixel mapped into the block is dark");
            lit += 1;
        } else if far {
            assert!(gain < 1e-6, "pixel mapped outside the block is lit: {gain}");
            dark += 1;
        }
    }
    assert!(lit > 20 && dark > 1000, "lit {lit}, dark {dark}");
    let _ = room
        .target_irradiance(0, &Frame::Uniform([1.0; 3]))
        .expect("target irradiance");
}

#[test]
fn radiosity_elements_integrate_fine_stripes_and_keep_coarse_ones() {
    // A real wall integrates a projector's light over its surface: one-pixel stripes reach a
    // radiosity element as their mean, whatever sample points the element has. (Sampling the
    // frame at 3×3 points per element aliased such stripes into each element's light: its
    // inter-reflected light then carried a code of its own.)
    let room = Room::build(empty_room(0.5, true)).expect("room");
    let (w, h) = (200u32, 200u32);
    let frame = |on: &dyn Fn(u32, u32) -> bool| {
        vec![Frame::Image(ProjectorImage {
            width: w,
            height: h,
            pixels: (0..w * h)
                .map(|i| [f32::from(u8::from(on(i % w, i / w))); 3])
                .collect(),
        })]
    };
    let white = room
        .element_irradiance(&[Frame::Uniform([1.0; 3])], None)
        .expect("white");
    let peak = white.iter().map(|e| e[1]).fold(0.0, f64::max);
    let lit: Vec<usize> = (0..white.len())
        .filter(|&i| white[i][1] > 0.05 * peak)
        .collect();
    assert!(lit.len() > 10, "{} elements lit", lit.len());
    for (name, on) in [
        (
            "columns",
            &(|x: u32, _: u32| x.is_multiple_of(2)) as &dyn Fn(u32, u32) -> bool,
        ),
        ("rows", &|_: u32, y: u32| y.is_multiple_of(2)),
    ] {
        let e = room.element_irradiance(&frame(on), None).expect("stripes");
        let mut dev: Vec<f64> = lit
            .iter()
            .map(|&i| (e[i][1] / white[i][1] - 0.5).abs())
            .collect();
        dev.sort_by(f64::total_cmp);
        let (median, worst) = (dev[dev.len() / 2], dev[dev.len() - 1]);
        println!("{name}: share of white per element − 0.5: median {median:.4}, worst {worst:.4}");
        assert!(median < 0.01 && worst < 0.05, "{name}: {median} / {worst}");
    }
    // The left half of the frame lit: elements lit only from the left half keep their full
    // light, the ones lit only from the right get none, the ones across the edge between.
    let e = room
        .element_irradiance(&frame(&|x: u32, _: u32| x < w / 2), None)
        .expect("half");
    let shares: Vec<f64> = lit.iter().map(|&i| e[i][1] / white[i][1]).collect();
    let full = shares.iter().filter(|s| (**s - 1.0).abs() < 1e-6).count();
    let none = shares.iter().filter(|s| s.abs() < 1e-6).count();
    assert!(
        full > lit.len() / 4 && none > lit.len() / 4,
        "{full} full, {none} dark of {}",
        lit.len()
    );
    let (lo, hi) = shares
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), s| (a.min(*s), b.max(*s)));
    // The white sums its factors in f32: a rounding above 1.
    assert!(lo >= -1e-6 && hi <= 1.0 + 1e-6, "shares {lo} to {hi}");
}
