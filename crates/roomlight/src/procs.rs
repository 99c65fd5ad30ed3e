//! The processes of an installation: `roomlight sim`, `roomlight camera`, `roomlight node`.
//! Each prints `listening on ADDR` once it serves, logs with tracing (RUST_LOG), and stops
//! cleanly on Ctrl-C or SIGTERM (nodes say goodbye and flush their state file).

use anyhow::{Context, Result, bail};
use roomlight_agent::camera::{self, CameraConfig, RoomModel};
use roomlight_agent::discovery::{self, MdnsConfig};
use roomlight_agent::hardware::VirtualRoom;
use roomlight_agent::node::{self, NodeConfig};
use roomlight_agent::remote::{RemoteCamera, remote_display, serve_hardware};
use roomlight_core::closed_loop::{Plant, PlantConfig};
use roomlight_core::synthetic::{SyntheticConfig, synthetic_room};
use roomlight_core::{LinearRgb, Problem, StepRule};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

/// The calibrated model a camera agent loads: every node's attenuation and who owns it.
#[derive(Debug, Serialize, Deserialize)]
pub struct ModelFile {
    /// Columns, targets, black offsets, noise.
    pub problem: Problem,
    /// Projector id → node ids.
    pub owners: HashMap<String, Vec<u32>>,
    /// Each node's start (the conventional start); absent: the node agents' own.
    #[serde(default)]
    pub start: Option<Vec<LinearRgb>>,
    /// Written by a camera agent calibrating over the wire: the room patch index of each model
    /// patch (a restarted camera agent resumes the model with it).
    #[serde(default)]
    pub patches: Option<Vec<usize>>,
}

/// Where the camera agent of a rendered room finds its patches in a camera image.
#[derive(Debug, Serialize, Deserialize)]
pub struct ChartsFile {
    pub corners: Vec<roomlight_calib::charts::ChartCorners>,
    /// Room patch index of each model patch.
    pub patches: Vec<usize>,
    pub sample: roomlight_calib::charts::SampleConfig,
}

/// The camera agent's camera: the synthetic room's patches, or a rendered room's images
/// sampled at the charts.
enum AnyCamera {
    Synthetic(RemoteCamera),
    Rendered(roomlight_lab::rendered::RenderedCamera),
}

impl roomlight_agent::hardware::Camera for AnyCamera {
    fn capture_image(
        &mut self,
    ) -> impl Future<
        Output = Result<roomlight_calib::image_io::LinearImage, roomlight_agent::AgentError>,
    > + Send {
        let capture: std::pin::Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture_image()),
            Self::Rendered(c) => Box::pin(c.capture_image()),
        };
        capture
    }

    fn capture(
        &mut self,
    ) -> impl Future<Output = Result<Vec<LinearRgb>, roomlight_agent::AgentError>> + Send {
        let capture: std::pin::Pin<Box<dyn Future<Output = _> + Send + '_>> = match self {
            Self::Synthetic(c) => Box::pin(c.capture()),
            Self::Rendered(c) => Box::pin(c.capture()),
        };
        capture
    }
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}: not {what}", path.display()))
}

#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// Nodes of the synthetic room.
    #[arg(long, default_value_t = 12)]
    synthetic: usize,
    /// Projectors (node agents) the nodes are split among.
    #[arg(long, default_value_t = 3)]
    projectors: usize,
    /// Seed of the room and of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Camera noise, in multiples of the patch noise (0: noiseless).
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Address to serve on (port 0: any free port, printed).
    #[arg(long, default_value = "127.0.0.1:50050")]
    listen: String,
    /// Where to write the synthetic room's model (the stand-in for calibration) for the
    /// camera agent. Required for a synthetic room.
    #[arg(long)]
    model_out: Option<PathBuf>,
    /// Serve a rendered room instead (the `RenderedRoom` service: projector images in, camera
    /// images out, LED presets): `default` (the embedded lab), `small`, or a scene TOML file.
    #[arg(long, conflicts_with_all = ["synthetic", "projectors", "model_out"])]
    scene: Option<String>,
    /// With --scene: the camera's resolution instead of the scene's, as WIDTHxHEIGHT.
    #[arg(long, requires = "scene")]
    camera: Option<String>,
}

/// `roomlight calibrate`: calibrates a simulated room (in one process, through captures only)
/// and writes what the processes of a rendered room need.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// `default` (the embedded lab), `small`, or a scene TOML file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// The camera's resolution instead of the scene's, as WIDTHxHEIGHT.
    #[arg(long)]
    camera: Option<String>,
    /// The LED preset whose light the projectors reproduce (default: the first).
    #[arg(long)]
    preset: Option<String>,
    /// Seed of the camera noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Folder for model.json, charts.json and one frame-PROJECTOR.json per luminaire (with
    /// --survey-only: survey.json).
    #[arg(long)]
    out: PathBuf,
    /// Write only survey.json, what an installer configures once for calibration over the wire
    /// (chart corners, patch sampling, the target's camera mask), and calibrate nothing: the
    /// camera agent then calibrates each projector through its node agent as it joins.
    #[arg(long)]
    survey_only: bool,
}

/// What a camera agent needs to calibrate projectors over the wire (DESIGN §4): the charts'
/// corners in the camera image (clicked once in a real room), how to sample them, and the
/// target's camera pixels.
#[derive(Debug, Serialize, Deserialize)]
pub struct SurveyFile {
    pub camera_width: u32,
    pub camera_height: u32,
    pub corners: Vec<roomlight_calib::charts::ChartCorners>,
    pub sample: roomlight_calib::charts::SampleConfig,
    /// Row-major camera pixels of the target, increasing.
    pub target_pixels: Vec<u32>,
}

/// A scene by name or file, with the camera's resolution optionally replaced.
fn load_scene(which: &str, camera: Option<&str>) -> Result<roomlight_sim::scene::Scene> {
    let mut scene = match which {
        "default" | "lab" => roomlight_sim::scenes::lab()?,
        "small" => roomlight_sim::scenes::small()?,
        path => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading the scene {path}"))?;
            roomlight_sim::scene::Scene::from_toml(&text, path)?
        }
    };
    if let Some(size) = camera {
        let parsed = size
            .split_once('x')
            .and_then(|(w, h)| Some([w.parse::<u32>().ok()?, h.parse::<u32>().ok()?]))
            .filter(|[w, h]| *w > 0 && *h > 0);
        let Some(resolution) = parsed else {
            bail!("--camera {size:?}: expected WIDTHxHEIGHT, e.g. 640x480");
        };
        scene.camera.resolution = resolution;
    }
    Ok(scene)
}

/// Writes `value` as JSON to `path` (through a temporary file, so a reader never sees half).
fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, serde_json::to_string(value)?)
        .with_context(|| format!("writing {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

/// Binds `listen`, prints where it serves, and runs `serve` until Ctrl-C or SIGTERM.
fn serve_until_stopped<Fut>(
    name: &str,
    listen: &str,
    serve: impl FnOnce(tokio::net::TcpListener, CancellationToken) -> Fut,
) -> Result<()>
where
    Fut: Future<Output = Result<()>>,
{
    runtime()?.block_on(async {
        let listener = tokio::net::TcpListener::bind(listen)
            .await
            .with_context(|| format!("binding {listen}"))?;
        announce(name, listener.local_addr()?);
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        serve(listener, cancel).await
    })
}

pub fn calibrate(args: &CalibrateArgs) -> Result<()> {
    let scene = load_scene(&args.scene, args.camera.as_deref())?;
    let room = std::sync::Arc::new(
        roomlight_sim::Room::build(scene)
            .with_context(|| format!("building the room of {}", args.scene))?,
    );
    if args.survey_only {
        std::fs::create_dir_all(&args.out)
            .with_context(|| format!("creating {}", args.out.display()))?;
        // The luminaires a node agent is started for (deploy/local-lab.sh reads these lines).
        for (p, spec) in room.projectors().iter().zip(&room.scene().projectors) {
            if spec.role == roomlight_sim::scene::ProjectorRole::Luminaire {
                let kind = match p.kind {
                    roomlight_sim::scene::ProjectorKind::LargeAperture => "large-aperture",
                    _ => "standard",
                };
                println!("luminaire {} {kind}", p.name);
            }
        }
        let [camera_width, camera_height] = room.scene().camera.resolution;
        return write_json(
            &args.out.join("survey.json"),
            &SurveyFile {
                camera_width,
                camera_height,
                corners: roomlight_lab::pipeline::chart_corners(&room)?,
                sample: roomlight_lab::pipeline::sample_config(&room),
                target_pixels: room
                    .pixels()
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| p.target)
                    .map(|(i, _)| i as u32)
                    .collect(),
            },
        );
    }
    let preset = match &args.preset {
        Some(name) => room
            .preset(name)
            .with_context(|| format!("--preset {name}"))?,
        None => 0,
    };
    let mut noise = roomlight_sim::CameraNoise::with_seed(&room, args.seed);
    let bar = indicatif::ProgressBar::hidden();
    let cal = roomlight_lab::pipeline::calibrate(&room, &mut noise, &bar, |line| println!("{line}"))?;
    let model = roomlight_lab::pipeline::measure_target(&room, &cal, preset, &mut noise)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    write_json(
        &args.out.join("model.json"),
        &ModelFile {
            problem: model.problem.clone(),
            owners: cal.owners(&room),
            start: Some(model.conventional.clone()),
            patches: None,
        },
    )?;
    write_json(
        &args.out.join("charts.json"),
        &ChartsFile {
            corners: cal.corners.clone(),
            patches: model.patches.clone(),
            sample: roomlight_lab::pipeline::sample_config(&room),
        },
    )?;
    for (k, p) in room.projectors().iter().enumerate() {
        let nodes: Vec<(u32, Vec<(u32, f32)>)> = cal
            .regions
            .iter()
            .enumerate()
            .filter(|(_, r)| r.projector == k)
            .map(|(n, r)| (n as u32, roomlight_lab::pipeline::sparse_weights(r)))
            .collect();
        if nodes.is_empty() {
            continue;
        }
        let spec = roomlight_lab::rendered::FrameSpec {
            projector: p.name.clone(),
            width: p.pinhole.width,
            height: p.pinhole.height,
            response: cal.responses[k].clone(),
            nodes,
        };
        write_json(&args.out.join(format!("frame-{}.json", p.name)), &spec)?;
    }
    Ok(())
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    room: String,
    token: String,
    listen: String,
    hardware: String,
    /// The calibrated model (`roomlight calibrate` or `roomlight sim` writes it); or `survey`.
    #[serde(default)]
    model: Option<PathBuf>,
    /// A rendered room: the charts file (`roomlight calibrate` writes it); absent: the
    /// synthetic room's patches.
    #[serde(default)]
    charts: Option<PathBuf>,
    /// Calibration over the wire on a rendered room: the survey file (`roomlight calibrate
    /// --survey-only` writes it); each projector is calibrated through its node agent as it
    /// joins. Instead of `model` and `charts`.
    #[serde(default)]
    survey: Option<PathBuf>,
    /// With `survey`: the LED preset whose light the projectors reproduce (default: the first).
    #[serde(default)]
    preset: Option<String>,
    /// Where to write the model (problem, owners, starts) whenever a projector has been
    /// calibrated over the wire or hot.
    #[serde(default)]
    model_out: Option<PathBuf>,
    #[serde(default = "heartbeat_default")]
    heartbeat_ms: u64,
    #[serde(default = "deadline_default")]
    deadline_ms: u64,
    #[serde(default)]
    model_rounds: usize,
    #[serde(default = "epoch_default")]
    calibration_epoch: u64,
    #[serde(default)]
    stale_frames: usize,
    /// Advertise the camera agent over mDNS.
    #[serde(default = "mdns_default")]
    mdns: bool,
    #[serde(default = "mdns_port_default")]
    mdns_port: u16,
    /// mDNS on the loopback interface only (one machine).
    #[serde(default)]
    mdns_loopback_only: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NodeFile {
    room: String,
    token: String,
    /// The camera agent's endpoint, or "mdns" to find the agent of `room` over mDNS.
    camera: String,
    #[serde(default = "mdns_port_default")]
    mdns_port: u16,
    #[serde(default)]
    mdns_loopback_only: bool,
    /// How long to look for the camera agent over mDNS, in seconds.
    #[serde(default = "mdns_wait_default")]
    mdns_wait_s: u64,
    hardware: String,
    /// A rendered room: this projector's frame file (`roomlight calibrate` writes it); absent:
    /// node values on the synthetic room, or (with `rendered`) weights from the camera agent.
    #[serde(default)]
    frame: Option<PathBuf>,
    /// A rendered room without a frame file: the camera agent calibrates this projector over
    /// the wire (its display shows the patterns and draws the weights it is sent).
    #[serde(default)]
    rendered: bool,
    /// `standard` or `large-aperture`.
    #[serde(default = "kind_default")]
    kind: String,
    projector: String,
    #[serde(default)]
    state_file: Option<PathBuf>,
    #[serde(default = "rule_default")]
    rule: String,
    #[serde(default = "theta_default")]
    theta: f64,
    #[serde(default = "start_default")]
    start: f64,
}

fn kind_default() -> String {
    "standard".into()
}
fn mdns_default() -> bool {
    true
}
fn mdns_port_default() -> u16 {
    5353
}
fn mdns_wait_default() -> u64 {
    30
}
fn heartbeat_default() -> u64 {
    500
}
fn deadline_default() -> u64 {
    2000
}
fn epoch_default() -> u64 {
    1
}
fn rule_default() -> String {
    "momentum".into()
}
fn theta_default() -> f64 {
    1.0
}
fn start_default() -> f64 {
    0.5
}

fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("{}: not a valid config", path.display()))
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("starting the runtime")
}

fn init_logs() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .try_init();
}

/// Cancels `token` on Ctrl-C or SIGTERM.
fn stop_on_signals(token: CancellationToken) {
    tokio::spawn(async move {
        let ctrl_c = tokio::signal::ctrl_c();
        #[cfg(unix)]
        {
            if let Ok(mut term) =
                tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
            {
                tokio::select! {
                    _ = ctrl_c => {}
                    _ = term.recv() => {}
                }
            } else {
                let _ = ctrl_c.await;
            }
        }
        #[cfg(not(unix))]
        let _ = ctrl_c.await;
        token.cancel();
    });
}

fn announce(what: &str, addr: std::net::SocketAddr) {
    println!("{what} listening on {addr}");
    let _ = std::io::stdout().flush();
}

pub fn sim(args: &SimArgs) -> Result<()> {
    init_logs();
    if let Some(which) = &args.scene {
        let scene = load_scene(which, args.camera.as_deref())?;
        let room = std::sync::Arc::new(
            roomlight_sim::Room::build(scene)
                .with_context(|| format!("building the room of {which}"))?,
        );
        return serve_until_stopped("sim", &args.listen, |listener, cancel| {
            roomlight_lab::rendered::serve(room, args.seed, listener, cancel)
        });
    }
    let Some(model_out) = &args.model_out else {
        bail!("--model-out FILE is required for a synthetic room (or give --scene)");
    };
    if args.projectors == 0 || args.synthetic < args.projectors {
        bail!(
            "--projectors must be between 1 and --synthetic ({})",
            args.synthetic
        );
    }
    let problem = synthetic_room(&SyntheticConfig::new(args.synthetic, args.seed))?.problem;
    let per = args.synthetic.div_ceil(args.projectors);
    let owners: HashMap<String, Vec<u32>> = (0..args.projectors)
        .map(|p| {
            (
                format!("p{p}"),
                ((p * per) as u32..((p + 1) * per).min(args.synthetic) as u32).collect(),
            )
        })
        .filter(|(_, nodes): &(String, Vec<u32>)| !nodes.is_empty())
        .collect();
    let model = ModelFile {
        problem: problem.clone(),
        owners,
        start: None,
        patches: None,
    };
    write_json(model_out, &model)?;
    let plant = Plant::new(
        problem,
        PlantConfig {
            noise_scale: args.noise,
            seed: args.seed,
            ..PlantConfig::default()
        },
    )?;
    let room = VirtualRoom::new(plant);
    serve_until_stopped("sim", &args.listen, |listener, cancel| async move {
        serve_hardware(room, listener, cancel).await?;
        Ok(())
    })
}

/// A calibrated model file, checked.
fn load_model(path: &Path) -> Result<ModelFile> {
    let model: ModelFile = read_json(path, "a room model")?;
    let problem = model
        .problem
        .revalidate()
        .with_context(|| format!("{}: invalid model", path.display()))?;
    for (p, nodes) in &model.owners {
        if let Some(n) = nodes.iter().find(|&&n| n as usize >= problem.nodes()) {
            bail!(
                "{}: projector {p} owns node {n}, the model has {} nodes",
                path.display(),
                problem.nodes()
            );
        }
    }
    Ok(ModelFile { problem, ..model })
}

/// `roomlight optimum`: nodes, patches (and those left out), G* and G with every node black.
pub fn optimum(path: &Path) -> Result<()> {
    let model = load_model(path)?;
    let p = &model.problem;
    let best = roomlight_core::optimum::optimum(p)
        .with_context(|| format!("{}: the optimum", path.display()))?;
    // A patch left out by calibration over the wire: no column covers it and its target is
    // its black level.
    let left_out = (0..p.patches())
        .filter(|&i| {
            p.target()[i] == p.black()[i]
                && p.columns()
                    .iter()
                    .all(|c| c.get(i as u32) == LinearRgb::ZERO)
        })
        .count();
    println!(
        "{}: {} nodes of {} projectors, {} patches ({left_out} left out), G* {:.6e}, G at black {:.6e}",
        path.display(),
        p.nodes(),
        model.owners.len(),
        p.patches(),
        best.objective,
        best.objective_black
    );
    Ok(())
}

/// Calibration over the wire, before any projector: the survey, and the room's black level
/// (LEDs off, projectors dark) and target (the LED preset) measured through the charts; the
/// model has no nodes yet and admits every projector that says its resolution. With `resume`
/// (the model a camera agent calibrating over the wire wrote, e.g. before it was restarted)
/// nothing is measured: the room is lit by the node agents, which keep their light, and the
/// model goes on from where it was (new projectors are still calibrated as they join).
async fn survey_model(
    survey_path: &Path,
    preset: Option<&str>,
    resume: Option<(&Path, ModelFile)>,
    client: roomlight_lab::rendered::Client,
) -> Result<(RoomModel, roomlight_lab::rendered::RenderedCamera)> {
    let survey: SurveyFile = read_json(survey_path, "a survey file")?;
    let pixels = u64::from(survey.camera_width) * u64::from(survey.camera_height);
    if let Some(&bad) = survey
        .target_pixels
        .iter()
        .find(|&&i| u64::from(i) >= pixels)
    {
        bail!(
            "{}: target pixel {bad} outside the {}×{} camera",
            survey_path.display(),
            survey.camera_width,
            survey.camera_height
        );
    }
    let mut target_mask = vec![false; pixels as usize];
    for &i in &survey.target_pixels {
        target_mask[i as usize] = true;
    }
    let description = client
        .clone()
        .describe(roomlight_proto::v1::DescribeRequest {})
        .await
        .context("describing the rendered room")?
        .into_inner();
    if (description.camera_width, description.camera_height)
        != (survey.camera_width, survey.camera_height)
    {
        bail!(
            "{}: surveyed with a {}×{} camera, the room's is {}×{}",
            survey_path.display(),
            survey.camera_width,
            survey.camera_height,
            description.camera_width,
            description.camera_height
        );
    }
    let target_survey = |patches: Vec<usize>| camera::Survey {
        corners: survey.corners.clone(),
        sample: survey.sample,
        target_mask: target_mask.clone(),
        patches,
    };
    if let Some((path, model)) = resume {
        let patches = model.patches.clone().with_context(|| {
            format!(
                "{}: no patches (not written by a camera agent calibrating over the wire)",
                path.display()
            )
        })?;
        let charts =
            survey.corners.len() * roomlight_calib::charts::COLUMNS * roomlight_calib::charts::ROWS;
        if patches.len() != model.problem.patches() || patches.iter().any(|&i| i >= charts) {
            bail!(
                "{}: {} patches for a model of {}, of {charts} surveyed",
                path.display(),
                patches.len(),
                model.problem.patches()
            );
        }
        println!(
            "resumed {}: {} nodes of {} projectors",
            path.display(),
            model.problem.nodes(),
            model.owners.len()
        );
        let camera = roomlight_lab::rendered::RenderedCamera::new(
            client,
            survey.corners.clone(),
            patches.clone(),
            survey.sample,
        );
        let model = RoomModel {
            problem: model.problem,
            owners: model.owners,
            start: model.start,
            hot: Default::default(),
            survey: Some(target_survey(patches)),
        };
        return Ok((model, camera));
    }
    let preset = match preset {
        Some(p) if description.presets.iter().any(|q| q == p) => p.to_string(),
        Some(p) => bail!(
            "preset {p:?}: the room has {}",
            description.presets.join(", ")
        ),
        None => description
            .presets
            .first()
            .cloned()
            .context("the room has no LED preset to reproduce")?,
    };
    let camera = roomlight_lab::rendered::RenderedCamera::new(
        client,
        survey.corners.clone(),
        Vec::new(),
        survey.sample,
    );
    let sample = |image| {
        roomlight_calib::charts::sample_charts(&image, &survey.corners, &survey.sample)
            .context("sampling the charts")
    };
    camera.set_lights("").await?;
    let black = sample(camera.image().await?)?;
    camera.set_lights(&preset).await?;
    let target = sample(camera.image().await?)?;
    camera.set_lights("").await?;
    let ok = roomlight_calib::charts::PatchStatus::Ok;
    let patches: Vec<usize> = (0..target.len())
        .filter(|&i| black[i].status == ok && target[i].status == ok)
        .collect();
    if patches.is_empty() {
        bail!("no chart patch could be measured under both the LEDs and the dark");
    }
    let problem = Problem::new(
        Vec::new(),
        patches.iter().map(|&i| black[i].mean).collect(),
        patches.iter().map(|&i| target[i].mean).collect(),
        patches.iter().map(|&i| target[i].std_error).collect(),
    )?;
    println!(
        "survey: {} of {} patches measured, target from preset {preset}",
        patches.len(),
        target.len()
    );
    let camera = roomlight_lab::rendered::RenderedCamera::new(
        camera.client(),
        survey.corners.clone(),
        patches.clone(),
        survey.sample,
    );
    let model = RoomModel {
        problem,
        owners: HashMap::new(),
        start: None,
        hot: Default::default(),
        survey: Some(target_survey(patches)),
    };
    Ok((model, camera))
}

pub fn camera(path: &Path) -> Result<()> {
    init_logs();
    let file: CameraFile = read_toml(path)?;
    if file.model.is_some() == file.survey.is_some() {
        bail!(
            "{}: give either model (a calibrated room) or survey (calibration over the wire)",
            path.display()
        );
    }
    // Without its model a restarted camera agent would measure the room's black and target
    // again while the node agents keep their light on, and get both wrong.
    if file.survey.is_some() && file.model_out.is_none() {
        bail!(
            "{}: survey needs model_out, the file from which a restarted camera agent resumes",
            path.display()
        );
    }
    let config = CameraConfig {
        room: file.room.clone(),
        token: file.token,
        heartbeat: Duration::from_millis(file.heartbeat_ms.max(50)),
        deadline: Duration::from_millis(file.deadline_ms.max(10)),
        model_rounds: file.model_rounds,
        calibration_epoch: file.calibration_epoch,
        stale_frames: file.stale_frames,
        model_out: file.model_out.clone(),
    };
    runtime()?.block_on(async {
        let connect_rendered = || async {
            roomlight_lab::rendered::connect(file.hardware.clone())
                .await
                .with_context(|| format!("connecting to the rendered room at {}", file.hardware))
        };
        let (model, camera) = match (&file.model, &file.survey) {
            (_, Some(survey)) => {
                // The model this camera agent wrote before it was restarted, if any.
                let resume = match &file.model_out {
                    Some(out) if out.exists() => Some((out.as_path(), load_model(out)?)),
                    _ => None,
                };
                let (model, camera) = survey_model(
                    survey,
                    file.preset.as_deref(),
                    resume,
                    connect_rendered().await?,
                )
                .await?;
                (model, AnyCamera::Rendered(camera))
            }
            (Some(model_path), None) => {
                let model = load_model(model_path)?;
                let camera = match &file.charts {
                    Some(path) => {
                        let charts: ChartsFile = read_json(path, "a charts file")?;
                        if charts.patches.len() != model.problem.patches() {
                            bail!(
                                "{}: {} patches, the model {} has {}",
                                path.display(),
                                charts.patches.len(),
                                model_path.display(),
                                model.problem.patches()
                            );
                        }
                        AnyCamera::Rendered(roomlight_lab::rendered::RenderedCamera::new(
                            connect_rendered().await?,
                            charts.corners,
                            charts.patches,
                            charts.sample,
                        ))
                    }
                    None => AnyCamera::Synthetic(
                        RemoteCamera::connect(file.hardware.clone())
                            .await
                            .with_context(|| {
                                format!("connecting to the camera at {}", file.hardware)
                            })?,
                    ),
                };
                let model = RoomModel {
                    problem: model.problem,
                    owners: model.owners,
                    start: model.start,
                    hot: Default::default(),
                    survey: None,
                };
                (model, camera)
            }
            (None, None) => unreachable!("checked above"),
        };
        let listener = tokio::net::TcpListener::bind(&file.listen).await.with_context(|| format!("binding {}", file.listen))?;
        announce("camera", listener.local_addr()?);
        // Advertised for as long as the agent runs (withdrawn when dropped).
        let _advertisement = if file.mdns {
            let mdns = MdnsConfig { port: file.mdns_port, loopback_only: file.mdns_loopback_only };
            Some(discovery::advertise(&file.room, listener.local_addr()?, &mdns).with_context(|| format!("advertising room {:?} over mDNS (mdns = false turns it off)", file.room))?)
        } else {
            None
        };
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        let (mut status, handle) = camera::serve(config, model, camera, listener, cancel.clone());
        loop {
            tokio::select! {
                () = cancel.cancelled() => break,
                changed = status.changed() => {
                    if changed.is_err() {
                        break;
                    }
                    let s = status.borrow().clone();
                    println!("round {} captures {} objective {:.6e} live {} calibrated {}", s.round, s.captures, s.measured_objective, s.live_projectors, s.calibrated_hot);
                    let _ = std::io::stdout().flush();
                }
            }
        }
        handle.await.context("the camera agent task")??;
        Ok(())
    })
}

pub fn node(path: &Path) -> Result<()> {
    init_logs();
    let file: NodeFile = read_toml(path)?;
    let rule = match file.rule.as_str() {
        "safe" => StepRule::Safe { theta: file.theta },
        "momentum" => StepRule::Momentum { theta: file.theta },
        "paper" => StepRule::paper(),
        other => bail!(
            "{}: rule {other:?}, expected safe, momentum or paper",
            path.display()
        ),
    };
    rule.validate()
        .with_context(|| format!("{}: theta", path.display()))?;
    let kind = match file.kind.as_str() {
        "standard" => roomlight_proto::v1::ProjectorKind::Standard,
        "large-aperture" => roomlight_proto::v1::ProjectorKind::LargeAperture,
        other => bail!(
            "{}: kind {other:?}, expected standard or large-aperture",
            path.display()
        ),
    };
    if !(0.0..=1.0).contains(&file.start) {
        bail!(
            "{}: start {}, expected a value in [0, 1]",
            path.display(),
            file.start
        );
    }
    let endpoint = if file.camera == "mdns" {
        let mdns = MdnsConfig {
            port: file.mdns_port,
            loopback_only: file.mdns_loopback_only,
        };
        let found =
            discovery::find_camera(&file.room, &mdns, Duration::from_secs(file.mdns_wait_s))
                .with_context(|| format!("{}: camera = \"mdns\"", path.display()))?;
        tracing::info!(camera = %found, room = %file.room, "found over mDNS");
        found
    } else {
        file.camera.clone()
    };
    runtime()?.block_on(async {
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        let display = match &file.frame {
            Some(path) => {
                let spec: roomlight_lab::rendered::FrameSpec = read_json(path, "a frame file")?;
                if spec.projector != file.projector {
                    bail!(
                        "{}: drawn for projector {:?}, this node agent is {:?}",
                        path.display(),
                        spec.projector,
                        file.projector
                    );
                }
                let client = roomlight_lab::rendered::connect(file.hardware.clone())
                    .await
                    .with_context(|| {
                        format!("connecting to the rendered room at {}", file.hardware)
                    })?;
                let (name, size) = (spec.projector.clone(), (spec.width, spec.height));
                roomlight_lab::rendered::rendered_display(client, name, size, Some(spec), cancel.clone())
            }
            None if file.rendered => {
                let client = roomlight_lab::rendered::connect(file.hardware.clone())
                    .await
                    .with_context(|| {
                        format!("connecting to the rendered room at {}", file.hardware)
                    })?;
                // The projector reports its own mode, as a real display does.
                let room = client
                    .clone()
                    .describe(roomlight_proto::v1::DescribeRequest {})
                    .await
                    .context("describing the rendered room")?
                    .into_inner();
                let Some(p) = room.projectors.iter().find(|p| p.name == file.projector) else {
                    bail!(
                        "{}: projector {:?}, the rendered room has {}",
                        path.display(),
                        file.projector,
                        room.projectors
                            .iter()
                            .map(|p| p.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    );
                };
                let size = (p.width, p.height);
                roomlight_lab::rendered::rendered_display(
                    client,
                    p.name.clone(),
                    size,
                    None,
                    cancel.clone(),
                )
            }
            None => remote_display(file.hardware.clone(), cancel.clone())
                .await
                .with_context(|| format!("connecting to the display at {}", file.hardware))?,
        };
        let config = NodeConfig {
            endpoint,
            room: file.room,
            token: file.token,
            projector_id: file.projector,
            kind,
            rule,
            start: LinearRgb::splat(file.start),
            state_file: file.state_file,
        };
        node::run(config, display, cancel).await?;
        Ok(())
    })
}
