//! The second structured-light pass (DESIGN §4.2): where the first pass leaves reached
//! pixels unknown (a dim face beside a brightly lit one, whose reflected light hides its code),
//! the projector shows its patterns again over only the pixels the first did not cover, with
//! the bright surfaces black and a longer exposure. It owns deciding, masking, exposing and
//! merging; it must not know how frames are shown or captured (the caller's `shoot`, or the
//! calibration procedure's rig).

use super::*;

impl Correspondence {
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

    /// The reached but unknown pixels ([`Self::reached_unknown`]) per decoded pixel (see
    /// [`Self::unknown_share`]): what decides a second pass, and inverses after a single shot.
    pub fn reached_unknown_share(&self, config: &DecodeConfig) -> f64 {
        self.reached_unknown_share_in(config, None)
    }

    /// [`Self::reached_unknown_share`] counting only the unknown pixels `needed` marks (all
    /// when `None`), still per decoded pixel.
    pub fn reached_unknown_share_in(&self, config: &DecodeConfig, needed: Option<&[bool]>) -> f64 {
        self.unknown_share(&self.reached_unknown_in(config, needed))
    }

    /// [`Self::reached_unknown`] among the camera pixels `needed` marks (all when `None`; a
    /// pixel beyond its end is not needed).
    fn reached_unknown_in(&self, config: &DecodeConfig, needed: Option<&[bool]>) -> Vec<bool> {
        let mut todo = self.reached_unknown(config);
        if let Some(needed) = needed {
            for (i, t) in todo.iter_mut().enumerate() {
                *t &= needed.get(i).copied().unwrap_or(false);
            }
        }
        todo
    }

    /// How many of the pixels `todo` marks there are for each decoded pixel: 0 when none is
    /// marked, infinite when some are and none is decoded.
    fn unknown_share(&self, todo: &[bool]) -> f64 {
        let unknown = todo.iter().filter(|t| **t).count();
        let decoded = self.map.iter().filter(|m| m.is_some()).count();
        match (unknown, decoded) {
            (0, _) => 0.0,
            (_, 0) => f64::INFINITY,
            _ => unknown as f64 / decoded as f64,
        }
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
/// ([`Correspondence::merge_second_pass`]). With `single` the bit patterns are shown without
/// their inverses ([`super::Captures::single_shot`]).
#[allow(clippy::too_many_arguments)]
pub fn second_pass<E: From<CalibError>>(
    manifest: &Manifest,
    config: &DecodeConfig,
    first: &mut Correspondence,
    saturation: f32,
    longest: f32,
    single: bool,
    mut shoot: impl FnMut(&LinearImage, f32) -> Result<LinearImage, E>,
) -> Result<Option<SecondPass>, E> {
    let Some(plan) = SecondPassPlan::new(config, first, None) else {
        return Ok(None);
    };
    let white = shoot(&plan.white(manifest)?, 1.0)?;
    let exposure = plan.exposure(first, &white, saturation, longest)?;
    let mut captures = Reduced::new();
    for p in manifest.shown(single) {
        captures.add(p, &shoot(&plan.pattern(manifest, p.pattern)?, exposure)?)?;
    }
    Ok(Some(plan.finish(
        manifest, config, first, exposure, &captures, single,
    )?))
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
    /// ([`SECOND_PASS_WORTH`]) among the camera pixels `needed` marks (all when `None`);
    /// `None` otherwise. A projector joining a lit room is needed only where the others leave
    /// some of the light to it ([`crate::procedure::needed`]): where they give all of it, its
    /// weights will be zero however well it is decoded, and a second pass there would cost
    /// its captures for nothing.
    pub fn new(
        config: &DecodeConfig,
        first: &Correspondence,
        needed: Option<&[bool]>,
    ) -> Option<Self> {
        let todo = first.reached_unknown_in(config, needed);
        if first.unknown_share(&todo) <= SECOND_PASS_WORTH {
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
        .enumerate()
        .map(|(i, (t, m))| {
            t && m.is_none() && needed.is_none_or(|n| n.get(i).copied().unwrap_or(false))
        })
        .collect();
        Some(Self { shown, share, todo })
    }

    /// The projector pixels this pass shows (row-major): its patterns are black elsewhere.
    pub fn shown(&self) -> &[bool] {
        &self.shown
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

    /// Decodes the pattern captures (every pattern of `manifest`, taken at `exposure`, reduced
    /// as they arrived; without the inverses when `single`, [`super::Captures::single_shot`])
    /// over the pixels the first pass left unknown and merges them into `first`
    /// ([`Correspondence::merge_second_pass`]).
    pub fn finish(
        &self,
        manifest: &Manifest,
        config: &DecodeConfig,
        first: &mut Correspondence,
        exposure: f32,
        captures: &Reduced,
        single: bool,
    ) -> Result<SecondPass, CalibError> {
        let mut made = Vec::new();
        let captures_read = if single {
            // Every capture `exposure` times as long, scaled back.
            captures.captures_single_shot(manifest, &mut made, config.saturation / exposure)?
        } else {
            captures.captures(manifest)?
        };
        let second = decode_captures(
            manifest,
            &config.exposed_longer(exposure),
            Some(&self.todo),
            false,
            &captures_read,
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
