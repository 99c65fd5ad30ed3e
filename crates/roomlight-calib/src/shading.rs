//! Per-pixel shading: each luminaire's light follows the room's reference photograph pixel by
//! pixel and colour channel by channel, not only at the charts (issue 22 item 2).
//!
//! A node drives one colour over its region; the LEDs' light varies across that region by the
//! surfaces' angles and distances to the LEDs (not the projector's), by the LED panels a preset
//! turns on, and by inter-reflection. What the camera sees of the whole room closes that gap:
//! with a photograph of the room under the LEDs (`reference`, projectors dark), one with the
//! projectors' current light (`current`, LEDs off) and the room dark (`dark`), every camera
//! pixel says by how much the projectors' light there should be multiplied, per channel:
//! `(reference − dark) / (current − dark)`. Through each projector's decode those ratios land on
//! blocks of its pixels ([`ratios`]), and the projector multiplies its drawn light by a gain per
//! block and channel, bilinear between block centres ([`Gains`]), stepped a power `rate` of the
//! ratio at a time ([`Gains::step`]). Every projector lighting a camera pixel gets that pixel's
//! ratio, so overlaps keep their blend: a multiplicative step of all the light a pixel receives.
//! Inter-reflection makes one step fall short; a few passes converge (docs/results.md).
//!
//! A block that cannot give what its ratio asks in some channel (already at full light there:
//! its headroom, [`headroom`], from what it draws) steps instead to the colour closest in ΔE00
//! to the LEDs' that it can still give ([`closest_within`], [`Gains::step_within`]), from the
//! block's light that [`ratios`] keeps beside its ratio.
//!
//! Bounds: a pass moves a block's gain by at most [`MAX_STEP`] either way, and a gain stays
//! within [`MIN_GAIN`]..[`MAX_GAIN`]; a block the camera does not read (too few decoded pixels,
//! too dim in the current light, saturated, on the target) is filled from read blocks up to
//! [`FILL_BLOCKS`] away, and beyond keeps its gain. No NaN or infinity can reach a gain: every
//! ratio is of finite, non-negative sums with a positive floor under the denominator.
//!
//! Hand-written: a ratio of images binned through a correspondence, no crate does it.

use crate::CalibError;
use crate::blocks::{fill, quantile};
use crate::graycode::Correspondence;
use crate::image_io::LinearImage;
use roomlight_core::LinearRgb;
use roomlight_core::metrics::{ciede2000, lab_from_linear_rgb, luminance};

/// Side of a block of projector pixels that carries one gain. A wall projector's block sees
/// some 40 camera pixels in the lab: enough to average the camera's noise down.
pub const BLOCK: u32 = 16;

/// Bounds of a gain: light down to 1/32 of the node's (a corner the LEDs leave dark) and up to
/// 64 times (a node its chart keeps dim, asked for much more light away from it; the
/// projector's codes clip at full light anyway). Measured on the lab: 8 instead moved its
/// whole-room figures by at most 0.13 ΔE00.
pub const MIN_GAIN: f32 = 1.0 / 32.0;
pub const MAX_GAIN: f32 = 64.0;

/// The light a shaded pixel starts from, at least, per unit of its nodes' summed weight: a
/// node its chart turned (almost) off still has light to shade, where the LEDs light what only
/// it reaches. A fiftieth of full light: with [`MAX_GAIN`] a dark node's pixels reach full
/// light, and the first pass dims what the LEDs leave dark ([`shaded_light`]).
pub const FLOOR: f64 = 0.02;

/// A pixel's light with its gains: its nodes' light `light` (their weighted sum, `weight` the
/// sum of their weights there), raised per channel to at least [`FLOOR`] × `weight`, times
/// `gain`. A pixel no node drives (`weight` 0) stays as its nodes give it.
pub fn shaded_light(light: [f64; 3], weight: f64, gain: [f32; 3]) -> [f64; 3] {
    if weight.is_nan() || weight <= 0.0 {
        return light;
    }
    std::array::from_fn(|c| light[c].max(FLOOR * weight) * f64::from(gain[c]))
}

/// One pass moves a gain by at most this factor up or down.
pub const MAX_STEP: f64 = 4.0;

/// How many blocks a read ratio is carried on into blocks without one.
pub const FILL_BLOCKS: u32 = 2;

/// A camera pixel counts only when the projectors' current light raises it by at least this
/// share of the 99th percentile of that rise over the decoded pixels: dimmer, its ratio is
/// mostly noise.
const MIN_SHARE: f64 = 0.02;

/// A block needs this many usable camera pixels.
const MIN_PIXELS: u32 = 3;

/// The photographs one pass reads, all the camera's size.
#[derive(Debug, Clone, Copy)]
pub struct Photographs<'a> {
    /// The room under the LEDs, projectors dark.
    pub reference: &'a LinearImage,
    /// The room under the projectors' current light, LEDs off.
    pub current: &'a LinearImage,
    /// The room dark.
    pub dark: &'a LinearImage,
    /// Camera pixels left out (the projection-mapping target: its light is not the room's).
    pub excluded: &'a [bool],
    /// The camera's saturation level: a pixel at or above it in any image is left out.
    pub saturation: f32,
}

/// Per block of one projector's pixels and per channel, the factor its light should be
/// multiplied by; `None` where the camera does not read it.
#[derive(Debug, Clone, PartialEq)]
pub struct Ratios {
    width: u32,
    height: u32,
    across: usize,
    down: usize,
    ratio: Vec<Option<[f64; 3]>>,
    /// Per block read (not filled), the LEDs' light and the current one above the dark room,
    /// the camera's mean over the block (in the camera's units from [`ratios`], in units of
    /// the white's luminance after [`Ratios::relative_to`]); `None` elsewhere, or all `None`
    /// when unknown (a step then takes the plain ratios).
    light: Vec<Option<[[f64; 3]; 2]>>,
}

impl Ratios {
    /// Blocks read (or filled) out of all.
    pub fn read(&self) -> (usize, usize) {
        (self.ratio.iter().flatten().count(), self.ratio.len())
    }

    /// The projector's size the blocks cover.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Each block's ratio, row-major, [`BLOCK`] pixels a side (`None`: not read).
    pub fn blocks(&self) -> &[Option<[f64; 3]>] {
        &self.ratio
    }

    /// Each block's light, the LEDs' and the current (see the field): what
    /// [`Gains::step_within`] needs to choose a colour where a channel is short of headroom.
    pub fn light(&self) -> &[Option<[[f64; 3]; 2]>] {
        &self.light
    }

    /// The light in units of `white` (the LEDs' luminance that is L* = 100, [`white`]); a
    /// `white` that is not finite and positive drops it (the steps take the plain ratios).
    pub fn relative_to(mut self, white: f64) -> Self {
        if white.is_finite() && white > 0.0 {
            for l in self.light.iter_mut().flatten() {
                *l = l.map(|v| v.map(|x| x / white));
            }
        } else {
            self.light.iter_mut().for_each(|l| *l = None);
        }
        self
    }

    /// These ratios with each block's light in units of the white (from the camera agent,
    /// one entry per block): every value finite within `0..=MAX_LIGHT`, else refused with the
    /// block it found.
    pub fn with_light(mut self, light: Vec<Option<[[f64; 3]; 2]>>) -> Result<Self, CalibError> {
        if light.len() != self.ratio.len() {
            return Err(CalibError::Invalid {
                field: "shading light",
                problem: format!(
                    "{} blocks, the ratios have {}",
                    light.len(),
                    self.ratio.len()
                ),
            });
        }
        if let Some(i) = light.iter().position(|l| {
            l.is_some_and(|l| l.iter().flatten().any(|v| !(0.0..=MAX_LIGHT).contains(v)))
        }) {
            return Err(CalibError::Invalid {
                field: "shading light",
                problem: format!(
                    "block {i} has {:?}, expected within 0..={MAX_LIGHT}",
                    light[i]
                ),
            });
        }
        self.light = light;
        Ok(self)
    }

    /// Ratios received for a `width`×`height` projector (from the camera agent): one entry per
    /// block of [`BLOCK`] pixels, row-major, each `None` or three finite ratios within
    /// 1/[`MAX_STEP`]..[`MAX_STEP`]. Anything else is refused with the block it found.
    pub fn from_blocks(
        width: u32,
        height: u32,
        blocks: Vec<Option<[f64; 3]>>,
    ) -> Result<Self, CalibError> {
        let invalid = |problem: String| CalibError::Invalid {
            field: "shading ratios",
            problem,
        };
        if width == 0 || height == 0 {
            return Err(invalid(format!("a {width}×{height} projector")));
        }
        let across = width.div_ceil(BLOCK) as usize;
        let down = height.div_ceil(BLOCK) as usize;
        if blocks.len() != across * down {
            return Err(invalid(format!(
                "{} blocks, a {width}×{height} projector has {across}×{down}",
                blocks.len()
            )));
        }
        let range = (1.0 / MAX_STEP)..=MAX_STEP;
        if let Some((i, r)) = blocks.iter().enumerate().find_map(|(i, b)| {
            b.filter(|r| !r.iter().all(|v| range.contains(v)))
                .map(|r| (i, r))
        }) {
            return Err(invalid(format!(
                "block {i} has ratios {r:?}, expected within 1/{MAX_STEP}..{MAX_STEP}"
            )));
        }
        let light = vec![None; blocks.len()];
        Ok(Self {
            width,
            height,
            across,
            down,
            ratio: blocks,
            light,
        })
    }
}

/// The ratio of the reference's light to the current one on blocks of the projector that
/// `corr` decodes, each block's ratio the ratio of its pixels' sums (per channel, so noise
/// averages before it divides). Errors name the image whose size is not the camera's.
pub fn ratios(photos: &Photographs<'_>, corr: &Correspondence) -> Result<Ratios, CalibError> {
    let pixels = corr.map.len();
    for (what, len) in [
        ("reference", photos.reference.pixels.len()),
        ("current", photos.current.pixels.len()),
        ("dark", photos.dark.pixels.len()),
        ("excluded", photos.excluded.len()),
    ] {
        if len != pixels {
            return Err(CalibError::Invalid {
                field: "shading",
                problem: format!("the {what} image has {len} pixels, the decode {pixels}"),
            });
        }
    }
    let (pw, ph) = (corr.projector_width, corr.projector_height);
    if pw == 0 || ph == 0 {
        return Err(CalibError::Invalid {
            field: "shading",
            problem: format!("the decode's projector is {pw}×{ph}"),
        });
    }
    let across = pw.div_ceil(BLOCK) as usize;
    let down = ph.div_ceil(BLOCK) as usize;
    let rise = |c: usize| -> Option<([f64; 3], [f64; 3])> {
        if photos.excluded[c] {
            return None;
        }
        let (r, u, d) = (
            photos.reference.pixels[c],
            photos.current.pixels[c],
            photos.dark.pixels[c],
        );
        if r.iter()
            .chain(&u)
            .chain(&d)
            .any(|v| !v.is_finite() || *v >= photos.saturation)
        {
            return None;
        }
        let up =
            |a: [f32; 3]| std::array::from_fn(|i| (f64::from(a[i]) - f64::from(d[i])).max(0.0));
        Some((up(r), up(u)))
    };
    let mean = |v: [f64; 3]| (v[0] + v[1] + v[2]) / 3.0;
    let mut lit: Vec<f64> = corr
        .map
        .iter()
        .enumerate()
        .filter(|(_, m)| m.is_some())
        .filter_map(|(c, _)| rise(c).map(|(_, u)| mean(u)))
        .collect();
    let floor = MIN_SHARE * quantile(&mut lit, 0.99).unwrap_or(0.0);
    let mut sums = vec![([0.0f64; 3], [0.0f64; 3], 0u32); across * down];
    for (c, m) in corr.map.iter().enumerate() {
        let Some((x, y)) = *m else { continue };
        let Some((r, u)) = rise(c) else { continue };
        if mean(u) < floor || mean(u) <= 0.0 {
            continue;
        }
        let b = (y / BLOCK) as usize * across + (x / BLOCK) as usize;
        if let Some(s) = sums.get_mut(b) {
            for i in 0..3 {
                s.0[i] += r[i];
                s.1[i] += u[i];
            }
            s.2 += 1;
        }
    }
    let light: Vec<Option<[[f64; 3]; 2]>> = sums
        .iter()
        .map(|(r, u, n)| {
            let n = f64::from(*n);
            (n >= f64::from(MIN_PIXELS)).then(|| [r.map(|v| v / n), u.map(|v| v / n)])
        })
        .collect();
    let mut ratio: Vec<Option<[f64; 3]>> = sums
        .iter()
        .map(|(r, u, n)| {
            // A channel the projectors barely give (a warm room's blue) divides by a floor of
            // a thousandth of the block's mean light, which is above zero (each pixel read
            // rose by more than 0 on average over its channels); it pulls a ratio towards 1
            // by at most a thousandth of the block's light.
            let eps = 1e-3 * mean(*u);
            (*n >= MIN_PIXELS && eps > 0.0).then(|| {
                std::array::from_fn(|i| {
                    ((r[i] + eps) / (u[i] + eps)).clamp(1.0 / MAX_STEP, MAX_STEP)
                })
            })
        })
        .collect();
    fill(&mut ratio, across, FILL_BLOCKS);
    Ok(Ratios {
        width: pw,
        height: ph,
        across,
        down,
        ratio,
        light,
    })
}

/// The LEDs' light in units of the white is at most this (a camera pixel far brighter than the
/// LEDs' 99th percentile is a lamp, not a wall).
pub const MAX_LIGHT: f64 = 64.0;

/// The white of a pass, for [`Ratios::relative_to`]: the 99th percentile (nearest rank) of the
/// luminance of the LEDs' light above the dark room, over the camera pixels not left out nor
/// saturated (a saturation that is not a number: none is); 0 when there is none.
pub fn white(photos: &Photographs<'_>) -> f64 {
    let mut l: Vec<f64> = photos
        .reference
        .pixels
        .iter()
        .zip(&photos.dark.pixels)
        .zip(photos.excluded)
        // As `ratios` reads it: a saturation that is not a number leaves nothing out.
        .filter(|((r, _), out)| {
            !**out
                && r.iter().all(|v| {
                    v.is_finite() && (photos.saturation.is_nan() || *v < photos.saturation)
                })
        })
        .map(|((r, d), _)| {
            let above = std::array::from_fn(|c| (f64::from(r[c]) - f64::from(d[c])).max(0.0));
            luminance(LinearRgb(above))
        })
        .filter(|v| v.is_finite())
        .collect();
    quantile(&mut l, 0.99).unwrap_or(0.0)
}

/// Per block of a `width`×`height` projector (row-major, [`BLOCK`] pixels a side), the most
/// each channel of its light can still be multiplied by: 1 over the block's mean drawn light
/// over the pixels that draw any (a block across a footprint's edge has only its lit part to
/// raise), `shares` being each pixel's light before the projector's clip (counted at most
/// full light); infinite for a black block or channel. `None` when `shares` is not `width`×`height` long.
pub fn headroom(shares: &[[f64; 3]], width: u32, height: u32) -> Option<Vec<[f64; 3]>> {
    if shares.len() as u64 != u64::from(width) * u64::from(height) || width == 0 {
        return None;
    }
    let across = width.div_ceil(BLOCK) as usize;
    let down = height.div_ceil(BLOCK) as usize;
    let mut sums = vec![([0.0f64; 3], 0u32); across * down];
    for (i, s) in shares.iter().enumerate() {
        // A pixel no node drives draws nothing whatever its gain (`shaded_light`): it neither
        // has nor lacks headroom.
        if s.iter().all(|v| *v <= 0.0) {
            continue;
        }
        let (x, y) = (i as u32 % width, i as u32 / width);
        let b = &mut sums[(y / BLOCK) as usize * across + (x / BLOCK) as usize];
        for (sum, v) in b.0.iter_mut().zip(s) {
            *sum += if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                1.0
            };
        }
        b.1 += 1;
    }
    Some(
        sums.iter()
            .map(|(sum, n)| {
                // Division by a positive mean, or infinite headroom for a block dark in c.
                sum.map(|v| {
                    let mean = v / f64::from((*n).max(1));
                    if mean > 0.0 {
                        1.0 / mean
                    } else {
                        f64::INFINITY
                    }
                })
            })
            .collect(),
    )
}

/// The step per channel that brings light `current` closest in ΔE00 to `reference` (both the
/// projectors' light above the dark room, linear camera RGB in units of the white's
/// luminance, L* = 100) when channel `c` can be multiplied by at most `most[c]` (the
/// projector's headroom: `1 / drawn light`). Where the plain ratio `reference / current` fits
/// under `most`, it is the answer; where a channel is short of headroom (a warm preset's red
/// at full light), matching the others channel by channel is not the closest colour: it
/// keeps their light and shifts the hue towards them. Then a channel short of headroom takes
/// all it has, and the others are chosen within `[1 / MAX_STEP, min(most, MAX_STEP)]` by
/// coordinate descent on their logarithms (two sweeps of 12 golden-section steps, within 1% of
/// the step; ΔE00 along one channel has one minimum in practice): some 56 ΔE00 a block short of
/// headroom, none for the others.
/// Non-finite or non-positive inputs give the plain ratio clamped to its bounds.
pub fn closest_within(reference: [f64; 3], current: [f64; 3], most: [f64; 3]) -> [f64; 3] {
    let low = (1.0 / MAX_STEP).ln();
    let high: [f64; 3] = std::array::from_fn(|c| {
        if most[c].is_finite() && most[c] > 0.0 {
            most[c].min(MAX_STEP).ln().max(low)
        } else {
            MAX_STEP.ln()
        }
    });
    let valid = reference
        .iter()
        .chain(&current)
        .all(|v| v.is_finite() && *v >= 0.0)
        && current.iter().any(|v| *v > 0.0);
    // A channel with no current light divides by a floor (as `ratios` does).
    let floor = 1e-3 * (current[0] + current[1] + current[2]) / 3.0;
    let plain: [f64; 3] = std::array::from_fn(|c| {
        if valid {
            ((reference[c] + floor) / (current[c] + floor)).ln()
        } else {
            0.0
        }
    });
    let mut log: [f64; 3] = std::array::from_fn(|c| plain[c].clamp(low, high[c]));
    if !valid || (0..3).all(|c| plain[c] <= high[c]) {
        return log.map(f64::exp);
    }
    let target = lab_from_linear_rgb(LinearRgb(reference), 1.0);
    let distance = |log: &[f64; 3]| {
        let lit = LinearRgb(std::array::from_fn(|c| current[c] * log[c].exp()));
        ciede2000(target, lab_from_linear_rgb(lit, 1.0))
    };
    let golden = (5f64.sqrt() - 1.0) / 2.0;
    // A channel short of headroom gives all it has (more of the light it lacks); the others
    // are chosen around it.
    let free: Vec<usize> = (0..3).filter(|&c| plain[c] <= high[c]).collect();
    for _ in 0..2 {
        for &c in &free {
            let (mut a, mut b) = (low, high[c]);
            let at = |v: f64, log: &[f64; 3]| {
                let mut l = *log;
                l[c] = v;
                distance(&l)
            };
            let mut x1 = b - golden * (b - a);
            let mut x2 = a + golden * (b - a);
            let (mut f1, mut f2) = (at(x1, &log), at(x2, &log));
            for _ in 0..12 {
                if f1 <= f2 {
                    b = x2;
                    x2 = x1;
                    f2 = f1;
                    x1 = b - golden * (b - a);
                    f1 = at(x1, &log);
                } else {
                    a = x1;
                    x1 = x2;
                    f1 = f2;
                    x2 = a + golden * (b - a);
                    f2 = at(x2, &log);
                }
            }
            let best = if f1 <= f2 { x1 } else { x2 };
            if at(best, &log) < distance(&log) {
                log[c] = best;
            }
        }
    }
    log.map(f64::exp)
}

/// One projector's gains, per block and channel; its drawn light is multiplied by them,
/// bilinear between block centres ([`Gains::at`]). Serialised as its size and its blocks'
/// gains; read back only when they fit the size and the bounds.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "GainsFile", into = "GainsFile")]
pub struct Gains {
    width: u32,
    height: u32,
    across: usize,
    down: usize,
    gains: Vec<[f32; 3]>,
}

/// [`Gains`] as a file holds them.
#[derive(serde::Serialize, serde::Deserialize)]
struct GainsFile {
    width: u32,
    height: u32,
    gains: Vec<[f32; 3]>,
}

impl From<Gains> for GainsFile {
    fn from(g: Gains) -> Self {
        Self {
            width: g.width,
            height: g.height,
            gains: g.gains,
        }
    }
}

impl TryFrom<GainsFile> for Gains {
    type Error = String;

    fn try_from(f: GainsFile) -> Result<Self, String> {
        let Some(mut g) = Gains::flat(f.width, f.height) else {
            return Err(format!("gains of a {}×{} projector", f.width, f.height));
        };
        if f.gains.len() != g.gains.len() {
            return Err(format!(
                "{} blocks of gains, a {}×{} projector has {}",
                f.gains.len(),
                f.width,
                f.height,
                g.gains.len()
            ));
        }
        if let Some((i, v)) = f
            .gains
            .iter()
            .enumerate()
            .find(|(_, v)| !v.iter().all(|x| (MIN_GAIN..=MAX_GAIN).contains(x)))
        {
            return Err(format!(
                "block {i} has gains {v:?}, expected within {MIN_GAIN}..{MAX_GAIN}"
            ));
        }
        g.gains = f.gains;
        Ok(g)
    }
}

impl Gains {
    /// Every gain 1: the nodes' light as it is. `None` for an empty projector.
    pub fn flat(width: u32, height: u32) -> Option<Self> {
        (width > 0 && height > 0).then(|| {
            let across = width.div_ceil(BLOCK) as usize;
            let down = height.div_ceil(BLOCK) as usize;
            Self {
                width,
                height,
                across,
                down,
                gains: vec![[1.0; 3]; across * down],
            }
        })
    }

    /// Multiplies every read block's gain by its ratio to the power `rate` (in `(0, 1]`; a
    /// rate outside is refused), within the bounds. Errors when `ratios` is of another
    /// projector size.
    pub fn step(&mut self, ratios: &Ratios, rate: f64) -> Result<(), CalibError> {
        self.step_within(ratios, rate, None).map(|_| ())
    }

    /// [`Self::step`], except that a block read with its light (see [`Ratios::light`]) and
    /// short of `headroom` (per block, [`headroom`]) in some channel steps by
    /// [`closest_within`] instead of its ratio: the closest colour the projector can still
    /// give. A warm preset's red at full light on a wall only one projector reaches, matched
    /// channel by channel, kept green and blue at the LEDs' level and turned the wall yellow;
    /// the lab's per-pixel ceiling's 95th percentile fell from 8.85 to 7.36 ΔE00 with it
    /// (docs/results.md). `headroom` of another length than the blocks is ignored. Returns
    /// how many blocks were short of it.
    pub fn step_within(
        &mut self,
        ratios: &Ratios,
        rate: f64,
        headroom: Option<&[[f64; 3]]>,
    ) -> Result<usize, CalibError> {
        if (ratios.width, ratios.height) != (self.width, self.height) {
            return Err(CalibError::Invalid {
                field: "shading",
                problem: format!(
                    "ratios of a {}×{} projector for gains of a {}×{} one",
                    ratios.width, ratios.height, self.width, self.height
                ),
            });
        }
        if rate.is_nan() || rate <= 0.0 || rate > 1.0 {
            return Err(CalibError::Invalid {
                field: "shading rate",
                problem: format!("{rate}, expected in (0, 1]"),
            });
        }
        let headroom = headroom.filter(|h| h.len() == self.gains.len());
        let mut short = 0;
        for (b, (g, r)) in self.gains.iter_mut().zip(&ratios.ratio).enumerate() {
            let Some(r) = r else { continue };
            let r = match (ratios.light.get(b).copied().flatten(), headroom) {
                (Some([reference, current]), Some(h)) if (0..3).any(|c| r[c] > h[b][c]) => {
                    short += 1;
                    closest_within(reference, current, h[b])
                }
                _ => *r,
            };
            for i in 0..3 {
                let next = f64::from(g[i]) * r[i].powf(rate);
                g[i] = (next as f32).clamp(MIN_GAIN, MAX_GAIN);
            }
        }
        Ok(short)
    }

    /// The gain at projector pixel `(x, y)`, bilinear between block centres (clamped at the
    /// frame's edge).
    pub fn at(&self, x: u32, y: u32) -> [f32; 3] {
        let b = f64::from(BLOCK);
        let fx = ((f64::from(x) + 0.5) / b - 0.5).clamp(0.0, (self.across - 1) as f64);
        let fy = ((f64::from(y) + 0.5) / b - 0.5).clamp(0.0, (self.down - 1) as f64);
        let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.across - 1), (y0 + 1).min(self.down - 1));
        let (tx, ty) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
        let g = |x: usize, y: usize| self.gains[y * self.across + x];
        std::array::from_fn(|i| {
            let top = g(x0, y0)[i] * (1.0 - tx) + g(x1, y0)[i] * tx;
            let bottom = g(x0, y1)[i] * (1.0 - tx) + g(x1, y1)[i] * tx;
            top * (1.0 - ty) + bottom * ty
        })
    }

    /// The projector's size.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The 5th and 95th percentiles of the gains over the blocks (channels pooled).
    pub fn spread(&self) -> (f32, f32) {
        let mut v: Vec<f64> = self.gains.iter().flat_map(|g| g.map(f64::from)).collect();
        let lo = quantile(&mut v, 0.05).unwrap_or(1.0);
        let hi = quantile(&mut v, 0.95).unwrap_or(1.0);
        (lo as f32, hi as f32)
    }
}

#[cfg(test)]
mod tests;
