//! The Rig: what differs between the places calibration runs (the in-process simulator, the
//! camera agent over the wire, a bench). It owns which projectors are live, showing frames on
//! them, and capturing whole linear images; the calibration procedure
//! ([`crate::procedure`]) is written once against it. This module knows patterns, node
//! drawings and images; it must not know processes, networks, runtimes or the simulator.

use crate::graycode::{Coding, Manifest, Pattern, Primary};
use crate::image_io::LinearImage;
use crate::response::Response;
use roomlight_core::LinearRgb;
use std::future::Future;
use std::sync::Arc;
use std::task::{Context, Poll, Wake, Waker};

/// How a projector's optics render a pattern: a large aperture's defocus blurs fine stripes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProjectorKind {
    Standard,
    LargeAperture,
}

/// What a projector is for: luminaires are calibrated and lit by node values; texture
/// projectors are only kept dark while the luminaires are measured.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProjectorRole {
    Luminaire,
    Texture,
}

/// A live projector, as the rig knows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Projector {
    /// Its name (over the wire: the node agent's projector id).
    pub id: String,
    pub width: u32,
    pub height: u32,
    pub kind: ProjectorKind,
    pub role: ProjectorRole,
}

impl Projector {
    /// Whether its nodes blend with other projectors' (a standard luminaire): where another
    /// such projector was decoded, that one can take the light.
    pub fn blends(&self) -> bool {
        self.kind == ProjectorKind::Standard && self.role == ProjectorRole::Luminaire
    }
}

/// What one projector shows until told otherwise.
#[derive(Debug, Clone, PartialEq)]
pub enum Frame {
    /// Every pixel at this code per channel, in [0, 1] (0: black).
    Uniform([f32; 3]),
    /// A structured-light pattern of the projector's own resolution, over code cells of
    /// `cell × cell` pixels ([`Manifest::with_cell`]), its stripes white or in one `primary`
    /// (groups coded at once in different colours, [`crate::graycode::Unmixing`]).
    Structured {
        pattern: Pattern,
        coding: Coding,
        cell: u32,
        primary: Option<Primary>,
    },
    /// A structured-light pattern shown only where `shown` (row-major projector pixels) is
    /// true and black elsewhere: a second pass's patterns. Only for rigs that
    /// [`Rig::shows_masks`].
    Masked {
        pattern: Pattern,
        coding: Coding,
        cell: u32,
        shown: Arc<[bool]>,
    },
    /// Node values (linear light) drawn through the projector's [`Assignment`]; nodes not
    /// listed are black.
    Nodes(Vec<(u32, LinearRgb)>),
}

impl Frame {
    /// Black: code 0 everywhere.
    pub const BLACK: Self = Self::Uniform([0.0; 3]);

    /// The frame as codes for a `width`×`height` projector drawing nodes with `assignment`
    /// (for rigs that render frames themselves). Node values without an assignment draw
    /// black; an image of another size is refused.
    pub fn codes(
        &self,
        width: u32,
        height: u32,
        assignment: Option<&Assignment>,
    ) -> Result<Vec<[f32; 3]>, crate::CalibError> {
        let n = (width * height) as usize;
        match self {
            Self::Uniform(code) => Ok(vec![*code; n]),
            Self::Structured {
                pattern,
                coding,
                cell,
                primary,
            } => {
                let manifest = Manifest::with_cell(width, height, *coding, *cell)?;
                let mut codes = manifest.pattern_image(*pattern).pixels;
                if let Some(primary) = primary {
                    primary.tint(&mut codes);
                }
                Ok(codes)
            }
            Self::Masked {
                pattern,
                coding,
                cell,
                shown,
            } => {
                let manifest = Manifest::with_cell(width, height, *coding, *cell)?;
                Ok(manifest.pattern_image_where(*pattern, shown)?.pixels)
            }
            Self::Nodes(values) => Ok(match assignment {
                Some(a) if a.width == width && a.height == height => a.draw(values),
                _ => vec![[0.0; 3]; n],
            }),
        }
    }
}

/// How a projector draws its nodes: each node's feathered weights (row-major pixels,
/// increasing, weights in (0, 1]) and the projector's measured response.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Assignment {
    pub width: u32,
    pub height: u32,
    pub response: Response,
    /// `(node id, [(pixel, weight)])`.
    pub nodes: Vec<(u32, Vec<(u32, f32)>)>,
}

impl Assignment {
    /// The codes that show `values` (linear light per node; unlisted nodes black): each
    /// pixel's light is the sum of its nodes' weights times their values, turned into a code
    /// through the response.
    pub fn draw(&self, values: &[(u32, LinearRgb)]) -> Vec<[f32; 3]> {
        self.draw_shaded(values, None)
    }

    /// [`Self::draw`] with each pixel's light shaded by `gains` (per-pixel shading: the floor
    /// and the gains of [`crate::shading::shaded_light`]); gains of another projector size, or
    /// none, draw the nodes' light as it is.
    pub fn draw_shaded(
        &self,
        values: &[(u32, LinearRgb)],
        gains: Option<&crate::shading::Gains>,
    ) -> Vec<[f32; 3]> {
        let mut last = None;
        self.light_shaded(values, gains)
            .into_iter()
            .map(|l| self.response.to_code_after(l, &mut last))
            .collect()
    }

    /// Each pixel's light as [`Self::draw_shaded`] draws it, before the response turns it into
    /// a code (so not clipped at full light).
    pub fn light_shaded(
        &self,
        values: &[(u32, LinearRgb)],
        gains: Option<&crate::shading::Gains>,
    ) -> Vec<LinearRgb> {
        let n = (self.width * self.height) as usize;
        let mut light = vec![LinearRgb::ZERO; n];
        let gains = gains.filter(|g| g.size() == (self.width, self.height));
        let mut weight = vec![0.0f64; if gains.is_some() { n } else { 0 }];
        for (node, weights) in &self.nodes {
            let Some(&(_, v)) = values.iter().find(|(n, _)| n == node) else {
                continue;
            };
            for &(i, w) in weights {
                if let Some(l) = light.get_mut(i as usize) {
                    *l += v * f64::from(w);
                }
                if let Some(s) = weight.get_mut(i as usize) {
                    *s += f64::from(w);
                }
            }
        }
        if let Some(g) = gains {
            let width = self.width.max(1);
            for (i, (l, w)) in light.iter_mut().zip(&weight).enumerate() {
                let i = i as u32;
                *l = LinearRgb(crate::shading::shaded_light(
                    l.0,
                    *w,
                    g.at(i % width, i / width),
                ));
            }
        }
        light
    }
}

/// Why the rig could not do what it was asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigError {
    /// The projector is not live (it left, or never was).
    #[error("projector {0} is not live")]
    Gone(String),
    /// A frame was not on the projector within the rig's deadline.
    #[error("projector {0} did not show its frame in time")]
    NotShown(String),
    /// The rig cannot show this kind of frame on it.
    #[error("projector {0} cannot show {1}")]
    Unsupported(String, &'static str),
    /// The camera failed.
    #[error("camera: {0}")]
    Camera(String),
    /// The worker that ran [`Rig::offload`]ed work failed.
    #[error("worker: {0}")]
    Worker(String),
}

/// The camera's limits that calibration plans with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraLimits {
    /// The level (per channel, capture units) at which a pixel saturates.
    pub saturation: f32,
    /// The longest exposure [`Rig::capture`] takes, as a multiple of the normal one (1: the
    /// camera has one exposure).
    pub longest_exposure: f32,
}

/// What differs between the callers of the calibration procedure. Async because the camera
/// agent waits on node agents and its camera; a rig that works synchronously returns ready
/// futures and its caller drives them with [`block_on`].
pub trait Rig: Send {
    /// The live projectors.
    fn projectors(&self) -> Vec<Projector>;

    /// Shows each frame on its projector (by id) and resolves once all are on; projectors not
    /// named keep what they show.
    fn show(
        &mut self,
        frames: &[(&str, Frame)],
    ) -> impl Future<Output = Result<(), RigError>> + Send;

    /// Hands a projector the drawing of its nodes (later [`Frame::Nodes`] use it).
    fn assign(
        &mut self,
        projector: &str,
        assignment: &Assignment,
    ) -> impl Future<Output = Result<(), RigError>> + Send;

    /// One whole linear image exposed `exposure` times as long as normal (at most
    /// [`CameraLimits::longest_exposure`]), in the units of a normal one.
    fn capture(
        &mut self,
        exposure: f32,
    ) -> impl Future<Output = Result<LinearImage, RigError>> + Send;

    /// The camera's limits.
    fn camera(&self) -> CameraLimits;

    /// Whether [`Frame::Masked`] can be shown (a second structured-light pass needs it).
    fn shows_masks(&self) -> bool {
        false
    }

    /// Runs CPU-heavy work (decoding, segmentation) where it does not stall the rig's other
    /// duties: an async rig hands it to a blocking thread; by default it runs in place.
    fn offload<T: Send + 'static>(
        &mut self,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> impl Future<Output = Result<T, RigError>> + Send {
        std::future::ready(Ok(work()))
    }
}

/// Wakes the thread that blocks on a future.
struct Unpark(std::thread::Thread);

impl Wake for Unpark {
    fn wake(self: Arc<Self>) {
        self.0.unpark();
    }
}

/// Runs a future to completion on this thread: for callers without a runtime driving a rig
/// whose futures complete without one (the simulator, a bench). Never call it on an async
/// runtime's worker thread.
pub fn block_on<F: Future>(future: F) -> F::Output {
    let waker = Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = Context::from_waker(&waker);
    let mut future = std::pin::pin!(future);
    loop {
        match future.as_mut().poll(&mut cx) {
            Poll::Ready(out) => return out,
            Poll::Pending => std::thread::park(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel's code is the response to its nodes' summed light, bit for bit, in the flat
    /// insides (where a code is reused) and in the feathered band alike; unlisted nodes draw
    /// black.
    #[test]
    fn draw_codes_each_pixels_summed_light() {
        let (width, height) = (40u32, 3u32);
        let n = (width * height) as usize;
        // Node 1 on columns 0–24, node 2 on 15–39, feathered over 15–24; node 3 unlisted.
        let weight = |i: usize, lo: u32, hi: u32, rising: bool| {
            let x = i as u32 % width;
            if x < lo || x > hi {
                return 0.0;
            }
            let t = (x.saturating_sub(15) as f32 / 10.0).min(1.0);
            if rising {
                t.max(0.05)
            } else {
                (1.0 - t).max(0.05)
            }
        };
        let node = |id: u32, lo: u32, hi: u32, rising: bool| {
            let weights: Vec<(u32, f32)> = (0..n)
                .map(|i| (i as u32, weight(i, lo, hi, rising)))
                .filter(|(_, w)| *w > 0.0)
                .collect();
            (id, weights)
        };
        let a = Assignment {
            width,
            height,
            response: Response {
                gamma: [2.2, 2.0, 2.4],
                max_residual: [0.0; 3],
            },
            nodes: vec![
                node(1, 0, 24, false),
                node(2, 15, 39, true),
                node(3, 0, 39, true),
            ],
        };
        let values = [
            (1, LinearRgb([0.3, 0.6, 0.9])),
            (2, LinearRgb([0.8, 0.2, 0.5])),
        ];
        let codes = a.draw(&values);
        assert_eq!(codes.len(), n);
        let mut distinct = std::collections::HashSet::new();
        for (i, code) in codes.iter().enumerate() {
            let mut light = LinearRgb::ZERO;
            for (id, weights) in &a.nodes[..2] {
                let v = values
                    .iter()
                    .find(|(m, _)| m == id)
                    .map(|(_, v)| *v)
                    .expect("a listed node");
                if let Some((_, w)) = weights.iter().find(|(p, _)| *p as usize == i) {
                    light += v * f64::from(*w);
                }
            }
            let want = a.response.to_code(light);
            assert_eq!(code.map(f32::to_bits), want.map(f32::to_bits), "pixel {i}");
            distinct.insert(code.map(f32::to_bits));
        }
        assert!(distinct.len() > 10, "the feathered band has its own codes");
    }

    /// Shaded drawing: flat gains keep a lit node's codes, a black node's pixels rise to the
    /// floor by its weight, stepped gains scale each channel's light where the camera asked,
    /// and gains of another size are ignored.
    #[test]
    fn draw_shaded_applies_the_floor_and_the_gains() {
        use crate::shading::{BLOCK, FLOOR, Gains, Ratios};
        let (width, height) = (2 * BLOCK, BLOCK);
        let n = width * height;
        let a = Assignment {
            width,
            height,
            response: Response::linear(),
            // Node 1 over the left half at weight 1, node 2 over the right half at 0.5.
            nodes: vec![
                (
                    1,
                    (0..n)
                        .filter(|i| i % width < BLOCK)
                        .map(|i| (i, 1.0))
                        .collect(),
                ),
                (
                    2,
                    (0..n)
                        .filter(|i| i % width >= BLOCK)
                        .map(|i| (i, 0.5))
                        .collect(),
                ),
            ],
        };
        let values = [(1, LinearRgb([0.4, 0.2, 0.1])), (2, LinearRgb::ZERO)];
        let plain = a.draw(&values);
        let flat = Gains::flat(width, height).expect("gains");
        let flat_codes = a.draw_shaded(&values, Some(&flat));
        let (left, right) = (8 * width + 3, 8 * width + width - 3);
        let bits = |c: [f32; 3]| c.map(f32::to_bits);
        assert_eq!(bits(flat_codes[left as usize]), bits(plain[left as usize]));
        assert_eq!(bits(plain[right as usize]), bits([0.0; 3]));
        for c in flat_codes[right as usize] {
            assert!((f64::from(c) - FLOOR * 0.5).abs() < 1e-6, "{c}");
        }
        // Double the red on the left block, the rest as it is.
        let ratios = Ratios::from_blocks(
            width,
            height,
            vec![Some([2.0, 1.0, 1.0]), Some([1.0, 1.0, 1.0])],
        )
        .expect("ratios");
        let mut g = flat.clone();
        g.step(&ratios, 1.0).expect("step");
        let shaded = a.draw_shaded(&values, Some(&g));
        let far_left = (8 * width) as usize;
        assert!(
            (shaded[far_left][0] - 0.8).abs() < 1e-6,
            "{:?}",
            shaded[far_left]
        );
        assert!((shaded[far_left][1] - 0.2).abs() < 1e-6);
        let other = Gains::flat(width + 1, height).expect("gains");
        let all_bits = |v: Vec<[f32; 3]>| v.into_iter().map(bits).collect::<Vec<_>>();
        assert_eq!(
            all_bits(a.draw_shaded(&values, Some(&other))),
            all_bits(plain)
        );
    }
}
