//! Gray-code structured light (DESIGN §4.2): column and row bit patterns with their inverses,
//! plus full white and black, and a decoder that is robust to inter-reflection and defocus.
//!
//! Hand-written: no crate decodes Gray codes with direct/global separation. The decoder follows
//! the ideas of Nayar et al. (2006) and Xu & Aliaga (2007): the finest patterns split each
//! pixel's light into a direct part `Ld` (which flips with the pattern) and a global part `Lg`
//! (which does not); a bit is trusted only where the direct light decides it, and a pixel with
//! more than one untrusted bit is reported unknown rather than wrong.

use crate::CalibError;
use crate::image_io::LinearImage;
use crate::nodes::dilate;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

mod captures;
mod cells;
mod checks;
mod code;
mod colour;
mod fill;
mod groups;
mod manifest;
mod resolve;
mod second_pass;
#[cfg(test)]
pub(crate) mod synthetic;

use captures::Pair;
pub use captures::{Captures, Reduced, brightest, less_black};
pub use code::{bits_for, gray, gray_inverse};
pub use colour::{MAX_DISTURBANCE, MAX_NOISE_GAIN, PRESENT_SHARE, Primary, Unmixing};
use fill::fill_from_neighbours;
pub use groups::group_disjoint;
pub use manifest::{MAX_CELL, MAX_SIDE, Manifest};
use resolve::resolve_pixel;
pub use second_pass::{
    COVER_SPAN, SECOND_PASS_BRIGHTER, SECOND_PASS_CROWD, SECOND_PASS_GROW, SECOND_PASS_LONGEST,
    SECOND_PASS_MARGIN, SECOND_PASS_SNR, SECOND_PASS_WORTH, SOLID_NEIGHBOURS, SecondPass,
    SecondPassPlan, second_pass, second_pass_exposure,
};

/// Which coordinate a pattern encodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Axis {
    /// Projector column (x).
    Column,
    /// Projector row (y).
    Row,
}

/// What one pattern shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Pattern {
    /// Every pixel white.
    White,
    /// Every pixel black.
    Black,
    /// Bit `bit` (0 is the most significant) of the Gray code of the column or row.
    Bit {
        /// Column or row.
        axis: Axis,
        /// Bit index from the most significant.
        bit: u32,
        /// True for the complemented pattern.
        inverse: bool,
    },
}

/// One file of the pattern set.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PatternFile {
    /// File name inside the pattern folder (captures carry the same name).
    pub file: String,
    /// What it encodes.
    #[serde(flatten)]
    pub pattern: Pattern,
}

/// How the bits are turned into patterns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Coding {
    /// Plain Gray code: the coarse bits are wide stripes, which inter-reflection can flip.
    Gray,
    /// Gray code XOR-ed with its 4-pixel-stripe bit (Gupta et al. 2012, "XOR-04"): every
    /// pattern is high-frequency, so global light is the same under a pattern and its inverse
    /// and cancels in their difference. Decoding XORs the base bit back out.
    #[default]
    Xor04,
}

/// Noise and thresholds of the decoder, in capture units (the sum of the three channels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodeConfig {
    /// Noise standard deviation of a pixel at black.
    pub noise_floor: f32,
    /// Noise standard deviation at value 1 from shot noise (it grows with √value).
    pub shot_noise: f32,
    /// A pixel is reached when its direct light is at least this share of the image's 99th
    /// percentile of direct light.
    pub min_direct_share: f32,
    /// A bit is trusted when pattern and inverse differ by at least this share of `Ld`.
    pub min_margin_share: f32,
    /// How many untrusted bits a pixel may have and still be decoded (0 or 1).
    pub max_uncertain_bits: usize,
    /// Decode pixels with more untrusted bits from their decoded neighbours (XOR coding only;
    /// see [`decode`]).
    pub fill_from_neighbours: bool,
    /// Resolve the bits a pixel straddling a stripe edge cannot decide, per axis, by fitting
    /// the nearby codes to its differences (see [`decode`]).
    pub resolve_edges: bool,
    /// The value (per channel, capture units) at which the camera clips: a white capture at it
    /// over a large share of the lit pixels is refused as saturated.
    pub saturation: f32,
    /// Refuse saturated captures (see `saturation`). The calibration procedure's first pass
    /// does not: it plans second passes at other exposures around what clipped, and refusing
    /// there stopped the simulated rooms whose reflective walls clip (small-reflective).
    pub refuse_saturated: bool,
}

impl DecodeConfig {
    /// For defocused projectors (the large aperture): every bit must be clearly decided, so
    /// that a blurred stripe edge gives "unknown" rather than a position off by the blur.
    pub fn strict() -> Self {
        Self {
            min_margin_share: 0.5,
            max_uncertain_bits: 0,
            fill_from_neighbours: false,
            resolve_edges: false,
            ..Self::default()
        }
    }

    /// The same decoder for captures exposed `factor` times as long and scaled back to the
    /// units of a normal one: read noise shrinks by `factor`, shot noise by its square root.
    /// A factor that is not a finite number ≥ 1 is taken as 1.
    pub fn exposed_longer(self, factor: f32) -> Self {
        let f = if factor.is_finite() && factor >= 1.0 {
            factor
        } else {
            1.0
        };
        Self {
            noise_floor: self.noise_floor / f,
            shot_noise: self.shot_noise / f.sqrt(),
            ..self
        }
    }
}

impl DecodeConfig {
    /// The same decoder for one group's shares of captures shown in its primary
    /// ([`Unmixing`]): a share reads about one camera channel's noise where an intensity sums
    /// three channels', up to [`MAX_NOISE_GAIN`] times that where crosstalk is unmixed. The
    /// floor, three channels' read noise, scales by `MAX_NOISE_GAIN / √3`; shot noise, which
    /// grows with the light read whatever the channels, stays.
    pub fn in_one_primary(self) -> Self {
        Self {
            noise_floor: self.noise_floor * MAX_NOISE_GAIN / 3.0f32.sqrt(),
            ..self
        }
    }
}

impl Default for DecodeConfig {
    fn default() -> Self {
        Self {
            noise_floor: 0.002,
            shot_noise: 0.007,
            min_direct_share: 0.005,
            min_margin_share: 0.4,
            max_uncertain_bits: 1,
            fill_from_neighbours: true,
            resolve_edges: true,
            saturation: 1.0,
            refuse_saturated: true,
        }
    }
}

/// The decoded correspondence of one projector.
#[derive(Debug, Clone, PartialEq)]
pub struct Correspondence {
    /// Camera width.
    pub width: u32,
    /// Camera height.
    pub height: u32,
    /// Projector width.
    pub projector_width: u32,
    /// Projector height.
    pub projector_height: u32,
    /// `(column, row)` for each camera pixel, or `None` where unknown.
    pub map: Vec<Option<(u32, u32)>>,
    /// Confidence in `[0, 1]`: the smallest trusted margin over `Ld`, halved where one bit was
    /// resolved by its sign alone.
    pub confidence: Vec<f32>,
    /// Direct light `Ld` per pixel.
    pub direct: Vec<f32>,
    /// Global light `Lg` per pixel.
    pub global: Vec<f32>,
    /// The direct light from which a pixel counts as reached (capture units).
    pub reach: f32,
}

impl Correspondence {
    /// Share of camera pixels with a decoded projector pixel.
    pub fn decoded_share(&self) -> f64 {
        self.map.iter().filter(|m| m.is_some()).count() as f64 / self.map.len().max(1) as f64
    }

    /// The 16-bit map of the `graycode decode` command: R = column + 1, G = row + 1 (0 where
    /// unknown), B = confidence × 65535.
    pub fn to_png16(&self) -> Vec<u16> {
        self.map
            .iter()
            .zip(&self.confidence)
            .flat_map(|(m, c)| match m {
                Some((x, y)) => [
                    (*x + 1).min(65_535) as u16,
                    (*y + 1).min(65_535) as u16,
                    (c.clamp(0.0, 1.0) * 65_535.0).round() as u16,
                ],
                None => [0, 0, 0],
            })
            .collect()
    }

    /// For tests: a camera of `w × h` that sees a projector of the same size pixel for pixel,
    /// every pixel decoded with full confidence.
    #[cfg(test)]
    pub(crate) fn identity(w: u32, h: u32) -> Self {
        let n = (w * h) as usize;
        Self {
            width: w,
            height: h,
            projector_width: w,
            projector_height: h,
            map: (0..w * h).map(|i| Some((i % w, i / w))).collect(),
            confidence: vec![1.0; n],
            direct: vec![1.0; n],
            global: vec![0.0; n],
            reach: 0.0,
        }
    }
}

/// Decodes one projector from its captures, looked up by pattern. Every capture must have the
/// camera's size.
///
/// Two passes: each pixel on its own (at most one untrusted bit), then, with XOR coding and
/// [`DecodeConfig::fill_from_neighbours`], pixels with more untrusted bits from their decoded
/// neighbours ([`fill_from_neighbours`]; with [`DecodeConfig::resolve_edges`] also pixels on a
/// stripe edge, by fitting the codes near their neighbours'). A pixel's noise is the camera
/// model's or, where larger, the captures' own. Refuses saturated captures and a projector the
/// camera did not see (`checks`).
pub fn decode<'a>(
    manifest: &Manifest,
    config: &DecodeConfig,
    capture: impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
) -> Result<Correspondence, CalibError> {
    decode_where(manifest, config, None, capture)
}

/// [`decode`] over the camera pixels `ours` marks (all when `None`): projectors coded at the
/// same time ([`group_disjoint`]) each decode the pixels they light most, and the second pass
/// does not grow into another's. A mask of another size than the captures is refused.
pub fn decode_where<'a>(
    manifest: &Manifest,
    config: &DecodeConfig,
    ours: Option<&[bool]>,
    capture: impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
) -> Result<Correspondence, CalibError> {
    decode_checked(manifest, config, ours, true, false, capture)
}

/// [`decode_where`] of a single-shot pattern set: white, black and each bit pattern captured
/// once, without inverses ([`Captures::single_shot`]; XOR coding only). Half the captures;
/// what it costs in accuracy is measured in the photographic tests.
pub fn decode_single_shot<'a>(
    manifest: &Manifest,
    config: &DecodeConfig,
    ours: Option<&[bool]>,
    capture: impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
) -> Result<Correspondence, CalibError> {
    decode_checked(manifest, config, ours, true, true, capture)
}

/// [`decode_where`], refusing saturated captures and a projector the camera did not see when
/// `checked` (a second pass, which shows a few projector pixels at a long exposure whose
/// clipped pixels it leaves unknown, is not checked); `single`: no inverse captured
/// ([`decode_single_shot`]).
pub(crate) fn decode_checked<'a>(
    manifest: &Manifest,
    config: &DecodeConfig,
    ours: Option<&[bool]>,
    checked: bool,
    single: bool,
    mut capture: impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
) -> Result<Correspondence, CalibError> {
    let reduced = Reduced::read(manifest, single, &mut capture)?;
    let mut made = Vec::new();
    let captures = if single {
        reduced.captures_single_shot(manifest, &mut made, config.saturation)?
    } else {
        reduced.captures(manifest)?
    };
    decode_captures(manifest, config, ours, checked, &captures)
}

/// [`decode_checked`] of captures already reduced to what the decoder reads ([`Captures`]):
/// the calibration's path, which never holds the images ([`Reduced`], [`less_black`]).
pub(crate) fn decode_captures(
    manifest: &Manifest,
    config: &DecodeConfig,
    ours: Option<&[bool]>,
    checked: bool,
    captures: &Captures<'_>,
) -> Result<Correspondence, CalibError> {
    // Over 80 lines: the decode's steps in their order (captures, light, noise, reach, the
    // saturation check, both passes, the unseen check), each a call, read best in one place.
    let Captures {
        w,
        h,
        white,
        black,
        white_top,
        ref pairs,
        single,
    } = *captures;
    let n = (w * h) as usize;
    if let Some(mask) = ours
        && mask.len() != n
    {
        return Err(CalibError::Invalid {
            field: "decode mask",
            problem: format!("{} pixels, the captures have {w}x{h}", mask.len()),
        });
    }
    let xor = manifest.coding == Coding::Xor04;
    // A difference against an inverse made from white (single shot) is 2·pattern − white:
    // four times a pattern capture's noise variance (read noise down by the exposure `f`,
    // shot noise by its root) and white's once, against twice one capture's for a pair.
    let single_config;
    let config = if let Some(f) = single {
        single_config = DecodeConfig {
            noise_floor: config.noise_floor * ((4.0 / (f * f) + 1.0) / 2.0).sqrt(),
            shot_noise: config.shot_noise * ((4.0 / f + 1.0) / 2.0).sqrt(),
            ..*config
        };
        &single_config
    } else {
        config
    };
    let (direct, global) = direct_and_global(manifest, pairs, n);
    // An inverse made from white carries no noise of its own, so pattern + inverse against
    // white, what measures the noise of pairs, says nothing: the camera model's alone. (Read
    // from how the differences spread instead, it took the shrinking of a whole axis near a
    // stripe edge for noise: 96.96% of the photographs' lit pixels within ±1 against 98.76%.)
    let noise = if single.is_some() {
        vec![0.0; n]
    } else {
        resolve::measured_noise(w as usize, h as usize, white, black, pairs)
    };
    let mut sorted: Vec<f32> = direct.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p99 = sorted.get(sorted.len() * 99 / 100).copied().unwrap_or(0.0);
    let reach = (config.min_direct_share * p99).max(6.0 * config.noise_floor);
    let reading = |i: usize, out: &mut Vec<Reading>| {
        read_pixel(config, xor, pairs, i, (direct[i], global[i]), noise[i], out);
    };
    let reached = |i: usize| {
        // NaN (a corrupt capture) counts as not reached; so does a pixel whose largest
        // difference is within what noise alone gives over all its pairs.
        ours.is_none_or(|m| m[i])
            && !(direct[i].is_nan()
                || direct[i] < reach
                || white[i] - black[i] < reach
                || direct[i] < REACH_SIGMAS * noise[i])
    };
    let lit = checked.then(|| checks::lit(white, black, reach, ours));
    let mut map = vec![None; n];
    let mut confidence = vec![0.0f32; n];
    let mut readings = Vec::with_capacity(pairs.len());
    for i in 0..n {
        if !reached(i) {
            continue;
        }
        reading(i, &mut readings);
        let decoded = decode_pixel(manifest, config, direct[i], &readings);
        if let Some((xy, c)) = decoded {
            map[i] = Some(xy);
            confidence[i] = c;
        }
    }
    // The fill correlates the differences with candidate codes: that needs every pair's sign to
    // be the direct light's, true of XOR coding's high-frequency patterns only.
    if config.fill_from_neighbours && xor {
        // Direct light is at least half of all the projector gives the pixel (white − black):
        // where reflected light dominates, a code near the neighbours' can fit by chance.
        let dominant: Vec<bool> = (0..n)
            .map(|i| direct[i] >= 0.3 * (white[i] - black[i]))
            .collect();
        fill_from_neighbours(
            manifest,
            config,
            (w as usize, h as usize),
            &reached,
            &reading,
            (&direct, &dominant),
            &mut map,
            &mut confidence,
        );
    }
    if let Some(lit) = lit.as_ref().filter(|_| config.refuse_saturated) {
        let clipped = checks::clipped(white_top, config.saturation);
        checks::refuse_saturated(&clipped, lit, &map)?;
    }
    // Cells to the projector pixels their camera pixels see.
    cells::to_pixels(manifest, (w as usize, h as usize), &mut map);
    let corr = Correspondence {
        width: w,
        height: h,
        projector_width: manifest.width,
        projector_height: manifest.height,
        map,
        confidence,
        direct,
        global,
        reach,
    };
    if checked {
        checks::refuse_unseen(&corr, ours)?;
    }
    Ok(corr)
}

/// A reached pixel's direct light must stand this many noise standard deviations (of one
/// difference, [`resolve::measured_noise`]) above zero: the largest of some twenty differences
/// of pure noise is about 2.5 of them.
const REACH_SIGMAS: f32 = 6.0;

/// Direct and global light per pixel from the two finest patterns of each axis (Nayar et al.):
/// with half the pixels on, max = Ld + Lg/2 and min = Lg/2. With XOR coding every pattern is
/// high-frequency, so every pair can be used.
fn direct_and_global(manifest: &Manifest, pairs: &[Pair], n: usize) -> (Vec<f32>, Vec<f32>) {
    let xor = manifest.coding == Coding::Xor04;
    let fine: Vec<&Pair> = pairs
        .iter()
        .filter(|(axis, bit, _, _)| {
            let bits = if *axis == Axis::Column {
                manifest.column_bits
            } else {
                manifest.row_bits
            };
            xor || bit + 2 >= bits
        })
        .collect();
    let mut direct = vec![0.0f32; n];
    let mut global = vec![0.0f32; n];
    for i in 0..n {
        let (mut ld, mut lg) = (0.0f32, 0.0f32);
        for (_, _, p, q) in &fine {
            let (hi, lo) = (p[i].max(q[i]), p[i].min(q[i]).max(0.0));
            ld = ld.max(hi - lo);
            lg += 2.0 * lo;
        }
        direct[i] = ld;
        global[i] = lg / fine.len().max(1) as f32;
    }
    (direct, global)
}

/// One reading per pattern pair at pixel `i` with direct and global light `(ld, lg)`: the
/// difference `d` and, where the direct light decides it, the encoded value it shows
/// (`None`: untrusted), with the noise of the difference (the camera's model, or the noise
/// `measured` in the captures where that is larger).
fn read_pixel(
    config: &DecodeConfig,
    xor: bool,
    pairs: &[Pair],
    i: usize,
    (ld, lg): (f32, f32),
    measured: f32,
    out: &mut Vec<Reading>,
) {
    out.clear();
    out.extend(pairs.iter().map(|(axis, bit, p, q)| {
        let (a, b) = (p[i], q[i]);
        let d = a - b;
        // Noise of a difference of two pixels around their level.
        let level = a.max(b).max(0.0);
        let sigma = (2.0
            * (config.noise_floor * config.noise_floor
                + config.shot_noise * config.shot_noise * level))
            .sqrt()
            .max(measured);
        let margin = (config.min_margin_share * ld).max(3.0 * sigma);
        let trusted = if d.abs() < margin {
            None
        } else if xor || ld > lg {
            // High-frequency pairs see the same global light: the sign is the direct
            // part's.
            Some(d > 0.0)
        } else if a < ld && b > lg {
            // Global light dominates a coarse stripe: trust only what direct light
            // explains.
            Some(false)
        } else if a > lg && b < ld {
            Some(true)
        } else {
            None
        };
        Reading {
            axis: *axis,
            bit: *bit,
            d,
            sigma,
            trusted,
        }
    }));
}

/// A reached pixel's projector pixel and confidence from its readings alone (direct light
/// `ld`); `None` with more untrusted bits than allowed or a code outside the projector.
fn decode_pixel(
    manifest: &Manifest,
    config: &DecodeConfig,
    ld: f32,
    readings: &[Reading],
) -> Option<((u32, u32), f32)> {
    // (value, trusted) of every encoded bit, per axis, most significant first.
    let mut read: [Vec<(bool, bool)>; 2] = [Vec::new(), Vec::new()];
    let mut worst = f32::INFINITY;
    for r in readings {
        if r.trusted.is_some() {
            worst = worst.min(r.d.abs() / ld);
        }
        read[usize::from(r.axis == Axis::Row)]
            .push((r.trusted.unwrap_or(r.d > 0.0), r.trusted.is_some()));
    }
    // Undo the XOR with the base bit; a bit is trusted only if its base is too.
    let mut codes = [0u32; 2];
    let mut uncertain = 0;
    for (k, bits) in read.iter().enumerate() {
        let base = manifest
            .base_bit(bits.len() as u32)
            .map(|b| bits[b as usize]);
        for (b, &(value, trusted)) in bits.iter().enumerate() {
            let (value, trusted) = match base {
                Some((bv, bt)) if Some(b as u32) != manifest.base_bit(bits.len() as u32) => {
                    (value != bv, trusted && bt)
                }
                _ => (value, trusted),
            };
            uncertain += usize::from(!trusted);
            codes[k] = (codes[k] << 1) | u32::from(value);
        }
    }
    // One untrusted bit lies on that bit's stripe edge, where both readings are neighbours:
    // at most one pixel off. More than one: unknown rather than wrong.
    if uncertain > config.max_uncertain_bits.min(1) {
        return None;
    }
    let (x, y) = (gray_inverse(codes[0]), gray_inverse(codes[1]));
    if x >= manifest.cells(Axis::Column) || y >= manifest.cells(Axis::Row) {
        return None;
    }
    let c = worst.min(1.0);
    Some(((x, y), if uncertain == 1 { 0.5 * c } else { c }))
}

/// One pattern pair at one camera pixel: `d` = pattern − inverse, its noise, and the encoded
/// value it shows where the direct light decides it.
struct Reading {
    axis: Axis,
    bit: u32,
    d: f32,
    sigma: f32,
    trusted: Option<bool>,
}
