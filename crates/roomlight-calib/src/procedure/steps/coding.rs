//! The structured-light pass of a group of projectors coded at the same time: its slots
//! shown and captured, each member decoded from them (shown once, or with inverses where
//! once left too much unknown), its direct light elsewhere disowned.

use super::planes::Planes;
use super::*;

impl<R: Rig> Procedure<'_, R> {
    /// The first structured-light pass on `projectors` (see [`Self::structured_light`]):
    /// those whose footprints do not overlap coded at the same time, each decoding the camera
    /// pixels it lights most, its direct light elsewhere zeroed ([`disown`]). In the order of
    /// `projectors`. A member shown once is shown its inverses too when it leaves too many of
    /// the camera pixels `needed` marks (all when `None`) unknown, not counting those a
    /// blending projector of an earlier group decoded ([`left_by`]).
    pub async fn code(
        &mut self,
        projectors: &[Projector],
        dark: &LinearImage,
        whites: &[LinearImage],
        needed: Option<&[bool]>,
    ) -> Result<Vec<Decoded>, ProcedureError> {
        let footprints = footprints(projectors, dark, whites, &self.settings);
        let dark_intensity = dark.intensity();
        let gains: Vec<Vec<f32>> = whites.iter().map(|w| gain(w, &dark_intensity)).collect();
        let manifests: Vec<Manifest> = projectors
            .iter()
            .zip(&footprints)
            .zip(&gains)
            .map(|((p, f), g)| {
                let cell = if self.settings.cells {
                    code_cell(p, cell_footprint(p, g, f))
                } else {
                    1
                };
                Manifest::with_cell(p.width, p.height, self.settings.coding(p), cell)
            })
            .collect::<Result<_, _>>()?;
        let groups = group_disjoint(&footprints);
        let once: Vec<bool> = projectors
            .iter()
            .map(|p| self.settings.shows_once(p))
            .collect();
        let sets = coding_sets(&groups, self.settings.primaries);
        let planned = sets
            .iter()
            .map(|set| {
                let whites = if set.len() > 1 { set.len() } else { 0 };
                let once = shown_once(&once, set.len());
                let slots_of = |g: &[usize]| {
                    g.iter()
                        .map(|&k| bit_patterns(&manifests[k], once[k]).len())
                        .max()
                        .unwrap_or(0)
                };
                whites + set.iter().map(|&g| slots_of(&groups[g])).max().unwrap_or(0)
            })
            .sum();
        self.report(Event::Stage {
            stage: Stage::StructuredLight,
            captures: planned,
        });
        self.report(Event::Grouped {
            groups: groups
                .iter()
                .map(|g| g.iter().map(|&k| projectors[k].id.clone()).collect())
                .collect(),
        });
        if sets.iter().any(|set| set.len() > 1) {
            self.report(Event::Primaries {
                sets: sets
                    .iter()
                    .map(|set| {
                        set.iter()
                            .zip(Primary::ALL)
                            .map(|(&g, primary)| {
                                let ids = groups[g].iter().map(|&k| projectors[k].id.clone());
                                (primary, ids.collect())
                            })
                            .collect()
                    })
                    .collect(),
            });
        }
        // Each decode with the decoder its group's job ran.
        let mut corrs: Vec<Option<(Correspondence, DecodeConfig)>> = vec![None; projectors.len()];
        for set in &sets {
            // Where a blending projector of an earlier set was decoded it takes the light
            // whatever this set leaves unknown there ([`left_by`]): no inverses for that.
            let earlier = projectors
                .iter()
                .zip(&corrs)
                .filter_map(|(p, c)| Some((p, &c.as_ref()?.0)));
            let left = left_by(earlier, needed, dark.pixels.len());
            let members: Vec<&[usize]> = set.iter().map(|&g| groups[g].as_slice()).collect();
            let decoded = self
                .code_set(
                    projectors,
                    (&manifests, &once),
                    &members,
                    &gains,
                    (dark, &dark_intensity, whites),
                    Some(&left),
                )
                .await?;
            for (group, group_corrs) in members.iter().zip(decoded) {
                for (&k, c) in group.iter().zip(group_corrs) {
                    corrs[k] = Some(c);
                }
            }
        }
        Ok(projectors
            .iter()
            .zip(manifests)
            .zip(corrs)
            .filter_map(|((p, manifest), decoded)| {
                decoded.map(|(corr, decoder)| Decoded {
                    projector: p.clone(),
                    manifest,
                    corr,
                    decoder,
                    second: None,
                })
            })
            .collect())
    }

    /// Shows one set of groups' bit patterns slot by slot (member `k` its own bit pattern
    /// `j`, black once it has no more), captures each, leaves the members black and decodes
    /// each. A set of one group shows white stripes; its white is the group's
    /// ([`group_white`]) and black the dark capture (`dark`), captured before in the same
    /// state of the room. A set of two or three groups, whose footprints may overlap, shows
    /// each group's stripes in its own primary ([`Primary::ALL`], in order), after one capture
    /// of each group at its primary's white: those tell the groups apart at every camera pixel
    /// ([`Unmixing`]), and each group then decodes from its own share of every capture, its
    /// primary's white standing for white. Each capture is reduced as it arrives to what the
    /// decoder reads of it ([`less_black`], or each group's share): 3.1 MB a group instead of
    /// 9.4 for the lab's camera. Per group, its members' correspondences.
    async fn code_set(
        &mut self,
        projectors: &[Projector],
        (manifests, once): (&[Manifest], &[bool]),
        set: &[&[usize]],
        gains: &[Vec<f32>],
        (dark, dark_intensity, whites): (&LinearImage, &[f32], &[LinearImage]),
        needed: Option<&[bool]>,
    ) -> Result<Vec<Vec<(Correspondence, DecodeConfig)>>, ProcedureError> {
        let once = shown_once(once, set.len());
        let once = once.as_slice();
        let bits: Vec<Vec<Pattern>> = manifests
            .iter()
            .zip(once)
            .map(|(m, &once)| bit_patterns(m, once))
            .collect();
        let members: Vec<Projector> = set
            .iter()
            .flat_map(|g| g.iter().map(|&k| projectors[k].clone()))
            .collect();
        let saturation = self.rig.camera().saturation;
        let longest_exposure = self.rig.camera().longest_exposure;
        let everywhere = vec![true; dark.pixels.len()];
        let all_once = set.iter().all(|g| g.iter().all(|&k| once[k]));
        // Per group: its white's intensity and the primary it is shown in; the set's white.
        let (reduction, group_whites, white, exposure) = if let [group] = set {
            let white = group_white(dark, &group.iter().map(|&k| &whites[k]).collect::<Vec<_>>());
            // A group shown once (every member XOR-coded) is exposed longer where its white
            // leaves room below the ceiling (its 99.9th percentile at 80% of it, as a second
            // pass's), up to SINGLE_SHOT_EXPOSURE and the camera's longest; a group with
            // inverses at the normal exposure.
            let exposure = if all_once {
                let longest = SINGLE_SHOT_EXPOSURE.min(longest_exposure);
                second_pass_exposure(&white, &everywhere, saturation, longest)
            } else {
                1.0
            };
            let reduction = Reduction::Intensity(dark_intensity.to_vec());
            (reduction, vec![(white.intensity(), None)], white, exposure)
        } else {
            let mut primary_whites = Vec::with_capacity(set.len());
            for (group, primary) in set.iter().zip(Primary::ALL) {
                let frames: Vec<(&str, Frame)> = group
                    .iter()
                    .map(|&k| (projectors[k].id.as_str(), Frame::Uniform(primary.white())))
                    .collect();
                self.rig.show(&frames).await?;
                let image = self.capture(Stage::StructuredLight, 1.0).await?;
                image.expect_size(dark.width, dark.height, "a primary's white")?;
                primary_whites.push(image);
                self.black(&members).await?;
            }
            let unmixing = Unmixing::new(dark, &primary_whites.iter().collect::<Vec<_>>())?;
            let white = group_white(dark, &primary_whites.iter().collect::<Vec<_>>());
            drop(primary_whites);
            // One primary is about a third of white: a set is exposed longer where its white
            // (every group at its primary) leaves room, up to PRIMARIES_EXPOSURE, pairs too
            // (they are then decoded as exposed longer).
            let longest = PRIMARIES_EXPOSURE.min(longest_exposure);
            let exposure = second_pass_exposure(&white, &everywhere, saturation, longest);
            let group_whites = (0..set.len())
                .map(|g| {
                    let rise = unmixing.rise(g).iter().zip(dark_intensity);
                    let white: Vec<f32> = rise.map(|(r, d)| d + r).collect();
                    (white, Some(Primary::ALL[g]))
                })
                .collect();
            let reduction = Reduction::Primaries {
                unmixing,
                dark: dark.clone(),
            };
            (reduction, group_whites, white, exposure)
        };
        let shown: Vec<Shown<'_>> = set
            .iter()
            .zip(&group_whites)
            .map(|(g, (_, primary))| (*g, *primary))
            .collect();
        let slots = |only_once: bool| {
            set.iter()
                .flat_map(|g| g.iter())
                .filter(|&&k| !only_once || once[k])
                .map(|&k| bits[k].len())
                .max()
                .unwrap_or(0)
        };
        let captures = self
            .capture_slots(
                projectors,
                (manifests, &bits),
                (&shown, once),
                exposure,
                &reduction,
                false,
            )
            .await?;
        self.black(&members).await?;
        let white_top = brightest(&white);
        let mut sets: Vec<(Vec<Job>, GroupCaptures)> = set
            .iter()
            .zip(group_whites)
            .zip(captures)
            .map(|((group, (white, primary)), bits)| {
                let jobs = group
                    .iter()
                    .zip(owned_pixels(group, gains))
                    .map(|(&k, ours)| {
                        let p = &projectors[k];
                        // Clipping here is planned around by the second passes, not
                        // refused; where it clips is the camera's ceiling (a single shot
                        // reads those pixels apart).
                        let config = DecodeConfig {
                            refuse_saturated: false,
                            saturation,
                            ..self.settings.decoder(p)
                        };
                        let config = match primary {
                            Some(_) => config.in_one_primary(),
                            None => config,
                        };
                        (p.clone(), manifests[k].clone(), config, ours, once[k])
                    })
                    .collect();
                let captures = GroupCaptures {
                    size: (dark.width, dark.height),
                    exposure,
                    white,
                    white_top: white_top.clone(),
                    dark: dark_intensity.to_vec(),
                    bits,
                    inverses: None,
                };
                (jobs, captures)
            })
            .collect();
        let decoders: Vec<Vec<DecodeConfig>> = sets
            .iter()
            .map(|(jobs, _)| jobs.iter().map(|(_, _, config, ..)| *config).collect())
            .collect();
        let mut corrs = Vec::with_capacity(sets.len());
        for (jobs, captures) in std::mem::take(&mut sets) {
            let (c, mut captures) = self.decode_group(jobs.clone(), captures).await?;
            corrs.push(c);
            // Only a group with members shown once reads its planes again (with inverses).
            if !jobs.iter().any(|(.., once)| *once) {
                captures.bits = Planes::default();
            }
            sets.push((jobs, captures));
        }
        // Shown once, a member that left many reached pixels unknown where it is needed (the
        // noisier differences, on dim parts of a footprint with bright ones) is shown its
        // inverses after all, with every member of the set shown once, and those decoded from
        // the pairs.
        let weak = sets.iter().zip(&corrs).any(|((jobs, _), corrs)| {
            jobs.iter().zip(corrs).any(|((.., config, _, once), corr)| {
                *once && corr.reached_unknown_share_in(config, needed) > PAIRS_AFTER_SINGLE
            })
        });
        if weak {
            self.report(Event::Stage {
                stage: Stage::StructuredLight,
                captures: slots(true),
            });
            let inverses = self
                .capture_slots(
                    projectors,
                    (manifests, &bits),
                    (&shown, once),
                    exposure,
                    &reduction,
                    true,
                )
                .await?;
            self.black(&members).await?;
            for (((jobs, captures), inverses), corrs) in
                sets.into_iter().zip(inverses).zip(&mut corrs)
            {
                if jobs.iter().any(|(.., once)| *once) {
                    let captures = GroupCaptures {
                        inverses: Some(inverses),
                        ..captures
                    };
                    *corrs = self.decode_group(jobs, captures).await?.0;
                }
            }
        }
        for (p, corr) in members.iter().zip(corrs.iter().flatten()) {
            self.report(Event::Decoded {
                projector: p.id.clone(),
                share: corr.decoded_share(),
            });
        }
        Ok(corrs
            .into_iter()
            .zip(decoders)
            .map(|(corrs, decoders)| corrs.into_iter().zip(decoders).collect())
            .collect())
    }

    /// Shows a set's bit patterns slot by slot (member `k` its pattern `j` in its group's
    /// primary, or its inverse when `inverse`, which only members shown once are shown; black
    /// once it has no more) and captures each at `exposure`, reduced to what each group reads
    /// of it ([`Reduction`]): per group, its slots (as many as its members have patterns).
    async fn capture_slots(
        &mut self,
        projectors: &[Projector],
        (manifests, bits): (&[Manifest], &[Vec<Pattern>]),
        (set, once): (&[Shown<'_>], &[bool]),
        exposure: f32,
        reduction: &Reduction,
        inverse: bool,
    ) -> Result<Vec<Planes>, ProcedureError> {
        let shows = |k: usize| !inverse || once[k];
        let slots_of = |group: &[usize]| {
            group
                .iter()
                .filter(|&&k| shows(k))
                .map(|&k| bits[k].len())
                .max()
                .unwrap_or(0)
        };
        let longest = set.iter().map(|(g, _)| slots_of(g)).max().unwrap_or(0);
        // A set of groups in their primaries holds every group's planes until the first is
        // decoded: in half precision ([`Planes`]).
        let compact = set.len() > 1;
        let mut captures: Vec<Planes> = set.iter().map(|_| Planes::default()).collect();
        for j in 0..longest {
            let frames: Vec<(&str, Frame)> = set
                .iter()
                .flat_map(|&(group, primary)| group.iter().map(move |&k| (k, primary)))
                .map(|(k, primary)| {
                    let frame = match bits[k].get(j).filter(|_| shows(k)) {
                        Some(&pattern) => Frame::Structured {
                            pattern: if inverse { inverted(pattern) } else { pattern },
                            coding: manifests[k].coding,
                            cell: manifests[k].cell,
                            primary,
                        },
                        None => Frame::BLACK,
                    };
                    (projectors[k].id.as_str(), frame)
                })
                .collect();
            self.rig.show(&frames).await?;
            let image = self.capture(Stage::StructuredLight, exposure).await?;
            let slot = format!("structured-light capture {} of {longest}", j + 1);
            let reduced = reduction.reduce(&image, &slot)?;
            for ((captures, plane), (group, _)) in captures.iter_mut().zip(reduced).zip(set) {
                // A group whose patterns have all been shown keeps no more planes.
                if j < slots_of(group) {
                    captures.push(plane, compact);
                }
            }
        }
        Ok(captures)
    }

    /// Decodes every member of a group off the runtime ([`GroupCaptures::decode`], then
    /// [`disown`]), handing the captures back.
    async fn decode_group(
        &mut self,
        jobs: Vec<Job>,
        mut group_captures: GroupCaptures,
    ) -> Result<(Vec<Correspondence>, GroupCaptures), ProcedureError> {
        let out = self
            .rig
            .offload(move || {
                group_captures.bits.widen();
                if let Some(inverses) = &mut group_captures.inverses {
                    inverses.widen();
                }
                let corrs = jobs
                    .iter()
                    .map(|(p, m, config, ours, once)| {
                        let mut corr = group_captures
                            .decode(m, config, ours.as_deref(), *once)
                            .map_err(|source| ProcedureError::Projector {
                                projector: p.id.clone(),
                                source,
                            })?;
                        disown(&mut corr, ours.as_deref());
                        Ok::<_, ProcedureError>(corr)
                    })
                    .collect::<Result<Vec<_>, _>>();
                corrs.map(|c| (c, group_captures))
            })
            .await??;
        Ok(out)
    }
}

/// The longest a group's bit patterns shown once are exposed, a multiple of the normal
/// exposure (the white's): a pattern − inverse pair has twice one capture's noise variance, a
/// single shot against white (2·pattern − white) four times a pattern's and white's once, so
/// at twice the exposure a read-noise-limited difference is as clean as a pair's. Only where
/// the group's white leaves the room: at a fixed ×2 a lit pattern that clipped where white
/// nearly did lost its sign (the lab's floor-right: 0.32% of its decoded pixels off by more
/// than 2; the texture projector, at full power, not seen at all).
const SINGLE_SHOT_EXPOSURE: f32 = 2.0;

/// The longest a set of groups coded at once in their primaries is exposed, a multiple of the
/// normal exposure: one primary gives about a third of white's light, so three times
/// [`SINGLE_SHOT_EXPOSURE`], where the set's white leaves the room below the ceiling.
const PRIMARIES_EXPOSURE: f32 = 3.0 * SINGLE_SHOT_EXPOSURE;

/// Which members of a set of `groups` are shown once: those `once` marks in a set of one; none
/// in a set coded in primaries. One primary carries about a third of white's light, and a
/// single shot's difference (2·pattern − white) is noisier than a pair's: shown once, the
/// lab's projectors decoded 2–5% fewer of their reached pixels in primaries than in white
/// (wall-right 95.18% within ±1 against 99.44%; with pairs 98.02%), the rest left unknown,
/// and the demo's charts lost a ΔE00 (neutral 2.09 → 3.17; with pairs 2.52), 2026-12-03.
fn shown_once(once: &[bool], groups: usize) -> Vec<bool> {
    if groups > 1 {
        vec![false; once.len()]
    } else {
        once.to_vec()
    }
}

/// Groups of projectors whose footprints do not overlap (indices into `groups`) coded at the
/// same time: up to three a set, each in its own primary, when `primaries`; otherwise, or
/// where only one group is left, one a set, in white.
fn coding_sets(groups: &[Vec<usize>], primaries: bool) -> Vec<Vec<usize>> {
    let per_set = if primaries { Primary::ALL.len() } else { 1 };
    let indices: Vec<usize> = (0..groups.len()).collect();
    indices.chunks(per_set).map(<[usize]>::to_vec).collect()
}

/// A group of a set as it is shown: its members, and its primary (`None`: white).
type Shown<'a> = (&'a [usize], Option<Primary>);

/// How a capture of a set is reduced to what each of its groups' decoders read.
enum Reduction {
    /// One group in white: its intensity less dark's ([`less_black`]).
    Intensity(Vec<f32>),
    /// Groups in their primaries: each group's share less dark, in intensity ([`Unmixing`]).
    Primaries {
        unmixing: Unmixing,
        dark: LinearImage,
    },
}

impl Reduction {
    /// `image` as each group reads it; one of another size is refused, named by `what`.
    fn reduce(&self, image: &LinearImage, what: &str) -> Result<Vec<Vec<f32>>, CalibError> {
        match self {
            Self::Intensity(dark) => {
                if image.pixels.len() != dark.len() {
                    return Err(CalibError::File {
                        file: what.to_string(),
                        problem: format!(
                            "{} pixels, the dark capture has {}",
                            image.pixels.len(),
                            dark.len()
                        ),
                    });
                }
                Ok(vec![less_black(image, dark)])
            }
            Self::Primaries { unmixing, dark } => unmixing.reduce(image, dark, what),
        }
    }
}

/// A member shown once whose decode leaves more of its reached pixels unknown than this share
/// of its decoded ones ([`Correspondence::reached_unknown_share`]) has its group shown the inverses
/// too. Measured on the lab (`roomlight bench calib`, 2026-11-28): shown once, the walls left
/// 0.00–0.55% and the floor projectors 1.19% and 5.93% (their bright near floor keeps the
/// exposure at ×1, and their far parts are dim).
const PAIRS_AFTER_SINGLE: f64 = 0.01;

/// One member's decode: the projector, its manifest, decoder, the camera pixels it owns in
/// its group and whether it was shown once.
type Job = (Projector, Manifest, DecodeConfig, Option<Vec<bool>>, bool);

/// The other one of a bit pattern and its inverse (white and black unchanged).
fn inverted(pattern: Pattern) -> Pattern {
    match pattern {
        Pattern::Bit { axis, bit, inverse } => Pattern::Bit {
            axis,
            bit,
            inverse: !inverse,
        },
        other => other,
    }
}

/// A projector coded together with others decodes only the camera pixels its white raises
/// most (`ours`); the direct light its captures show elsewhere is the other members' (all were
/// shown at once). It is zeroed there, so that the second-pass plan does not take another
/// member's footprint for its own reached but unknown pixels: over the wire that cost every
/// member of a group a second pass that took nothing (the apart room: 130 captures together
/// against 93 one after the other).
fn disown(corr: &mut Correspondence, ours: Option<&[bool]>) {
    let Some(ours) = ours else { return };
    for (direct, &mine) in corr.direct.iter_mut().zip(ours) {
        if !mine {
            *direct = 0.0;
        }
    }
}

/// One coding group's captures as its members' decoders read them: the group's white and the
/// dark capture as intensities (and white's brightest channel), and each slot's capture less
/// dark ([`less_black`]), slot `j` showing every member's bit pattern `j`.
struct GroupCaptures {
    size: (u32, u32),
    /// The bit captures' exposure, a multiple of white's (scaled back to its units).
    exposure: f32,
    white: Vec<f32>,
    white_top: Vec<f32>,
    dark: Vec<f32>,
    bits: Planes,
    /// The inverse of each slot, where members shown once were shown them after all
    /// ([`PAIRS_AFTER_SINGLE`]): they then decode from pairs.
    inverses: Option<Planes>,
}

impl GroupCaptures {
    /// Decodes the member with manifest `m` over the camera pixels `ours` marks
    /// ([`crate::graycode::decode_where`]'s checks); `once`: its bit patterns were shown
    /// without their inverses ([`Captures::single_shot`]).
    fn decode(
        &self,
        m: &Manifest,
        config: &DecodeConfig,
        ours: Option<&[bool]>,
        once: bool,
    ) -> Result<Correspondence, CalibError> {
        let slots = bit_patterns(m, once);
        let slot = |pattern| {
            slots
                .iter()
                .position(|q| *q == pattern)
                .and_then(|j| self.bits.get(j))
                .ok_or_else(|| CalibError::File {
                    file: format!("{pattern:?}"),
                    problem: format!("not captured ({} slots)", self.bits.len()),
                })
        };
        let light = (
            self.white.as_slice(),
            self.dark.as_slice(),
            self.white_top.as_slice(),
        );
        let mut made = Vec::new();
        let paired;
        let config = match (&self.inverses, once) {
            (Some(_), true) => {
                paired = config.exposed_longer(self.exposure);
                &paired
            }
            // Pairs of a set exposed longer (groups in their primaries).
            (_, false) => {
                paired = config.exposed_longer(self.exposure);
                &paired
            }
            (None, true) => config,
        };
        let captures = match (&self.inverses, once) {
            (Some(inverses), true) => {
                Captures::new(m, self.size, light, |pattern| match pattern {
                    Pattern::Bit { inverse: true, .. } => slots
                        .iter()
                        .position(|q| *q == inverted(pattern))
                        .and_then(|j| inverses.get(j))
                        .ok_or_else(|| CalibError::File {
                            file: format!("{pattern:?}"),
                            problem: format!("not captured ({} inverse slots)", inverses.len()),
                        }),
                    _ => slot(pattern),
                })?
            }
            (None, true) => {
                // White was captured at the normal exposure, the patterns `exposure` times as
                // long and scaled back: they clip at the camera's ceiling over that.
                let clip = config.saturation / self.exposure;
                Captures::single_shot(m, self.size, light, slot, &mut made, self.exposure, clip)?
            }
            (_, false) => Captures::new(m, self.size, light, slot)?,
        };
        decode_captures(m, config, ours, true, &captures)
    }
}

/// A manifest's bit patterns (pattern and inverse; without the inverses when shown `once`),
/// in order: what structured light shows, white and black being the dark and white captures
/// taken before.
fn bit_patterns(m: &Manifest, once: bool) -> Vec<Pattern> {
    m.shown(once)
        .map(|f| f.pattern)
        .filter(|p| matches!(p, Pattern::Bit { .. }))
        .collect()
}

/// A group's white as one capture of all its members at white would show it: `dark` plus
/// each member's white's rise above it (light adds; their footprints are disjoint).
fn group_white(dark: &LinearImage, whites: &[&LinearImage]) -> LinearImage {
    match whites {
        [one] => (*one).clone(),
        _ => {
            let mut white = dark.clone();
            for w in whites {
                for (o, (p, d)) in white
                    .pixels
                    .iter_mut()
                    .zip(w.pixels.iter().zip(&dark.pixels))
                {
                    *o = std::array::from_fn(|c| o[c] + p[c] - d[c]);
                }
            }
            white
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graycode::decode_where;
    use crate::graycode::synthetic::{Lit, capture};

    fn same_bits(a: &[f32], b: &[f32]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    /// A coding group decoded from its captures reduced as they arrived ([`GroupCaptures`])
    /// gives, to the bit, what decoding the whole images gave before (the lookup of
    /// `code_group` up to ed2da48, kept here as the reference).
    #[test]
    fn a_group_decodes_from_reduced_captures_as_from_the_images() {
        let size = (72, 30);
        let manifests = [
            Manifest::new(40, 24).expect("manifest"),
            Manifest::new(20, 12).expect("manifest"),
        ];
        let lit = [
            Lit {
                manifest: &manifests[0],
                area: (2, 1, 40, 29),
            },
            Lit {
                manifest: &manifests[1],
                area: (36, 3, 70, 27),
            },
        ];
        let dark = capture(size, &lit, &[None, None], 1000);
        let whites: Vec<LinearImage> = (0..2)
            .map(|k| {
                let shown = [0, 1].map(|o| (o == k).then_some(Pattern::White));
                capture(size, &lit, &shown, 1001 + k as u64)
            })
            .collect();
        let white = group_white(&dark, &whites.iter().collect::<Vec<_>>());
        let slots: Vec<Vec<Pattern>> = manifests.iter().map(|m| bit_patterns(m, false)).collect();
        let longest = slots.iter().map(Vec::len).max().unwrap_or(0);
        assert!(
            slots[1].len() < longest,
            "the members have different bit counts"
        );
        let images: Vec<LinearImage> = (0..longest)
            .map(|j| {
                let shown = [0, 1].map(|k| slots[k].get(j).copied());
                capture(size, &lit, &shown, j as u64)
            })
            .collect();
        let dark_intensity = dark.intensity();
        let group = GroupCaptures {
            size,
            exposure: 1.0,
            white: white.intensity(),
            white_top: brightest(&white),
            dark: dark_intensity.clone(),
            bits: Planes::full(
                images
                    .iter()
                    .map(|i| less_black(i, &dark_intensity))
                    .collect(),
            ),
            inverses: None,
        };
        let gains: Vec<Vec<f32>> = whites.iter().map(|w| gain(w, &dark_intensity)).collect();
        for (k, ours) in owned_pixels(&[0, 1], &gains).into_iter().enumerate() {
            let m = &manifests[k];
            let config = DecodeConfig {
                refuse_saturated: false,
                ..DecodeConfig::default()
            };
            let before = decode_where(m, &config, ours.as_deref(), |f| {
                Ok(match f.pattern {
                    Pattern::White => &white,
                    Pattern::Black => &dark,
                    Pattern::Bit { .. } => {
                        let j = bit_patterns(m, false)
                            .iter()
                            .position(|q| *q == f.pattern)
                            .unwrap_or(0);
                        &images[j]
                    }
                })
            })
            .expect("decode images");
            let after = group
                .decode(m, &config, ours.as_deref(), false)
                .expect("decode reduced");
            assert!(before.decoded_share() > 0.2, "member {k}");
            assert_eq!(before.map, after.map, "member {k}");
            assert!(same_bits(&before.confidence, &after.confidence));
            assert!(same_bits(&before.direct, &after.direct));
            assert!(same_bits(&before.global, &after.global));
            assert_eq!(before.reach.to_bits(), after.reach.to_bits());
        }
    }
}
