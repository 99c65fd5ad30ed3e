//! The simulated room as a calibration rig ([`roomlight_calib::rig::Rig`]): frames rendered
//! with the simulator's hidden responses, captures exposed through its noisy camera. It knows
//! the simulator and the rig; the order of captures is the procedure's
//! ([`roomlight_calib::procedure`]), the same as over the wire.

use roomlight_calib::image_io::LinearImage;
use roomlight_calib::rig::{
    Assignment, CameraLimits, Frame, Projector, ProjectorKind, ProjectorRole, Rig, RigError,
};
use roomlight_sim::{CameraNoise, ProjectorImage, Room};
use std::collections::HashMap;

/// The longest exposure the simulated camera takes for a second pass, as a multiple of the
/// normal one (in the lab floor-right's needs ×6; ×64 decoded no more pixels).
const LONGEST_EXPOSURE: f32 = roomlight_calib::graycode::SECOND_PASS_LONGEST;

/// The simulated room as a rig; every projector is live.
#[derive(Debug)]
pub struct SimRig<'a> {
    room: &'a Room,
    noise: &'a mut CameraNoise,
    frames: Vec<roomlight_sim::Frame>,
    assignments: HashMap<usize, Assignment>,
}

impl<'a> SimRig<'a> {
    /// Every projector black, the LEDs off.
    pub fn new(room: &'a Room, noise: &'a mut CameraNoise) -> Self {
        Self {
            room,
            noise,
            frames: vec![roomlight_sim::Frame::Black; room.projectors().len()],
            assignments: HashMap::new(),
        }
    }

    /// The frames every projector shows now, in the simulator's terms.
    pub fn frames(&self) -> &[roomlight_sim::Frame] {
        &self.frames
    }

    fn index(&self, id: &str) -> Result<usize, RigError> {
        self.room
            .projector(id)
            .map_err(|_| RigError::Gone(id.to_string()))
    }

    /// `frame` on projector `k` in the simulator's terms (uniform codes take its fast path).
    fn sim_frame(&self, k: usize, frame: &Frame) -> Result<roomlight_sim::Frame, RigError> {
        let p = &self.room.projectors()[k].pinhole;
        Ok(match frame {
            Frame::Uniform(code) => roomlight_sim::Frame::Uniform(*code),
            other => roomlight_sim::Frame::Image(ProjectorImage {
                width: p.width,
                height: p.height,
                pixels: other
                    .codes(p.width, p.height, self.assignments.get(&k))
                    .map_err(|_| {
                        RigError::Unsupported(
                            self.room.projectors()[k].name.clone(),
                            "a frame of another size",
                        )
                    })?,
            }),
        })
    }
}

/// Room projector `k` as the rig describes it.
pub fn projector(room: &Room, k: usize) -> Projector {
    let p = &room.projectors()[k];
    Projector {
        id: p.name.clone(),
        width: p.pinhole.width,
        height: p.pinhole.height,
        kind: match p.kind {
            roomlight_sim::scene::ProjectorKind::LargeAperture => ProjectorKind::LargeAperture,
            roomlight_sim::scene::ProjectorKind::Standard => ProjectorKind::Standard,
        },
        role: match room.scene().projectors[k].role {
            roomlight_sim::scene::ProjectorRole::Luminaire => ProjectorRole::Luminaire,
            roomlight_sim::scene::ProjectorRole::Texture => ProjectorRole::Texture,
        },
    }
}

impl Rig for SimRig<'_> {
    fn projectors(&self) -> Vec<Projector> {
        (0..self.room.projectors().len())
            .map(|k| projector(self.room, k))
            .collect()
    }

    async fn show(&mut self, frames: &[(&str, Frame)]) -> Result<(), RigError> {
        for (id, frame) in frames {
            let k = self.index(id)?;
            self.frames[k] = self.sim_frame(k, frame)?;
        }
        Ok(())
    }

    async fn assign(&mut self, projector: &str, assignment: &Assignment) -> Result<(), RigError> {
        let k = self.index(projector)?;
        self.assignments.insert(k, assignment.clone());
        Ok(())
    }

    async fn capture(&mut self, exposure: f32) -> Result<LinearImage, RigError> {
        let capture = self
            .room
            .render(&self.frames, None)
            .map_err(|e| RigError::Camera(e.to_string()))?;
        let c = self.noise.expose_longer(&capture, f64::from(exposure));
        Ok(LinearImage {
            width: c.width,
            height: c.height,
            pixels: c.pixels,
        })
    }

    fn camera(&self) -> CameraLimits {
        CameraLimits {
            saturation: self.room.scene().camera.saturation as f32,
            longest_exposure: LONGEST_EXPOSURE,
        }
    }

    fn shows_masks(&self) -> bool {
        true
    }
}
