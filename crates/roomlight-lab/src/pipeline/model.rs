//! The measured model for one lighting target and what is derived from it: node weights as
//! sparse pixel lists, node values as projector frames, the problem without its sparsity
//! cut-off. The model's patches and problem come from [`Target`], as for a camera agent
//! surveying a room.

use anyhow::{Context, Result};
use rayon::prelude::*;
use roomlight_calib::procedure::Target;
use roomlight_calib::response::{Encoder, Response};
use roomlight_calib::shading::{Gains, shaded_light};
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

/// Rows a task of [`FrameBuilder::frames`] codes.
const FRAME_ROWS: usize = 16;

/// One projector's nodes by pixel, compactly (a pixel's nodes are few, node ids small): pixel
/// `i` has `counts[i]` `(node, weight)` pairs, in ascending node order, in `nodes` and
/// `weights`, starting at `row_start[row]` plus the counts of the row's pixels before it.
#[derive(Debug)]
struct PixelNodes {
    width: u32,
    height: u32,
    row_start: Vec<u32>,
    counts: Vec<u8>,
    nodes: Vec<u16>,
    weights: Vec<f32>,
}

impl PixelNodes {
    /// The non-zero weights of `regions` (node `n` is `regions[n]`) on projector `k`. Refused
    /// when a pixel lies in more than 255 nodes or a node id exceeds 65535 (no room comes
    /// near either).
    fn new(width: u32, height: u32, regions: &[NodeRegion], k: usize) -> Result<Self> {
        let count = (width * height) as usize;
        let mine: Vec<(usize, &NodeRegion)> = regions
            .iter()
            .enumerate()
            .filter(|(_, r)| r.projector == k)
            .collect();
        let mut counts = vec![0u8; count];
        for (n, r) in &mine {
            anyhow::ensure!(
                *n <= usize::from(u16::MAX),
                "node {n}: a frame builder takes node ids up to {}",
                u16::MAX
            );
            for (c, w) in counts.iter_mut().zip(&r.weights) {
                if *w > 0.0 {
                    *c = c.checked_add(1).with_context(|| {
                        format!("projector {k}: a pixel in more than 255 nodes")
                    })?;
                }
            }
        }
        let mut row_start = Vec::with_capacity(height as usize + 1);
        let mut total = 0u32;
        for row in counts.chunks(width.max(1) as usize) {
            row_start.push(total);
            total += row.iter().map(|&c| u32::from(c)).sum::<u32>();
        }
        row_start.push(total);
        // Each pixel's next free slot; nodes in ascending order fill them in that order.
        let mut next = Vec::with_capacity(count);
        let mut at = 0u32;
        for &c in &counts {
            next.push(at);
            at += u32::from(c);
        }
        let mut nodes = vec![0u16; total as usize];
        let mut weights = vec![0.0f32; total as usize];
        for (n, r) in &mine {
            for (slot, w) in next.iter_mut().zip(&r.weights) {
                if *w > 0.0 {
                    nodes[*slot as usize] = *n as u16;
                    weights[*slot as usize] = *w;
                    *slot += 1;
                }
            }
        }
        Ok(Self {
            width,
            height,
            row_start,
            counts,
            nodes,
            weights,
        })
    }
}

/// Node values as projector frames: each pixel's linear light is the sum of its nodes' weights
/// times their values (in ascending node order), turned into a code through the projector's
/// measured response's [`Encoder`] (as a node agent does before it shows a frame). The weights
/// are kept by pixel, so a frame is written in one pass with no light buffer.
#[derive(Debug)]
pub struct FrameBuilder {
    projectors: Vec<PixelNodes>,
    encoders: Vec<Encoder>,
}

impl FrameBuilder {
    /// For `regions` of `room`'s projectors with their measured `responses`. Refused when a
    /// projector pixel lies in more than 255 nodes or there are more than 65536 nodes.
    pub fn new(room: &Room, regions: &[NodeRegion], responses: Vec<Response>) -> Result<Self> {
        // Built on the calling thread: its memory lives as long as the builder, and kept in a
        // worker thread's malloc arena it held that arena's freed memory too.
        let projectors = room
            .projectors()
            .iter()
            .enumerate()
            .map(|(k, p)| PixelNodes::new(p.pinhole.width, p.pinhole.height, regions, k))
            .collect::<Result<_>>()?;
        Ok(Self {
            projectors,
            // A projector without a measured response is drawn linear.
            encoders: (0..room.projectors().len())
                .map(|k| responses.get(k).unwrap_or(&Response::linear()).encoder())
                .collect(),
        })
    }

    /// The frames for node values `x` (a missing value counts as black).
    pub fn frames(&self, x: &[LinearRgb]) -> Vec<Frame> {
        self.frames_shaded(x, &[])
    }

    /// The frames for node values `x`, each projector's light multiplied pixel by pixel by its
    /// gains (`gains[k]` for room projector `k`; none, or missing: as the nodes give it).
    pub fn frames_shaded(&self, x: &[LinearRgb], gains: &[Option<Gains>]) -> Vec<Frame> {
        // Bands of rows are independent tasks: the same codes on any number of cores.
        self.projectors
            .par_iter()
            .enumerate()
            .map(|(k, p)| {
                let encoder = &self.encoders[k];
                let gains = gains
                    .get(k)
                    .and_then(Option::as_ref)
                    .filter(|g| g.size() == (p.width, p.height));
                let width = p.width.max(1) as usize;
                let mut pixels = vec![[0.0f32; 3]; p.counts.len()];
                pixels
                    .par_chunks_mut(width * FRAME_ROWS)
                    .enumerate()
                    .for_each(|(band, chunk)| {
                        let first = band * width * FRAME_ROWS;
                        let mut at = p.row_start[band * FRAME_ROWS] as usize;
                        // The last light's bits and code, kept apart rather than as an
                        // `Option` of both: compared through memory, the option stalled every
                        // pixel on a store it had just made (a quarter of a capture's time).
                        let (mut seen, mut last_bits, mut last_code) =
                            (false, [0u64; 3], [0.0f32; 3]);
                        for (j, (code, &c)) in chunk.iter_mut().zip(&p.counts[first..]).enumerate()
                        {
                            let end = at + usize::from(c);
                            let (mut l, mut weight) = (LinearRgb::ZERO, 0.0);
                            for (&n, &w) in p.nodes[at..end].iter().zip(&p.weights[at..end]) {
                                let v = x.get(usize::from(n)).copied().unwrap_or(LinearRgb::ZERO);
                                l += v * f64::from(w);
                                weight += f64::from(w);
                            }
                            at = end;
                            if let Some(g) = gains {
                                let i = (first + j) as u32;
                                let g = g.at(i % p.width, i / p.width);
                                l = LinearRgb(shaded_light(l.0, weight, g));
                            }
                            let bits = l.0.map(f64::to_bits);
                            if !seen || bits != last_bits {
                                (seen, last_bits, last_code) = (true, bits, encoder.code(l));
                            }
                            *code = last_code;
                        }
                    });
                Frame::Image(ProjectorImage {
                    width: p.width,
                    height: p.height,
                    pixels,
                })
            })
            .collect()
    }
}

/// `model` with every attenuation entry kept (no cut-off), over the same patches: what the
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

    /// Each pixel's code is its response (by table, within 1e-6 of the power) to the sum of its
    /// nodes' weights times their values, feathered edges and flat insides alike (the code of a
    /// repeated light is reused).
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
        let frames = FrameBuilder::new(&room, &regions, responses)
            .expect("builder")
            .frames(&x);
        let Frame::Image(img) = &frames[0] else {
            panic!("an image for the projector with nodes");
        };
        let mut distinct = std::collections::HashSet::new();
        let encoder = response.encoder();
        for (i, code) in img.pixels.iter().enumerate() {
            let light = x[0] * f64::from(left[i]) + x[1] * f64::from(right[i]);
            let want = encoder.code(light);
            assert_eq!(code.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
            let power = response.to_code(light);
            for c in 0..3 {
                assert!(
                    (code[c] - power[c]).abs() < 1e-6,
                    "pixel {i}: {code:?} {power:?}"
                );
            }
            distinct.insert(code.map(f32::to_bits));
        }
        assert!(distinct.len() > 10, "the feathered band has its own codes");
        // Projectors without nodes show black on every pixel.
        for frame in &frames[1..] {
            let Frame::Image(img) = frame else {
                panic!("an image for every projector");
            };
            assert!(
                img.pixels
                    .iter()
                    .all(|c| c.iter().all(|v| v.to_bits() == 0))
            );
        }
    }

    /// Shaded frames: flat gains change nothing where the nodes give more than the floor; a
    /// node at black is raised to the floor in proportion to its weight; gains of another
    /// projector's size, or none, leave the nodes' frames as they are.
    #[test]
    fn flat_gains_keep_the_nodes_light_and_floor_a_black_node() {
        use roomlight_calib::shading::FLOOR;
        let room = Room::build(roomlight_sim::scenes::small().expect("scene")).expect("room");
        let p = &room.projectors()[0];
        let (w, h) = (p.pinhole.width, p.pinhole.height);
        let right: Vec<f32> = (0..w * h)
            .map(|i| ((i % w) as f32 / w as f32 - 0.4).clamp(0.0, 0.2) * 5.0)
            .collect();
        let left: Vec<f32> = right.iter().map(|v| 1.0 - v).collect();
        let regions: Vec<NodeRegion> = [&left, &right]
            .into_iter()
            .map(|weights| NodeRegion {
                projector: 0,
                weights: weights.clone(),
            })
            .collect();
        let responses = vec![Response::linear(); room.projectors().len()];
        let builder = FrameBuilder::new(&room, &regions, responses).expect("builder");
        let image = |frames: Vec<Frame>| match frames.into_iter().next() {
            Some(Frame::Image(img)) => img.pixels,
            _ => panic!("an image for the projector with nodes"),
        };
        let lit = [LinearRgb([0.2, 0.5, 0.9]), LinearRgb([0.7, 0.1, 0.4])];
        let flat = Gains::flat(w, h).expect("gains");
        let plain = image(builder.frames(&lit));
        assert_eq!(
            image(builder.frames_shaded(&lit, &[Some(flat.clone())])),
            plain
        );
        let other = Gains::flat(w + 1, h).expect("gains");
        assert_eq!(image(builder.frames_shaded(&lit, &[Some(other)])), plain);
        // The right node black: its pixels at the floor times its weight, the left's as they were.
        let dark = [lit[0], LinearRgb::ZERO];
        let shaded = image(builder.frames_shaded(&dark, &[Some(flat)]));
        let encoder = Response::linear().encoder();
        for (i, code) in shaded.iter().enumerate() {
            let nodes = lit[0] * f64::from(left[i]);
            let floor = FLOOR * f64::from(left[i] + right[i]);
            let want = encoder.code(LinearRgb(nodes.0.map(|v| v.max(floor))));
            assert_eq!(code.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
        }
        let x = (w - 1) as usize; // the right edge: the right node alone, at black
        assert!(
            (f64::from(shaded[x][0]) - FLOOR).abs() < 1e-6,
            "{:?}",
            shaded[x]
        );
    }

    /// A pixel in 255 nodes is taken, in 256 refused with the projector named; the nodes of
    /// other projectors are not counted.
    #[test]
    fn pixel_nodes_refuse_a_pixel_in_too_many_nodes() {
        let region = |projector: usize| NodeRegion {
            projector,
            weights: vec![0.5, 0.0],
        };
        let mut regions: Vec<NodeRegion> = (0..255).map(|_| region(0)).collect();
        regions.push(region(1));
        let nodes = PixelNodes::new(2, 1, &regions, 0).expect("255 nodes on pixel 0");
        assert_eq!(nodes.counts, vec![255, 0]);
        assert_eq!(nodes.row_start, vec![0, 255]);
        regions.push(region(0));
        let e = PixelNodes::new(2, 1, &regions, 0).expect_err("256 nodes on pixel 0");
        assert!(format!("{e:#}").contains("projector 0"), "{e:#}");
    }
}
