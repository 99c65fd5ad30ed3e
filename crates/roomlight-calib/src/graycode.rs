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

/// The pattern set of one projector resolution: what `patterns.json` holds.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    /// Projector width.
    pub width: u32,
    /// Projector height.
    pub height: u32,
    /// How bits become patterns (files without it are plain Gray code).
    #[serde(default = "gray_coding")]
    pub coding: Coding,
    /// Bits for the columns.
    pub column_bits: u32,
    /// Bits for the rows.
    pub row_bits: u32,
    /// Every pattern, in display order.
    pub patterns: Vec<PatternFile>,
}

fn gray_coding() -> Coding {
    Coding::Gray
}

/// Bits needed to code `n` positions (at least 1).
pub fn bits_for(n: u32) -> u32 {
    (32 - n.saturating_sub(1).leading_zeros()).max(1)
}

/// The reflected binary (Gray) code of `v`.
pub fn gray(v: u32) -> u32 {
    v ^ (v >> 1)
}

/// The value whose Gray code is `g`.
pub fn gray_inverse(g: u32) -> u32 {
    let mut v = g;
    let mut shift = g >> 1;
    while shift != 0 {
        v ^= shift;
        shift >>= 1;
    }
    v
}

impl Manifest {
    /// The pattern set for a `width × height` projector: white, black, then each column bit and
    /// its inverse from the most significant, then the rows.
    pub fn new(width: u32, height: u32) -> Result<Self, CalibError> {
        Self::with_coding(width, height, Coding::default())
    }

    /// The pattern set with a chosen coding.
    pub fn with_coding(width: u32, height: u32, coding: Coding) -> Result<Self, CalibError> {
        if width == 0 || height == 0 || width > 65_535 || height > 65_535 {
            return Err(CalibError::Invalid {
                field: "projector resolution",
                problem: format!("{width}x{height}, expected 1 to 65535 per side"),
            });
        }
        let (column_bits, row_bits) = (bits_for(width), bits_for(height));
        let mut patterns = vec![
            PatternFile {
                file: "white.png".into(),
                pattern: Pattern::White,
            },
            PatternFile {
                file: "black.png".into(),
                pattern: Pattern::Black,
            },
        ];
        for (axis, bits, name) in [
            (Axis::Column, column_bits, "col"),
            (Axis::Row, row_bits, "row"),
        ] {
            for bit in 0..bits {
                for inverse in [false, true] {
                    let suffix = if inverse { "-inv" } else { "" };
                    patterns.push(PatternFile {
                        file: format!("{name}-{bit:02}{suffix}.png"),
                        pattern: Pattern::Bit { axis, bit, inverse },
                    });
                }
            }
        }
        Ok(Self {
            width,
            height,
            coding,
            column_bits,
            row_bits,
            patterns,
        })
    }

    /// Checks a manifest read from a file: sizes, bit counts and a complete, unique pattern set.
    pub fn validate(&self, file: &str) -> Result<(), CalibError> {
        let expected = Self::with_coding(self.width, self.height, self.coding).map_err(|e| {
            CalibError::File {
                file: file.into(),
                problem: e.to_string(),
            }
        })?;
        if self.column_bits != expected.column_bits || self.row_bits != expected.row_bits {
            return Err(CalibError::File {
                file: file.into(),
                problem: format!(
                    "column_bits/row_bits are {}/{}, a {}x{} projector needs {}/{}",
                    self.column_bits,
                    self.row_bits,
                    self.width,
                    self.height,
                    expected.column_bits,
                    expected.row_bits
                ),
            });
        }
        for p in &expected.patterns {
            let n = self
                .patterns
                .iter()
                .filter(|q| q.pattern == p.pattern)
                .count();
            if n != 1 {
                return Err(CalibError::File {
                    file: file.into(),
                    problem: format!("lists {:?} {n} times, expected once", p.pattern),
                });
            }
        }
        if self.patterns.len() != expected.patterns.len() {
            return Err(CalibError::File {
                file: file.into(),
                problem: format!(
                    "lists {} patterns, expected {}",
                    self.patterns.len(),
                    expected.patterns.len()
                ),
            });
        }
        let mut names: Vec<&str> = self.patterns.iter().map(|p| p.file.as_str()).collect();
        names.sort_unstable();
        if names.windows(2).any(|w| w[0] == w[1])
            || names
                .iter()
                .any(|n| n.contains('/') || n.contains('\\') || n.is_empty())
        {
            return Err(CalibError::File {
                file: file.into(),
                problem: "file names must be unique plain names".into(),
            });
        }
        Ok(())
    }

    /// The code value (0 or 1) of every projector pixel for a pattern.
    pub fn pattern_values(&self, pattern: Pattern) -> Vec<f32> {
        let (w, h) = (self.width, self.height);
        (0..w * h)
            .map(|i| {
                let on = match pattern {
                    Pattern::White => true,
                    Pattern::Black => false,
                    Pattern::Bit { axis, bit, inverse } => {
                        let v = match axis {
                            Axis::Column => i % w,
                            Axis::Row => i / w,
                        };
                        self.encoded_bit(axis, bit, v) != inverse
                    }
                };
                f32::from(u8::from(on))
            })
            .collect()
    }

    /// The value `bit` of `axis` shows at projector coordinate `v` (before the inverse): the
    /// Gray code's bit, XOR-ed with the base bit under XOR coding.
    pub fn encoded_bit(&self, axis: Axis, bit: u32, v: u32) -> bool {
        let bits = match axis {
            Axis::Column => self.column_bits,
            Axis::Row => self.row_bits,
        };
        let g = |b: u32| (gray(v) >> (bits - 1 - b)) & 1 == 1;
        match self.base_bit(bits) {
            Some(base) if base != bit => g(bit) != g(base),
            _ => g(bit),
        }
    }

    /// The bit every other bit is XOR-ed with, for an axis of `bits` bits.
    pub fn base_bit(&self, bits: u32) -> Option<u32> {
        match self.coding {
            Coding::Xor04 if bits >= 3 => Some(bits - 2),
            _ => None,
        }
    }

    /// The pattern with only the projector pixels `shown` marks lit (the others black): the
    /// second pass of [`Correspondence::second_pass_mask`]. A mask of another size than the
    /// projector is refused.
    pub fn pattern_image_where(
        &self,
        pattern: Pattern,
        shown: &[bool],
    ) -> Result<LinearImage, CalibError> {
        if shown.len() != (self.width * self.height) as usize {
            return Err(CalibError::Invalid {
                field: "pattern mask",
                problem: format!(
                    "{} pixels, the projector has {}x{}",
                    shown.len(),
                    self.width,
                    self.height
                ),
            });
        }
        let mut image = self.pattern_image(pattern);
        for (px, &on) in image.pixels.iter_mut().zip(shown) {
            if !on {
                *px = [0.0; 3];
            }
        }
        Ok(image)
    }

    /// The pattern as an image (white where on).
    pub fn pattern_image(&self, pattern: Pattern) -> LinearImage {
        LinearImage {
            width: self.width,
            height: self.height,
            pixels: self
                .pattern_values(pattern)
                .into_iter()
                .map(|v| [v; 3])
                .collect(),
        }
    }
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
}

impl DecodeConfig {
    /// For defocused projectors (the large aperture): every bit must be clearly decided, so
    /// that a blurred stripe edge gives "unknown" rather than a position off by the blur.
    pub fn strict() -> Self {
        Self {
            min_margin_share: 0.5,
            max_uncertain_bits: 0,
            fill_from_neighbours: false,
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

impl Default for DecodeConfig {
    fn default() -> Self {
        Self {
            noise_floor: 0.002,
            shot_noise: 0.007,
            min_direct_share: 0.005,
            min_margin_share: 0.4,
            max_uncertain_bits: 1,
            fill_from_neighbours: true,
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

    /// Projector pixels the decoded surfaces cover: every 2×2 block of decoded camera pixels
    /// whose projector coordinates lie within [`COVER_SPAN`] of each other (one surface, no
    /// depth edge between them) marks the projector rectangle they span, grown by `margin`
    /// pixels; a decoded pixel outside such blocks marks only its own. Only the camera pixels
    /// `counted` marks take part (all when `None`).
    pub fn covered(&self, margin: u32, counted: Option<&[bool]>) -> Vec<bool> {
        let (pw, ph) = (
            self.projector_width as usize,
            self.projector_height as usize,
        );
        let (w, h) = (self.width as usize, self.height as usize);
        let mut blocks = vec![false; pw * ph];
        let mut points = Vec::new();
        let mut mark = |x0: u32, x1: u32, y0: u32, y1: u32| {
            for y in y0 as usize..=(y1 as usize).min(ph.saturating_sub(1)) {
                for x in x0 as usize..=(x1 as usize).min(pw.saturating_sub(1)) {
                    blocks[y * pw + x] = true;
                }
            }
        };
        let at = |i: usize| {
            self.map[i].filter(|_| counted.is_none_or(|c| c.get(i).copied().unwrap_or(false)))
        };
        for y in 0..h {
            for x in 0..w {
                let Some(a) = at(y * w + x) else {
                    continue;
                };
                points.push(a);
                if x + 1 == w || y + 1 == h {
                    continue;
                }
                let block = [
                    at(y * w + x + 1),
                    at((y + 1) * w + x),
                    at((y + 1) * w + x + 1),
                ];
                let (mut x0, mut x1, mut y0, mut y1) = (a.0, a.0, a.1, a.1);
                let mut whole = true;
                for b in block {
                    let Some(b) = b else {
                        whole = false;
                        break;
                    };
                    (x0, x1, y0, y1) = (x0.min(b.0), x1.max(b.0), y0.min(b.1), y1.max(b.1));
                }
                if whole && x1 - x0 <= COVER_SPAN && y1 - y0 <= COVER_SPAN {
                    mark(x0, x1, y0, y1);
                }
            }
        }
        let mut covered = dilate(&blocks, pw, ph, margin);
        for (x, y) in points {
            if let Some(c) = covered.get_mut(y as usize * pw + x as usize) {
                *c = true;
            }
        }
        covered
    }

    /// The projector pixels a second structured-light pass shows: all but those that light
    /// decoded surfaces brighter than the pixels `left` to decode ([`Correspondence::covered`]
    /// over the decoded pixels whose direct light is at least [`SECOND_PASS_BRIGHTER`] times
    /// the median of `left`'s, which is [`Correspondence::reached_unknown`]). Dark surfaces
    /// beside bright ones (a wall at grazing incidence in a corner with a lit floor) decode
    /// wrongly or not at all in the first pass, because the bright surface's inter-reflected
    /// light carries its own code onto them; with the bright surface left black, their direct
    /// light decides. Decoded pixels on the dark surface itself stay shown, so that all of it
    /// is lit. The share of shown pixels is returned with the mask.
    pub fn second_pass_mask(&self, left: &[bool], margin: u32) -> (Vec<bool>, f64) {
        let mut levels: Vec<f32> = left
            .iter()
            .zip(&self.direct)
            .filter(|(u, _)| **u)
            .map(|(_, d)| *d)
            .collect();
        // Nothing left to decode: every decoded surface counts (a threshold of zero).
        let threshold = if levels.is_empty() {
            0.0
        } else {
            let k = levels.len() / 2;
            SECOND_PASS_BRIGHTER * *levels.select_nth_unstable_by(k, f32::total_cmp).1
        };
        let bright: Vec<bool> = self.direct.iter().map(|d| *d >= threshold).collect();
        let shown: Vec<bool> = self
            .covered(margin, Some(&bright))
            .into_iter()
            .map(|c| !c)
            .collect();
        let share = shown.iter().filter(|s| **s).count() as f64 / shown.len().max(1) as f64;
        (shown, share)
    }

    /// The camera pixels a second pass decodes: those this pass found reached by direct light
    /// (`direct ≥ reach`) but could not decode, inside a reached region (at least
    /// [`SOLID_NEIGHBOURS`] of the 8 neighbours reached, decoded or not). A pixel lit only by
    /// inter-reflected light can pass the reach threshold by noise alone (the direct light is
    /// the largest of many noisy differences), but such pixels are scattered, not a surface; in
    /// a second pass that shows only a few projector pixels their inter-reflected light can
    /// carry a consistent code (the lab's wall-front: 6% of its frame shown, before this test
    /// and the simulator's area-integrated elements, gave 234,000 such pixels, 71% off).
    pub fn reached_unknown(&self, config: &DecodeConfig) -> Vec<bool> {
        let (w, h) = (self.width as usize, self.height as usize);
        let reached: Vec<bool> = (0..w * h)
            .map(|i| {
                let (ld, lg) = (self.direct[i], self.global[i]);
                // The noise of one pattern − inverse difference at the pixel's level.
                let level = (0.5 * (lg + ld)).max(0.0);
                let sigma = (2.0
                    * (config.noise_floor * config.noise_floor
                        + config.shot_noise * config.shot_noise * level))
                    .sqrt();
                self.map[i].is_some() || (ld >= self.reach && ld >= SECOND_PASS_SNR * sigma)
            })
            .collect();
        (0..w * h)
            .map(|i| {
                if self.map[i].is_some() || !reached[i] {
                    return false;
                }
                let (x, y) = (i % w, i / w);
                let around = (y.saturating_sub(1)..=(y + 1).min(h - 1))
                    .flat_map(|yy| {
                        (x.saturating_sub(1)..=(x + 1).min(w - 1)).map(move |xx| (xx, yy))
                    })
                    .filter(|&(xx, yy)| (xx, yy) != (x, y) && reached[yy * w + xx])
                    .count();
                around >= SOLID_NEIGHBOURS
            })
            .collect()
    }

    /// Takes every pixel this correspondence leaves unknown and a second pass (`other`, same
    /// camera and projector, showing the projector pixels `shown` marks) decodes onto a shown
    /// pixel or one beside it; returns how many were taken. A pixel decoded onto a black part
    /// of the frame was lit by reflected light, not directly: it stays unknown. Another camera
    /// or projector size, or a mask of another size, is refused.
    pub fn merge_second_pass(
        &mut self,
        other: &Correspondence,
        shown: &[bool],
    ) -> Result<usize, CalibError> {
        if (
            self.width,
            self.height,
            self.projector_width,
            self.projector_height,
        ) != (
            other.width,
            other.height,
            other.projector_width,
            other.projector_height,
        ) {
            return Err(CalibError::Invalid {
                field: "second pass",
                problem: format!(
                    "camera {}x{} and projector {}x{}, the first pass has camera {}x{} and projector {}x{}",
                    other.width,
                    other.height,
                    other.projector_width,
                    other.projector_height,
                    self.width,
                    self.height,
                    self.projector_width,
                    self.projector_height
                ),
            });
        }
        let (pw, ph) = (
            self.projector_width as usize,
            self.projector_height as usize,
        );
        if shown.len() != pw * ph {
            return Err(CalibError::Invalid {
                field: "second pass mask",
                problem: format!("{} pixels, the projector has {pw}x{ph}", shown.len()),
            });
        }
        let near_shown = dilate(shown, pw, ph, 1);
        // How many camera pixels land on each projector pixel: on a directly lit surface about
        // as many as in the first pass; a few shown pixels that light the room only through
        // its reflection give one code to a wide area.
        let per_pixel = |c: &Correspondence| {
            let mut n = vec![0u32; pw * ph];
            for (x, y) in c.map.iter().flatten() {
                if let Some(v) = n.get_mut(*y as usize * pw + *x as usize) {
                    *v += 1;
                }
            }
            n
        };
        let mut first: Vec<u32> = per_pixel(self).into_iter().filter(|n| *n > 0).collect();
        let typical = if first.is_empty() {
            1
        } else {
            let k = (first.len() - 1) * 99 / 100;
            *first.select_nth_unstable(k).1
        };
        let crowd = per_pixel(other);
        let most = SECOND_PASS_CROWD * typical.max(1);
        let mut taken = 0;
        for i in 0..self.map.len() {
            if self.map[i].is_none()
                && other.map[i].is_some_and(|(x, y)| {
                    let p = y as usize * pw + x as usize;
                    near_shown[p] && crowd[p] <= most
                })
            {
                self.map[i] = other.map[i];
                self.confidence[i] = other.confidence[i];
                self.direct[i] = other.direct[i];
                self.global[i] = other.global[i];
                taken += 1;
            }
        }
        Ok(taken)
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
}

/// Decodes one projector from its captures, looked up by pattern. Every capture must have the
/// camera's size.
///
/// Two passes: each pixel on its own (at most one untrusted bit), then, with XOR coding and
/// [`DecodeConfig::fill_from_neighbours`], pixels with more untrusted bits from their decoded
/// neighbours ([`fill_from_neighbours`]).
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
    mut capture: impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
) -> Result<Correspondence, CalibError> {
    let find = |pattern: Pattern| {
        manifest
            .patterns
            .iter()
            .find(|p| p.pattern == pattern)
            .ok_or(CalibError::Invalid {
                field: "manifest",
                problem: format!("has no {pattern:?} pattern"),
            })
    };
    let white_file = find(Pattern::White)?;
    let white = capture(white_file)?;
    let (w, h) = (white.width, white.height);
    let mut intensity = |p: &PatternFile| -> Result<Vec<f32>, CalibError> {
        let img = capture(p)?;
        img.expect_size(w, h, &p.file)?;
        Ok(img.intensity())
    };
    let white = intensity(white_file)?;
    let black = intensity(find(Pattern::Black)?)?;
    let n = (w * h) as usize;
    if let Some(mask) = ours
        && mask.len() != n
    {
        return Err(CalibError::Invalid {
            field: "decode mask",
            problem: format!("{} pixels, the captures have {w}x{h}", mask.len()),
        });
    }
    // Pairs (pattern − black, inverse − black) per axis and bit.
    let mut pairs: Vec<(Axis, u32, Vec<f32>, Vec<f32>)> = Vec::new();
    for (axis, bits) in [
        (Axis::Column, manifest.column_bits),
        (Axis::Row, manifest.row_bits),
    ] {
        for bit in 0..bits {
            let p = intensity(find(Pattern::Bit {
                axis,
                bit,
                inverse: false,
            })?)?;
            let q = intensity(find(Pattern::Bit {
                axis,
                bit,
                inverse: true,
            })?)?;
            let p: Vec<f32> = p.iter().zip(&black).map(|(a, b)| a - b).collect();
            let q: Vec<f32> = q.iter().zip(&black).map(|(a, b)| a - b).collect();
            pairs.push((axis, bit, p, q));
        }
    }
    // Direct and global light from the two finest patterns of each axis (Nayar et al.): with
    // half the pixels on, max = Ld + Lg/2 and min = Lg/2.
    // With XOR coding every pattern is high-frequency, so every pair can be used.
    let xor = manifest.coding == Coding::Xor04;
    let fine: Vec<&(Axis, u32, Vec<f32>, Vec<f32>)> = pairs
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
    let mut sorted: Vec<f32> = direct.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p99 = sorted.get(sorted.len() * 99 / 100).copied().unwrap_or(0.0);
    let reach = (config.min_direct_share * p99).max(6.0 * config.noise_floor);
    // One reading per pattern pair: the difference `d` and, where the direct light decides it,
    // the encoded value it shows (`None`: untrusted), with the noise of the difference.
    let reading = |i: usize, out: &mut Vec<Reading>| {
        let (ld, lg) = (direct[i], global[i]);
        out.clear();
        out.extend(pairs.iter().map(|(axis, bit, p, q)| {
            let (a, b) = (p[i], q[i]);
            let d = a - b;
            // Noise of a difference of two pixels around their level.
            let level = a.max(b).max(0.0);
            let sigma = (2.0
                * (config.noise_floor * config.noise_floor
                    + config.shot_noise * config.shot_noise * level))
                .sqrt();
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
    };
    let reached = |i: usize| {
        // NaN (a corrupt capture) counts as not reached.
        ours.is_none_or(|m| m[i])
            && !(direct[i].is_nan() || direct[i] < reach || white[i] - black[i] < reach)
    };
    let mut map = vec![None; n];
    let mut confidence = vec![0.0f32; n];
    let mut readings = Vec::with_capacity(pairs.len());
    for i in 0..n {
        if !reached(i) {
            continue;
        }
        let ld = direct[i];
        // (value, trusted) of every encoded bit, per axis, most significant first.
        let mut read: [Vec<(bool, bool)>; 2] = [Vec::new(), Vec::new()];
        let mut worst = f32::INFINITY;
        reading(i, &mut readings);
        for r in &readings {
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
            continue;
        }
        let (x, y) = (gray_inverse(codes[0]), gray_inverse(codes[1]));
        if x >= manifest.width || y >= manifest.height {
            continue;
        }
        map[i] = Some((x, y));
        let c = worst.min(1.0);
        confidence[i] = if uncertain == 1 { 0.5 * c } else { c };
    }
    // The fill correlates the differences with candidate codes: that needs every pair's sign to
    // be the direct light's, true of XOR coding's high-frequency patterns only.
    if config.fill_from_neighbours && xor {
        fill_from_neighbours(
            manifest,
            w as usize,
            h as usize,
            &reached,
            &reading,
            &direct,
            &mut map,
            &mut confidence,
        );
    }
    Ok(Correspondence {
        width: w,
        height: h,
        projector_width: manifest.width,
        projector_height: manifest.height,
        map,
        confidence,
        direct,
        global,
        reach,
    })
}

/// A first pass that leaves more than this share of its decoded pixels reached but unknown
/// ([`Correspondence::reached_unknown`]) gets a second pass ([`second_pass`]). In the lab only
/// floor-right does (5.8%: a face at grazing incidence in a corner with a lit floor); the others
/// leave 0.04–2.6% and a second pass would add almost nothing for its captures.
pub const SECOND_PASS_WORTH: f64 = 0.03;
/// A decoded surface is black in a second pass when its direct light is at least this many
/// times the median of the pixels left to decode.
pub const SECOND_PASS_BRIGHTER: f32 = 2.0;
/// The direct light (the largest pattern − inverse difference) a pixel needs, in noise standard
/// deviations of one difference, to count as reached for a second pass: the largest of about
/// 20 differences of pure noise is a median 2.5 of them (measured: 2.4–2.9 on inter-reflected
/// light in the small room; 4.4 on the lab's dim face).
pub const SECOND_PASS_SNR: f32 = 3.5;
/// A second pass decodes the unknown pixels within this many pixels of
/// [`Correspondence::reached_unknown`]'s.
pub const SECOND_PASS_GROW: u32 = 4;
/// Of a pixel's 8 neighbours, how many must be reached for it to be part of a reached surface
/// ([`Correspondence::reached_unknown`]).
pub const SOLID_NEIGHBOURS: usize = 6;
/// A second pass's pixel is refused when more camera pixels than this many times the first
/// pass's 99th percentile land on its projector pixel ([`Correspondence::merge_second_pass`]).
pub const SECOND_PASS_CROWD: u32 = 4;
/// How far apart (projector pixels, per axis) the coordinates of a 2×2 block of camera pixels
/// may lie and still be one surface in [`Correspondence::covered`]: a camera pixel spans a few
/// projector pixels on a minified surface, a depth edge many.
pub const COVER_SPAN: u32 = 8;

/// Projector pixels within this distance of a bright decoded surface stay black in a second
/// pass. None: in the lab a margin of one pixel blacked out the edge of the dim face next to the
/// lit floor (floor-right 97.9% within ±1 after the second pass, 98.9% without it, none off by
/// more than 2 either way).
pub const SECOND_PASS_MARGIN: u32 = 0;
/// The longest exposure of a second pass, as a multiple of the normal one, when the camera
/// allows it (in the lab: floor-right's second pass needs ×6; ×64 decoded no more pixels).
pub const SECOND_PASS_LONGEST: f32 = 16.0;

/// What a [`second_pass`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SecondPass {
    /// Share of the projector frame shown.
    pub shown: f64,
    /// Exposure as a multiple of the normal one.
    pub exposure: f32,
    /// Captures taken (the masked white at the normal exposure, then the pattern set).
    pub captures: usize,
    /// Camera pixels it decoded that the first pass had left unknown.
    pub taken: usize,
}

/// A second structured-light pass over the projector pixels the first did not cover
/// ([`Correspondence::second_pass_mask`]), when the first left enough reached pixels unknown
/// ([`SECOND_PASS_WORTH`]); `None` otherwise. `shoot(image, exposure)` shows `image` on this
/// projector (the others black) and returns a capture `exposure` times as long, scaled back to
/// the units of a normal one. The exposure comes from the masked white at the normal exposure
/// ([`second_pass_exposure`], at most `longest`); the pass decodes only the pixels the first
/// found reached but could not decode and merges them into `first`
/// ([`Correspondence::merge_second_pass`]).
pub fn second_pass<E: From<CalibError>>(
    manifest: &Manifest,
    config: &DecodeConfig,
    first: &mut Correspondence,
    saturation: f32,
    longest: f32,
    mut shoot: impl FnMut(&LinearImage, f32) -> Result<LinearImage, E>,
) -> Result<Option<SecondPass>, E> {
    let Some(plan) = SecondPassPlan::new(config, first) else {
        return Ok(None);
    };
    let white = shoot(&plan.white(manifest)?, 1.0)?;
    let exposure = plan.exposure(first, &white, saturation, longest)?;
    let mut captures = Vec::with_capacity(manifest.patterns.len());
    for p in &manifest.patterns {
        captures.push(shoot(&plan.pattern(manifest, p.pattern)?, exposure)?);
    }
    Ok(Some(
        plan.finish(manifest, config, first, exposure, &captures)?,
    ))
}

/// A [`second_pass`] decided on, taken apart for callers that show and capture on their own
/// terms (asynchronously, [`crate::procedure`]): the masked white at the normal exposure,
/// then every pattern of the manifest masked the same way at [`SecondPassPlan::exposure`],
/// then [`SecondPassPlan::finish`].
#[derive(Debug, Clone, PartialEq)]
pub struct SecondPassPlan {
    /// Projector pixels shown ([`Correspondence::second_pass_mask`]).
    shown: Vec<bool>,
    /// Their share of the frame.
    share: f64,
    /// Camera pixels it decodes.
    todo: Vec<bool>,
}

impl SecondPassPlan {
    /// The plan when the first pass left enough reached pixels unknown
    /// ([`SECOND_PASS_WORTH`]); `None` otherwise.
    pub fn new(config: &DecodeConfig, first: &Correspondence) -> Option<Self> {
        let todo = first.reached_unknown(config);
        let unknown = todo.iter().filter(|t| **t).count();
        let decoded = first.map.iter().filter(|m| m.is_some()).count();
        if (unknown as f64) <= SECOND_PASS_WORTH * decoded as f64 {
            return None;
        }
        let (shown, share) = first.second_pass_mask(&todo, SECOND_PASS_MARGIN);
        // The unknown pixels within a few pixels of those regions too: a dim surface's weakest
        // pixels (and those on the image border) fail the test by themselves.
        let todo: Vec<bool> = dilate(
            &todo,
            first.width as usize,
            first.height as usize,
            SECOND_PASS_GROW,
        )
        .into_iter()
        .zip(&first.map)
        .map(|(t, m)| t && m.is_none())
        .collect();
        Some(Self { shown, share, todo })
    }

    /// The masked white, shown first at the normal exposure.
    pub fn white(&self, manifest: &Manifest) -> Result<LinearImage, CalibError> {
        self.pattern(manifest, Pattern::White)
    }

    /// `pattern` masked to the projector pixels this pass shows.
    pub fn pattern(
        &self,
        manifest: &Manifest,
        pattern: Pattern,
    ) -> Result<LinearImage, CalibError> {
        manifest.pattern_image_where(pattern, &self.shown)
    }

    /// The exposure of the pattern captures from the masked white's capture
    /// ([`second_pass_exposure`]); a white of another size than the camera is refused.
    pub fn exposure(
        &self,
        first: &Correspondence,
        white: &LinearImage,
        saturation: f32,
        longest: f32,
    ) -> Result<f32, CalibError> {
        white.expect_size(first.width, first.height, "second pass white")?;
        Ok(second_pass_exposure(white, &self.todo, saturation, longest))
    }

    /// Decodes the pattern captures (in manifest order, taken at `exposure`) over the pixels
    /// the first pass left unknown and merges them into `first`
    /// ([`Correspondence::merge_second_pass`]).
    pub fn finish(
        &self,
        manifest: &Manifest,
        config: &DecodeConfig,
        first: &mut Correspondence,
        exposure: f32,
        captures: &[LinearImage],
    ) -> Result<SecondPass, CalibError> {
        let second = decode_where(
            manifest,
            &config.exposed_longer(exposure),
            Some(&self.todo),
            |f| {
                manifest
                    .patterns
                    .iter()
                    .position(|p| p.file == f.file)
                    .and_then(|j| captures.get(j))
                    .ok_or_else(|| CalibError::File {
                        file: f.file.clone(),
                        problem: "not captured in the second pass".into(),
                    })
            },
        )?;
        let taken = first.merge_second_pass(&second, &self.shown)?;
        Ok(SecondPass {
            shown: self.share,
            exposure,
            captures: captures.len() + 1,
            taken,
        })
    }
}

/// The exposure factor (1 to `longest`) of a second pass from its white frame captured at the
/// normal exposure: the camera pixels it decodes (`among`) must stay below `saturation` (per
/// channel, capture units) with a margin. Light being additive, no masked pattern gives a pixel
/// more than the masked white; its 99.9th percentile over `among` sets the factor (the
/// brightest 0.1% may clip and stay unknown). Nothing to decode or nothing lit: `longest`;
/// a saturation that is not a positive number: 1.
pub fn second_pass_exposure(
    white: &LinearImage,
    among: &[bool],
    saturation: f32,
    longest: f32,
) -> f32 {
    let longest = if longest.is_finite() {
        longest.max(1.0)
    } else {
        1.0
    };
    let mut levels: Vec<f32> = white
        .pixels
        .iter()
        .zip(among)
        .filter(|(_, a)| **a)
        .map(|(p, _)| p[0].max(p[1]).max(p[2]))
        .filter(|v| v.is_finite())
        .collect();
    if levels.is_empty() {
        return longest;
    }
    let k = (levels.len() - 1) * 999 / 1000;
    let (_, top, _) = levels.select_nth_unstable_by(k, f32::total_cmp);
    // At zero light any exposure is safe: the longest.
    if *top <= 0.0 {
        return longest;
    }
    let factor = 0.8 * saturation / *top;
    // A saturation that is not a positive number: the normal exposure.
    if factor.is_finite() {
        factor.clamp(1.0, longest)
    } else {
        1.0
    }
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

/// How far (projector pixels) a candidate may lie from the neighbours' prediction.
const FILL_RADIUS: i64 = 8;
/// The share of the measured differences (by magnitude) a filled pixel's code must agree with:
/// a pixel in shadow next to a lit surface sees that surface's code in its inter-reflected
/// light, which agrees with no single position that well.
const FILL_AGREEMENT: f32 = 0.9;
/// How many times a pixel is tried as its neighbours fill in.
const FILL_TRIES: u8 = 3;

/// The second pass of [`decode`]: a reached pixel with more than one untrusted bit (a weak
/// direct signal next to strong global light, or a surface at grazing incidence where
/// pattern-dependent inter-reflection flips weak bits) is decoded from its decoded neighbours,
/// growing inwards from them. Per axis, the neighbours predict its coordinate (a linear
/// extrapolation of two neighbours in a row where there are such, else the neighbours
/// themselves); of the coordinates within [`FILL_RADIUS`] of the prediction that agree with
/// every trusted bit, the one whose code correlates best with the measured differences is taken
/// when it agrees with [`FILL_AGREEMENT`] of them and beats every candidate more than one pixel
/// away by six noise standard deviations and half the direct light. Otherwise the pixel stays
/// unknown: across a depth edge the prediction is wrong and no candidate agrees clearly.
#[allow(clippy::too_many_arguments)]
fn fill_from_neighbours(
    manifest: &Manifest,
    w: usize,
    h: usize,
    reached: &impl Fn(usize) -> bool,
    reading: &impl Fn(usize, &mut Vec<Reading>),
    direct: &[f32],
    map: &mut [Option<(u32, u32)>],
    confidence: &mut [f32],
) {
    const AROUND: [(isize, isize); 8] = [
        (-1, -1),
        (0, -1),
        (1, -1),
        (-1, 0),
        (1, 0),
        (-1, 1),
        (0, 1),
        (1, 1),
    ];
    let at = |i: usize, (dx, dy): (isize, isize), k: isize| -> Option<usize> {
        let (x, y) = ((i % w) as isize + dx * k, (i / w) as isize + dy * k);
        (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
            .then(|| y as usize * w + x as usize)
    };
    let mut tries = vec![0u8; w * h];
    let mut readings = Vec::new();
    let mut queue: VecDeque<usize> = VecDeque::new();
    let push_around =
        |i: usize, map: &[Option<(u32, u32)>], tries: &mut [u8], queue: &mut VecDeque<usize>| {
            for dir in AROUND {
                if let Some(j) = at(i, dir, 1)
                    && map[j].is_none()
                    && tries[j] < FILL_TRIES
                    && reached(j)
                {
                    tries[j] += 1;
                    queue.push_back(j);
                }
            }
        };
    for i in 0..w * h {
        if map[i].is_some() {
            push_around(i, map, &mut tries, &mut queue);
        }
    }
    while let Some(i) = queue.pop_front() {
        if map[i].is_some() {
            continue;
        }
        // Predictions per axis from the neighbours: extrapolations where there are any.
        let (mut extrapolated, mut adjacent): ([Vec<i64>; 2], [Vec<i64>; 2]) = Default::default();
        for dir in AROUND {
            let Some(a) = at(i, dir, 1).and_then(|j| map[j]) else {
                continue;
            };
            let b = at(i, dir, 2).and_then(|j| map[j]);
            for (k, (va, vb)) in [(a.0, b.map(|b| b.0)), (a.1, b.map(|b| b.1))]
                .into_iter()
                .enumerate()
            {
                adjacent[k].push(i64::from(va));
                if let Some(vb) = vb {
                    extrapolated[k].push(2 * i64::from(va) - i64::from(vb));
                }
            }
        }
        let mut predictions = [0, 1].map(|k| {
            if extrapolated[k].is_empty() {
                std::mem::take(&mut adjacent[k])
            } else {
                std::mem::take(&mut extrapolated[k])
            }
        });
        reading(i, &mut readings);
        let ld = direct[i];
        let (Some((x, x_gap)), Some((y, y_gap))) = (
            best_on_axis(manifest, Axis::Column, &readings, &mut predictions[0], ld),
            best_on_axis(manifest, Axis::Row, &readings, &mut predictions[1], ld),
        ) else {
            continue;
        };
        map[i] = Some((x, y));
        // At most a quarter: where a measured pixel lands on the same projector pixel the
        // inverse map mostly prefers it.
        confidence[i] = 0.25 * (x_gap.min(y_gap) / (2.0 * ld).max(f32::MIN_POSITIVE)).min(1.0);
        push_around(i, map, &mut tries, &mut queue);
    }
}

/// One axis of [`fill_from_neighbours`]: the coordinate near the median of `predictions` whose
/// code agrees with every trusted reading and best with all of them, with its lead over every
/// candidate more than one pixel away; `None` when no candidate is clear.
fn best_on_axis(
    manifest: &Manifest,
    axis: Axis,
    readings: &[Reading],
    predictions: &mut [i64],
    ld: f32,
) -> Option<(u32, f32)> {
    predictions.sort_unstable();
    let centre = *predictions.get(predictions.len() / 2)?;
    let size = i64::from(match axis {
        Axis::Column => manifest.width,
        Axis::Row => manifest.height,
    });
    let ours: Vec<&Reading> = readings.iter().filter(|r| r.axis == axis).collect();
    let noise = ours.iter().map(|r| r.sigma).sum::<f32>() / ours.len().max(1) as f32;
    let candidates: Vec<(i64, f32)> = ((centre - FILL_RADIUS).max(0)
        ..=(centre + FILL_RADIUS).min(size - 1))
        .filter_map(|v| {
            let mut score = 0.0f32;
            for r in &ours {
                let e = manifest.encoded_bit(axis, r.bit, v as u32);
                if r.trusted.is_some_and(|t| t != e) {
                    return None;
                }
                score += if e { r.d } else { -r.d };
            }
            Some((v, score))
        })
        .collect();
    let &(best, score) = candidates.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    // No rival at all (every other candidate disagrees with a trusted bit): an infinite lead.
    let rival = candidates
        .iter()
        .filter(|(v, _)| (v - best).abs() > 1)
        .map(|c| c.1)
        .fold(f32::NEG_INFINITY, f32::max);
    let gap = score - rival;
    let total: f32 = ours.iter().map(|r| r.d.abs()).sum();
    // NaN differences (a corrupt capture) fail both comparisons.
    (score >= FILL_AGREEMENT * total && gap >= (6.0 * noise).max(0.5 * ld))
        .then_some((best as u32, gap))
}

/// Groups projectors whose footprints (camera pixels each lights directly) do not overlap, so
/// that each group shows its patterns at the same time. Greedy, in the given order.
pub fn group_disjoint(footprints: &[Vec<bool>]) -> Vec<Vec<usize>> {
    let mut groups: Vec<(Vec<usize>, Vec<bool>)> = Vec::new();
    for (k, fp) in footprints.iter().enumerate() {
        match groups
            .iter_mut()
            .find(|(_, used)| used.iter().zip(fp).all(|(a, b)| !(*a && *b)))
        {
            Some((members, used)) => {
                members.push(k);
                for (u, f) in used.iter_mut().zip(fp) {
                    *u |= *f;
                }
            }
            None => groups.push((vec![k], fp.clone())),
        }
    }
    groups.into_iter().map(|(m, _)| m).collect()
}
