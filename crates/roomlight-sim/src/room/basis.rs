//! The fast path for uniform node values: each node's light rendered once, captures and chart
//! patches afterwards a weighted sum. Knows the room's rendering, nothing of calibration.

use super::{Capture, Frame, ProjectorImage, Room, SimError};
use roomlight_core::LinearRgb;

/// One node for [`NodeBasis`]: a projector and the linear-light weight of each of its pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeRegion {
    /// Index of the projector.
    pub projector: usize,
    /// Weight in `[0, 1]` of every projector pixel (row-major); feathered regions overlap.
    pub weights: Vec<f32>,
}

/// The fast path for projectors that show uniform node values: because light adds, the
/// capture with node `n` at linear light `x_n` is `C_black + Σ_n Σ_c x_{n,c} (C_{n,c} − C_black)`.
/// Each node's response is rendered once (per channel when its projector mixes primaries);
/// afterwards a capture costs one multiply-add per node, pixel and channel, and the chart
/// patches one per node and patch.
#[derive(Debug, Clone)]
pub struct NodeBasis {
    black_capture: Vec<[f32; 3]>,
    black_patches: Vec<LinearRgb>,
    nodes: Vec<NodePart>,
    width: u32,
    height: u32,
}

/// One node's change of the capture and patches at full light.
#[derive(Debug, Clone)]
struct NodePart {
    /// Without mixing: one image, channel c of the light moves channel c only. With mixing:
    /// one image per input channel.
    capture: Vec<Vec<[f32; 3]>>,
    patches: Vec<Vec<LinearRgb>>,
}

impl NodeBasis {
    /// Renders each node's response with every other projector black and the LEDs of `preset`.
    pub fn new(room: &Room, nodes: &[NodeRegion], preset: Option<usize>) -> Result<Self, SimError> {
        let mut parts = Vec::with_capacity(nodes.len());
        let (black_capture, black_patches) = Self::render_parts(room, nodes, preset, |_, part| {
            parts.push(part);
            Ok(())
        })?;
        Ok(Self {
            black_capture,
            black_patches,
            nodes: parts,
            width: room.camera.width,
            height: room.camera.height,
        })
    }

    /// What [`Self::capture`] returns with every node black, then with node `n` alone at full
    /// light (`[1, 1, 1]`), for each node in turn, to `visit(n, capture)`: the same captures
    /// without keeping every node's image (one at a time in memory instead of all of them).
    pub fn visit_node_captures(
        room: &Room,
        nodes: &[NodeRegion],
        preset: Option<usize>,
        mut visit: impl FnMut(Option<usize>, Capture) -> Result<(), SimError>,
    ) -> Result<(), SimError> {
        let (width, height) = (room.camera.width, room.camera.height);
        let mut black: Option<Vec<[f32; 3]>> = None;
        let mut n = 0;
        let (black_capture, _) = Self::render_parts(room, nodes, preset, |black_capture, part| {
            if black.is_none() {
                black = Some(black_capture.to_vec());
                visit(
                    None,
                    Capture {
                        width,
                        height,
                        pixels: black_capture.to_vec(),
                    },
                )?;
            }
            let mut pixels = black_capture.to_vec();
            part.add_capture(&mut pixels, [1.0; 3]);
            visit(
                Some(n),
                Capture {
                    width,
                    height,
                    pixels,
                },
            )?;
            n += 1;
            Ok(())
        })?;
        if black.is_none() {
            visit(
                None,
                Capture {
                    width,
                    height,
                    pixels: black_capture,
                },
            )?;
        }
        Ok(())
    }

    /// The black render and each node's part in turn, handed to `keep` with the black capture.
    fn render_parts(
        room: &Room,
        nodes: &[NodeRegion],
        preset: Option<usize>,
        mut keep: impl FnMut(&[[f32; 3]], NodePart) -> Result<(), SimError>,
    ) -> Result<(Vec<[f32; 3]>, Vec<LinearRgb>), SimError> {
        let n = room.projectors.len();
        let black_frames = vec![Frame::Black; n];
        let (black_capture, black_patches) = room.render_with_patches(&black_frames, preset)?;
        for node in nodes {
            let p = room
                .projectors
                .get(node.projector)
                .ok_or_else(|| SimError::Unknown {
                    kind: "projector",
                    name: node.projector.to_string(),
                })?;
            let (w, h) = (p.pinhole.width, p.pinhole.height);
            if node.weights.len() != (w * h) as usize
                || node.weights.iter().any(|v| !(0.0..=1.0).contains(v))
            {
                return Err(SimError::Frame {
                    projector: p.name.clone(),
                    problem: format!("node weights: expected {} values in [0, 1]", w * h),
                });
            }
            let inputs: Vec<[f32; 3]> = if p.mixes() {
                vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            } else {
                vec![[1.0; 3]]
            };
            let mut part = NodePart {
                capture: Vec::new(),
                patches: Vec::new(),
            };
            for input in inputs {
                let pixels = node.weights.iter().map(|&v| input.map(|i| i * v)).collect();
                let mut frames = black_frames.clone();
                frames[node.projector] = Frame::Linear(ProjectorImage {
                    width: w,
                    height: h,
                    pixels,
                });
                let (cap, pat) = room.render_with_patches(&frames, preset)?;
                part.capture.push(
                    cap.iter()
                        .zip(&black_capture)
                        .map(|(a, b)| [a[0] - b[0], a[1] - b[1], a[2] - b[2]])
                        .collect(),
                );
                part.patches.push(
                    pat.iter()
                        .zip(&black_patches)
                        .map(|(a, b)| *a - *b)
                        .collect(),
                );
            }
            keep(&black_capture, part)?;
        }
        Ok((black_capture, black_patches))
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.nodes.len()
    }

    /// The noiseless patch values with node `n` at linear light `x[n]` (clipped to `[0, 1]`).
    pub fn patch_values(&self, x: &[LinearRgb]) -> Vec<LinearRgb> {
        let mut out = self.black_patches.clone();
        for (part, xn) in self.nodes.iter().zip(x) {
            let xn = xn.clamp_unit();
            if part.patches.len() == 1 {
                for (o, v) in out.iter_mut().zip(&part.patches[0]) {
                    *o += v.hadamard(xn);
                }
            } else {
                for (c, image) in part.patches.iter().enumerate() {
                    for (o, v) in out.iter_mut().zip(image) {
                        *o += *v * xn[c];
                    }
                }
            }
        }
        out
    }

    /// The noiseless capture with node `n` at linear light `x[n]`.
    pub fn capture(&self, x: &[LinearRgb]) -> Capture {
        let mut out = self.black_capture.clone();
        for (part, xn) in self.nodes.iter().zip(x) {
            part.add_capture(&mut out, xn.clamp_unit().0.map(|v| v as f32));
        }
        Capture {
            width: self.width,
            height: self.height,
            pixels: out,
        }
    }
}

impl NodePart {
    /// `out += ` this node's change of the capture at linear light `xn`.
    fn add_capture(&self, out: &mut [[f32; 3]], xn: [f32; 3]) {
        if self.capture.len() == 1 {
            for (o, v) in out.iter_mut().zip(&self.capture[0]) {
                o[0] += v[0] * xn[0];
                o[1] += v[1] * xn[1];
                o[2] += v[2] * xn[2];
            }
        } else {
            for (c, image) in self.capture.iter().enumerate() {
                for (o, v) in out.iter_mut().zip(image) {
                    o[0] += v[0] * xn[c];
                    o[1] += v[1] * xn[c];
                    o[2] += v[2] * xn[c];
                }
            }
        }
    }
}
