//! Scene files: the embedded rooms build; each kind of mistake is refused with a message that
//! names the element, the field and what was expected.

use roomlight_sim::scenes::{self, HardCase, LAB_TOML, SMALL_TOML};
use roomlight_sim::{Room, Scene, SimError};

fn error_of(text: &str) -> String {
    match Scene::from_toml(text, "test.toml").and_then(|s| {
        roomlight_sim::geometry::Geometry::build(&s)?;
        Ok(s)
    }) {
        Ok(_) => panic!("the scene was accepted"),
        Err(e) => e.to_string(),
    }
}

fn edited(from: &str, to: &str) -> String {
    assert!(SMALL_TOML.contains(from), "test edit {from:?} not found");
    SMALL_TOML.replacen(from, to, 1)
}

#[test]
fn embedded_scenes_parse_and_the_small_room_builds() {
    let lab = scenes::lab().expect("lab");
    assert_eq!(lab.charts.len(), 12);
    assert_eq!(lab.presets.len(), 5);
    let paper = lab
        .presets
        .iter()
        .find(|p| p.name == "paper")
        .expect("paper preset");
    assert!((paper.intensity - 0.14).abs() < 1e-12);
    let luminaires = lab
        .projectors
        .iter()
        .filter(|p| p.role == roomlight_sim::scene::ProjectorRole::Luminaire)
        .count();
    assert_eq!(
        luminaires, 6,
        "five standard luminaires and the large-aperture one"
    );
    roomlight_sim::geometry::Geometry::build(&lab).expect("lab geometry");
    for case in HardCase::ALL {
        let scene = scenes::hard_case(case).expect("hard case");
        roomlight_sim::geometry::Geometry::build(&scene)
            .unwrap_or_else(|e| panic!("{}: {e}", case.name()));
        // The same cases fit the small test room (the quick benchmark runs them there).
        let small = scenes::hard_case_of(scenes::small().expect("small"), case)
            .unwrap_or_else(|e| panic!("small {}: {e}", case.name()));
        roomlight_sim::geometry::Geometry::build(&small)
            .unwrap_or_else(|e| panic!("small {}: {e}", case.name()));
        assert_eq!(small.name, format!("small-{}", case.name()));
    }
    let bright = scenes::hard_case(HardCase::BrightTarget).expect("bright");
    for (a, b) in bright.lights.iter().zip(&lab.lights) {
        assert!(
            (a.intensity - 4.0 * b.intensity).abs() < 1e-12,
            "light {}",
            a.name
        );
    }
    let room = Room::build(scenes::small().expect("small")).expect("small room");
    assert_eq!(room.patches(), 48);
    assert!(LAB_TOML.contains("large_aperture"));
}

#[test]
fn each_kind_of_mistake_is_refused_with_the_right_message() {
    let cases: Vec<(String, &[&str])> = vec![
        (
            edited(
                "position_mm = [100, 300, 1100]",
                "position_mm = [-100, 300, 1100]",
            ),
            &["projector left", "not inside the room"],
        ),
        (
            edited(
                "position_mm = [100, 300, 1100]",
                "position_mm = [900, 700, 400]",
            ),
            &["projector left", "inside object target"],
        ),
        (
            edited(
                "center_mm = [600, 1200, 700]",
                "center_mm = [600, 1000, 700]",
            ),
            &["chart back", "does not lie on any surface"],
        ),
        (
            edited("albedo = [0.6, 0.5, 0.4]", "albedo = [-0.1, 0.5, 0.4]"),
            &["object table", "albedo", "[0, 1]"],
        ),
        (
            edited("size_mm = [400, 400]", "size_mm = [0, 400]"),
            &["light ceiling", "size_mm", "> 0"],
        ),
        (
            edited("lights = [\"ceiling\"]", "lights = [\"floor\"]"),
            &["preset on", "\"floor\"", "no light"],
        ),
        (
            edited("fov_deg = 75", "fov_deg = 75\nzoom = 2"),
            &["test.toml", "zoom"],
        ),
        (
            edited("name = \"right\"", "name = \"left\""),
            &["projector left", "used twice"],
        ),
        (
            edited("cct_k = 4000", "cct_k = 400"),
            &["light ceiling", "cct_k"],
        ),
        (
            edited(
                "lights = [\"ceiling\"]",
                "lights = [\"ceiling\"]\nintensity = 0.0",
            ),
            &["preset on", "intensity", "finite scale > 0"],
        ),
        (
            edited(
                "lights = [\"ceiling\"]",
                "lights = [\"ceiling\"]\nintensity = -2.0",
            ),
            &["preset on", "intensity", "> 0"],
        ),
        (
            edited(
                "lights = [\"ceiling\"]",
                "lights = [\"ceiling\"]\nintensity = nan",
            ),
            &["preset on", "intensity"],
        ),
        (
            edited("gamma = [2.0, 2.2, 2.4]", "gamma = [2.0, 0.0, 2.4]"),
            &["projector right", "gamma"],
        ),
        (
            edited("resolution = [320, 240]", "resolution = [0, 240]"),
            &["projector left", "resolution"],
        ),
        (
            edited("aperture_mm = 200\n", ""),
            &["projector area", "aperture_mm"],
        ),
        (
            edited("exposure = 6.0", "exposure = 0.0"),
            &["camera", "exposure"],
        ),
        (
            edited("element_mm = 200", "element_mm = 2"),
            &["room", "element_mm"],
        ),
        (
            edited(
                "up = [0, 0, 1]\nwidth_mm = 300",
                "up = [0, -1, 0]\nwidth_mm = 300",
            ),
            &["chart back", "not perpendicular"],
        ),
        (
            edited("size_mm = [500, 400, 40]", "size_mm = [500, 400]"),
            &["test.toml"],
        ),
    ];
    for (text, expected) in cases {
        let message = error_of(&text);
        for e in expected {
            assert!(message.contains(e), "message {message:?} lacks {e:?}");
        }
    }
}

/// A preset's intensity scales its LEDs' light linearly: the render with the lights at a scale
/// minus the dark room is that scale times the render at 1 minus the dark room, on every patch
/// and pixel (direct light and inter-reflection alike).
#[test]
fn a_presets_intensity_scales_its_light_linearly() {
    let text = edited(
        "lights = [\"ceiling\"]",
        "lights = [\"ceiling\"]\n\n[[preset]]\nname = \"dim\"\nlights = [\"ceiling\"]\nintensity = 0.15",
    );
    let scene = Scene::from_toml(&text, "test.toml").expect("scene");
    assert!(
        (scene.presets[0].intensity - 1.0).abs() < 1e-15,
        "left out, it is 1"
    );
    assert!((scene.presets[1].intensity - 0.15).abs() < 1e-15);
    let room = Room::build(scene).expect("room");
    let dark_frames = vec![roomlight_sim::Frame::Black; room.projectors().len()];
    let dark = room.render(&dark_frames, None).expect("dark");
    let full = room.render(&dark_frames, Some(0)).expect("full");
    let dim = room.render(&dark_frames, Some(1)).expect("dim");
    let mut compared = 0;
    for ((d, f), m) in dark.pixels.iter().zip(&full.pixels).zip(&dim.pixels) {
        for c in 0..3 {
            let (full_light, dim_light) = (f64::from(f[c] - d[c]), f64::from(m[c] - d[c]));
            // Below the camera's clipping only.
            if f64::from(f[c]) < 0.9 * room.scene().camera.saturation {
                assert!(
                    (dim_light - 0.15 * full_light).abs() <= 1e-5 + 1e-4 * full_light.abs(),
                    "{dim_light} against 0.15 × {full_light}"
                );
                compared += usize::from(full_light > 1e-3);
            }
        }
    }
    assert!(compared > 1000, "only {compared} lit values compared");
}

#[test]
fn frames_that_do_not_fit_the_projectors_are_refused() {
    let room = Room::build(scenes::small().expect("small")).expect("room");
    let n = room.projectors().len();
    let err = room
        .render(&vec![roomlight_sim::Frame::Black; n - 1], None)
        .expect_err("too few frames");
    assert!(err.to_string().contains("frames for"), "{err}");
    let mut frames = vec![roomlight_sim::Frame::Black; n];
    frames[1] = roomlight_sim::Frame::Image(roomlight_sim::ProjectorImage {
        width: 10,
        height: 10,
        pixels: vec![[0.0; 3]; 100],
    });
    let err = room.render(&frames, None).expect_err("wrong size");
    assert!(
        matches!(err, SimError::Frame { ref projector, .. } if projector == "right"),
        "{err}"
    );
    frames[1] = roomlight_sim::Frame::Uniform([f32::NAN, 0.0, 0.0]);
    assert!(room.render(&frames, None).is_err());
    assert!(matches!(
        room.preset("party"),
        Err(SimError::Unknown { .. })
    ));
}
