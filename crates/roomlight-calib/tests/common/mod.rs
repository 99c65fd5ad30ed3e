//! Helpers shared by the calibration tests: the simulated room as the real system would see it
//! (captures and the room config), never simulator internals in the code under test.
#![allow(dead_code)]

use roomlight_calib::charts::ChartCorners;
use roomlight_calib::image_io::LinearImage;
use roomlight_sim::{Capture, Room, Scene, scenes};

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
