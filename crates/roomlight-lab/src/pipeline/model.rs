//! The measured model for one lighting target and what is derived from it: node weights as
//! sparse pixel lists, node values as projector frames, the problem without its sparsity
//! cut-off. The model's patches and problem come from [`Target`], as for a camera agent
//! surveying a room.

use anyhow::Result;
use rayon::prelude::*;
use roomlight_calib::procedure::Target;
use roomlight_calib::response::Response;
use roomlight_core::optimum::Optimum;
use roomlight_core::{LinearRgb, Problem};
use roomlight_sim::{Frame, NodeRegion, ProjectorImage, Room};

use super::*;

/// The model for one lighting target: the measured problem over the patches usable in every
/// capture.
#[derive(Debug)]
pub struct Model {
    /// Columns, black, target and noise over the usable patches.
    pub problem: Problem,
    /// Room patch index of each model patch.
    pub patches: Vec<usize>,
    /// The target lighting on those patches, as measured.
    pub target: Target,
    /// The conventional start (DESIGN §3.1), one value per node.
    pub conventional: Vec<LinearRgb>,
}

/// A node's non-zero weights: `(node, [(pixel, weight)])`.
type SparseNode = (usize, Vec<(u32, f32)>);

/// A node region's non-zero weights as `(pixel, weight)`, row-major pixels.
pub fn sparse_weights(region: &NodeRegion) -> Vec<(u32, f32)> {
    region
        .weights
        .iter()
        .enumerate()
        .filter(|(_, w)| **w > 0.0)
        .map(|(i, w)| (i as u32, *w))
        .collect()
}

/// Node values as projector frames: each pixel's linear light is the sum of its nodes' weights
/// times their values, turned into a code through the projector's measured response (as a node
/// agent does before it shows a frame). Each node's weights are kept sparse.
#[derive(Debug)]
pub struct FrameBuilder {
    /// Per projector: width, height, and its nodes.
    projectors: Vec<(u32, u32, Vec<SparseNode>)>,
    responses: Vec<Response>,
}

impl FrameBuilder {
    /// For `regions` of `room`'s projectors with their measured `responses`.
    pub fn new(room: &Room, regions: &[NodeRegion], responses: Vec<Response>) -> Self {
        let projectors = room
            .projectors()
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let nodes = regions
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| r.projector == k)
                    .map(|(n, r)| (n, sparse_weights(r)))
                    .collect();
                (p.pinhole.width, p.pinhole.height, nodes)
            })
            .collect();
        Self {
            projectors,
            responses,
        }
    }

    /// The frames for node values `x` (a missing value counts as black).
    pub fn frames(&self, x: &[LinearRgb]) -> Vec<Frame> {
        let linear = Response::linear();
        // One projector's frame per task: independent, the same on any number of cores.
        self.projectors
            .par_iter()
            .enumerate()
            .map(|(k, (width, height, nodes))| {
                let mut light = vec![LinearRgb::ZERO; (width * height) as usize];
                for (n, weights) in nodes {
                    let v = x.get(*n).copied().unwrap_or(LinearRgb::ZERO);
                    for &(i, w) in weights {
                        light[i as usize] += v * f64::from(w);
                    }
                }
                let response = self.responses.get(k).unwrap_or(&linear);
                // A node's inside (and everything outside the nodes) is one light: its code
                // is worked out once (three powers a pixel were most of a run's capture).
                let mut last: Option<(LinearRgb, [f32; 3])> = None;
                let pixels = light
                    .into_iter()
                    .map(|l| match last {
                        Some((seen, code)) if seen.0.map(f64::to_bits) == l.0.map(f64::to_bits) => {
                            code
                        }
                        _ => {
                            let code = response.to_code(l);
                            last = Some((l, code));
                            code
                        }
                    })
                    .collect();
                Frame::Image(ProjectorImage {
                    width: *width,
                    height: *height,
                    pixels,
                })
            })
            .collect()
    }
}

/// `model` with every attenuation entry kept (no 3σ cut-off), over the same patches: what the
/// sparse supports are compared against.
pub fn uncut_problem(cal: &Calibrated, model: &Model) -> Result<Problem> {
    let uncut: Vec<Vec<(u32, LinearRgb)>> = cal
        .attenuation
        .columns(0.0)?
        .iter()
        .map(|c| c.iter().collect())
        .collect();
    Ok(Problem::new(
        model.target.columns(&uncut)?,
        model.problem.black().to_vec(),
        model.problem.target().to_vec(),
        model.problem.noise().to_vec(),
    )?)
}

/// `(G_c(x) − G*_c)/G*_c` per colour channel: each channel's objective over its own optimum
/// (the problem is separable by channel, so `best` is each channel's optimum too). A channel
/// whose optimum is 0 has its excess over `1e-9 · G(black)`, as [`Optimum::excess`] does; 0
/// when that is 0 too.
pub fn channel_excess(problem: &Problem, best: &Optimum, x: &[LinearRgb]) -> [f64; 3] {
    let errors = problem.errors(x);
    std::array::from_fn(|c| {
        let g = 0.5 * errors.iter().map(|e| e[c] * e[c]).sum::<f64>();
        let star = best.objective_per_channel[c];
        let den = star.max(1e-9 * best.objective_black);
        if den > 0.0 { (g - star) / den } else { 0.0 }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each pixel's code is its response to the sum of its nodes' weights times their values,
    /// feathered edges and flat insides alike (the code of a repeated light is reused).
    #[test]
    fn frames_are_the_response_of_each_pixels_blended_light() {
        let room = Room::build(roomlight_sim::scenes::small().expect("scene")).expect("room");
        let p = &room.projectors()[0];
        let (w, h) = (p.pinhole.width, p.pinhole.height);
        // Two nodes: left and right, feathered over the middle fifth.
        let ramp = |i: u32| ((i % w) as f32 / w as f32 - 0.4).clamp(0.0, 0.2) * 5.0;
        let right: Vec<f32> = (0..w * h).map(ramp).collect();
        let left: Vec<f32> = right.iter().map(|v| 1.0 - v).collect();
        let regions = vec![
            NodeRegion {
                projector: 0,
                weights: left.clone(),
            },
            NodeRegion {
                projector: 0,
                weights: right.clone(),
            },
        ];
        let response = Response {
            gamma: [2.2, 2.0, 2.4],
            max_residual: [0.0; 3],
        };
        let responses = vec![response.clone(); room.projectors().len()];
        let x = [LinearRgb([0.2, 0.5, 0.9]), LinearRgb([0.7, 0.1, 0.4])];
        let frames = FrameBuilder::new(&room, &regions, responses).frames(&x);
        let Frame::Image(img) = &frames[0] else {
            panic!("an image for the projector with nodes");
        };
        let mut distinct = std::collections::HashSet::new();
        for (i, code) in img.pixels.iter().enumerate() {
            let light = x[0] * f64::from(left[i]) + x[1] * f64::from(right[i]);
            let want = response.to_code(light);
            assert_eq!(code.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
            distinct.insert(code.map(f32::to_bits));
        }
        assert!(distinct.len() > 10, "the feathered band has its own codes");
    }
}
