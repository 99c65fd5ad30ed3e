//! What the lab's calibration tests share, in process (`procedure.rs`) and over the wire
//! (`wire_calibration.rs`): the rooms they calibrate, so both measure the same scene, and how a
//! decode is scored against the truth (`accuracy`). It must not know how a test drives the
//! procedure.

use roomlight_sim::{Scene, scenes};

pub mod accuracy;

/// The small room seen by a 640×480 camera (enough pixels per patch).
pub fn small_scene() -> Scene {
    let mut scene = scenes::small().expect("scene");
    scene.camera.resolution = [640, 480];
    scene
}

/// The small room with its two standard luminaires turned apart, one onto each chart, so that
/// their footprints do not overlap.
pub fn apart_scene() -> Scene {
    let mut scene = small_scene();
    scene.projectors.truncate(2);
    scene.objects.retain(|o| !o.target);
    let left = &mut scene.projectors[0];
    left.look_at_mm = [400.0, 600.0, 0.0];
    left.fov_deg = 40.0;
    let right = &mut scene.projectors[1];
    right.position_mm = [1500.0, 300.0, 1100.0];
    right.look_at_mm = [1100.0, 1200.0, 700.0];
    right.fov_deg = 35.0;
    scene
}

/// `room` started over the wire (`roomlight_lab::wire_room`) with `options`, once its two
/// luminaires are brought up; the status then.
pub async fn brought_up_two(
    room: &std::sync::Arc<roomlight_sim::Room>,
    options: roomlight_lab::wire_room::Options,
) -> (
    roomlight_lab::wire_room::WireRoom,
    roomlight_agent::camera::RoomStatus,
) {
    let mut wire = roomlight_lab::wire_room::WireRoom::start(room.clone(), options)
        .await
        .expect("started");
    let up = wire
        .until(std::time::Duration::from_secs(600), "the bring-up", |s| {
            s.calibrated_hot == 2
        })
        .await
        .expect("brought up");
    (wire, up)
}
