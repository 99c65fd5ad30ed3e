//! The processes of an installation: `roomlight sim`, `roomlight camera`, `roomlight node`.
//! Each prints `listening on ADDR` once it serves, logs with tracing (RUST_LOG), and stops
//! cleanly on Ctrl-C or SIGTERM (nodes say goodbye and flush their state file).

use anyhow::{Context, Result, bail};
use roomlight_agent::camera::CameraConfig;
use roomlight_agent::discovery::{self, MdnsConfig};
use roomlight_agent::node::NodeConfig;
use roomlight_core::{LinearRgb, StepRule};
use roomlight_lab::process::{
    self, CalibrateOptions, CameraProcess, CameraSource, NodeDisplay, SimRoom, SyntheticSim,
};
use serde::Deserialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tokio_util::sync::CancellationToken;

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

/// `WIDTHxHEIGHT`, both positive.
fn resolution(size: Option<&str>) -> Result<Option<[u32; 2]>> {
    let Some(size) = size else { return Ok(None) };
    let parsed = size
        .split_once('x')
        .and_then(|(w, h)| Some([w.parse::<u32>().ok()?, h.parse::<u32>().ok()?]))
        .filter(|[w, h]| *w > 0 && *h > 0);
    match parsed {
        Some(r) => Ok(Some(r)),
        None => bail!("--camera {size:?}: expected WIDTHxHEIGHT, e.g. 640x480"),
    }
}

pub fn calibrate(args: &CalibrateArgs) -> Result<()> {
    process::calibrate_to_files(&CalibrateOptions {
        scene: args.scene.clone(),
        camera: resolution(args.camera.as_deref())?,
        preset: args.preset.clone(),
        seed: args.seed,
        out: args.out.clone(),
        survey_only: args.survey_only,
    })
}

pub fn sim(args: &SimArgs) -> Result<()> {
    init_logs();
    let room = match &args.scene {
        Some(scene) => SimRoom::Rendered {
            scene: scene.clone(),
            camera: resolution(args.camera.as_deref())?,
            seed: args.seed,
        },
        None => {
            let Some(model_out) = &args.model_out else {
                bail!("--model-out FILE is required for a synthetic room (or give --scene)");
            };
            SimRoom::Synthetic(SyntheticSim {
                nodes: args.synthetic,
                projectors: args.projectors,
                seed: args.seed,
                noise: args.noise,
                model_out: model_out.clone(),
            })
        }
    };
    let prepared = process::prepare_sim(&room)?;
    serve_until_stopped("sim", &args.listen, |listener, cancel| {
        prepared.serve(listener, cancel)
    })
}

/// `roomlight optimum`: nodes, patches (and those left out), G* and G with every node black.
pub fn optimum(path: &Path) -> Result<()> {
    println!("{}", process::optimum_summary(path)?);
    Ok(())
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
    let source = match (file.model, file.survey) {
        (Some(model), _) => CameraSource::Model {
            model,
            charts: file.charts,
        },
        (None, Some(survey)) => CameraSource::Survey {
            survey,
            preset: file.preset,
        },
        (None, None) => unreachable!("checked above"),
    };
    let process = CameraProcess {
        agent: CameraConfig {
            room: file.room.clone(),
            token: file.token,
            heartbeat: Duration::from_millis(file.heartbeat_ms.max(50)),
            deadline: Duration::from_millis(file.deadline_ms.max(10)),
            model_rounds: file.model_rounds,
            calibration_epoch: file.calibration_epoch,
            stale_frames: file.stale_frames,
            model_out: file.model_out,
        },
        hardware: file.hardware,
        source,
        listen: file.listen,
        advertise: file.mdns.then_some(MdnsConfig {
            port: file.mdns_port,
            loopback_only: file.mdns_loopback_only,
        }),
    };
    runtime()?.block_on(async {
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        process::serve_camera(process, |addr| announce("camera", addr), cancel).await
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
    let display = match (file.frame, file.rendered) {
        (Some(frame), _) => NodeDisplay::Frame(frame),
        (None, true) => NodeDisplay::OverTheWire,
        (None, false) => NodeDisplay::Synthetic,
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
    runtime()?.block_on(async {
        let cancel = CancellationToken::new();
        stop_on_signals(cancel.clone());
        process::run_node(config, &file.hardware, &display, cancel)
            .await
            .with_context(|| format!("the node agent of {}", path.display()))
    })
}
