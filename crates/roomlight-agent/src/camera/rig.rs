//! The wire rig: the calibration procedure's [`Rig`] over the camera agent's peers. A frame is
//! a Show message to the projector's node agent (a second pass's mask bit-packed beside its
//! pattern), and the rig waits for each peer's Shown within the round deadline; an assignment
//! is an Assign message; a capture is the camera agent's own camera (stale frames discarded);
//! decoding runs on a blocking thread. It knows the registry and the wire messages; it must not
//! know the order of captures (the procedure's) or the live model.

use super::Shared;
use super::capture::Captures;
use super::registry::Outbox;
use crate::hardware::{Assignment, Camera};
use roomlight_calib::graycode::{Axis, Coding, Pattern as Gray, Primary};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::rig::{
    CameraLimits, Frame, Projector, ProjectorKind, ProjectorRole, Rig, RigError,
};
use roomlight_core::LinearRgb;
use roomlight_proto::convert::to_rgb;
use roomlight_proto::v1;
use std::sync::atomic::Ordering;

/// The peers named at its creation, as a rig: the procedure calibrates them while every other
/// projector keeps what it shows.
pub(super) struct WireRig<'a, C> {
    shared: &'a Shared,
    eye: &'a mut Captures<C>,
    ids: Vec<String>,
}

impl<'a, C: Camera> WireRig<'a, C> {
    /// A rig over the attached projectors `ids` capturing with `eye`.
    pub(super) fn new(shared: &'a Shared, eye: &'a mut Captures<C>, ids: Vec<String>) -> Self {
        Self { shared, eye, ids }
    }

    /// A capture of the model's patches with whether each could be measured (for cameras that
    /// deliver patches: see [`Captures::measured`]); `None` when the camera failed (logged).
    pub(super) async fn measured(&mut self) -> Option<(Vec<LinearRgb>, Vec<bool>)> {
        self.eye.measured(self.shared).await
    }

    /// A peer's queue and resolution; `Gone` when it is not attached.
    fn peer(&self, id: &str) -> Result<(Outbox, u32, u32), RigError> {
        self.shared
            .registry
            .lock()
            .peer(id)
            .map(|p| (p.tx.clone(), p.width, p.height))
            .ok_or_else(|| RigError::Gone(id.to_string()))
    }
}

impl<C: Camera> Rig for WireRig<'_, C> {
    fn projectors(&self) -> Vec<Projector> {
        let registry = self.shared.registry.lock();
        self.ids
            .iter()
            .filter_map(|id| {
                let p = registry.peer(id)?;
                Some(Projector {
                    id: id.clone(),
                    width: p.width,
                    height: p.height,
                    kind: match p.kind {
                        v1::ProjectorKind::LargeAperture => ProjectorKind::LargeAperture,
                        _ => ProjectorKind::Standard,
                    },
                    // Texture projectors are not calibrated over the wire: every peer lights.
                    role: ProjectorRole::Luminaire,
                })
            })
            .collect()
    }

    /// Queues every Show first and then waits for all the Shown, so that projectors coded at
    /// the same time switch in parallel.
    async fn show(&mut self, frames: &[(&str, Frame)]) -> Result<(), RigError> {
        let mut awaited: Vec<(String, Outbox, u64)> = Vec::with_capacity(frames.len());
        for (id, frame) in frames {
            let (tx, width, height) = self.peer(id)?;
            let (pattern, mask) = show_pattern(frame, width, height)
                .map_err(|what| RigError::Unsupported(id.to_string(), what))?;
            let seq = self.shared.pattern_seq.fetch_add(1, Ordering::Relaxed) + 1;
            let show = v1::room_message::Body::Show(v1::Show {
                seq,
                pattern: Some(pattern),
                mask,
            });
            if !self.shared.offer(id, &tx, vec![show]) {
                return Err(RigError::Gone(id.to_string()));
            }
            awaited.push((id.to_string(), tx, seq));
        }
        // A peer that left (or reconnected: another queue) is not waited for.
        let state =
            |peers: &super::registry::Peers, (id, tx, seq): &(String, Outbox, u64)| match peers
                .peer(id)
            {
                Some(p) if p.tx.same_channel(tx) => Ok(p.pattern_shown.is_some_and(|s| s >= *seq)),
                _ => Err(RigError::Gone(id.clone())),
            };
        self.shared
            .registry
            .wait_for(self.shared.config.deadline, |peers| {
                awaited.iter().all(|a| state(peers, a) != Ok(false))
            })
            .await;
        let peers = self.shared.registry.lock();
        for a in &awaited {
            if !state(&peers, a)? {
                tracing::warn!(projector = %a.0, seq = a.2, "pattern not shown within the deadline");
                return Err(RigError::NotShown(a.0.clone()));
            }
        }
        Ok(())
    }

    /// Resolves once the node agent has taken the assignment (an empty Show of node values
    /// behind it changes nothing on the display and is acknowledged after it): taking one
    /// writes the node's state file, and a bring-up that assigned every projector at once kept
    /// six node agents busy together for long enough to miss their heartbeats (the lab over the
    /// wire).
    async fn assign(&mut self, projector: &str, assignment: &Assignment) -> Result<(), RigError> {
        let (tx, _, _) = self.peer(projector)?;
        let assign = v1::room_message::Body::Assign(assign_message(assignment));
        if !self.shared.offer(projector, &tx, vec![assign]) {
            return Err(RigError::Gone(projector.to_string()));
        }
        self.show(&[(projector, Frame::Nodes(Vec::new()))]).await
    }

    async fn capture(&mut self, exposure: f32) -> Result<LinearImage, RigError> {
        self.eye
            .image_exposed(self.shared, exposure)
            .await
            .ok_or_else(|| RigError::Camera("the capture failed (logged)".into()))
    }

    fn camera(&self) -> CameraLimits {
        self.eye.limits()
    }

    fn shows_masks(&self) -> bool {
        true
    }

    /// Decoding and segmentation take a good part of a second: off the runtime's threads, so
    /// that the peers' readers and heartbeats go on.
    async fn offload<T: Send + 'static>(
        &mut self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, RigError> {
        tokio::task::spawn_blocking(work)
            .await
            .map_err(|e| RigError::Worker(e.to_string()))
    }
}

/// An assignment as the Assign message that carries it.
pub(super) fn assign_message(a: &Assignment) -> v1::Assign {
    v1::Assign {
        nodes: a
            .nodes
            .iter()
            .map(|(n, w)| v1::NodeAssignment {
                node: *n,
                chart: *n,
                pixels: w.iter().map(|p| p.0).collect(),
                weights: w.iter().map(|p| p.1).collect(),
            })
            .collect(),
        width: a.width,
        height: a.height,
        gamma: a.response.gamma.to_vec(),
    }
}

/// A frame as a Show's pattern and mask for a `width`×`height` projector (white and black as
/// uniform codes); a mask of another size is refused.
pub(super) fn show_pattern(
    frame: &Frame,
    width: u32,
    height: u32,
) -> Result<(v1::show::Pattern, Vec<u8>), &'static str> {
    Ok(match frame {
        Frame::Uniform(code) => (uniform(LinearRgb(code.map(f64::from))), Vec::new()),
        Frame::Structured {
            pattern,
            coding,
            cell,
            primary,
        } => (structured(*pattern, *coding, *cell, *primary), Vec::new()),
        Frame::Masked {
            pattern,
            coding,
            cell,
            shown,
        } => {
            if shown.len() != width as usize * height as usize {
                return Err("a mask of another size");
            }
            (structured(*pattern, *coding, *cell, None), pack_mask(shown))
        }
        Frame::Nodes(values) => (
            v1::show::Pattern::Nodes(v1::NodeValues {
                values: values
                    .iter()
                    .map(|&(node, x)| v1::NodeState {
                        node,
                        x: Some(to_rgb(x)),
                        attenuation: None,
                    })
                    .collect(),
            }),
            Vec::new(),
        ),
    })
}

/// One bit per pixel, row-major, least significant bit first (the Show message's mask).
pub(super) fn pack_mask(shown: &[bool]) -> Vec<u8> {
    let mut bytes = vec![0u8; shown.len().div_ceil(8)];
    for (i, _) in shown.iter().enumerate().filter(|(_, s)| **s) {
        bytes[i / 8] |= 1 << (i % 8);
    }
    bytes
}

fn uniform(code: LinearRgb) -> v1::show::Pattern {
    v1::show::Pattern::Uniform(v1::Uniform {
        code: Some(to_rgb(code)),
    })
}

fn structured(
    pattern: Gray,
    coding: Coding,
    cell: u32,
    primary: Option<Primary>,
) -> v1::show::Pattern {
    match pattern {
        Gray::White => uniform(match primary {
            Some(p) => LinearRgb(p.white().map(f64::from)),
            None => LinearRgb::splat(1.0),
        }),
        Gray::Black => uniform(LinearRgb::ZERO),
        Gray::Bit { axis, bit, inverse } => v1::show::Pattern::Gray(v1::GrayBit {
            axis: match axis {
                Axis::Column => v1::Axis::Column,
                Axis::Row => v1::Axis::Row,
            } as i32,
            bit,
            inverse,
            coding: match coding {
                Coding::Gray => v1::Coding::Gray,
                Coding::Xor04 => v1::Coding::Xor04,
            } as i32,
            cell,
            primary: match primary {
                None => v1::Primary::All,
                Some(Primary::Red) => v1::Primary::Red,
                Some(Primary::Green) => v1::Primary::Green,
                Some(Primary::Blue) => v1::Primary::Blue,
            } as i32,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// The bits land where the node agent reads them: pixel `i` is bit `i % 8` of byte `i / 8`.
    #[test]
    fn masks_are_packed_one_bit_per_pixel_lsb_first() {
        let shown = [
            true, false, false, true, false, false, false, false, false, true,
        ];
        assert_eq!(pack_mask(&shown), vec![0b0000_1001, 0b0000_0010]);
        assert_eq!(pack_mask(&[]), Vec::<u8>::new());
        assert_eq!(pack_mask(&[true; 8]), vec![0xff]);
    }

    /// A structured frame in one primary travels with it (the node draws that primary
    /// alone), and its white as that primary's uniform code.
    #[test]
    fn a_frame_in_a_primary_is_sent_with_it() {
        let bit = Gray::Bit {
            axis: Axis::Column,
            bit: 0,
            inverse: false,
        };
        let frame = Frame::Structured {
            pattern: bit,
            coding: Coding::Xor04,
            cell: 1,
            primary: Some(Primary::Blue),
        };
        let (pattern, mask) = show_pattern(&frame, 4, 3).expect("4×3");
        assert!(mask.is_empty());
        let v1::show::Pattern::Gray(g) = pattern else {
            panic!("a Gray bit: {pattern:?}");
        };
        assert_eq!(g.primary, v1::Primary::Blue as i32);
        let white = structured(Gray::White, Coding::Xor04, 1, Some(Primary::Green));
        assert_eq!(white, uniform(LinearRgb([0.0, 1.0, 0.0])));
    }

    /// A second pass's frame travels as its pattern plus the packed mask; one drawn for another
    /// size is refused before anything is sent.
    #[test]
    fn a_masked_frame_is_sent_as_its_pattern_and_mask() {
        let shown: Arc<[bool]> = (0..12).map(|i| i % 5 == 0).collect();
        let bit = Gray::Bit {
            axis: Axis::Row,
            bit: 1,
            inverse: true,
        };
        let frame = Frame::Masked {
            pattern: bit,
            coding: Coding::Xor04,
            cell: 2,
            shown: shown.clone(),
        };
        let (pattern, mask) = show_pattern(&frame, 4, 3).expect("4×3");
        assert_eq!(pattern, structured(bit, Coding::Xor04, 2, None));
        assert_eq!(mask, pack_mask(&shown));
        assert!(show_pattern(&frame, 5, 3).is_err(), "a 12-pixel mask on 15");
        let white = Frame::Masked {
            pattern: Gray::White,
            coding: Coding::Xor04,
            cell: 1,
            shown,
        };
        let (pattern, _) = show_pattern(&white, 4, 3).expect("white");
        assert_eq!(pattern, uniform(LinearRgb::splat(1.0)));
        let (_, unmasked) = show_pattern(&Frame::BLACK, 4, 3).expect("black");
        assert!(unmasked.is_empty(), "everywhere: no mask");
    }
}
