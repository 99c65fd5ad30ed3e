//! Helpers shared by the calibration tests: the simulated room as the real system would see it
//! (captures and the room config), never simulator internals in the code under test.
#![allow(dead_code)]

pub mod photo;

use roomlight_calib::charts::ChartCorners;
use roomlight_calib::graycode::{Coding, Correspondence, DecodeConfig, Manifest, decode};
use roomlight_calib::image_io::LinearImage;
use roomlight_sim::{CameraNoise, Capture, Frame, ProjectorImage, Room, Scene, scenes};

/// The small room seen by a 640×480 camera (enough pixels per patch).
pub fn small_scene() -> Scene {
    let mut scene = scenes::small().expect("scene");
    scene.camera.resolution = [640, 480];
    scene
}

pub fn to_image(c: &Capture) -> LinearImage {
    LinearImage {
        width: c.width,
        height: c.height,
        pixels: c.pixels.clone(),
    }
}

/// The chart corners in camera pixels, as a person would click them once (here: from the room
/// config through the camera model).
pub fn chart_corners(room: &Room) -> Vec<ChartCorners> {
    room.chart_corners_px()
        .into_iter()
        .zip(&room.scene().charts)
        .map(|(corners, spec)| ChartCorners {
            name: spec.name.clone(),
            corners: corners.expect("chart in view"),
        })
        .collect()
}

/// Renders every pattern of `manifest` on projector `k` (others black, LEDs of `preset`) through
/// the noisy camera.
pub fn pattern_captures(
    room: &Room,
    k: usize,
    manifest: &Manifest,
    preset: Option<usize>,
    seed: u64,
) -> Vec<LinearImage> {
    let mut noise = CameraNoise::with_seed(room, seed);
    manifest
        .patterns
        .iter()
        .map(|p| {
            let mut frames = vec![Frame::Black; room.projectors().len()];
            let img = manifest.pattern_image(p.pattern);
            frames[k] = Frame::Image(ProjectorImage {
                width: img.width,
                height: img.height,
                pixels: img.pixels,
            });
            to_image(&noise.expose(&room.render(&frames, preset).expect("render")))
        })
        .collect()
}

/// Structured light on projector `k` of the simulated room, decoded as the real system would.
pub fn decode_projector(
    room: &Room,
    k: usize,
    coding: Coding,
    config: &DecodeConfig,
    seed: u64,
) -> Correspondence {
    let p = &room.projectors()[k].pinhole;
    let manifest = Manifest::with_coding(p.width, p.height, coding).expect("manifest");
    let caps = pattern_captures(room, k, &manifest, None, seed);
    decode(&manifest, config, |f| {
        Ok(&caps[manifest
            .patterns
            .iter()
            .position(|p| p.file == f.file)
            .expect("pattern")])
    })
    .expect("decode")
}
