//! One projector's structured-light captures as the decoder reads them ([`Captures`]): the
//! intensity (the sum of the three channels) of white and black, white's brightest channel (for
//! the saturation check), and each pattern and its inverse less black. A capture of the lab's
//! 1024×768 camera is 9.4 MB as linear RGB and 3.1 MB reduced; a projector has some 44, so
//! the calibration reduces each as it arrives ([`Reduced`], or [`less_black`] for captures
//! shared by a group) and never holds the images. It owns that reduction; it must not know how
//! frames are shown or captured.

use super::{Axis, Manifest, Pattern, PatternFile};
use crate::CalibError;
use crate::image_io::LinearImage;

/// A pattern and its inverse, each less the black capture: `(axis, bit, pattern, inverse)`.
pub(super) type Pair<'a> = (Axis, u32, &'a [f32], &'a [f32]);

/// What the decoder reads of one projector's captures, borrowed from whoever reduced them.
#[derive(Debug)]
pub struct Captures<'a> {
    pub(super) w: u32,
    pub(super) h: u32,
    pub(super) white: &'a [f32],
    pub(super) black: &'a [f32],
    /// White's brightest channel per pixel: where it reaches the camera's ceiling, white clips.
    pub(super) white_top: &'a [f32],
    /// Every bit's pair, column bits first, each from the most significant.
    pub(super) pairs: Vec<Pair<'a>>,
    /// `Some(exposure)` when no inverse was captured: each is white less its pattern
    /// ([`Captures::single_shot`]), the patterns exposed `exposure` times as long as white
    /// (and scaled back to its units).
    pub(super) single: Option<f32>,
}

impl<'a> Captures<'a> {
    /// The captures of a `w × h` camera for `manifest`: white's and black's intensity, white's
    /// brightest channel ([`brightest`]), and `less_black(pattern)`, each bit pattern's
    /// intensity less black's ([`less_black`]). Anything not of `w × h` pixels is refused,
    /// named.
    pub fn new(
        manifest: &Manifest,
        (w, h): (u32, u32),
        (white, black, white_top): (&'a [f32], &'a [f32], &'a [f32]),
        mut less_black: impl FnMut(Pattern) -> Result<&'a [f32], CalibError>,
    ) -> Result<Self, CalibError> {
        let n = (w as usize) * (h as usize);
        let sized = |what: &str, len: usize| {
            if len == n {
                Ok(())
            } else {
                Err(CalibError::File {
                    file: what.to_string(),
                    problem: format!("{len} pixels, the captures have {w}x{h}"),
                })
            }
        };
        sized("white", white.len())?;
        sized("black", black.len())?;
        sized("white's brightest channel", white_top.len())?;
        let mut pairs = Vec::new();
        for (axis, bits) in [
            (Axis::Column, manifest.column_bits),
            (Axis::Row, manifest.row_bits),
        ] {
            for bit in 0..bits {
                let mut one = |inverse| {
                    let pattern = Pattern::Bit { axis, bit, inverse };
                    let v = less_black(pattern)?;
                    sized(&format!("{pattern:?}"), v.len())?;
                    Ok::<_, CalibError>(v)
                };
                let (p, q) = (one(false)?, one(true)?);
                pairs.push((axis, bit, p, q));
            }
        }
        Ok(Self {
            w,
            h,
            white,
            black,
            white_top,
            pairs,
            single: None,
        })
    }

    /// The captures of a single-shot pattern set: each bit pattern captured once, without its
    /// inverse. XOR coding makes every pattern high-frequency, so a pixel's reflected light is
    /// about half of white's under a pattern as under its inverse: the inverse a camera would
    /// have captured is white less the pattern (both less black), made here into `made`.
    /// A difference is then 2·pattern − white, which carries the same reflected light as a
    /// pair's (pattern − inverse) but four times a capture's noise variance and white's,
    /// against twice; the noise cannot be measured from pattern + inverse against white, so
    /// the decoder takes the camera model's, for patterns `exposure` times as long as white
    /// (≥ 1; scaled back to white's units). At twice the exposure a read-noise-limited
    /// difference is as clean as a pair's in half the captures. Plain Gray code is refused, not
    /// for its reflected light (white less a pattern is, by linearity, the inverse a camera
    /// would capture, reflected light and blur included) but for what it codes: the defocused
    /// large aperture, whose blurred fine stripes differ from their inverses by little more
    /// than the noise; shown once, 9.6% of the lab's large aperture's decoded pixels fell where
    /// it gives no direct light (2026-12-04). The clipping fallback below also needs XOR's
    /// patterns, which light about half of every pixel's.
    ///
    /// Where a lit pattern can clip (white's brightest channel at `clip`, the level at which
    /// a pattern capture clips in these captures' units: the camera's ceiling over the
    /// patterns' exposure; none when it is not a positive number), white less black
    /// understates what a lit pattern would give, and the pixel would read every pattern as
    /// lit: a code from the clipping alone, confidently wrong (a joiner's edge in a room the
    /// others light near the ceiling). There the inverse is made from the pixel's own brightest
    /// and darkest pattern instead (their sum stands for white): XOR coding lights about half
    /// of a pixel's patterns, so the two are its lit and unlit levels, and a pixel that reads
    /// the same under every pattern gets no difference at all, unknown, as a pair would.
    pub fn single_shot(
        manifest: &Manifest,
        (w, h): (u32, u32),
        (white, black, white_top): (&'a [f32], &'a [f32], &'a [f32]),
        mut less_black: impl FnMut(Pattern) -> Result<&'a [f32], CalibError>,
        made: &'a mut Vec<Vec<f32>>,
        exposure: f32,
        clip: f32,
    ) -> Result<Self, CalibError> {
        if !(exposure.is_finite() && exposure >= 1.0) {
            return Err(CalibError::Invalid {
                field: "single-shot exposure",
                problem: format!("{exposure}, expected a finite factor of at least 1"),
            });
        }
        if manifest.coding != super::Coding::Xor04 {
            return Err(CalibError::Invalid {
                field: "single-shot structured light",
                problem: format!(
                    "needs XOR coding, the pattern set is {:?} (plain Gray code codes a \
                     defocused projector, whose blurred stripes need captured inverses' lower \
                     noise)",
                    manifest.coding
                ),
            });
        }
        let n = (w as usize) * (h as usize);
        if white.len() != n || black.len() != n {
            return Err(CalibError::File {
                file: "white and black".into(),
                problem: format!(
                    "{} and {} pixels, the captures have {w}x{h}",
                    white.len(),
                    black.len()
                ),
            });
        }
        let mut patterns = Vec::new();
        made.clear();
        for (axis, bits) in [
            (Axis::Column, manifest.column_bits),
            (Axis::Row, manifest.row_bits),
        ] {
            for bit in 0..bits {
                let pattern = Pattern::Bit {
                    axis,
                    bit,
                    inverse: false,
                };
                let p = less_black(pattern)?;
                if p.len() != n {
                    return Err(CalibError::File {
                        file: format!("{pattern:?}"),
                        problem: format!("{} pixels, the captures have {w}x{h}", p.len()),
                    });
                }
                patterns.push((axis, bit, p));
            }
        }
        // What a lit pattern plus an unlit one give each pixel (see above).
        let ceiling = clip * (1.0 - 1e-3);
        let base: Vec<f32> = (0..n)
            .map(|i| {
                let clips = clip > 0.0 && white_top[i] >= ceiling;
                if !clips {
                    return white[i] - black[i];
                }
                let (lo, hi) = patterns
                    .iter()
                    .map(|(.., p)| p[i])
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
                        (lo.min(v), hi.max(v))
                    });
                // No pattern (a manifest of no bits): nothing to read either way.
                if lo.is_finite() && hi.is_finite() {
                    lo + hi
                } else {
                    0.0
                }
            })
            .collect();
        for (.., p) in &patterns {
            made.push(p.iter().zip(&base).map(|(v, b)| b - v).collect());
        }
        let made: &'a Vec<Vec<f32>> = made;
        let mut captures = Self::new(manifest, (w, h), (white, black, white_top), |pattern| {
            match pattern {
                Pattern::Bit { axis, bit, inverse } => patterns
                    .iter()
                    .position(|&(a, b, _)| (a, b) == (axis, bit))
                    .map(|j| {
                        if inverse {
                            made[j].as_slice()
                        } else {
                            patterns[j].2
                        }
                    }),
                _ => None,
            }
            .ok_or_else(|| CalibError::Invalid {
                field: "single-shot structured light",
                problem: format!("no capture for {pattern:?}"),
            })
        })?;
        captures.single = Some(exposure);
        Ok(captures)
    }
}

/// A capture's intensity less `black` (black's intensity) per pixel: what the decoder reads
/// of a bit pattern. `black` must have the capture's pixel count (the caller checks sizes).
pub fn less_black(image: &LinearImage, black: &[f32]) -> Vec<f32> {
    let mut v = image.intensity();
    for (a, b) in v.iter_mut().zip(black) {
        *a -= b;
    }
    v
}

/// Each pixel's brightest channel: what the saturation check reads of white.
pub fn brightest(image: &LinearImage) -> Vec<f32> {
    image
        .pixels
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .collect()
}

/// Structured-light captures reduced as they arrive, in any order, to what decoding reads
/// ([`Captures`]): the images can be dropped at once. A bit pattern that arrives before black
/// is kept as its intensity and made less black when black comes.
#[derive(Debug, Clone, Default)]
pub struct Reduced {
    size: Option<(u32, u32)>,
    /// White's intensity and brightest channel.
    white: Option<(Vec<f32>, Vec<f32>)>,
    black: Option<Vec<f32>>,
    /// Bit patterns' intensities, less black's once black is in.
    bits: Vec<(Pattern, Vec<f32>)>,
}

impl Reduced {
    /// Nothing captured yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the capture of `file`'s pattern. The first capture sets the camera's size; one of
    /// another size, or a pattern captured twice, is refused.
    pub fn add(&mut self, file: &PatternFile, image: &LinearImage) -> Result<(), CalibError> {
        let (w, h) = *self.size.get_or_insert((image.width, image.height));
        image.expect_size(w, h, &file.file)?;
        let twice = match file.pattern {
            Pattern::White => self.white.is_some(),
            Pattern::Black => self.black.is_some(),
            Pattern::Bit { .. } => self.bits.iter().any(|(p, _)| *p == file.pattern),
        };
        if twice {
            return Err(CalibError::File {
                file: file.file.clone(),
                problem: "captured twice".into(),
            });
        }
        match file.pattern {
            Pattern::White => self.white = Some((image.intensity(), brightest(image))),
            Pattern::Black => {
                let black = image.intensity();
                for (_, v) in &mut self.bits {
                    for (a, b) in v.iter_mut().zip(&black) {
                        *a -= b;
                    }
                }
                self.black = Some(black);
            }
            Pattern::Bit { .. } => {
                let v = match &self.black {
                    Some(black) => less_black(image, black),
                    None => image.intensity(),
                };
                self.bits.push((file.pattern, v));
            }
        }
        Ok(())
    }

    /// Captures added so far.
    pub fn len(&self) -> usize {
        usize::from(self.white.is_some()) + usize::from(self.black.is_some()) + self.bits.len()
    }

    /// Whether nothing was added.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reads `manifest`'s captures in the order a rig that shows them one by one expects:
    /// white (its size is the camera's), black, then every pair, column bits first; with
    /// `single`, every bit pattern without its inverse ([`Captures::single_shot`]).
    pub fn read<'a>(
        manifest: &Manifest,
        single: bool,
        capture: &mut impl FnMut(&PatternFile) -> Result<&'a LinearImage, CalibError>,
    ) -> Result<Self, CalibError> {
        let mut reduced = Self::new();
        let mut order = vec![Pattern::White, Pattern::Black];
        for (axis, bits) in [
            (Axis::Column, manifest.column_bits),
            (Axis::Row, manifest.row_bits),
        ] {
            for bit in 0..bits {
                for inverse in [false, true] {
                    if !(single && inverse) {
                        order.push(Pattern::Bit { axis, bit, inverse });
                    }
                }
            }
        }
        for pattern in order {
            let file = find(manifest, pattern)?;
            reduced.add(file, capture(file)?)?;
        }
        Ok(reduced)
    }

    /// What the decoder reads of `manifest`'s captures; one not added is refused, named.
    pub fn captures(&self, manifest: &Manifest) -> Result<Captures<'_>, CalibError> {
        let (size, light) = self.light(manifest)?;
        Captures::new(manifest, size, light, |pattern| self.bit(manifest, pattern))
    }

    /// What the decoder reads of `manifest`'s single-shot captures (no inverse captured;
    /// [`Captures::single_shot`] makes them into `made`), all at the same exposure.
    pub fn captures_single_shot<'s>(
        &'s self,
        manifest: &Manifest,
        made: &'s mut Vec<Vec<f32>>,
        clip: f32,
    ) -> Result<Captures<'s>, CalibError> {
        let (size, light) = self.light(manifest)?;
        Captures::single_shot(
            manifest,
            size,
            light,
            |pattern| self.bit(manifest, pattern),
            made,
            1.0,
            clip,
        )
    }

    /// The camera's size and white's intensity, black's and white's brightest channel.
    #[allow(clippy::type_complexity)]
    fn light(
        &self,
        manifest: &Manifest,
    ) -> Result<((u32, u32), (&[f32], &[f32], &[f32])), CalibError> {
        let (white, white_top) = self
            .white
            .as_ref()
            .ok_or_else(|| not_captured(manifest, Pattern::White))?;
        let black = self
            .black
            .as_ref()
            .ok_or_else(|| not_captured(manifest, Pattern::Black))?;
        Ok((self.size.unwrap_or((0, 0)), (white, black, white_top)))
    }

    /// Bit pattern `pattern`'s capture less black.
    fn bit(&self, manifest: &Manifest, pattern: Pattern) -> Result<&[f32], CalibError> {
        self.bits
            .iter()
            .find(|(p, _)| *p == pattern)
            .map(|(_, v)| v.as_slice())
            .ok_or_else(|| not_captured(manifest, pattern))
    }
}

/// `pattern` was not captured, named by its file where the manifest has one.
fn not_captured(manifest: &Manifest, pattern: Pattern) -> CalibError {
    CalibError::File {
        file: find(manifest, pattern).map_or_else(|_| format!("{pattern:?}"), |f| f.file.clone()),
        problem: "not captured".into(),
    }
}

/// The manifest's entry for `pattern`.
pub(super) fn find(manifest: &Manifest, pattern: Pattern) -> Result<&PatternFile, CalibError> {
    manifest
        .patterns
        .iter()
        .find(|p| p.pattern == pattern)
        .ok_or(CalibError::Invalid {
            field: "manifest",
            problem: format!("has no {pattern:?} pattern"),
        })
}

#[cfg(test)]
mod tests {
    use super::super::synthetic::{Lit, capture};
    use super::super::{Correspondence, DecodeConfig, decode_captures, decode_where};
    use super::*;

    /// What the decoder read before captures were reduced as they arrive (kept here word for
    /// word as the reference): each image's intensity, white's clipped pixels, every pair
    /// less black.
    #[allow(clippy::type_complexity)]
    fn old_reading(
        manifest: &Manifest,
        saturation: f32,
        image: impl Fn(Pattern) -> LinearImage,
    ) -> (
        Vec<f32>,
        Vec<f32>,
        Vec<bool>,
        Vec<(Axis, u32, Vec<f32>, Vec<f32>)>,
    ) {
        let white = image(Pattern::White);
        let ceiling = saturation * (1.0 - 1e-3);
        let clipped = white
            .pixels
            .iter()
            .map(|p| saturation > 0.0 && p.iter().any(|&v| v >= ceiling))
            .collect();
        let black = image(Pattern::Black).intensity();
        let mut pairs = Vec::new();
        for (axis, bits) in [
            (Axis::Column, manifest.column_bits),
            (Axis::Row, manifest.row_bits),
        ] {
            for bit in 0..bits {
                let one = |inverse| image(Pattern::Bit { axis, bit, inverse }).intensity();
                let (p, q) = (one(false), one(true));
                let p: Vec<f32> = p.iter().zip(&black).map(|(a, b)| a - b).collect();
                let q: Vec<f32> = q.iter().zip(&black).map(|(a, b)| a - b).collect();
                pairs.push((axis, bit, p, q));
            }
        }
        (white.intensity(), black, clipped, pairs)
    }

    fn bits(v: &[f32]) -> Vec<u32> {
        v.iter().map(|x| x.to_bits()).collect()
    }

    /// Two correspondences equal to the bit (f32 compared by their bits, so -0 ≠ 0).
    fn assert_same(a: &Correspondence, b: &Correspondence) {
        assert_eq!(a.map, b.map);
        assert_eq!(bits(&a.confidence), bits(&b.confidence));
        assert_eq!(bits(&a.direct), bits(&b.direct));
        assert_eq!(bits(&a.global), bits(&b.global));
        assert_eq!(a.reach.to_bits(), b.reach.to_bits());
        assert_eq!(
            (a.width, a.height, a.projector_width, a.projector_height),
            (b.width, b.height, b.projector_width, b.projector_height)
        );
    }

    /// A 48×20 projector's every pattern on a 64×30 camera, one capture each.
    fn pattern_set() -> (Manifest, Vec<LinearImage>) {
        let manifest = Manifest::new(48, 20).expect("manifest");
        let lit = [Lit {
            manifest: &manifest,
            area: (4, 2, 62, 28),
        }];
        let images = (0u64..)
            .zip(&manifest.patterns)
            .map(|(shot, f)| capture((64, 30), &lit, &[Some(f.pattern)], shot))
            .collect();
        (manifest, images)
    }

    #[test]
    fn captures_reduced_as_they_arrive_read_and_decode_as_the_images_did() {
        let (manifest, images) = pattern_set();
        let image = |pattern: Pattern| {
            let j = manifest.patterns.iter().position(|f| f.pattern == pattern);
            images[j.expect("pattern")].clone()
        };
        // The right of the frame clips at white: the saturation check has something to read.
        let config = DecodeConfig::default();
        let (white, black, clipped, pairs) = old_reading(&manifest, config.saturation, image);
        assert!(clipped.iter().any(|&c| c) && !clipped.iter().all(|&c| c));
        // Arriving in the manifest's order, and with every bit before black and white last.
        let mut late = manifest.patterns.clone();
        late.rotate_left(2);
        for order in [manifest.patterns.clone(), late] {
            let mut reduced = Reduced::new();
            for f in &order {
                reduced.add(f, &image(f.pattern)).expect("add");
            }
            assert_eq!(reduced.len(), manifest.patterns.len());
            let read = reduced.captures(&manifest).expect("all captured");
            assert_eq!(bits(read.white), bits(&white));
            assert_eq!(bits(read.black), bits(&black));
            assert_eq!(super::super::checks::clipped(read.white_top, 1.0), clipped);
            assert_eq!(read.pairs.len(), pairs.len());
            for (new, old) in read.pairs.iter().zip(&pairs) {
                assert_eq!((new.0, new.1), (old.0, old.1));
                assert_eq!((bits(new.2), bits(new.3)), (bits(&old.2), bits(&old.3)));
            }
            // Decoded from the images (the public path) and from the reduction: the same.
            let ours: Vec<bool> = (0..64 * 30).map(|i| i % 64 < 50).collect();
            for mask in [None, Some(ours.as_slice())] {
                let from_images = decode_where(&manifest, &config, mask, |f| {
                    let j = manifest.patterns.iter().position(|p| p == f);
                    Ok(&images[j.expect("pattern")])
                })
                .expect("decode images");
                let reduced =
                    decode_captures(&manifest, &config, mask, true, &read).expect("decode reduced");
                assert!(from_images.decoded_share() > 0.5);
                assert_same(&from_images, &reduced);
            }
        }
        // Twice the same pattern, another size, or one missing: refused, named.
        let mut reduced = Reduced::new();
        let white_file = find(&manifest, Pattern::White).expect("white");
        reduced.add(white_file, &images[0]).expect("add");
        let twice = reduced.add(white_file, &images[0]).expect_err("twice");
        assert!(twice.to_string().contains("white.png"), "{twice}");
        let small = capture((8, 8), &[], &[], 0);
        assert!(reduced.add(&manifest.patterns[1], &small).is_err());
        let missing = reduced.captures(&manifest).expect_err("black missing");
        assert!(missing.to_string().contains("black.png"), "{missing}");
    }

    #[test]
    fn a_single_shot_decodes_where_pattern_and_inverse_do() {
        let (manifest, images) = pattern_set();
        let config = DecodeConfig {
            refuse_saturated: false,
            ..DecodeConfig::default()
        };
        let image = |f: &PatternFile| {
            let j = manifest.patterns.iter().position(|p| p == f);
            Ok(&images[j.expect("pattern")])
        };
        let paired = decode_where(&manifest, &config, None, image).expect("pairs");
        let single =
            super::super::decode_single_shot(&manifest, &config, None, image).expect("single shot");
        let known = |c: &Correspondence| c.map.iter().filter(|m| m.is_some()).count();
        let agree = paired
            .map
            .iter()
            .zip(&single.map)
            .filter(|(a, b)| a.is_some() && a == b)
            .count();
        println!(
            "paired {} single {} agree {agree}",
            known(&paired),
            known(&single)
        );
        assert!(known(&single) * 100 >= known(&paired) * 95);
        assert!(agree * 100 >= known(&single) * 99);
    }
}
