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

/// The simulated room as a rig: every projector live unless told otherwise; a projector that
/// is not live shows black and cannot be shown on.
#[derive(Debug)]
pub struct SimRig<'a> {
    room: &'a Room,
    noise: &'a mut CameraNoise,
    frames: Vec<roomlight_sim::Frame>,
    assignments: HashMap<usize, Assignment>,
    /// Room indices of the live projectors, in the order they went live.
    live: Vec<usize>,
    shows_masks: bool,
    captures: usize,
}

impl<'a> SimRig<'a> {
    /// Every projector live and black, the LEDs off.
    pub fn new(room: &'a Room, noise: &'a mut CameraNoise) -> Self {
        Self {
            room,
            noise,
            frames: vec![roomlight_sim::Frame::Black; room.projectors().len()],
            assignments: HashMap::new(),
            live: (0..room.projectors().len()).collect(),
            shows_masks: true,
            captures: 0,
        }
    }

    /// Only the projectors named live (the others stay black until they [`Self::go_live`]).
    pub fn with_live(mut self, ids: &[&str]) -> Result<Self, RigError> {
        self.live = ids
            .iter()
            .map(|id| {
                self.room
                    .projector(id)
                    .map_err(|_| RigError::Gone((*id).to_string()))
            })
            .collect::<Result<_, _>>()?;
        Ok(self)
    }

    /// Projector `id` switched on: live from now on (a projector joining the room).
    pub fn go_live(&mut self, id: &str) -> Result<(), RigError> {
        let k = self
            .room
            .projector(id)
            .map_err(|_| RigError::Gone(id.to_string()))?;
        if !self.live.contains(&k) {
            self.live.push(k);
        }
        Ok(())
    }

    /// Whether the rig shows masked patterns (a rig that cannot skips the second pass).
    pub fn set_shows_masks(&mut self, shows: bool) {
        self.shows_masks = shows;
    }

    /// Captures taken.
    pub fn captures(&self) -> usize {
        self.captures
    }

    /// The room it shows frames in.
    pub fn room(&self) -> &'a Room {
        self.room
    }

    /// The frames every projector shows now, in the simulator's terms.
    pub fn frames(&self) -> &[roomlight_sim::Frame] {
        &self.frames
    }

    fn index(&self, id: &str) -> Result<usize, RigError> {
        self.room
            .projector(id)
            .ok()
            .filter(|k| self.live.contains(k))
            .ok_or_else(|| RigError::Gone(id.to_string()))
    }

    /// `frame` on projector `id` in the simulator's terms, drawn as the rig draws it (uniform
    /// codes take the simulator's fast path).
    pub fn sim_frame_of(&self, id: &str, frame: &Frame) -> Result<roomlight_sim::Frame, RigError> {
        let k = self
            .room
            .projector(id)
            .map_err(|_| RigError::Gone(id.to_string()))?;
        self.sim_frame(k, frame)
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
        self.live.iter().map(|&k| projector(self.room, k)).collect()
    }

    async fn show(&mut self, frames: &[(&str, Frame)]) -> Result<(), RigError> {
        for (id, frame) in frames {
            let k = self.index(id)?;
            if matches!(frame, Frame::Masked { .. }) && !self.shows_masks {
                return Err(RigError::Unsupported(id.to_string(), "masked patterns"));
            }
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
        self.captures += 1;
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
        self.shows_masks
    }
}
