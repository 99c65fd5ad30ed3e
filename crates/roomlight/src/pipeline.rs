//! The whole method on a simulated room, as the system does it: structured light, projector
//! responses, nodes and feathering, Hadamard attenuation and the LED target measured from noisy
//! captures through the charts, then the real agents over loopback gRPC. The simulator is touched
//! only through captures, except the target mask, which a real room configures by hand. Node
//! values become projector codes through the measured responses (the simulator keeps its own
//! gamma hidden), and every capture during the rounds is rendered, exposed with camera noise and
//! sampled through the charts exactly as in calibration. The truth for the metrics is what a
//! noiseless camera samples the same way: the simulator's own patch averages differ from that
//! sampling by enough to hold a loop fed with them 4–37% above the optimum.

use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::hardware::{Camera, Display};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_calib::attenuation::{Attenuation, Scheme, plan, solve};
use roomlight_calib::charts::{
    ChartCorners, PatchSample, PatchStatus, SampleConfig, sample_charts,
};
use roomlight_calib::graycode::{
    Coding, Correspondence, DecodeConfig, Manifest, SECOND_PASS_LONGEST, decode, second_pass,
};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::nodes::{NodeConfig as SplitConfig, segment};
use roomlight_calib::response::{Response, fit_response, ramp_codes};
use roomlight_core::conventional::conventional_value;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::{AttenuationColumn, LinearRgb, PatchId, Problem, StepRule};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Frame, NodeBasis, NodeRegion, ProjectorImage, Room};
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};
use tokio_util::sync::CancellationToken;

fn image(c: &roomlight_sim::Capture) -> LinearImage {
    LinearImage {
        width: c.width,
        height: c.height,
        pixels: c.pixels.clone(),
    }
}

/// The charts' corners in the camera image, as configured for a real room (here from the
/// simulator's camera model); a chart out of view is an error, not skipped.
pub fn chart_corners(room: &Room) -> Result<Vec<ChartCorners>> {
    room.chart_corners_px()
        .into_iter()
        .zip(&room.scene().charts)
        .map(|(c, spec)| {
            c.map(|corners| ChartCorners {
                name: spec.name.clone(),
                corners,
            })
            .with_context(|| format!("chart {} is not in the camera's view", spec.name))
        })
        .collect()
}

/// What calibration measured once for the room, whatever the lighting target.
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

/// The model for one lighting target: the measured problem over the patches usable in every
/// capture.
pub struct Model {
    /// Columns, black, target and noise over the usable patches.
    pub problem: Problem,
    /// Room patch index of each model patch.
    pub patches: Vec<usize>,
    /// The conventional start (DESIGN §3.1), one value per node.
    pub conventional: Vec<LinearRgb>,
}

/// A node's non-zero weights: `(node, [(pixel, weight)])`.
type SparseNode = (usize, Vec<(u32, f32)>);

/// A node region's non-zero weights as `(pixel, weight)`, row-major pixels.
pub fn sparse_weights(region: &NodeRegion) -> Vec<(u32, f32)> {
    region
        .weights
        .iter()
        .enumerate()
        .filter(|(_, w)| **w > 0.0)
        .map(|(i, w)| (i as u32, *w))
        .collect()
}

/// Node values as projector frames: each pixel's linear light is the sum of its nodes' weights
/// times their values, turned into a code through the projector's measured response (as a node
/// agent does before it shows a frame). Each node's weights are kept sparse.
pub struct FrameBuilder {
    /// Per projector: width, height, and its nodes.
    projectors: Vec<(u32, u32, Vec<SparseNode>)>,
    responses: Vec<Response>,
}

impl FrameBuilder {
    /// For `regions` of `room`'s projectors with their measured `responses`.
    pub fn new(room: &Room, regions: &[NodeRegion], responses: Vec<Response>) -> Self {
        let projectors = room
            .projectors()
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let nodes = regions
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| r.projector == k)
                    .map(|(n, r)| (n, sparse_weights(r)))
                    .collect();
                (p.pinhole.width, p.pinhole.height, nodes)
            })
            .collect();
        Self {
            projectors,
            responses,
        }
    }

    /// The frames for node values `x` (a missing value counts as black).
    pub fn frames(&self, x: &[LinearRgb]) -> Vec<Frame> {
        let linear = Response::linear();
        self.projectors
            .iter()
            .enumerate()
            .map(|(k, (width, height, nodes))| {
                let mut light = vec![LinearRgb::ZERO; (width * height) as usize];
                for (n, weights) in nodes {
                    let v = x.get(*n).copied().unwrap_or(LinearRgb::ZERO);
                    for &(i, w) in weights {
                        light[i as usize] += v * f64::from(w);
                    }
                }
                let response = self.responses.get(k).unwrap_or(&linear);
                Frame::Image(ProjectorImage {
                    width: *width,
                    height: *height,
                    pixels: light.into_iter().map(|l| response.to_code(l)).collect(),
                })
            })
            .collect()
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
/// patches measured in every capture, with its conventional start.
pub fn measure_target(
    room: &Room,
    cal: &Calibrated,
    preset: usize,
    noise: &mut CameraNoise,
) -> Result<Model> {
    let frames = vec![Frame::Black; room.projectors().len()];
    let capture = image(&noise.expose(&room.render(&frames, Some(preset))?));
    let target = sample_charts(&capture, &cal.corners, &sample_config(room))?;
    let att = &cal.attenuation;
    let patches: Vec<usize> = (0..target.len())
        .filter(|&i| att.usable[i] && target[i].status == PatchStatus::Ok)
        .collect();
    if patches.is_empty() {
        bail!("no chart patch could be measured in every capture");
    }
    let index: HashMap<usize, PatchId> = patches
        .iter()
        .enumerate()
        .map(|(k, &i)| (i, k as PatchId))
        .collect();
    let columns: Vec<AttenuationColumn> = cal
        .columns
        .iter()
        .map(|c| {
            let (s, v): (Vec<PatchId>, Vec<LinearRgb>) = c
                .iter()
                .filter_map(|&(i, p)| index.get(&(i as usize)).map(|&k| (k, p)))
                .unzip();
            AttenuationColumn::new(s, v)
        })
        .collect::<Result<_, _>>()?;
    let problem = Problem::new(
        columns,
        patches.iter().map(|&i| att.black[i]).collect(),
        patches.iter().map(|&i| target[i].mean).collect(),
        patches.iter().map(|&i| target[i].std_error).collect(),
    )?;
    let per_chart = cal.corners.len().max(1);
    let patches_per_chart = target.len() / per_chart;
    let charts: Vec<Vec<PatchId>> = cal
        .node_charts
        .iter()
        .map(|m| match m {
            // No chart: an empty one, so the conventional start falls back (lights stay on).
            None => Vec::new(),
            Some(m) => (0..patches_per_chart)
                .filter_map(|j| index.get(&(patches_per_chart * m + j)).copied())
                .collect(),
        })
        .collect();
    let conventional = problem
        .columns()
        .iter()
        .zip(&charts)
        .map(|(c, chart)| {
            conventional_value(
                c,
                chart,
                problem.target(),
                problem.black(),
                LinearRgb::splat(0.5),
            )
        })
        .collect::<Result<_, _>>()?;
    Ok(Model {
        problem,
        patches,
        conventional,
    })
}

/// The simulated projectors and camera behind the agents: node values in, turned into codes
/// through the measured responses and rendered by the simulator (with its hidden gamma); out,
/// the chart patches sampled from the capture with camera noise, exactly as calibration
/// measured them.
#[derive(Clone)]
struct SimHardware {
    room: Arc<Room>,
    frames: Arc<FrameBuilder>,
    corners: Arc<Vec<ChartCorners>>,
    config: SampleConfig,
    shown: Arc<Mutex<Vec<LinearRgb>>>,
    patches: Arc<Vec<usize>>,
    noise: Arc<Mutex<CameraNoise>>,
    /// Every capture: when, the noisy patch values returned and the noiseless ones.
    log: Arc<Mutex<Vec<CaptureLog>>>,
    /// A camera with this many captures of latency hands the camera agent the image taken that
    /// many captures earlier (the first one while there is none that old): stale errors.
    latency: usize,
    delayed: Arc<Mutex<VecDeque<Vec<LinearRgb>>>>,
}

struct CaptureLog {
    at: Instant,
    /// How long the capture took (render, noise, sampling): the simulated camera's time.
    took: Duration,
    shown: Vec<LinearRgb>,
    measured: Vec<LinearRgb>,
    /// What a noiseless camera saw of the same frame.
    noiseless: Vec<LinearRgb>,
}

/// How the charts are sampled: the camera's saturation and noise, as a real installation knows
/// them from its sensor's characterisation (dark frames and flat fields).
pub fn sample_config(room: &Room) -> SampleConfig {
    let c = &room.scene().camera;
    SampleConfig {
        saturation: (0.98 * c.saturation) as f32,
        read_noise: c.read_noise as f32,
        shot_noise: c.shot_noise as f32,
        ..SampleConfig::default()
    }
}

/// The chart patches of a capture, every room patch.
fn sample(
    capture: &roomlight_sim::Capture,
    corners: &[ChartCorners],
    config: &SampleConfig,
) -> Result<Vec<LinearRgb>> {
    Ok(sample_charts(&image(capture), corners, config)?
        .iter()
        .map(|p| p.mean)
        .collect())
}

impl SimHardware {
    fn pick(&self, all: &[LinearRgb]) -> Vec<LinearRgb> {
        self.patches.iter().map(|&i| all[i]).collect()
    }

    fn render(&self, x: &[LinearRgb]) -> Result<roomlight_sim::Capture> {
        Ok(self.room.render(&self.frames.frames(x), None)?)
    }

    /// What a noiseless camera would measure on the model's patches for node values `x`.
    fn noiseless(&self, x: &[LinearRgb]) -> Result<Vec<LinearRgb>> {
        Ok(self.pick(&sample(&self.render(x)?, &self.corners, &self.config)?))
    }

    fn shown(&self) -> Vec<LinearRgb> {
        self.shown
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    fn measure(&self) -> Result<Vec<LinearRgb>> {
        let started = Instant::now();
        let shown = self.shown();
        let capture = self.render(&shown)?;
        let noiseless = self.pick(&sample(&capture, &self.corners, &self.config)?);
        let noisy = self
            .noise
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .expose(&capture);
        let measured = self.pick(&sample(&noisy, &self.corners, &self.config)?);
        let handed = {
            let mut delayed = self.delayed.lock().unwrap_or_else(PoisonError::into_inner);
            delayed.push_back(measured.clone());
            while delayed.len() > self.latency + 1 {
                delayed.pop_front();
            }
            delayed.front().cloned().unwrap_or_else(|| measured.clone())
        };
        self.log
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(CaptureLog {
                at: Instant::now(),
                took: started.elapsed(),
                shown,
                measured,
                noiseless,
            });
        Ok(handed)
    }
}

impl Display for SimHardware {
    fn show(&mut self, node: u32, value: LinearRgb) {
        if let Some(v) = self
            .shown
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get_mut(node as usize)
        {
            *v = value.clamp_unit();
        }
    }
}

impl Camera for SimHardware {
    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<LinearRgb>, roomlight_agent::AgentError>> + Send {
        std::future::ready(
            self.measure()
                .map_err(|e| roomlight_agent::AgentError::Protocol(format!("capture: {e:#}"))),
        )
    }
}

/// `model` with every attenuation entry kept (no 3σ cut-off), over the same patches: what the
/// sparse supports are compared against.
pub fn uncut_problem(cal: &Calibrated, model: &Model) -> Result<Problem> {
    let index: HashMap<usize, PatchId> = model
        .patches
        .iter()
        .enumerate()
        .map(|(k, &i)| (i, k as PatchId))
        .collect();
    let columns = cal
        .attenuation
        .columns(0.0)?
        .iter()
        .map(|c| {
            let (s, v): (Vec<PatchId>, Vec<LinearRgb>) = c
                .iter()
                .filter_map(|(i, p)| index.get(&(i as usize)).map(|&k| (k, p)))
                .unzip();
            AttenuationColumn::new(s, v)
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Problem::new(
        columns,
        model.problem.black().to_vec(),
        model.problem.target().to_vec(),
        model.problem.noise().to_vec(),
    )?)
}

/// How the agents run for one target.
#[derive(Debug, Clone, Copy)]
pub struct RunOptions {
    /// The node agents' update rule.
    pub rule: StepRule,
    /// Model rounds per capture (DESIGN §3.4).
    pub model_rounds: usize,
    /// Stop here if the camera agent has not reported settled before.
    pub max_captures: u64,
    /// Stop when the camera agent reports settled (DESIGN §3.6); otherwise run to
    /// `max_captures` (to compare rules over the same budget).
    pub stop_when_settled: bool,
    /// Seed of the capture noise.
    pub seed: u64,
    /// Captures of camera latency: the errors the nodes act on are this many captures stale.
    pub latency: usize,
    /// The camera agent knows the latency and discards that many captures before each measured
    /// round (fresh errors, more captures).
    pub discard_stale: bool,
    /// A projector leaving and another joining mid-run.
    pub churn: Option<Churn>,
}

/// A projector leaving the room (switched off, its node agent stopped) once `leave_at`
/// captures are taken, and another, off from the start, whose node agent joins after
/// `join_at` captures. Projectors are indices into the room's projectors. `hot`: the camera
/// agent does not know the joining projector's attenuation and measures it when it joins.
#[derive(Debug, Clone, Copy)]
pub struct Churn {
    pub leaving: usize,
    pub leave_at: u64,
    pub joining: usize,
    pub join_at: u64,
    pub hot: bool,
}

impl Churn {
    /// The first standard luminaire with nodes leaves, the last one (off until then) joins.
    pub fn pick(
        room: &Room,
        cal: &Calibrated,
        leave_at: u64,
        join_at: u64,
        hot: bool,
    ) -> Result<Self> {
        let standard: Vec<usize> = room
            .projectors()
            .iter()
            .enumerate()
            .filter(|(k, p)| {
                p.kind == ProjectorKind::Standard && cal.regions.iter().any(|r| r.projector == *k)
            })
            .map(|(k, _)| k)
            .collect();
        let (Some(&leaving), Some(&joining)) = (standard.first(), standard.last()) else {
            bail!("the room has no standard luminaire with nodes");
        };
        if leaving == joining {
            bail!("the room has a single standard luminaire: none to join after one left");
        }
        Ok(Self {
            leaving,
            leave_at,
            joining,
            join_at,
            hot,
        })
    }
}

impl RunOptions {
    /// The default: FISTA momentum with restarts and twenty model rounds per capture, the
    /// fastest combination on the demo rooms in captures and in wall time (`roomlight demo`
    /// prints the comparison). The rounds wait for every node's acknowledgement, so the errors
    /// are never stale and momentum keeps its guarantee.
    pub fn default_rule(seed: u64) -> Self {
        Self {
            rule: StepRule::Momentum { theta: 1.0 },
            model_rounds: 20,
            max_captures: 60,
            stop_when_settled: true,
            seed,
            latency: 0,
            discard_stale: false,
            churn: None,
        }
    }
}

/// The room after each capture's rounds, against the simulator's truth.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct TracePoint {
    /// Captures taken (0: the conventional start, before any).
    pub capture: u64,
    /// Wall time since the agents started.
    pub seconds: f64,
    /// `(G − G*)/G*` of the measured model from the camera's capture of these values (noisy;
    /// none for the final values, which no capture saw).
    pub measured_excess: Option<f64>,
    /// `(G − G*)/G*` of the measured model for the values shown (noiseless: the quantity the
    /// rules minimise).
    pub model_excess: f64,
    /// The same on the true problem for the values shown after this capture's rounds.
    pub true_excess: f64,
    /// True mean ΔE00 against the LED target for those values.
    pub mean_de00: f64,
}

/// One run of the agents on one target.
#[derive(Debug, Clone)]
pub struct RunResult {
    /// Captures until the camera agent settled (or the cap).
    pub captures: u64,
    /// Whether the camera agent reported settled (DESIGN §3.6) before the cap.
    pub settled: bool,
    /// Every capture's point, the conventional start first.
    pub trace: Vec<TracePoint>,
    /// The values the nodes show at the end.
    pub x: Vec<LinearRgb>,
    /// The measured model's `G` for them and its optimum `G*`.
    pub g: f64,
    /// The measured model's optimum.
    pub g_star: f64,
    /// `(G − G*)/G*` on the measured model.
    pub final_excess: f64,
    /// The same on the true problem.
    pub true_excess: f64,
    /// True ΔE00 per model patch at the end and at the conventional start.
    pub de00: Vec<f64>,
    /// True ΔE00 per model patch at the conventional start.
    pub conventional_de00: Vec<f64>,
    /// Mean ΔE00 the true optimum would reach (what the room allows).
    pub best_mean_de00: f64,
    /// Wall time of the run.
    pub seconds: f64,
    /// Of which the simulated camera (render, noise, chart sampling).
    pub capture_seconds: f64,
    /// Rounds run (captures and model rounds).
    pub rounds: u64,
    /// Projectors the camera agent calibrated hot during the run.
    pub calibrated_hot: u64,
    /// Protobuf bytes between the agents, both ways, per round once the agents are attached (the first capture's traffic, which
    /// carries every node's attenuation, left out).
    pub bytes_per_round: f64,
}

/// The room as a noiseless camera sees it through the charts: every node's light at full
/// white and the black level, on every room patch. Measured once per calibration.
pub struct Transport {
    corners: Arc<Vec<ChartCorners>>,
    config: SampleConfig,
    black: Vec<LinearRgb>,
    columns: Vec<Vec<LinearRgb>>,
}

impl Transport {
    /// Renders each node alone at full white (and all black), noiselessly, and samples the charts.
    pub fn new(
        basis: Arc<NodeBasis>,
        corners: &[ChartCorners],
        config: SampleConfig,
    ) -> Result<Self> {
        let nodes = basis.nodes();
        let black = sample(
            &basis.capture(&vec![LinearRgb::ZERO; nodes]),
            corners,
            &config,
        )?;
        let columns = (0..nodes)
            .map(|n| {
                let mut x = vec![LinearRgb::ZERO; nodes];
                x[n] = LinearRgb::ONE;
                Ok(sample(&basis.capture(&x), corners, &config)?
                    .iter()
                    .zip(&black)
                    .map(|(a, b)| (*a - *b).map(|v| v.max(0.0)))
                    .collect())
            })
            .collect::<Result<_>>()?;
        Ok(Self {
            corners: Arc::new(corners.to_vec()),
            config,
            black,
            columns,
        })
    }
}

/// The truth for one target on the model's patches, as a noiseless camera sees it.
pub struct Truth {
    /// The LED target.
    pub target: Vec<LinearRgb>,
    /// The true problem (true transport and target): its optimum is what the room could reach;
    /// the measured model's optimum differs from it by the calibration's errors.
    pub problem: Problem,
}

impl Truth {
    /// `G` of what a noiseless camera measured against the true target.
    pub fn objective(&self, values: &[LinearRgb]) -> f64 {
        let errors: Vec<LinearRgb> = self
            .target
            .iter()
            .zip(values)
            .map(|(r, y)| *r - *y)
            .collect();
        roomlight_core::metrics::objective(&errors)
    }

    /// The truth for `model`'s patches under `preset`.
    pub fn new(room: &Room, transport: &Transport, model: &Model, preset: usize) -> Result<Self> {
        let pick = |v: &[LinearRgb]| model.patches.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let target = pick(&sample(
            &room.render(&vec![Frame::Black; room.projectors().len()], Some(preset))?,
            &transport.corners,
            &transport.config,
        )?);
        let columns = transport
            .columns
            .iter()
            .map(|c| {
                let dense = pick(c);
                AttenuationColumn::from_dense_with_cutoff(
                    &dense,
                    &vec![LinearRgb::ZERO; dense.len()],
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        let problem = Problem::new(
            columns,
            pick(&transport.black),
            target.clone(),
            model.problem.noise().to_vec(),
        )?;
        Ok(Self { target, problem })
    }
}

/// Runs the camera agent and one node agent per projector over loopback gRPC on `model`, from
/// its conventional start until the camera agent reports settled (or `max_captures`), and
/// measures the result against the simulator's truth.
pub fn run_agents(
    room: &Arc<Room>,
    cal: &Calibrated,
    model: &Model,
    transport: &Transport,
    truth: &Truth,
    options: RunOptions,
    bar: &indicatif::ProgressBar,
) -> Result<RunResult> {
    let nodes_of = |projector: usize| -> Vec<usize> {
        (0..cal.regions.len())
            .filter(|&n| cal.regions[n].projector == projector)
            .collect()
    };
    let name_of = |projector: usize| -> Result<String> {
        room.projectors()
            .get(projector)
            .map(|p| p.name.clone())
            .with_context(|| format!("churn: the room has no projector {projector}"))
    };
    // With a projector leaving, the room it leaves behind is the reference: its optimum is what
    // the others can reach without it.
    let (gone, joining) = match options.churn {
        Some(c) => {
            if c.join_at >= options.max_captures || c.leave_at >= options.max_captures {
                bail!(
                    "churn at captures {} and {} does not fit a budget of {} captures",
                    c.leave_at,
                    c.join_at,
                    options.max_captures
                );
            }
            let (gone, joining) = (nodes_of(c.leaving), nodes_of(c.joining));
            if gone.is_empty() || joining.is_empty() || c.leaving == c.joining {
                bail!(
                    "churn: projectors {} and {} must be two luminaires with nodes",
                    name_of(c.leaving)?,
                    name_of(c.joining)?
                );
            }
            (gone, joining)
        }
        None => (Vec::new(), Vec::new()),
    };
    let mut initial = model.conventional.clone();
    for &n in &joining {
        initial[n] = LinearRgb::ZERO;
    }
    let hw = SimHardware {
        room: room.clone(),
        frames: Arc::new(FrameBuilder::new(room, &cal.regions, cal.responses.clone())),
        corners: transport.corners.clone(),
        config: transport.config,
        shown: Arc::new(Mutex::new(initial.clone())),
        patches: Arc::new(model.patches.clone()),
        noise: Arc::new(Mutex::new(CameraNoise::with_seed(room, options.seed))),
        log: Arc::new(Mutex::new(Vec::new())),
        latency: options.latency,
        delayed: Arc::new(Mutex::new(VecDeque::new())),
    };
    let best = optimum(&model.problem.without_nodes(&gone))?;
    let true_best = optimum(&truth.problem.without_nodes(&gone))?;
    let de_conv = patch_delta_e(&truth.target, &hw.noiseless(&initial)?)?;
    let owners = cal.owners(room);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let t0 = Instant::now();
    let mut steady = PerRound::default();
    let last = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        let config = CameraConfig {
            room: "lab".into(),
            token: "demo".into(),
            heartbeat: Duration::from_millis(500),
            deadline: Duration::from_secs(2),
            model_rounds: options.model_rounds,
            calibration_epoch: 1,
            stale_frames: if options.discard_stale {
                options.latency
            } else {
                0
            },
            model_out: None,
        };
        // A projector joining hot is measured by the camera agent when it joins.
        let hot = match options.churn.filter(|c| c.hot) {
            Some(c) => [name_of(c.joining)?].into(),
            None => Default::default(),
        };
        let (mut status, camera_task) = camera::serve(
            config,
            RoomModel {
                problem: model.problem.clone(),
                owners: owners.clone(),
                start: Some(model.conventional.clone()),
                hot,
                survey: None,
            },
            hw.clone(),
            listener,
            cancel.clone(),
        );
        let spawn = |id: &str| {
            let config = NodeConfig {
                endpoint: endpoint.clone(),
                room: "lab".into(),
                token: "demo".into(),
                projector_id: id.to_string(),
                kind: roomlight_proto::v1::ProjectorKind::Standard,
                rule: options.rule,
                start: LinearRgb::splat(0.5),
                state_file: None,
            };
            let token = cancel.child_token();
            let task = tokio::spawn(node::run(config, hw.clone(), token.clone()));
            (id.to_string(), (token, task))
        };
        let (leaving, joining) = match options.churn {
            Some(c) => (Some(name_of(c.leaving)?), Some(name_of(c.joining)?)),
            None => (None, None),
        };
        let mut node_tasks: HashMap<_, _> = owners
            .keys()
            .filter(|id| Some(*id) != joining.as_ref())
            .map(|id| spawn(id))
            .collect();
        let (mut left, mut joined) = (false, joining.is_none());
        let outcome = tokio::time::timeout(Duration::from_secs(120), async {
            loop {
                status.changed().await?;
                let s = status.borrow().clone();
                steady.add(&s);
                if !bar.is_hidden() {
                    // The live line: ΔE00 against the truth costs a render, so only when shown.
                    let de = hw
                        .noiseless(&hw.shown())
                        .and_then(|v| Ok(patch_delta_e(&truth.target, &v)?.mean))
                        .unwrap_or(f64::NAN);
                    bar.set_position(s.captures);
                    bar.set_message(format!(
                        "round {} · G {:.3e} · excess {:.1e} · ΔE00 {de:.2}",
                        s.round,
                        s.measured_objective,
                        best.excess(s.measured_objective)
                    ));
                }
                if let (Some(c), Some(id)) = (options.churn, &leaving)
                    && !left
                    && s.captures >= c.leave_at
                {
                    // The projector is switched off: its agent stops, its light is gone.
                    if let Some((token, task)) = node_tasks.remove(id) {
                        token.cancel();
                        let _ = tokio::time::timeout(Duration::from_secs(5), task).await;
                    }
                    let mut shown = hw.shown.lock().unwrap_or_else(PoisonError::into_inner);
                    for &n in &gone {
                        shown[n] = LinearRgb::ZERO;
                    }
                    left = true;
                }
                if let (Some(c), Some(id)) = (options.churn, &joining)
                    && !joined
                    && s.captures >= c.join_at
                {
                    let (id, handles) = spawn(id);
                    node_tasks.insert(id, handles);
                    joined = true;
                }
                let settled_or_done =
                    s.settled && options.stop_when_settled || s.captures >= options.max_captures;
                if s.live_projectors == node_tasks.len() && joined && settled_or_done {
                    return Ok::<_, anyhow::Error>(s);
                }
            }
        })
        .await;
        cancel.cancel();
        for (_, (_, task)) in node_tasks {
            let _ = tokio::time::timeout(Duration::from_secs(5), task).await;
        }
        let _ = tokio::time::timeout(Duration::from_secs(5), camera_task).await;
        outcome.with_context(|| {
            format!(
                "the agents neither stopped nor took {} captures within 120 s",
                options.max_captures
            )
        })?
    })?;
    let end = Instant::now();
    let x = hw
        .shown
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    let final_values = hw.noiseless(&x)?;
    let de = patch_delta_e(&truth.target, &final_values)?;
    // The room after k captures' rounds is what capture k + 1 saw; after the last, what it shows.
    let log = std::mem::take(&mut *hw.log.lock().unwrap_or_else(PoisonError::into_inner));
    let capture_seconds: f64 = log.iter().map(|l| l.took.as_secs_f64()).sum();
    let states = log
        .iter()
        .map(|l| (l.at, &l.shown, &l.noiseless, Some(&l.measured)))
        .chain(std::iter::once((end, &x, &final_values, None)));
    let trace = states
        .enumerate()
        .map(|(k, (at, shown, values, measured))| {
            Ok(TracePoint {
                capture: k as u64,
                seconds: at.saturating_duration_since(t0).as_secs_f64(),
                measured_excess: measured.map(|y| {
                    best.excess(roomlight_core::metrics::objective(
                        &model
                            .problem
                            .target()
                            .iter()
                            .zip(y)
                            .map(|(r, y)| *r - *y)
                            .collect::<Vec<_>>(),
                    ))
                }),
                model_excess: best.excess(model.problem.objective(shown)),
                true_excess: true_best.excess(truth.objective(values)),
                mean_de00: patch_delta_e(&truth.target, values)?.mean,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let de_best = patch_delta_e(&truth.target, &truth.problem.response(&true_best.x))?;
    let g = model.problem.objective(&x);
    Ok(RunResult {
        captures: last.captures,
        settled: last.settled,
        trace,
        g,
        g_star: best.objective,
        final_excess: best.excess(g),
        true_excess: true_best.excess(truth.objective(&final_values)),
        x,
        de00: de.per_patch,
        conventional_de00: de_conv.per_patch,
        best_mean_de00: de_best.mean,
        seconds: t0.elapsed().as_secs_f64(),
        capture_seconds,
        rounds: last.round,
        bytes_per_round: steady.bytes_per_round(),
        calibrated_hot: last.calibrated_hot,
    })
}

/// Bytes per round from the camera agent's status, the first status (attachment, attenuation)
/// left out.
#[derive(Debug, Default)]
pub struct PerRound {
    first_round: Option<u64>,
    last_round: u64,
    bytes: u64,
    all_bytes: u64,
}

impl PerRound {
    pub fn add(&mut self, s: &camera::RoomStatus) {
        let b = s.bytes_in + s.bytes_out;
        self.all_bytes += b;
        if self.first_round.is_some() {
            self.bytes += b;
        } else {
            self.first_round = Some(s.round);
        }
        self.last_round = s.round;
    }

    /// Over the rounds after the first status; with none, over all (0 before any round).
    pub fn bytes_per_round(&self) -> f64 {
        match self.first_round {
            Some(first) if self.last_round > first => {
                self.bytes as f64 / (self.last_round - first) as f64
            }
            _ => self.all_bytes as f64 / self.last_round.max(1) as f64,
        }
    }
}
