//! Nodes shaped to the room's own light (issue 22 item 2). A node drives one colour over its
//! region, so where the LEDs' light falls off across a wall differently from a projector's
//! white (their distances and angles to the surface differ), the room drifts away from the
//! colour its node was fitted to at the chart. Given a photograph of the room under its own
//! lighting with every projector dark ([`super::Setup::reference`]), each luminaire's node
//! weights are multiplied by how much more light the reference gives than the projector's white
//! at the surface each projector pixel lights, relative to that ratio's median over the node
//! (capped at weight 1: see [`MAX_SHAPE`]). Inside the node's region its light then follows the
//! reference's falloff wherever that is dimmer than typical. Across overlaps every projector is
//! shaped to the same reference, so the blend still adds up to it. The attenuation is measured
//! after the shaping ([`super::Procedure::bring_up`]): the model knows the shaped nodes exactly,
//! and the blend itself (what the partition of unity is checked on) is the unshaped one.
//!
//! One scalar per projector pixel (luminance): the weights are scalar, so colour that varies
//! across a region is still the node's one colour. Hand-written (a ratio of two images on a
//! coarse grid of projector blocks); nothing in a crate does it.

use super::{Layout, Placed, Setup};
use crate::CalibError;
use crate::blocks::{fill, quantile};
use crate::graycode::Correspondence;
use crate::image_io::LinearImage;
use roomlight_core::LinearRgb;
use roomlight_core::metrics::luminance;

/// Side of a block of projector pixels over which the ratio is read. Falloff varies slowly;
/// a wall projector's block of 16 sees some 40 camera pixels.
const BLOCK: u32 = 16;

/// A camera pixel counts towards a block only when the projector's white raises it by at
/// least this share of its 99th percentile: dimmer, its ratio is mostly noise.
const MIN_SHARE: f64 = 0.02;

/// Bounds of a pixel's shape against its node's typical ratio: the reference's falloff is
/// followed up to four times brighter or twenty times dimmer, no further (a shadow the
/// reference has and the projector not, a saturated pixel missed). A shaped weight is capped
/// at 1, so a node's fully driven pixels only dim: it keeps all the light it had where the
/// reference is brighter than typical (scaling a node down to give those pixels more cost the
/// demo's saturated warm preset 1.8 ΔE00 at its charts, docs/results.md). The typical ratio
/// is the node's median, not its chart's: normalised at the chart, the lab's paper preset
/// ended at whole-room ΔE00 11.0 against 9.2.
const MAX_SHAPE: f64 = 4.0;
const MIN_SHAPE: f64 = 0.05;

/// What shaping did to one projector's nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Shaped {
    pub projector: String,
    /// Nodes shaped.
    pub nodes: usize,
    /// The 5th and 95th percentiles of the shape over the projector's driven pixels (1: as the
    /// node's typical pixel; below: the reference is dimmer there than the projector's white).
    pub spread: (f32, f32),
}

/// One projector's white capture (the room dark but it) and its decode.
#[derive(Debug, Clone, Copy)]
pub struct Lit<'a> {
    pub white: &'a LinearImage,
    pub corr: &'a Correspondence,
}

/// How one projector's nodes are shaped: the reference-to-white ratio over its frame, and per
/// node its typical ratio;
/// kept with the projector's nodes ([`Placed::shape`]) so that nodes placed again (another
/// target mask) are shaped the same.
#[derive(Debug, Clone, PartialEq)]
pub struct Shape {
    grid: Grid,
    /// Per node, in order: its typical ratio (the median over the pixels it fully drives),
    /// `None` for a node left flat.
    nodes: Vec<Option<f64>>,
}

impl Shape {
    /// Multiplies `weights` (node `k`'s of this projector) by its shape, capped at 1.
    fn apply_to(&self, k: usize, weights: &mut [f32]) -> Vec<f64> {
        let Some(Some(typical)) = self.nodes.get(k) else {
            return Vec::new();
        };
        let mut applied = Vec::new();
        for (i, w) in weights.iter_mut().enumerate() {
            if *w > 0.0 {
                let s = (self.grid.at(i, *typical) / typical).clamp(MIN_SHAPE, MAX_SHAPE);
                *w = ((*w as f64) * s).min(1.0) as f32;
                applied.push(s);
            }
        }
        applied
    }

    /// Shapes `p`'s nodes (flat, as placed); the number of nodes must be the one measured.
    pub fn apply(&self, p: &mut Placed) -> Result<Shaped, CalibError> {
        if p.nodes.len() != self.nodes.len() {
            return Err(CalibError::Invalid {
                field: "shape",
                problem: format!(
                    "{}: {} nodes placed, {} shaped",
                    p.projector.id,
                    p.nodes.len(),
                    self.nodes.len()
                ),
            });
        }
        let mut all = Vec::new();
        for (k, node) in p.nodes.iter_mut().enumerate() {
            all.extend(self.apply_to(k, &mut node.weights));
        }
        let spread = (
            quantile(&mut all, 0.05).unwrap_or(1.0) as f32,
            quantile(&mut all, 0.95).unwrap_or(1.0) as f32,
        );
        p.shape = Some(self.clone());
        Ok(Shaped {
            projector: p.projector.id.clone(),
            nodes: self.nodes.iter().flatten().count(),
            spread,
        })
    }
}

/// Shapes the nodes of every charted projector in `placed` to `reference` (the room under its
/// own lighting, projectors dark), `lit[k]` being `placed[k]`'s white and decode (`None`: left
/// as it is, like a whole-frame node), and keeps each projector's [`Shape`] with it. Errors
/// when an image's size is not the camera's.
pub fn shape(
    setup: &Setup,
    reference: &LinearImage,
    dark: &LinearImage,
    placed: &mut [Placed],
    lit: &[Option<Lit<'_>>],
) -> Result<Vec<Shaped>, CalibError> {
    let pixels = setup.target_mask.len();
    for (what, image) in [("reference", reference), ("dark", dark)] {
        if image.pixels.len() != pixels {
            return Err(CalibError::Invalid {
                field: "reference",
                problem: format!(
                    "the {what} image has {} pixels, the camera {pixels}",
                    image.pixels.len()
                ),
            });
        }
    }
    let mut out = Vec::new();
    for (p, lit) in placed.iter_mut().zip(lit) {
        let Some(lit) = lit else { continue };
        if p.layout != Layout::Charted || p.nodes.is_empty() {
            continue;
        }
        if lit.white.pixels.len() != pixels || lit.corr.map.len() != pixels {
            return Err(CalibError::Invalid {
                field: "reference",
                problem: format!(
                    "{}: its white or decode has {} or {} pixels, the camera {pixels}",
                    p.projector.id,
                    lit.white.pixels.len(),
                    lit.corr.map.len()
                ),
            });
        }
        let usable = Usable {
            setup,
            reference,
            dark,
            white: lit.white,
            saturation: setup.sample.saturation,
            floor: MIN_SHARE * white_p99(lit, dark),
        };
        let Some(grid) = Grid::read(&usable, lit.corr) else {
            continue;
        };
        let nodes = p
            .nodes
            .iter()
            .map(|node| {
                grid.median(&node.weights)
                    .filter(|r| *r > 0.0 && r.is_finite())
            })
            .collect();
        out.push(Shape { grid, nodes }.apply(p)?);
    }
    Ok(out)
}

/// The luminance `a` adds over `b` (negative where it is darker).
fn rise(a: [f32; 3], b: [f32; 3]) -> f64 {
    luminance(LinearRgb(a.map(f64::from)) - LinearRgb(b.map(f64::from)))
}

/// The 99th percentile of the white's rise over dark on the decoded camera pixels (0 if none).
fn white_p99(lit: &Lit<'_>, dark: &LinearImage) -> f64 {
    let mut v: Vec<f64> = lit
        .corr
        .map
        .iter()
        .zip(lit.white.pixels.iter().zip(&dark.pixels))
        .filter(|(m, _)| m.is_some())
        .map(|(_, (w, d))| rise(*w, *d))
        .collect();
    quantile(&mut v, 0.99).unwrap_or(0.0)
}

/// Which camera pixels carry a ratio, and what they read.
struct Usable<'a> {
    setup: &'a Setup,
    reference: &'a LinearImage,
    dark: &'a LinearImage,
    white: &'a LinearImage,
    saturation: f32,
    floor: f64,
}

impl Usable<'_> {
    /// Camera pixel `c`'s reference and white light above dark, or `None` where it should not
    /// count: on the target, saturated in either image, or too dim in the white.
    fn read(&self, c: usize) -> Option<(f64, f64)> {
        if self.setup.target_mask[c] {
            return None;
        }
        let (r, w) = (self.reference.pixels[c], self.white.pixels[c]);
        if r.iter()
            .chain(&w)
            .any(|v| !v.is_finite() || *v >= self.saturation)
        {
            return None;
        }
        let d = self.dark.pixels[c];
        let white = rise(w, d);
        (white >= self.floor && white > 0.0).then(|| (rise(r, d).max(0.0), white))
    }
}

/// The reference-to-white ratio on blocks of projector pixels: read where enough camera pixels
/// see the block, carried up to [`FILL_BLOCKS`] blocks on (a footprint's rim, a block the
/// camera sees too few pixels of); unknown beyond
/// (a face the camera does not see, a reference saturated there), where a node stays flat.
#[derive(Debug, Clone, PartialEq)]
struct Grid {
    /// Projector width, blocks across and down.
    width: usize,
    across: usize,
    down: usize,
    ratio: Vec<Option<f64>>,
}

/// How many blocks a read ratio is carried on into blocks without one.
const FILL_BLOCKS: u32 = 2;

impl Grid {
    /// `None` when no block could be read (the projector lights nothing the camera can use).
    fn read(usable: &Usable<'_>, corr: &Correspondence) -> Option<Self> {
        let (pw, ph) = (corr.projector_width, corr.projector_height);
        let across = pw.div_ceil(BLOCK) as usize;
        let down = ph.div_ceil(BLOCK) as usize;
        let mut sums = vec![(0.0f64, 0.0f64, 0u32); across * down];
        for (c, m) in corr.map.iter().enumerate() {
            let Some((x, y)) = *m else { continue };
            let Some((r, w)) = usable.read(c) else {
                continue;
            };
            let b = (y / BLOCK) as usize * across + (x / BLOCK) as usize;
            if let Some(s) = sums.get_mut(b) {
                s.0 += r;
                s.1 += w;
                s.2 += 1;
            }
        }
        // A block needs a few camera pixels; its white sum is then above zero (each read one
        // is above the floor).
        let mut ratio: Vec<Option<f64>> = sums
            .iter()
            .map(|&(r, w, n)| (n >= 3 && w > 0.0).then(|| r / w))
            .collect();
        if !fill(&mut ratio, across, FILL_BLOCKS) {
            return None;
        }
        Some(Self {
            width: pw as usize,
            across,
            down,
            ratio,
        })
    }

    /// The ratio at projector pixel `i` (row-major), bilinear between block centres, a block
    /// without one counting as `unknown`.
    fn at(&self, i: usize, unknown: f64) -> f64 {
        let (x, y) = ((i % self.width) as f64, (i / self.width) as f64);
        let b = BLOCK as f64;
        let fx = ((x + 0.5) / b - 0.5).clamp(0.0, (self.across - 1) as f64);
        let fy = ((y + 0.5) / b - 0.5).clamp(0.0, (self.down - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.across - 1), (y0 + 1).min(self.down - 1));
        let (tx, ty) = (fx - x0 as f64, fy - y0 as f64);
        let r = |x: usize, y: usize| self.ratio[y * self.across + x].unwrap_or(unknown);
        let top = r(x0, y0) * (1.0 - tx) + r(x1, y0) * tx;
        let bottom = r(x0, y1) * (1.0 - tx) + r(x1, y1) * tx;
        top * (1.0 - ty) + bottom * ty
    }

    /// The median read ratio over the pixels a node fully drives (weight ≥ ½), else over all
    /// it drives; `None` when it reads none.
    fn median(&self, weights: &[f32]) -> Option<f64> {
        let of = |least: f32| {
            let mut v: Vec<f64> = weights
                .iter()
                .enumerate()
                .filter(|(_, w)| **w >= least && **w > 0.0)
                .map(|(i, _)| self.at(i, f64::NAN))
                .filter(|r| r.is_finite())
                .collect();
            quantile(&mut v, 0.5)
        };
        of(0.5).or_else(|| of(0.0))
    }
}

#[cfg(test)]
mod tests;
