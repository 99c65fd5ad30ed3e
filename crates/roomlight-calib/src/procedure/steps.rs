//! The steps of the procedure as run on a rig ([`Procedure`]): what is shown for each
//! capture, in which order, and what is kept between steps. It must not know where frames are
//! shown or photos come from.

use super::*;
use crate::graycode::{
    Captures, Pattern, PatternFile, Reduced, brightest, decode_captures, less_black,
    second_pass_exposure,
};
use std::sync::Arc;

mod coding;
mod planes;

/// Runs the steps of calibration on a rig, counting captures and reporting progress.
pub struct Procedure<'a, R: Rig> {
    rig: &'a mut R,
    settings: Settings,
    captures: usize,
    progress: Box<dyn FnMut(Event) + Send + 'a>,
}

impl<R: Rig> std::fmt::Debug for Procedure<'_, R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Procedure")
            .field("settings", &self.settings)
            .field("captures", &self.captures)
            .finish_non_exhaustive()
    }
}

impl<'a, R: Rig> Procedure<'a, R> {
    /// A procedure on `rig` that reports to `progress`.
    pub fn new(
        rig: &'a mut R,
        settings: Settings,
        progress: impl FnMut(Event) + Send + 'a,
    ) -> Self {
        Self {
            rig,
            settings,
            captures: 0,
            progress: Box::new(progress),
        }
    }

    /// Captures taken so far.
    pub fn captures(&self) -> usize {
        self.captures
    }

    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The rig, for what the caller shows between steps.
    pub fn rig(&mut self) -> &mut R {
        self.rig
    }

    fn report(&mut self, event: Event) {
        (self.progress)(event);
    }

    async fn capture(&mut self, stage: Stage, exposure: f32) -> Result<LinearImage, RigError> {
        let image = self.rig.capture(exposure).await?;
        self.captures += 1;
        self.report(Event::Captured { stage });
        Ok(image)
    }

    async fn show_and_capture(
        &mut self,
        stage: Stage,
        frames: &[(&str, Frame)],
    ) -> Result<LinearImage, RigError> {
        self.rig.show(frames).await?;
        self.capture(stage, 1.0).await
    }

    async fn black(&mut self, projectors: &[Projector]) -> Result<(), RigError> {
        let frames: Vec<(&str, Frame)> = projectors
            .iter()
            .map(|p| (p.id.as_str(), Frame::BLACK))
            .collect();
        self.rig.show(&frames).await
    }

    /// The black offset: `projectors` black (the others keep their light), one capture.
    pub async fn dark(&mut self, projectors: &[Projector]) -> Result<LinearImage, RigError> {
        self.report(Event::Stage {
            stage: Stage::Dark,
            captures: 1,
        });
        self.black(projectors).await?;
        self.capture(Stage::Dark, 1.0).await
    }

    /// Each projector alone at white (one capture each), then black again: its footprint
    /// for grouping, and the top of its response ramp.
    pub async fn whites(&mut self, projectors: &[Projector]) -> Result<Vec<LinearImage>, RigError> {
        self.report(Event::Stage {
            stage: Stage::Footprints,
            captures: projectors.len(),
        });
        let mut whites = Vec::with_capacity(projectors.len());
        for p in projectors {
            let white = Frame::Uniform([1.0; 3]);
            whites.push(
                self.show_and_capture(Stage::Footprints, &[(&p.id, white)])
                    .await?,
            );
            self.rig.show(&[(&p.id, Frame::BLACK)]).await?;
        }
        Ok(whites)
    }

    /// Structured light on `projectors` (black, with `dark` and `whites` from [`Self::dark`]
    /// and [`Self::whites`]): the first pass ([`Self::code`]), then a second pass for each
    /// standard projector where the first left enough reached pixels unknown among the camera
    /// pixels `needed` marks (all when `None`; [`needed`] for projectors joining a lit room)
    /// that no other blending projector decoded ([`left_by`]), on rigs that show images; the
    /// same pixels decide whether a projector shown once needs its inverses. In the order of
    /// `projectors`.
    pub async fn structured_light(
        &mut self,
        projectors: &[Projector],
        dark: &LinearImage,
        whites: &[LinearImage],
        needed: Option<&[bool]>,
    ) -> Result<Vec<Decoded>, ProcedureError> {
        let mut decoded = self.code(projectors, dark, whites, needed).await?;
        for k in 0..decoded.len() {
            // Where another blending projector was decoded it takes the light whatever this
            // one leaves unknown there: no second pass for it.
            let others = decoded
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, d)| (&d.projector, &d.corr));
            let left = left_by(others, needed, decoded[k].corr.map.len());
            let d = &mut decoded[k];
            d.second = self
                .second_pass(&d.projector, &d.manifest, &mut d.corr, Some(&left))
                .await?;
        }
        Ok(decoded)
    }

    /// A second structured-light pass on standard projector `p` coded with XOR-04 (shown
    /// alone; the others keep their light) where [`SecondPassPlan::new`] finds it worth its
    /// captures and the rig can show masked patterns: plain Gray code's coarse stripes do not
    /// cancel the reflected light a second pass is for. Only the camera pixels `needed` marks
    /// count (all when `None`). Leaves `p` black.
    pub async fn second_pass(
        &mut self,
        p: &Projector,
        manifest: &Manifest,
        corr: &mut Correspondence,
        needed: Option<&[bool]>,
    ) -> Result<Option<SecondPass>, ProcedureError> {
        let config = self.settings.decode;
        let plan = match SecondPassPlan::new(&config, corr, needed) {
            Some(plan)
                if p.kind == ProjectorKind::Standard
                    && manifest.coding == Coding::Xor04
                    && self.rig.shows_masks() =>
            {
                plan
            }
            _ => return Ok(None),
        };
        // The masked patterns without their inverses where the first pass showed none.
        let once = self.settings.shows_once(p);
        let patterns: Vec<&PatternFile> = manifest.shown(once).collect();
        self.report(Event::Stage {
            stage: Stage::SecondPass,
            captures: patterns.len() + 1,
        });
        let refused = |source| ProcedureError::Projector {
            projector: p.id.clone(),
            source,
        };
        let shown: Arc<[bool]> = plan.shown().into();
        let masked = |pattern| Frame::Masked {
            pattern,
            coding: manifest.coding,
            cell: manifest.cell,
            shown: Arc::clone(&shown),
        };
        self.rig.show(&[(&p.id, masked(Pattern::White))]).await?;
        let white = self.capture(Stage::SecondPass, 1.0).await?;
        let limits = self.rig.camera();
        let exposure = plan
            .exposure(corr, &white, limits.saturation, limits.longest_exposure)
            .map_err(refused)?;
        drop(white);
        // Reduced as they arrive: the decoder reads one intensity per capture.
        let mut captures = Reduced::new();
        for f in patterns {
            self.rig.show(&[(&p.id, masked(f.pattern))]).await?;
            let image = self.capture(Stage::SecondPass, exposure).await?;
            captures.add(f, &image).map_err(refused)?;
        }
        self.rig.show(&[(&p.id, Frame::BLACK)]).await?;
        // Where the patterns clip is the camera's ceiling, as in the first pass.
        let config = DecodeConfig {
            saturation: limits.saturation,
            ..config
        };
        let pass = plan
            .finish(manifest, &config, corr, exposure, &captures, once)
            .map_err(refused)?;
        self.report(Event::SecondPass {
            projector: p.id.clone(),
            pass,
        });
        Ok(Some(pass))
    }

    /// Projector `d`'s response (DESIGN §4.3): a ramp of uniform codes read over the camera
    /// pixels it was decoded on; its first level is `dark` and its last `white` (taken
    /// before), the levels between are captured now. Leaves the projector black.
    pub async fn response(
        &mut self,
        d: Decoded,
        dark: &LinearImage,
        white: &LinearImage,
    ) -> Result<Measured, ProcedureError> {
        let codes = ramp_codes(self.settings.ramp_levels)?;
        let mut middle = Vec::with_capacity(codes.len().saturating_sub(2));
        for &code in &codes[1..codes.len() - 1] {
            let frame = Frame::Uniform([code as f32; 3]);
            middle.push(
                self.show_and_capture(Stage::Responses, &[(&d.projector.id, frame)])
                    .await?,
            );
        }
        self.rig.show(&[(&d.projector.id, Frame::BLACK)]).await?;
        let ramp: Vec<&LinearImage> = std::iter::once(dark)
            .chain(&middle)
            .chain(std::iter::once(white))
            .collect();
        let (measured, noise) = footprint_ramp(&ramp, &d.corr);
        self.fitted(d, &codes, &measured, &noise)
    }

    /// The response fitted to a ramp read over `d`'s pixels, reported.
    fn fitted(
        &mut self,
        d: Decoded,
        codes: &[f64],
        measured: &[LinearRgb],
        noise: &[LinearRgb],
    ) -> Result<Measured, ProcedureError> {
        let response =
            fit_response(codes, measured, noise).map_err(|source| ProcedureError::Projector {
                projector: d.projector.id.clone(),
                source,
            })?;
        self.report(Event::Response {
            projector: d.projector.id.clone(),
            gamma: response.gamma,
        });
        Ok(Measured {
            projector: d.projector,
            manifest: d.manifest,
            corr: d.corr,
            decoder: d.decoder,
            response,
            second: d.second,
        })
    }

    /// The middle levels of the ramp shown by every decoded projector at once, one capture a
    /// level ([`Settings::ramp_together`]), `whites[k]` being `decoded[k]`'s. `None` (the
    /// projectors black again, the captures counted) when the shares cannot be told apart:
    /// the caller shows the levels one projector at a time.
    async fn shared_levels(
        &mut self,
        decoded: &[Decoded],
        dark: &LinearImage,
        whites: &[&LinearImage],
    ) -> Result<Option<Vec<Vec<LinearRgb>>>, ProcedureError> {
        let codes = ramp_codes(self.settings.ramp_levels)?;
        let middle = &codes[1..codes.len() - 1];
        self.report(Event::Stage {
            stage: Stage::Responses,
            captures: middle.len(),
        });
        let corrs: Vec<&Correspondence> = decoded.iter().map(|d| &d.corr).collect();
        let names: Vec<&str> = decoded.iter().map(|d| d.projector.id.as_str()).collect();
        let mut shares = Vec::with_capacity(middle.len());
        let mut refused = None;
        for &code in middle {
            let frames: Vec<(&str, Frame)> = decoded
                .iter()
                .map(|d| (d.projector.id.as_str(), Frame::Uniform([code as f32; 3])))
                .collect();
            let level = self.show_and_capture(Stage::Responses, &frames).await?;
            match crate::shared_ramp::shared_level(&level, dark, whites, &corrs, &names) {
                Ok(s) => shares.push(s),
                Err(e) => {
                    refused = Some(e);
                    break;
                }
            }
        }
        self.black(
            &decoded
                .iter()
                .map(|d| d.projector.clone())
                .collect::<Vec<_>>(),
        )
        .await?;
        match refused {
            None => Ok(Some(shares)),
            Some(e) => {
                self.report(Event::RampApart {
                    reason: e.to_string(),
                });
                Ok(None)
            }
        }
    }

    /// Hands every placed projector its nodes.
    pub async fn assign(&mut self, placed: &[Placed]) -> Result<(), RigError> {
        for p in placed {
            self.rig.assign(&p.projector.id, &p.assignment()).await?;
        }
        Ok(())
    }

    /// Attenuation of every node of `placed` through the charts (DESIGN §4.5), multiplexed by
    /// the settings' scheme: the black level (from `black`, a capture of the room with every
    /// node black, when the caller has one), then one capture per row of the plan.
    pub async fn attenuation(
        &mut self,
        setup: &Setup,
        placed: &[Placed],
        black: Option<&LinearImage>,
    ) -> Result<Columns, ProcedureError> {
        let ids: Vec<u32> = placed.iter().flat_map(Placed::ids).collect();
        let scheme = self.settings.scheme;
        let rows = plan(ids.len(), scheme);
        self.report(Event::Stage {
            stage: Stage::Attenuation,
            captures: rows.len() + usize::from(black.is_none()),
        });
        let black = match black {
            Some(image) => image.clone(),
            None => {
                let all_off = node_frames(&owners(placed), |_| false);
                self.show_and_capture(Stage::Attenuation, &borrow(&all_off))
                    .await?
            }
        };
        let black = setup.sample_room(&black)?;
        let mut measured = Vec::with_capacity(rows.len());
        for on in &rows {
            let frames = node_frames(&owners(placed), |j| on[j]);
            let image = self
                .show_and_capture(Stage::Attenuation, &borrow(&frames))
                .await?;
            measured.push(setup.sample_room(&image)?);
        }
        let off = node_frames(&owners(placed), |_| false);
        self.rig.show(&borrow(&off)).await?;
        let attenuation = solve(scheme, ids.len(), &black, &measured)?;
        Ok(Columns { ids, attenuation })
    }

    /// Hot calibration of projector `id`'s `nodes` (DESIGN §4.7): its nodes all black (the
    /// capture `black` when the caller took one in that state, else one now), then each alone
    /// at white, one capture each, while every other projector keeps its light. Leaves its
    /// nodes black.
    pub async fn hot(
        &mut self,
        setup: &Setup,
        id: &str,
        nodes: &[u32],
        black: Option<&LinearImage>,
    ) -> Result<Hot, ProcedureError> {
        self.report(Event::Stage {
            stage: Stage::Hot,
            captures: nodes.len() + usize::from(black.is_none()),
        });
        let one = [(id.to_string(), nodes.to_vec())];
        let off = node_frames(&one, |_| false);
        let image = match black {
            Some(image) => image.clone(),
            None => self.show_and_capture(Stage::Hot, &borrow(&off)).await?,
        };
        let black = setup.sample_room(&image)?;
        let mut measurable: Vec<bool> = black.iter().map(|s| s.status == PatchStatus::Ok).collect();
        let (mut columns, mut sigma) = (Vec::new(), Vec::new());
        for (j, &node) in nodes.iter().enumerate() {
            let frames = node_frames(&one, |i| i == j);
            let image = self.show_and_capture(Stage::Hot, &borrow(&frames)).await?;
            let white = setup.sample_room(&image)?;
            for (m, w) in measurable.iter_mut().zip(&white) {
                *m &= w.status == PatchStatus::Ok;
            }
            let (p, s) = differential(&white, &black)?;
            columns.push((node, p));
            sigma.push(s);
        }
        self.rig.show(&borrow(&off)).await?;
        Ok(Hot {
            columns,
            sigma,
            measurable,
            black,
        })
    }

    /// Brings up a dark room: every live projector black, then the luminaires' footprints,
    /// structured light (disjoint ones together, second passes), responses, nodes feathered
    /// together with the target kept dark ([`place_calibrated`]), and their attenuation.
    /// Leaves every node black.
    pub async fn bring_up(&mut self, setup: &Setup) -> Result<BringUp, ProcedureError> {
        let live = self.rig.projectors();
        let luminaires = luminaires(&live);
        let dark = self.dark(&live).await?;
        let whites = self.whites(&luminaires).await?;
        let decoded = self
            .structured_light(&luminaires, &dark, &whites, None)
            .await?;
        let measured = self.responses(decoded, &luminaires, &dark, &whites).await?;
        let mut placed = place_calibrated(
            setup,
            &measured,
            None,
            0,
            &self.settings,
            &mut *self.progress,
        )?;
        self.shape(setup, &dark, &mut placed, &measured, &luminaires, &whites)?;
        drop(whites);
        self.assign(&placed).await?;
        // Every node black is the room as `dark` saw it: its black level.
        let columns = self.attenuation(setup, &placed, Some(&dark)).await?;
        Ok(BringUp {
            measured,
            placed,
            columns,
            captures: self.captures,
        })
    }

    /// Shapes `placed`'s nodes to the setup's reference, if it has one ([`shape::shape`]),
    /// `whites[k]` being `projectors[k]`'s and `measured` holding their decodes.
    fn shape(
        &mut self,
        setup: &Setup,
        dark: &LinearImage,
        placed: &mut [Placed],
        measured: &[Measured],
        projectors: &[Projector],
        whites: &[LinearImage],
    ) -> Result<(), CalibError> {
        let Some(reference) = &setup.reference else {
            return Ok(());
        };
        let lit: Vec<Option<shape::Lit<'_>>> = placed
            .iter()
            .map(|p| {
                let k = projectors.iter().position(|q| q.id == p.projector.id)?;
                let m = measured.iter().find(|m| m.projector.id == p.projector.id)?;
                Some(shape::Lit {
                    white: whites.get(k)?,
                    corr: &m.corr,
                })
            })
            .collect();
        for s in shape::shape(setup, reference, dark, placed, &lit)? {
            self.report(Event::Shaped {
                projector: s.projector,
                nodes: s.nodes,
                spread: s.spread,
            });
        }
        Ok(())
    }

    /// The responses of decoded projectors, `whites[k]` being `projectors[k]`'s: shown
    /// together when there are several ([`Settings::ramp_together`]), else one at a time.
    pub async fn responses(
        &mut self,
        decoded: Vec<Decoded>,
        projectors: &[Projector],
        dark: &LinearImage,
        whites: &[LinearImage],
    ) -> Result<Vec<Measured>, ProcedureError> {
        let decoded: Vec<(Decoded, &LinearImage)> = decoded
            .into_iter()
            .filter_map(|d| {
                let k = projectors.iter().position(|p| p.id == d.projector.id)?;
                Some((d, &whites[k]))
            })
            .collect();
        let (decoded, whites): (Vec<Decoded>, Vec<&LinearImage>) = decoded.into_iter().unzip();
        let shared = if self.settings.ramp_together && decoded.len() > 1 {
            self.shared_levels(&decoded, dark, &whites).await?
        } else {
            None
        };
        let mut measured = Vec::with_capacity(decoded.len());
        if let Some(shares) = shared {
            let codes = ramp_codes(self.settings.ramp_levels)?;
            for (k, (d, white)) in decoded.into_iter().zip(whites).enumerate() {
                // The ends as read alone; each level between is the dark plus its share of
                // what the white adds, with the noise of the white's reading.
                let (ends, noise) = footprint_ramp(&[dark, white], &d.corr);
                let (low, high) = (ends[0], ends[1]);
                let mut levels = vec![low];
                let mut sigma = vec![noise[0]];
                for level in &shares {
                    levels.push(low + level[k].hadamard(high - low));
                    sigma.push(noise[1]);
                }
                levels.push(high);
                sigma.push(noise[1]);
                measured.push(self.fitted(d, &codes, &levels, &sigma)?);
            }
            return Ok(measured);
        }
        let levels = self.settings.ramp_levels.saturating_sub(2);
        self.report(Event::Stage {
            stage: Stage::Responses,
            captures: decoded.len() * levels,
        });
        for (d, white) in decoded.into_iter().zip(whites) {
            measured.push(self.response(d, dark, white).await?);
        }
        Ok(measured)
    }

    /// Calibrates live projector `id` while the others keep their light: its black offset
    /// and white, structured light (pattern against inverse, [`Settings::lit_room`]), a second
    /// pass where pixels the others do not already light fully were left unknown
    /// ([`needed`]), its response, its nodes beside the projectors
    /// already lit (`claimed`, the sum of their claims) with ids from `first_node`, and its
    /// attenuation measured hot against the dark capture. Leaves its nodes black.
    pub async fn join(
        &mut self,
        setup: &Setup,
        id: &str,
        claimed: Option<&[f32]>,
        first_node: u32,
    ) -> Result<Joined, ProcedureError> {
        let projector = self
            .rig
            .projectors()
            .into_iter()
            .find(|p| p.id == id)
            .ok_or_else(|| RigError::Gone(id.to_string()))?;
        let one = std::slice::from_ref(&projector);
        let dark = self.dark(one).await?;
        let whites = self.whites(one).await?;
        // Pattern and inverse in a lit room ([`Settings::lit_room`]).
        let settings = self.settings;
        self.settings = settings.lit_room();
        let needed = claimed.map(needed);
        let decoded = self
            .structured_light(one, &dark, &whites, needed.as_deref())
            .await;
        self.settings = settings;
        let measured = self.responses(decoded?, one, &dark, &whites).await?;
        let nodes = self.settings.nodes;
        let mut placed = place(
            setup,
            &measured,
            claimed,
            first_node,
            &nodes,
            &mut *self.progress,
        )?;
        self.shape(setup, &dark, &mut placed, &measured, one, &whites)?;
        let (Some(measured), Some(placed)) =
            (measured.into_iter().next(), placed.into_iter().next())
        else {
            return Err(RigError::Gone(id.to_string()).into());
        };
        self.assign(std::slice::from_ref(&placed)).await?;
        // Its nodes all black, the others lit: the room as its dark capture saw it.
        let hot = self
            .hot(setup, &placed.projector.id, &placed.ids(), Some(&dark))
            .await?;
        Ok(Joined {
            measured,
            placed,
            hot,
            captures: self.captures,
        })
    }
}

/// The camera pixels `needed` marks (all when `None`) that no blending projector (a standard
/// luminaire) among `decoded` decoded. Where one did, the blend gives it the light however
/// another projector is decoded there, as a lit room's claims do for a joiner ([`needed`]):
/// a projector brought up with others needs neither a second pass nor its inverses there.
fn left_by<'a>(
    decoded: impl IntoIterator<Item = (&'a Projector, &'a Correspondence)>,
    needed: Option<&[bool]>,
    pixels: usize,
) -> Vec<bool> {
    let mut left = needed.map_or_else(|| vec![true; pixels], <[bool]>::to_vec);
    left.resize(pixels, false);
    for (p, corr) in decoded {
        if p.blends() {
            for (l, m) in left.iter_mut().zip(&corr.map) {
                *l &= m.is_none();
            }
        }
    }
    left
}

/// Frames addressed by owned ids, as the rig takes them.
fn borrow(frames: &[(String, Frame)]) -> Vec<(&str, Frame)> {
    frames
        .iter()
        .map(|(id, f)| (id.as_str(), f.clone()))
        .collect()
}

/// Each placed projector's id and node ids.
fn owners(placed: &[Placed]) -> Vec<(String, Vec<u32>)> {
    placed
        .iter()
        .map(|p| (p.projector.id.clone(), p.ids()))
        .collect()
}

/// Node-value frames for projectors and their nodes: node `j` (counted over all of them, in
/// order) at white where `on(j)`, else black.
fn node_frames(owners: &[(String, Vec<u32>)], on: impl Fn(usize) -> bool) -> Vec<(String, Frame)> {
    let mut j = 0;
    owners
        .iter()
        .map(|(id, nodes)| {
            let values = nodes
                .iter()
                .map(|&n| {
                    j += 1;
                    (
                        n,
                        if on(j - 1) {
                            LinearRgb::ONE
                        } else {
                            LinearRgb::ZERO
                        },
                    )
                })
                .collect();
            (id.clone(), Frame::Nodes(values))
        })
        .collect()
}
