//! Calibration of the simulated room from captures: decode each projector, fit its response,
//! segment its nodes and feather them, measure attenuation, then the LED target per preset.
//! Written against the simulator; the one calibration procedure of roomlight-calib replaces it.

use anyhow::{Context, Result, bail};
use roomlight_calib::attenuation::{Attenuation, Scheme, plan, solve};
use roomlight_calib::charts::{ChartCorners, PatchSample, sample_charts};
use roomlight_calib::graycode::{
    Coding, Correspondence, DecodeConfig, Manifest, SECOND_PASS_LONGEST, decode, second_pass,
};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::nodes::{NodeConfig as SplitConfig, segment};
use roomlight_calib::procedure::Target;
use roomlight_calib::response::{Response, fit_response, ramp_codes};
use roomlight_core::LinearRgb;
use roomlight_core::conventional::conventional_value;
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Frame, NodeRegion, ProjectorImage, Room};
use std::collections::HashMap;
use std::time::Instant;

use super::*;

/// What calibration measured once for the room, whatever the lighting target.
#[derive(Debug)]
pub struct Calibrated {
    /// Each node's projector and weights (for the simulated hardware).
    pub regions: Vec<NodeRegion>,
    /// Each node's own chart (room chart index).
    pub node_charts: Vec<Option<usize>>,
    /// The charts' corners in the camera image.
    pub corners: Vec<ChartCorners>,
    /// Attenuation, black level and which patches it could measure.
    pub attenuation: Attenuation,
    /// Attenuation columns (entries within 3σ of zero dropped), over every room patch.
    pub columns: Vec<Vec<(u32, LinearRgb)>>,
    /// Captures used.
    pub captures: usize,
    /// The decoded structured light of each luminaire that lights a chart.
    pub correspondences: Vec<Correspondence>,
    /// Room projector index of each of those.
    pub charted: Vec<usize>,
    /// Standard luminaires that light no chart, with their decoded structured light.
    pub chartless: Vec<(usize, Correspondence)>,
    /// Each room projector's measured response (linear for those not calibrated).
    pub responses: Vec<Response>,
    /// Each large-aperture luminaire and its decoded structured light.
    pub areas: Vec<(usize, Correspondence)>,
}

/// A projector as one node (`roomlight_calib::nodes::whole_frame`): its whole frame except
/// the pixels that land on the target, and the chart it lights most, if any.
fn whole_frame_node(
    k: usize,
    corr: &Correspondence,
    corners: &[ChartCorners],
    target: &[bool],
) -> (NodeRegion, Option<usize>) {
    let (weights, chart) = roomlight_calib::nodes::whole_frame(corr, corners, target);
    (
        NodeRegion {
            projector: k,
            weights,
        },
        chart,
    )
}

/// Levels of the response ramp.
const RAMP_LEVELS: usize = 9;

impl Calibrated {
    /// Projector name → its node ids.
    pub fn owners(&self, room: &Room) -> HashMap<String, Vec<u32>> {
        let mut owners: HashMap<String, Vec<u32>> = HashMap::new();
        for (n, r) in self.regions.iter().enumerate() {
            owners
                .entry(room.projectors()[r.projector].name.clone())
                .or_default()
                .push(n as u32);
        }
        owners
    }

    /// The same nodes with another target kept dark (`mask`: camera pixels of the new target),
    /// e.g. a contrast board put where the bust was. Fails if the nodes would change.
    pub fn regions_with_mask(&self, mask: &[bool]) -> Result<Vec<NodeRegion>> {
        let seg = segment(
            &self.correspondences,
            &self.corners,
            Some(mask),
            &SplitConfig::default(),
        )?;
        let mut charts: Vec<Option<usize>> = seg.nodes.iter().map(|nd| Some(nd.chart)).collect();
        let mut regions: Vec<NodeRegion> = seg
            .nodes
            .iter()
            .map(|nd| NodeRegion {
                projector: self.charted[nd.projector],
                weights: nd.weights.clone(),
            })
            .collect();
        for (k, c) in self.chartless.iter().chain(&self.areas) {
            let (region, chart) = whole_frame_node(*k, c, &self.corners, mask);
            regions.push(region);
            charts.push(chart);
        }
        if charts != self.node_charts {
            bail!(
                "the new target changes the nodes ({} instead of {}); recalibrate",
                charts.len(),
                self.node_charts.len()
            );
        }
        Ok(regions)
    }
}

/// Shows one projector's structured light (every other projector black), captures each
/// pattern with `shoot(frames, exposure)` (the exposure a multiple of the normal one, the
/// capture scaled back to its units) and decodes the camera → projector map. With XOR coding,
/// a second pass over what the first left uncovered follows where it is worth its captures
/// ([`second_pass`]).
pub fn decode_projector(
    room: &Room,
    k: usize,
    coding: Coding,
    mut shoot: impl FnMut(&[Frame], f32) -> Result<LinearImage>,
) -> Result<Correspondence> {
    let p = &room.projectors()[k].pinhole;
    let manifest = Manifest::with_coding(p.width, p.height, coding)?;
    let n = room.projectors().len();
    let frames_with = |img: LinearImage| {
        let mut frames = vec![Frame::Black; n];
        frames[k] = Frame::Image(ProjectorImage {
            width: img.width,
            height: img.height,
            pixels: img.pixels,
        });
        frames
    };
    let mut caps = Vec::with_capacity(manifest.patterns.len());
    for pat in &manifest.patterns {
        caps.push(shoot(
            &frames_with(manifest.pattern_image(pat.pattern)),
            1.0,
        )?);
    }
    let config = DecodeConfig::default();
    let mut corr = decode(&manifest, &config, |f| {
        Ok(&caps[manifest
            .patterns
            .iter()
            .position(|p| p.file == f.file)
            .unwrap_or(0)])
    })?;
    if coding == Coding::Xor04 {
        let done = second_pass(
            &manifest,
            &config,
            &mut corr,
            room.scene().camera.saturation as f32,
            SECOND_PASS_LONGEST,
            |img, exposure| shoot(&frames_with(img.clone()), exposure),
        )?;
        if let Some(done) = done {
            tracing::info!(
                projector = %room.projectors()[k].name,
                shown = done.shown,
                exposure = done.exposure,
                captures = done.captures,
                decoded = done.taken,
                "second structured-light pass"
            );
        }
    }
    Ok(corr)
}

/// Calibrates the standard luminaires of `room`: structured light, nodes, black level and
/// Hadamard attenuation, all from noisy captures through the charts.
pub fn calibrate(
    room: &Room,
    noise: &mut CameraNoise,
    bar: &indicatif::ProgressBar,
    mut say: impl FnMut(String),
) -> Result<Calibrated> {
    let n = room.projectors().len();
    let corners = chart_corners(room)?;
    let luminaires: Vec<usize> = (0..n)
        .filter(|&k| {
            room.scene().projectors[k].role == ProjectorRole::Luminaire
                && room.projectors()[k].kind == ProjectorKind::Standard
        })
        .collect();
    // Large-aperture luminaires: decoded with plain Gray code (their defocus blurs XOR-04's fine
    // stripes), each one node over its whole frame but the target.
    let areas: Vec<usize> = (0..n)
        .filter(|&k| {
            room.scene().projectors[k].role == ProjectorRole::Luminaire
                && room.projectors()[k].kind == ProjectorKind::LargeAperture
        })
        .collect();
    let coding = |k: usize| {
        if areas.contains(&k) {
            Coding::Gray
        } else {
            Coding::Xor04
        }
    };
    let decoded: Vec<usize> = luminaires.iter().chain(&areas).copied().collect();
    let captures = std::cell::Cell::new(0usize);
    let stage = |name: &str, len: usize| {
        bar.reset();
        bar.set_length(len as u64);
        bar.set_message(name.to_string());
    };
    let mut shoot = |frames: &[Frame], exposure: f32| -> Result<LinearImage> {
        captures.set(captures.get() + 1);
        bar.inc(1);
        Ok(image(&noise.expose_longer(
            &room.render(frames, None)?,
            f64::from(exposure),
        )))
    };
    // 1. Structured light, one projector at a time.
    let t = Instant::now();
    let mut corr = Vec::new();
    stage(
        "structured light",
        decoded
            .iter()
            .map(|&k| {
                let p = &room.projectors()[k].pinhole;
                Manifest::with_coding(p.width, p.height, coding(k)).map_or(0, |m| m.patterns.len())
            })
            .sum(),
    );
    for &k in &decoded {
        corr.push(decode_projector(room, k, coding(k), &mut shoot)?);
    }
    let area_corr = corr.split_off(luminaires.len());
    let areas: Vec<(usize, Correspondence)> = areas.into_iter().zip(area_corr).collect();
    say(format!(
        "structured light: {} projectors decoded, {} captures, {:.1} s",
        decoded.len(),
        captures.get(),
        t.elapsed().as_secs_f64()
    ));
    // 2. Responses: a ramp of uniform codes per luminaire, read on the chart patch it lights
    // most (DESIGN §4.3); the hidden gamma is the simulator's, the fit is ours.
    let t = Instant::now();
    let codes = ramp_codes(RAMP_LEVELS)?;
    stage("responses", decoded.len() * codes.len());
    let config = sample_config(room);
    let mut responses = vec![Response::linear(); n];
    let all_corr: Vec<&Correspondence> = corr.iter().chain(areas.iter().map(|(_, c)| c)).collect();
    for (&k, c) in decoded.iter().zip(all_corr) {
        let mut ramp = Vec::with_capacity(codes.len());
        for &code in &codes {
            let mut frames = vec![Frame::Black; n];
            frames[k] = Frame::Uniform([code as f32; 3]);
            ramp.push(shoot(&frames, 1.0)?);
        }
        let (measured, noise) = roomlight_calib::response::footprint_ramp(&ramp, c);
        responses[k] = fit_response(&codes, &measured, &noise)
            .with_context(|| format!("response of {}", room.projectors()[k].name))?;
    }
    say(format!(
        "responses: {} ramps of {} levels, γ {}, {:.1} s",
        decoded.len(),
        codes.len(),
        decoded
            .iter()
            .map(|&k| {
                let g = responses[k].gamma;
                format!("{:.2}/{:.2}/{:.2}", g[0], g[1], g[2])
            })
            .collect::<Vec<_>>()
            .join(", "),
        t.elapsed().as_secs_f64()
    ));
    // 3. Nodes.
    let t = Instant::now();
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    // A luminaire that lights no chart cannot be split by charts: it becomes one node over its
    // frame (but the target) with no chart, started from the fallback so the lights stay on.
    let charted: Vec<bool> = corr
        .iter()
        .map(|c| {
            segment(
                std::slice::from_ref(c),
                &corners,
                Some(&mask),
                &SplitConfig::default(),
            )
            .is_ok()
        })
        .collect();
    let with_chart: Vec<Correspondence> = corr
        .iter()
        .zip(&charted)
        .filter(|(_, c)| **c)
        .map(|(c, _)| c.clone())
        .collect();
    let charted_index: Vec<usize> = luminaires
        .iter()
        .zip(&charted)
        .filter(|(_, c)| **c)
        .map(|(k, _)| *k)
        .collect();
    let seg = segment(&with_chart, &corners, Some(&mask), &SplitConfig::default())?;
    let mut regions: Vec<NodeRegion> = seg
        .nodes
        .iter()
        .map(|nd| NodeRegion {
            projector: charted_index[nd.projector],
            weights: nd.weights.clone(),
        })
        .collect();
    let mut node_charts: Vec<Option<usize>> = seg.nodes.iter().map(|nd| Some(nd.chart)).collect();
    let chartless: Vec<(usize, Correspondence)> = luminaires
        .iter()
        .zip(&corr)
        .zip(&charted)
        .filter(|(_, ok)| !**ok)
        .map(|((&k, c), _)| (k, c.clone()))
        .collect();
    for (k, c) in &chartless {
        let (k, c) = (*k, c);
        let (region, _) = whole_frame_node(k, c, &corners, &mask);
        say(format!(
            "{}: lights no chart; one node over its frame, started from the fallback",
            room.projectors()[k].name
        ));
        regions.push(region);
        node_charts.push(None);
    }
    // A large aperture that reaches no chart cannot be measured through the charts: left out
    // (it stays dark), and said so.
    let mut kept = Vec::with_capacity(areas.len());
    for (k, c) in areas {
        let (region, chart) = whole_frame_node(k, &c, &corners, &mask);
        if chart.is_none() {
            say(format!(
                "{}: reaches no chart; started from the fallback",
                room.projectors()[k].name
            ));
        }
        regions.push(region);
        node_charts.push(chart);
        kept.push((k, c));
    }
    let areas = kept;
    say(format!(
        "nodes: {} over {} charts, {:.1} s",
        regions.len(),
        corners.len(),
        t.elapsed().as_secs_f64()
    ));
    // 4. Black and attenuation (Hadamard), through the charts.
    let t = Instant::now();
    let before = captures.get();
    let nodes = regions.len();
    let builder = FrameBuilder::new(room, &regions, responses.clone());
    let on_off = |on: &[bool]| {
        let x: Vec<LinearRgb> = on
            .iter()
            .map(|&o| if o { LinearRgb::ONE } else { LinearRgb::ZERO })
            .collect();
        builder.frames(&x)
    };
    let black = sample_charts(
        &shoot(&on_off(&vec![false; nodes]), 1.0)?,
        &corners,
        &config,
    )?;
    let rows = plan(nodes, Scheme::Hadamard);
    stage("attenuation", rows.len());
    let mut measured: Vec<Vec<PatchSample>> = Vec::with_capacity(rows.len());
    for on in &rows {
        measured.push(sample_charts(&shoot(&on_off(on), 1.0)?, &corners, &config)?);
    }
    let attenuation = solve(Scheme::Hadamard, nodes, &black, &measured)?;
    let columns: Vec<Vec<(u32, LinearRgb)>> = attenuation
        .columns(3.0)?
        .iter()
        .map(|c| c.iter().collect())
        .collect();
    say(format!(
        "attenuation: {} captures (black + Hadamard), {} of {} patches usable, {:.1} s",
        captures.get() - before,
        attenuation.usable.iter().filter(|&&u| u).count(),
        black.len(),
        t.elapsed().as_secs_f64()
    ));
    Ok(Calibrated {
        regions,
        node_charts,
        corners,
        attenuation,
        columns,
        captures: captures.get(),
        correspondences: with_chart,
        charted: charted_index,
        chartless,
        responses,
        areas,
    })
}

/// Captures the LED preset `preset` (projectors dark) and builds the model for it over the
/// patches measured in every capture ([`Target`]), with its conventional start.
pub fn measure_target(
    room: &Room,
    cal: &Calibrated,
    preset: usize,
    noise: &mut CameraNoise,
) -> Result<Model> {
    let frames = vec![Frame::Black; room.projectors().len()];
    let capture = image(&noise.expose(&room.render(&frames, Some(preset))?));
    let lit = sample_charts(&capture, &cal.corners, &sample_config(room))?;
    let att = &cal.attenuation;
    let target = Target::new(&att.black, &att.usable, &lit)?;
    let problem = target.problem(target.columns(&cal.columns)?)?;
    let charts = target.chart_patches(cal.corners.len(), PATCHES_PER_CHART);
    // A node without a chart gets an empty one, so the conventional start falls back (its
    // lights stay on).
    let conventional = problem
        .columns()
        .iter()
        .zip(&cal.node_charts)
        .map(|(c, chart)| {
            conventional_value(
                c,
                chart.map_or(&[][..], |m| &charts[m]),
                problem.target(),
                problem.black(),
                LinearRgb::splat(0.5),
            )
        })
        .collect::<Result<_, _>>()?;
    Ok(Model {
        problem,
        patches: target.patches.clone(),
        target,
        conventional,
    })
}
