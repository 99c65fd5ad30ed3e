//! The whole method on a simulated room, as the system does it: structured light, nodes and
//! feathering, Hadamard attenuation and the LED target measured from noisy captures through the
//! charts, then the real agents over loopback gRPC. The simulator is touched only through
//! captures, except (1) the target mask, which a real room configures by hand, (2) projector
//! frames in linear light (a real node inverts its measured response), and (3) the rounds use the
//! node basis' patch values with the measured patch noise instead of rendering and sampling a
//! full capture each round (the same numbers, faster).

use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::hardware::{Camera, Display};
use roomlight_agent::node::{self, NodeConfig};
use roomlight_calib::attenuation::{Scheme, plan, solve};
use roomlight_calib::charts::{
    ChartCorners, PatchSample, PatchStatus, SampleConfig, sample_charts,
};
use roomlight_calib::graycode::{Coding, DecodeConfig, Manifest, decode};
use roomlight_calib::image_io::LinearImage;
use roomlight_calib::nodes::{NodeConfig as SplitConfig, segment};
use roomlight_core::conventional::conventional_value;
use roomlight_core::metrics::patch_delta_e;
use roomlight_core::optimum::optimum;
use roomlight_core::{AttenuationColumn, LinearRgb, PatchId, Problem, StepRule};
use roomlight_sim::scene::{ProjectorKind, ProjectorRole};
use roomlight_sim::{CameraNoise, Frame, NodeBasis, NodeRegion, ProjectorImage, Room};
use std::collections::HashMap;
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

/// The result of calibrating a room.
pub struct Calibrated {
    /// The measured model over the usable patches.
    pub problem: Problem,
    /// Each node's projector and weights (for the simulated hardware).
    pub regions: Vec<NodeRegion>,
    /// Room patch index of each model patch.
    pub patches: Vec<usize>,
    /// Each node's own chart, in model patch ids.
    pub charts: Vec<Vec<PatchId>>,
    /// Captures used.
    pub captures: usize,
}

/// Calibrates the standard luminaires of `room` against the LED preset `preset`.
pub fn calibrate(
    room: &Room,
    preset: usize,
    noise: &mut CameraNoise,
    mut say: impl FnMut(String),
) -> Result<Calibrated> {
    let n = room.projectors().len();
    let charts = chart_corners(room)?;
    let luminaires: Vec<usize> = (0..n)
        .filter(|&k| {
            room.scene().projectors[k].role == ProjectorRole::Luminaire
                && room.projectors()[k].kind == ProjectorKind::Standard
        })
        .collect();
    let mut captures = 0;
    let mut shoot = |frames: &[Frame], preset: Option<usize>| -> Result<LinearImage> {
        captures += 1;
        Ok(image(&noise.expose(&room.render(frames, preset)?)))
    };
    // 1. Structured light, one projector at a time.
    let t = Instant::now();
    let mut corr = Vec::new();
    for &k in &luminaires {
        let p = &room.projectors()[k].pinhole;
        let manifest = Manifest::with_coding(p.width, p.height, Coding::Xor04)?;
        let mut caps = Vec::with_capacity(manifest.patterns.len());
        for pat in &manifest.patterns {
            let img = manifest.pattern_image(pat.pattern);
            let mut frames = vec![Frame::Black; n];
            frames[k] = Frame::Image(ProjectorImage {
                width: img.width,
                height: img.height,
                pixels: img.pixels,
            });
            caps.push(shoot(&frames, None)?);
        }
        corr.push(decode(&manifest, &DecodeConfig::default(), |f| {
            Ok(&caps[manifest
                .patterns
                .iter()
                .position(|p| p.file == f.file)
                .unwrap_or(0)])
        })?);
    }
    say(format!(
        "structured light: {} projectors decoded in {:.1} s",
        luminaires.len(),
        t.elapsed().as_secs_f64()
    ));
    // 2. Nodes.
    let mask: Vec<bool> = room.pixels().iter().map(|p| p.target).collect();
    let seg = segment(&corr, &charts, Some(&mask), &SplitConfig::default())?;
    let regions: Vec<NodeRegion> = seg
        .nodes
        .iter()
        .map(|nd| NodeRegion {
            projector: luminaires[nd.projector],
            weights: nd.weights.clone(),
        })
        .collect();
    let node_charts: Vec<usize> = seg.nodes.iter().map(|nd| nd.chart).collect();
    say(format!(
        "nodes: {} over {} charts",
        regions.len(),
        charts.len()
    ));
    // 3. Black, attenuation (Hadamard) and the LED target, through the charts.
    let frames_for = |on: &[bool]| -> Vec<Frame> {
        (0..n)
            .map(|k| {
                let p = &room.projectors()[k].pinhole;
                let mut pixels = vec![[0.0f32; 3]; (p.width * p.height) as usize];
                for (r, _) in regions
                    .iter()
                    .zip(on)
                    .filter(|(r, o)| **o && r.projector == k)
                {
                    for (px, w) in pixels.iter_mut().zip(&r.weights) {
                        px.iter_mut().for_each(|c| *c += w);
                    }
                }
                Frame::Linear(ProjectorImage {
                    width: p.width,
                    height: p.height,
                    pixels,
                })
            })
            .collect()
    };
    let config = SampleConfig::default();
    let nodes = regions.len();
    let black = sample_charts(
        &shoot(&frames_for(&vec![false; nodes]), None)?,
        &charts,
        &config,
    )?;
    let rows = plan(nodes, Scheme::Hadamard);
    let mut measured: Vec<Vec<PatchSample>> = Vec::with_capacity(rows.len());
    for on in &rows {
        measured.push(sample_charts(
            &shoot(&frames_for(on), None)?,
            &charts,
            &config,
        )?);
    }
    let att = solve(Scheme::Hadamard, nodes, &black, &measured)?;
    let target = sample_charts(
        &shoot(&vec![Frame::Black; n], Some(preset))?,
        &charts,
        &config,
    )?;
    // 4. The model over the patches measured everywhere.
    let patches: Vec<usize> = (0..black.len())
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
    let full = att.columns(3.0)?;
    let columns: Vec<AttenuationColumn> = full
        .iter()
        .map(|c| {
            let (s, v): (Vec<PatchId>, Vec<LinearRgb>) = c
                .iter()
                .filter_map(|(i, p)| index.get(&(i as usize)).map(|&k| (k, p)))
                .unzip();
            AttenuationColumn::new(s, v)
        })
        .collect::<Result<_, _>>()?;
    let pick = |v: &[LinearRgb]| patches.iter().map(|&i| v[i]).collect::<Vec<_>>();
    let problem = Problem::new(
        columns,
        pick(&att.black),
        patches.iter().map(|&i| target[i].mean).collect(),
        patches.iter().map(|&i| target[i].std_error).collect(),
    )?;
    let charts_of_nodes = node_charts
        .iter()
        .map(|&m| {
            (0..24)
                .filter_map(|j| index.get(&(24 * m + j)).copied())
                .collect()
        })
        .collect();
    say(format!(
        "attenuation: {} Hadamard captures, {} of {} patches usable, {:.1}% of the entries kept",
        rows.len(),
        patches.len(),
        black.len(),
        100.0 * problem.columns().iter().map(|c| c.len()).sum::<usize>() as f64
            / (nodes * patches.len()).max(1) as f64
    ));
    Ok(Calibrated {
        problem,
        regions,
        patches,
        charts: charts_of_nodes,
        captures,
    })
}

/// The simulated projectors and camera behind the agents: node values in, noisy patch values out.
#[derive(Clone)]
struct SimHardware {
    basis: Arc<NodeBasis>,
    shown: Arc<Mutex<Vec<LinearRgb>>>,
    patches: Arc<Vec<usize>>,
    sigma: Arc<Vec<LinearRgb>>,
    rng: Arc<Mutex<u64>>,
}

impl SimHardware {
    fn true_values(&self) -> Vec<LinearRgb> {
        let x = self
            .shown
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone();
        let all = self.basis.patch_values(&x);
        self.patches.iter().map(|&i| all[i]).collect()
    }

    /// A standard normal sample (Box–Muller on a 64-bit LCG; the noise only needs to be plausible).
    fn normal(&self) -> f64 {
        let mut s = self.rng.lock().unwrap_or_else(PoisonError::into_inner);
        let mut next = || {
            *s = s
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((*s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (u, v) = (next(), next());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
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
        let values = self.true_values();
        let noisy = values
            .iter()
            .zip(self.sigma.iter())
            .map(|(v, s)| {
                LinearRgb(std::array::from_fn(|c| {
                    (v[c] + s[c] * self.normal()).max(0.0)
                }))
            })
            .collect();
        std::future::ready(Ok(noisy))
    }
}

/// Runs the agents on a calibrated room and reports true ΔE00 against the LED target.
pub fn run_agents(
    room: &Room,
    preset: usize,
    cal: &Calibrated,
    mut say: impl FnMut(String),
) -> Result<()> {
    let basis = NodeBasis::new(room, &cal.regions, None)?;
    let truth_target: Vec<LinearRgb> = {
        let all = room.patch_values(&vec![Frame::Black; room.projectors().len()], Some(preset))?;
        cal.patches.iter().map(|&i| all[i]).collect()
    };
    let nodes = cal.problem.nodes();
    let hw = SimHardware {
        basis: Arc::new(basis),
        shown: Arc::new(Mutex::new(vec![LinearRgb::ZERO; nodes])),
        patches: Arc::new(cal.patches.clone()),
        sigma: Arc::new(cal.problem.noise().to_vec()),
        rng: Arc::new(Mutex::new(7)),
    };
    // The conventional start, for comparison (DESIGN §3.1), shown by the same hardware.
    let conventional: Vec<LinearRgb> = cal
        .problem
        .columns()
        .iter()
        .zip(&cal.charts)
        .map(|(c, chart)| {
            conventional_value(
                c,
                chart,
                cal.problem.target(),
                cal.problem.black(),
                LinearRgb::splat(0.5),
            )
        })
        .collect::<Result<_, _>>()?;
    *hw.shown.lock().unwrap_or_else(PoisonError::into_inner) = conventional;
    let de_conv = patch_delta_e(&truth_target, &hw.true_values())?;
    let best = optimum(&cal.problem)?;
    let mut owners: HashMap<String, Vec<u32>> = HashMap::new();
    for (n, r) in cal.regions.iter().enumerate() {
        owners
            .entry(room.projectors()[r.projector].name.clone())
            .or_default()
            .push(n as u32);
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let result = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
        let endpoint = format!("http://{}", listener.local_addr()?);
        let cancel = CancellationToken::new();
        let config = CameraConfig {
            room: "lab".into(),
            token: "demo".into(),
            heartbeat: Duration::from_millis(500),
            deadline: Duration::from_secs(2),
            model_rounds: 5,
            calibration_epoch: 1,
        };
        let (mut status, _h) = camera::serve(
            config,
            RoomModel {
                problem: cal.problem.clone(),
                owners: owners.clone(),
                start: None,
            },
            hw.clone(),
            listener,
            cancel.clone(),
        );
        for id in owners.keys() {
            let config = NodeConfig {
                endpoint: endpoint.clone(),
                room: "lab".into(),
                token: "demo".into(),
                projector_id: id.clone(),
                rule: StepRule::Safe { theta: 1.0 },
                start: LinearRgb::splat(0.5),
                state_file: None,
            };
            tokio::spawn(node::run(config, hw.clone(), cancel.child_token()));
        }
        let outcome = tokio::time::timeout(Duration::from_secs(120), async {
            loop {
                status.changed().await?;
                let s = status.borrow().clone();
                if s.live_projectors == owners.len() && s.captures >= 25 {
                    return Ok::<_, anyhow::Error>(s);
                }
            }
        })
        .await;
        cancel.cancel();
        outcome.context("the agents did not finish 25 captures within 120 s")?
    })?;
    let de = patch_delta_e(&truth_target, &hw.true_values())?;
    let shown = hw
        .shown
        .lock()
        .unwrap_or_else(PoisonError::into_inner)
        .clone();
    // The true problem (simulator transport over the same patches, the true LED target): its
    // optimum is what the room could reach; the measured model's optimum differs from it by
    // the calibration's errors.
    let true_problem = {
        let pick = |v: Vec<LinearRgb>| cal.patches.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let black = pick(hw.basis.patch_values(&vec![LinearRgb::ZERO; nodes]));
        let columns = (0..nodes)
            .map(|n| {
                let mut x = vec![LinearRgb::ZERO; nodes];
                x[n] = LinearRgb::ONE;
                let dense: Vec<LinearRgb> = pick(hw.basis.patch_values(&x))
                    .iter()
                    .zip(&black)
                    .map(|(a, b)| (*a - *b).map(|v| v.max(0.0)))
                    .collect();
                AttenuationColumn::from_dense_with_cutoff(
                    &dense,
                    &vec![LinearRgb::ZERO; dense.len()],
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Problem::new(
            columns,
            black,
            truth_target.clone(),
            cal.problem.noise().to_vec(),
        )?
    };
    let true_best = optimum(&true_problem)?;
    let de_best = patch_delta_e(&truth_target, &true_problem.response(&true_best.x))?;
    say(format!(
        "against the truth: excess over the true optimum {:.2e} (the true optimum's mean ΔE00 is {:.2})",
        true_best.excess(true_problem.objective(&shown)),
        de_best.mean
    ));
    let at_white = shown
        .iter()
        .flat_map(|x| x.0)
        .filter(|&v| v >= 0.999)
        .count();
    let at_black = shown
        .iter()
        .flat_map(|x| x.0)
        .filter(|&v| v <= 0.001)
        .count();
    say(format!(
        "node channels at full white: {at_white}, at black: {at_black}, of {}",
        3 * shown.len()
    ));
    say(format!(
        "agents over loopback gRPC: {} node agents, {} captures; excess over the measured model's optimum {:.2e}; true mean ΔE00 {:.2} (max {:.2}) against the LED target, conventional start {:.2}",
        owners.len(),
        result.captures,
        best.excess(cal.problem.objective(&shown)),
        de.mean,
        de.max,
        de_conv.mean
    ));
    Ok(())
}
